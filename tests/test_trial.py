"""vlr.trial: what a trial's world is made of, and settings that make no sense refused."""

import pytest

import models
from vlr.errors import UserError
from vlr.trial import TrialSettings, open_world


def test_truth_settings_are_for_the_synthetic_world_only():
    with pytest.raises(UserError, match="true_stiffness"):
        TrialSettings(backend="sim", true_stiffness={"thumb.distal": 0.045})
    with pytest.raises(UserError, match="true_hand"):
        TrialSettings(backend="sim", true_hand="nh1")


def test_the_filter_models_the_object_the_hardware_config_names():
    """The config (apple) decides what is in the hand, not --object's value."""
    config = models.ROOT.parent / "hardware" / "example_sim_config.yaml"
    w = open_world(TrialSettings(backend="hardware", object="wine_glass", particles=100,
                                 config=str(config)))
    try:
        assert w.object_spec.name == "apple"
        assert w.obj.mass == pytest.approx(w.object_spec.mass)
    finally:
        w.close()
