"""The hardware config loader: valid files load, bad ones name the file and the key."""

from __future__ import annotations

from pathlib import Path

import pytest
from vlr.hardware.config import HardwareConfigError, load_config
from vlr.hardware.control_table import OperatingMode

from tests.extras import needs_hardware
from tests.hardware_fixtures import config_dict, write_config
from vlr.spec import SpecError

ROOT = Path(__file__).resolve().parents[1]




def test_example_config_loads():
    cfg = load_config(ROOT / "hardware" / "example_config.yaml")
    assert cfg.ids == (1, 2, 3, 4)
    assert [f.slot for f in cfg.fingers] == ["thumb", "left", "right"]
    assert cfg.bus.baud == 57_600 and cfg.motion.mode == OperatingMode.CURRENT_BASED_POSITION
    assert cfg.camera.calibration.is_file()


def test_sim_example_config_loads():
    cfg = load_config(ROOT / "hardware" / "example_sim_config.yaml")
    assert cfg.bus.port == "emulator" and cfg.camera.fake == "sim" and cfg.spread is None
    assert cfg.camera.calibration is None


def test_error_is_a_value_error_the_cli_prints():
    assert issubclass(HardwareConfigError, ValueError)
    assert issubclass(HardwareConfigError, SpecError)


def _edit(section: str, key: str, value):
    data = config_dict()
    if key:
        data[section][key] = value
    else:
        data[section] = value
    return data


@pytest.mark.parametrize("data, message", [
    (_edit("bus", "baud", 12345), r"bus.baud = 12345 is not a baud rate"),
    (_edit("bus", "protocol", 1), r"bus.protocol = 1 is not supported"),
    (_edit("bus", "prot", 2), r"unknown key 'bus.prot'"),
    (_edit("motion", "spool_radius", -0.01), r"motion.spool_radius = -0.01 must be > 0"),
    (_edit("motion", "range", [0.03, 0.0]), r"motion.range = \[0.03, 0.0\] must be"),
    (_edit("motion", "mode", "velocity"), r"motion.mode = 'velocity' must be one of"),
    (_edit("motion", "max_step", "big"), r"motion.max_step = 'big' must be a finite number"),
    (_edit("fingers", "left", {"id": 300}), r"fingers.left.id = 300 must be in \[0, 252\]"),
    (_edit("fingers", "left", {"id": 2, "direction": 2}),
     r"fingers.left.direction = 2 must be 1 or -1"),
    (_edit("fingers", "left", {"id": 1}), r"motor ids \[1, 1, 3, 4\].*must be distinct"),
    (_edit("grasp", "commands", [0.01, 0.01]), r"grasp.commands = .* list of 3"),
    (_edit("grasp", "commands", [0.01, 0.01, 0.5]), r"right = 0.5 m outside motion.range"),
    (_edit("camera", "", {"calibration": "x.yaml"}), r"camera needs exactly one of"),
    (_edit("camera", "", {"index": 0, "calibration": "nope.yaml"}),
     r"camera.calibration = 'nope.yaml' does not exist"),
    (_edit("camera", "", {"fake": "sim"}), r"camera.fake = 'sim' needs bus.port"),
    (_edit("calibration", "current_ma", 900), r"must not exceed motion.current_limit_ma"),
    (_edit("emulator", "plant", "gazebo"), r"emulator.plant = 'gazebo' must be one of"),
    (_edit("spread", "position", 5000), r"spread.position = 5000 must be in \[0, 4095\]"),
    (_edit("hand", "", "nohand"), r"hand = 'nohand': unknown hand"),
    (_edit("object", "", "banana"), r"object = 'banana': unknown object"),
    (_edit("motion", "", None), r"motion = None must be a mapping"),
    (_edit("tension", "", {"newton_per_ma": 0, "zero_ma": [0, 0, 0]}),
     r"tension.newton_per_ma = 0 must be > 0"),
    (_edit("tension", "", {"newton_per_ma": 0.18, "zero_ma": [0, 0]}),
     r"tension.zero_ma = \[0, 0\] must be a list of 3"),
    (_edit("tension", "", {"newton_per_ma": 0.18}), r"tension.zero_ma"),
])
def test_bad_values_are_named(tmp_path, data, message):
    path = write_config(tmp_path, data)
    with pytest.raises(HardwareConfigError, match=message) as e:
        load_config(path)
    assert str(path) in str(e.value)


def test_missing_slot_and_key_and_file(tmp_path):
    data = config_dict()
    del data["fingers"]["thumb"]
    with pytest.raises(HardwareConfigError, match="fingers has no entry for slot 'thumb'"):
        load_config(write_config(tmp_path, data))
    data = config_dict()
    del data["object"]
    with pytest.raises(HardwareConfigError, match="missing key 'object'"):
        load_config(write_config(tmp_path, data))
    with pytest.raises(HardwareConfigError, match="does not exist"):
        load_config(tmp_path / "absent.yaml")
    (tmp_path / "bad.yaml").write_text("bus: [1, 2\n")
    with pytest.raises(HardwareConfigError, match="not valid YAML"):
        load_config(tmp_path / "bad.yaml")


def test_cli_prints_config_errors_in_one_line(tmp_path, capsys):
    from vlr.cli import main

    path = write_config(tmp_path, _edit("bus", "baud", 12345))
    assert main(["emulate", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vlr emulate: error:") and "bus.baud" in err
    assert "Traceback" not in err


@needs_hardware
def test_cli_prints_a_bad_camera_calibration_in_one_line(tmp_path, capsys):
    from vlr.cli import main

    (tmp_path / "cam.yaml").write_text("width: 640\n")
    data = config_dict()
    data["camera"]["calibration"] = "cam.yaml"
    path = write_config(tmp_path, data)
    out = tmp_path / "out"
    assert main(["identify", "--backend", "hardware", "--config", str(path), "--out",
                 str(out), "--particles", "100"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vlr identify: error: calibration file") and "height" in err
    assert "Traceback" not in err and not out.exists()


def test_unreadable_config_is_named(tmp_path):
    (tmp_path / "dir.yaml").mkdir()
    with pytest.raises(HardwareConfigError, match="dir.yaml is not a file"):
        load_config(tmp_path / "dir.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n")
    with pytest.raises(HardwareConfigError, match="must hold a mapping, got list"):
        load_config(tmp_path / "list.yaml")
