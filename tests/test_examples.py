"""examples/compare_policies.py: a user's policy, the baseline and a reference side by side
in one `vlr task` summary (a tiny filter: the plumbing, not the accuracy)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "compare_policies.py"


def test_compare_policies_prints_one_table_with_every_policy(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("compare_policies", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--particles", "300", "--identify-iterations", "2",
                        "--out", str(tmp_path)]) == 0
    table = capsys.readouterr().out.split("the policies side by side")[1]
    assert "| handwriting | 0 |" in table, table       # the baseline's row
    for policy in ("compare_policies.py:goal_step", "tasks.examples:hold"):
        assert f"| handwriting, policy {policy} | 0 |" in table, table
