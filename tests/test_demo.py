"""`vlr demo`: a short identification in the sim, estimates beside the truth, next commands."""

import json

from vlr.cli import main


def test_demo_identifies_and_names_the_next_commands(tmp_path, capsys):
    # The smallest run that still goes through the grasp, one action and the scoring.
    rc = main(["demo", "--particles", "300", "--actions", "1", "--out", str(tmp_path)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "identified modelo holding apple after 1 actions" in out
    for row in ("thumb proximal", "left distal", "right distal"):
        assert row in out
    assert "[mm from the distal joint]" in out
    assert "inside their 95% intervals" in out
    for cmd in ("vlr identify", "vlr task", "vlr sweep", "vlr bench"):
        assert f"  {cmd}" in out
    result = json.loads((tmp_path / "result.json").read_text())
    assert (result["particles"], result["iterations"]) == (300, 1)


def test_demo_refuses_a_negative_budget(capsys):
    assert main(["demo", "--actions", "-1"]) == 2
    assert "--actions -1 must be >= 0" in capsys.readouterr().err


def test_demo_refuses_a_bad_setting(capsys):
    assert main(["demo", "--particles", "0"]) == 2
    assert "vlr demo: error:" in capsys.readouterr().err
