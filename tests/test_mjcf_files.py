"""The committed MJCF files (models/mjcf/) are what `python -m vlr.models.make_mjcf` writes today,
compile to the sim's own model, and load and step on their own."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from vlr.models import make_mjcf
from vlr.models.make_mjcf import HANDS, OUT_DIR, scene_pairs

SCENES = [f"scene_{h}_{o}.xml" for h, o in scene_pairs()]
# Fields that name things or hold the keyframe: the files add the `home` key and a scene's
# model name, so these legitimately differ from the sim's in-memory model.
_NAMING = ("name_", "names", "nnames", "nbuffer", "npaths", "paths", "signature", "key_",
           "nkey", "mesh_pathadr", "tex_pathadr", "hfield_pathadr", "skin_pathadr",
           "plugin_pathadr")


def test_committed_files_are_what_the_script_writes():
    expected = make_mjcf.generate()
    committed = {p.name: p.read_text() for p in sorted(OUT_DIR.glob("*.xml"))}
    assert sorted(committed) == sorted(expected), "run `python -m vlr.models.make_mjcf`"
    stale = [name for name, text in expected.items() if committed[name] != text]
    assert not stale, f"{stale} differ from the generator: run `python -m vlr.models.make_mjcf`"


@pytest.mark.parametrize("hand, obj", scene_pairs(), ids=[s[6:-4] for s in SCENES])
def test_scene_file_compiles_to_the_sims_model(hand, obj):
    from vlr.sim.model import build_scene, compile_scene

    from vlr.spec import load_hand, load_object

    ours = mujoco.MjModel.from_xml_path(str(OUT_DIR / f"scene_{hand}_{obj}.xml"))
    sims = compile_scene(build_scene(load_hand(hand), load_object(obj))).model
    differ = []
    for field in dir(sims):
        if field.startswith("_") or field.startswith(_NAMING):
            continue
        a, b = getattr(ours, field), getattr(sims, field)
        if isinstance(b, np.ndarray):
            if a.shape != b.shape or not np.array_equal(a, b):
                differ.append(field)
        elif isinstance(b, int | float) and a != b:
            differ.append(field)
    assert not differ, differ
    for kind in (mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_GEOM,
                 mujoco.mjtObj.mjOBJ_TENDON, mujoco.mjtObj.mjOBJ_ACTUATOR):
        count = {mujoco.mjtObj.mjOBJ_BODY: sims.nbody, mujoco.mjtObj.mjOBJ_JOINT: sims.njnt,
                 mujoco.mjtObj.mjOBJ_GEOM: sims.ngeom, mujoco.mjtObj.mjOBJ_TENDON: sims.ntendon,
                 mujoco.mjtObj.mjOBJ_ACTUATOR: sims.nu}[kind]
        assert [mujoco.mj_id2name(ours, kind, i) for i in range(count)] == \
            [mujoco.mj_id2name(sims, kind, i) for i in range(count)]


@pytest.mark.parametrize("name", [f"{h}.xml" for h in HANDS] + SCENES)
def test_file_steps_one_second_of_noise_over_its_control_range(name):
    """From `home`, random controls uniform in ctrlrange, resampled every 0.1 s."""
    model = mujoco.MjModel.from_xml_path(str(OUT_DIR / name))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    lo, hi = model.actuator_ctrlrange.T
    rng = np.random.default_rng(0)
    every = round(0.1 / model.opt.timestep)
    for k in range(round(1.0 / model.opt.timestep)):
        if k % every == 0:
            data.ctrl[:] = rng.uniform(lo, hi)
        mujoco.mj_step(model, data)
    warned = {mujoco.mjtWarning(i).name: w.number for i, w in enumerate(data.warning)
              if w.number}
    assert not warned, warned
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    assert np.all(np.isfinite(data.act)) and np.all(np.isfinite(data.qacc))
