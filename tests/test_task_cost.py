"""`python -m vlr.tasks.cost`: the environments' reset and step costs (docs/TASKS.md, "Cost")."""

import numpy as np
from vlr.tasks.cost import env_cost, main

from vlr import tasks


def test_a_cost_is_measured_per_reset_and_step():
    reset, step = env_cost(tasks.HANDWRITING, seeds=1, steps=1, identify=False, word="I")
    assert np.isfinite(reset) and reset > 0 and np.isfinite(step) and step > 0


def test_bad_input_is_one_line(capsys):
    assert main(["--ids", "vlr/Nope-v0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'vlr/Nope-v0'" in err
    assert "vlr/Handwriting-v2" in err and "vlr/HandwritingDense-v2" in err   # every id
    assert main(["--seeds", "0"]) == 2
    assert "--seeds 0" in capsys.readouterr().err
    assert main(["--particles", "5"]) == 2
    assert "--particles 5" in capsys.readouterr().err
