"""`vlr tension-calibrate`: the current-to-tension fit, on numbers, on the simulated hand
behind the emulated motors, and through the CLI with typed readings."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

pytest.importorskip("dynamixel_sdk", reason="the real hand's tests need the hardware extra "
                    "(pip install -e '.[hardware]')")

from vlr.hardware.config import load_config  # noqa: E402
from vlr.hardware.tension_calibration import (  # noqa: E402
    CalibrationInputError,
    TensionSample,
    fit_tension,
    prompt_tensions,
)

from tests.hardware_fixtures import config_dict, write_config  # noqa: E402
from vlr.cli import main  # noqa: E402


def _samples(slope, zeros, currents, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    zeros = np.asarray(zeros)
    out = []
    for c in currents:
        c = np.asarray(c, dtype=float)
        t = slope * (c - zeros) + noise * rng.standard_normal(c.shape)
        out.append(TensionSample(commands=np.zeros(len(c)), currents_ma=c, tensions_n=t))
    return out


def test_fit_recovers_the_slope_and_each_motors_zero():
    currents = [[40 + 20 * i, 55 + 18 * i, 30 + 25 * i] for i in range(5)]
    fit = fit_tension(_samples(0.18, [12.0, -5.0, 3.0], currents))
    assert fit.config.newton_per_ma == pytest.approx(0.18)
    np.testing.assert_allclose(fit.config.zero_ma, [12.0, -5.0, 3.0], atol=1e-9)
    assert fit.rms_n == pytest.approx(0.0, abs=1e-9)
    # Noisy load-cell readings: the RMS says how noisy (0.3 N here).
    noisy = fit_tension(_samples(0.18, [12.0, -5.0, 3.0], currents * 4, noise=0.3))
    assert noisy.config.newton_per_ma == pytest.approx(0.18, rel=0.05)
    assert 0.15 < noisy.rms_n < 0.4


def test_fit_refuses_readings_that_cannot_give_a_map():
    one = _samples(0.18, [0, 0, 0], [[50, 50, 50]])
    with pytest.raises(CalibrationInputError, match="at least 2"):
        fit_tension(one)
    flat = _samples(0.18, [0, 0, 0], [[50, 50, 50], [60, 50, 70]])  # left never changes
    with pytest.raises(CalibrationInputError, match="finger 1"):
        fit_tension(flat)
    with pytest.raises(CalibrationInputError, match="finger left's"):
        fit_tension(flat, ["thumb", "left", "right"])
    backwards = _samples(-0.18, [0, 0, 0], [[50, 40, 30], [70, 60, 50]])
    with pytest.raises(CalibrationInputError, match="not positive"):
        fit_tension(backwards)


def test_prompt_asks_again_until_it_has_one_number_per_finger():
    answers = iter(["12", "a b c", "12.5, 9 10.25"])
    read = prompt_tensions(["thumb", "left", "right"], ask=lambda prompt: next(answers))
    np.testing.assert_allclose(read(np.array([0.003, 0.002, 0.002])), [12.5, 9.0, 10.25])

    def ended(prompt):
        raise EOFError

    with pytest.raises(CalibrationInputError, match="input ended"):
        prompt_tensions(["thumb"], ask=ended)(np.array([0.003]))


def test_calibration_on_the_simulated_hand_recovers_its_torque_constant(tmp_path):
    """The sim plant's motors draw tension x spool radius / torque constant (hardware/
    sim_plant.py); the sim's own tensions as the load cell give back that constant, and the
    RMS of the fit is what the current's 2.69 mA unit costs."""
    pytest.importorskip("vlr.sim.backend")
    from vlr.hardware.sim_plant import TORQUE_CONSTANT
    from vlr.hardware.tension_calibration import collect_samples

    from tests.hardware_fixtures import hand_on_sim_plant, sim_config_dict

    cfg = load_config(write_config(tmp_path, sim_config_dict()))
    with hand_on_sim_plant(cfg) as (hand, _, plant):
        samples = collect_samples(
            hand, [-2e-4, 0.0, 2e-4, 4e-4, 6e-4],   # the CLI's default pulls
            lambda u: plant._call(lambda sim: sim.static_tensions()))
    fit = fit_tension(samples)
    # Measured 0.1815 against 0.1783 N/mA, zeros 1.2-2.8 mA, RMS 0.11 N.
    assert fit.config.newton_per_ma == pytest.approx(TORQUE_CONSTANT / 0.01 / 1000, rel=0.04)
    assert np.all(np.abs(fit.config.zero_ma) < 5.0)      # mA: the sim's motors have no offset
    assert fit.rms_n < 0.5                               # 2.69 mA is 0.48 N


def test_cli_writes_a_tension_section_the_config_accepts(tmp_path, monkeypatch, capsys):
    path = write_config(tmp_path, config_dict())
    # The kinematic plant's load current rises with the wind: typed tensions that rise too.
    answers = iter(f"{t} {t - 1} {t + 1}" for t in (8.0, 10.0, 12.0, 14.0, 16.0))
    monkeypatch.setattr("builtins.input", lambda prompt: next(answers))
    out = tmp_path / "tension.yaml"
    assert main(["tension-calibrate", "--config", str(path), "--out", str(out)]) == 0
    section = yaml.safe_load(out.read_text())["tension"]
    assert section["newton_per_ma"] > 0 and len(section["zero_ma"]) == 3
    data = yaml.safe_load(path.read_text())
    data.update(yaml.safe_load(out.read_text()))
    assert load_config(write_config(tmp_path, data, "with_tension.yaml")).tension is not None
    assert "give filter.observation.sigma_tension_n at least" in capsys.readouterr().out


def test_cli_refuses_pulls_outside_the_motion_range_before_moving(tmp_path, capsys):
    # No emulator behind this port: a refusal that opened the hand first would fail on it.
    path = write_config(tmp_path, config_dict(bus={"port": "/dev/null-no-motors",
                                                   "baud": 1_000_000}))
    out = tmp_path / "tension.yaml"
    assert main(["tension-calibrate", "--config", str(path), "--pulls-mm", "0", "40",
                 "--out", str(out)]) == 2
    assert main(["tension-calibrate", "--config", str(path), "--pulls-mm", "0.2", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "--pulls-mm 40" in err and "motion.range" in err and "Traceback" not in err
    assert "two different pulls" in err
    assert not out.exists()
    assert main(["tension-calibrate", "--config", str(path), "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_cli_input_that_ends_is_one_line_and_no_file(tmp_path, monkeypatch, capsys):
    path = write_config(tmp_path, config_dict())

    def ended(prompt):
        raise EOFError

    monkeypatch.setattr("builtins.input", ended)
    out = tmp_path / "tension.yaml"
    assert main(["tension-calibrate", "--config", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "input ended" in err and "Traceback" not in err
    assert not out.exists()
