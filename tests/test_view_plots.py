"""Trial pictures (vlr.plots): the particle cloud and the sweep box plots."""

from types import SimpleNamespace

import numpy as np
import pytest

from vlr.plots import CloudRecorder, boxplots, particle_cloud, pick_iterations


def test_pick_iterations_spans_first_to_last():
    assert pick_iterations(range(11), 4) == [0, 3, 7, 10]
    assert pick_iterations([0, 1], 4) == [0, 1]
    assert pick_iterations([5, 0, 5, 2]) == [0, 2, 5]


def test_cloud_recorder_samples_valid_particles_and_the_picture_draws(tmp_path):
    rng = np.random.default_rng(0)
    rec = CloudRecorder(sample=50, seed=0)
    for it in range(3):
        theta = rng.normal(0.3, 0.1 / (it + 1), (400, 3, 2))
        valid = np.ones(400, bool)
        valid[:200] = False
        theta[:200] = np.nan  # failed solves must never be drawn
        rec(SimpleNamespace(state=SimpleNamespace(theta=theta, valid=valid)),
            SimpleNamespace(iteration=it))
    assert sorted(rec.snapshots) == [0, 1, 2]
    assert rec.snapshots[2].shape == (50, 3, 2) and np.isfinite(rec.snapshots[2]).all()
    truth = {it: np.full((3, 2), 0.3) for it in range(3)}
    png = particle_cloud(tmp_path / "particles.png", rec.snapshots, ("a", "b", "c"),
                         truth=truth)
    assert png.stat().st_size > 5000
    with pytest.raises(ValueError, match="no snapshot"):
        particle_cloud(tmp_path / "none.png", rec.snapshots, ("a", "b", "c"), [7])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["particles.png"]


def _row(obj, hand, prox, **extra):
    return {"object": obj, "hand": hand,
            "errors": {"proximal_deg_mean": prox, "distal_deg_mean": 2 * prox, **extra}}


def test_boxplots_group_by_object_and_hand(tmp_path):
    rows = [_row("apple", "modelo", p, contact_mm_mean=1.0 + p) for p in (1.0, 1.5, 2.0)]
    rows += [_row("toy_block", "nh1", p, link_length_mm={"left": 3.0}) for p in (4.0, 5.0)]
    rows.append({"object": "apple", "hand": "modelo", "backend": "hardware"})  # no truth
    png = boxplots(rows, tmp_path / "sweep" / "boxplots.png")
    assert png.stat().st_size > 5000
    with pytest.raises(ValueError, match="no trial has errors"):
        boxplots([{"object": "apple", "hand": "modelo"}], tmp_path / "empty.png")
    assert not (tmp_path / "empty.png").exists()
