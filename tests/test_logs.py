"""`vlr -v` / `-q` and the project's log lines (`vlr.logs`); a missing extra named in one line."""

import logging
import sys

import pytest

from vlr.backends import get_backend
from vlr.cli import main
from vlr.logs import configure, level_for


@pytest.fixture(autouse=True)
def _restore_levels():
    yield
    configure(logging.INFO)  # as `vlr` leaves them, whatever a test set


def test_flags_set_the_level():
    assert level_for() == logging.INFO
    assert level_for(verbose=1) == logging.DEBUG
    assert level_for(quiet=1) == logging.WARNING
    assert level_for(quiet=2) == logging.ERROR


def test_lines_keep_the_hardware_prefix(capsys):
    configure(logging.INFO)
    logging.getLogger("vlr.hardware.backend").info("tendon zeros found")
    logging.getLogger("vlr.hardware.backend").warning("motor 2 did not confirm torque off")
    logging.getLogger("vlr.hardware.backend").debug("not shown")
    assert capsys.readouterr().err.splitlines() == [
        "[hardware] tendon zeros found",
        "[hardware] WARNING: motor 2 did not confirm torque off"]


def test_verbose_identify_logs_each_iteration_and_quiet_logs_nothing(tmp_path, capsys):
    args = ["identify", "--backend", "synthetic", "--particles", "200", "--max-iterations",
            "1", "--quiet", "--out", str(tmp_path)]
    assert main(["-v", *args]) == 0
    err = capsys.readouterr().err
    assert "[vlr.run] iteration 1: mean 95% interval" in err
    assert main(["-q", *args]) == 0
    assert capsys.readouterr().err == ""


def test_the_hardware_backend_without_its_extra_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "dynamixel_sdk", None)  # `import` raises ImportError
    for name in ("vlr.hardware.backend", "vlr.hardware.bus", "vlr.hardware.calibration",
                 "vlr.hardware.tendons"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    get_backend.cache_clear()
    try:
        rc = main(["identify", "--backend", "hardware", "--config", "my_hand.yaml",
                   "--out", str(tmp_path / "o")])
    finally:
        get_backend.cache_clear()
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    # (Without the extra at all, pyserial is the first import missing.)
    assert len(err) == 1 and ".[hardware]" in err[0], err
    assert "needs dynamixel-sdk" in err[0] or "needs pyserial" in err[0], err


def test_a_root_handler_does_not_print_the_projects_lines_twice(capsys):
    """`import dm_control.mjcf` (through absl) installs a root handler; the project's
    records must not propagate to it."""
    root = logging.getLogger()
    extra = logging.StreamHandler(sys.stderr)
    root.addHandler(extra)
    try:
        configure(logging.INFO)
        logging.getLogger("vlr.run").info("sim world open")
    finally:
        root.removeHandler(extra)
    assert capsys.readouterr().err.splitlines() == ["[vlr] sim world open"]


def test_the_progress_bar_follows_quiet_and_the_terminal(monkeypatch):
    from vlr.logs import progress_bar

    class Terminal:
        def isatty(self):
            return True

        def write(self, text):
            pass

        def flush(self):
            pass

    configure(logging.INFO)
    assert progress_bar(total=1).disable                      # stderr here is no terminal
    assert not progress_bar(total=1, file=Terminal()).disable
    assert progress_bar(True, total=1, file=Terminal()).disable      # --quiet
    configure(logging.WARNING)                                        # vlr -q
    assert progress_bar(total=1, file=Terminal()).disable
