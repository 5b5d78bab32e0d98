"""Spec files are strict: an unknown key or a value of the wrong type is refused with one
line naming the file, the key and what is accepted there, never silently defaulted."""

from pathlib import Path

import pytest

from vlr import models
from vlr.cli import main
from vlr.spec import (
    SpecError,
    available_fingers,
    available_hands,
    available_objects,
    load_finger,
    load_hand,
    load_object,
)

LOADERS = {"objects": load_object, "fingers": load_finger, "hands": load_hand}


def _edited(tmp_path: Path, folder: str, name: str, old: str, new: str) -> Path:
    """A copy of models/FOLDER/NAME.yaml in tmp_path with `old` replaced by `new` once."""
    text = (models.ROOT / folder / f"{name}.yaml").read_text()
    assert text.count(old) >= 1, f"{old!r} is not in {folder}/{name}.yaml"
    # Relative mesh paths are resolved against the file, which moves to tmp_path.
    text = text.replace("../assets/", f"{models.ROOT / 'assets'}/")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize("folder, name, old, new, message", [
    # Misspelt keys: named, with the key they resemble and the keys accepted there.
    ("objects", "apple", "friction:", "frction:",
     "unknown key 'frction' (did you mean 'friction'?); accepted: com, extras, friction,"),
    ("objects", "apple", "mass:", "mas:", "unknown key 'mas' (did you mean 'mass'?)"),
    ("objects", "cup1", "upright:", "uprigth:",
     "unknown key 'extras.uprigth' (did you mean 'extras.upright'?); accepted in extras:"),
    ("fingers", "modelo", "pad_radius:", "pad_raduis:",
     "unknown key 'pad_raduis' (did you mean 'pad_radius'?); accepted: distal_length,"),
    ("fingers", "modelo", "  distal_visual:", "  distal_visul:",
     "unknown key 'meshes.distal_visul' (did you mean 'meshes.distal_visual'?); "
     "accepted in meshes: distal_collision, distal_visual, proximal_collision, "
     "proximal_visual"),
    ("hands", "modelo", "spread:", "sprad:",
     "unknown key 'sprad' (did you mean 'spread'?); accepted: name, palm_radius, "
     "palm_thickness, slots, spread, tendon_stiffness"),
    ("hands", "modelo", "slot: left,  position", "slot: left,  positon",
     "unknown key 'slots[1].positon' (did you mean 'slots[1].position'?); "
     "accepted in slots[1]: finger, position, slot, yaw"),
    # Wrong types and shapes: the key, the value given and what it must be.
    ("objects", "apple", "mass: 0.068", "mass: heavy", "mass = 'heavy' must be a number"),
    ("objects", "apple", "com: [0.0, 0.0, 0.0395]", "com: [0.0, 0.0395]",
     "com = [0.0, 0.0395] must be a list of 3 numbers (x, y, z)"),
    ("objects", "apple", "size: [0.0375]", "size: [0.0375, 0.01]",
     "size = [0.0375, 0.01] must be a list of 1 number (sphere: radius)"),
    ("objects", "cup1", "upright: true", "upright: 1",
     "extras.upright = 1 must be true or false"),
    ("fingers", "modelo", "pad_radius: 0.012", "pad_radius: '12 mm'",
     "pad_radius = '12 mm' must be a number"),
    ("fingers", "modelo", "pad_center: [0.0, 0.003, 0.032]", "pad_center: [0.003, 0.032]",
     "pad_center = [0.003, 0.032] must be a list of 3 numbers (x, y, z)"),
    ("fingers", "modelo", "[0.0, 1.24]]", "[0.0]]", "limits[1] = [0.0] must be a list of 2 "
     "numbers"),
    ("hands", "modelo", "yaw: 1.5707963, finger: modelo}", "yaw: north, finger: modelo}",
     "slots[0].yaw = 'north' must be a number"),
    ("hands", "modelo", "position: [0.0, -0.034, 0.012]", "position: [0.0, -0.034]",
     "slots[0].position = [0.0, -0.034] must be a list of 3 numbers (x, y, z)"),
])
def test_unknown_keys_and_wrong_types_are_refused_in_one_line(tmp_path, folder, name, old,
                                                              new, message):
    path = _edited(tmp_path, folder, name, old, new)
    with pytest.raises(SpecError) as info:
        LOADERS[folder](path)
    text = str(info.value)
    assert "\n" not in text
    assert text.startswith(f"{path}: {message}"), text


def test_a_bad_finger_file_is_named_through_the_hand_that_uses_it(tmp_path):
    finger = _edited(tmp_path, "fingers", "nf1", "stiffness:", "stifness:")
    hand = _edited(tmp_path, "hands", "nh1", "finger: nf1", f"finger: {finger.name}")
    with pytest.raises(SpecError) as info:
        load_hand(hand)
    assert str(info.value).startswith(
        f"{hand}: slots[1].finger = 'nf1.yaml': {finger}: unknown key 'stifness' "
        "(did you mean 'stiffness'?)"), str(info.value)


def test_every_spec_in_models_loads():
    for names, load in ((available_fingers(), load_finger), (available_hands(), load_hand),
                        (available_objects(), load_object)):
        assert names
        for name in names:
            load(name)


@pytest.mark.parametrize("option, folder, name, old, new, message", [
    ("--object", "objects", "apple", "friction:", "frction:",
     "unknown key 'frction' (did you mean 'friction'?)"),
    ("--hand", "hands", "modelo", "tendon_stiffness: 20000.0", "tendon_stiffness: [20000.0]",
     "tendon_stiffness = [20000.0] must be a number"),
])
def test_the_cli_exits_2_with_the_one_line(tmp_path, capsys, option, folder, name, old, new,
                                           message):
    bad = _edited(tmp_path, folder, name, old, new)
    out = tmp_path / "run"
    rc = main(["identify", "--backend", "synthetic", option, str(bad), "--out", str(out),
               "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(f"vlr identify: error: {bad}: {message}"), err
    assert not out.exists()
