"""The committed MJCF files (models/mjcf/<hand>/) are what `python -m vlr.models.make_mjcf`
writes today, compile to the sim's own model, are Menagerie model folders a viewer opens from
anywhere, and load and step on their own."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections import Counter

import cv2
import mujoco
import numpy as np
import pytest
from vlr.models import make_mjcf
from vlr.models.make_mjcf import HANDS, OUT_DIR, PICTURE, clean_name, scene_file, scene_pairs

SCENES = [scene_file(h, o) for h, o in scene_pairs()]
XML_FILES = [f"{h}/{h}.xml" for h in HANDS] + SCENES
# Fields that name things or hold the keyframe: the files add the `home` key and a scene's
# model name, so these legitimately differ from the sim's in-memory model.
_NAMING = ("name_", "names", "nnames", "nbuffer", "npaths", "paths", "signature", "key_",
           "nkey", "mesh_pathadr", "tex_pathadr", "hfield_pathadr", "skin_pathadr",
           "plugin_pathadr")
# The named elements compared name by name, with the model field that counts them.
_NAMED = {mujoco.mjtObj.mjOBJ_BODY: "nbody", mujoco.mjtObj.mjOBJ_JOINT: "njnt",
          mujoco.mjtObj.mjOBJ_GEOM: "ngeom", mujoco.mjtObj.mjOBJ_SITE: "nsite",
          mujoco.mjtObj.mjOBJ_TENDON: "ntendon", mujoco.mjtObj.mjOBJ_ACTUATOR: "nu",
          mujoco.mjtObj.mjOBJ_EQUALITY: "neq", mujoco.mjtObj.mjOBJ_CAMERA: "ncam",
          mujoco.mjtObj.mjOBJ_LIGHT: "nlight", mujoco.mjtObj.mjOBJ_MATERIAL: "nmat",
          mujoco.mjtObj.mjOBJ_TEXTURE: "ntex"}


def _committed() -> dict[str, bytes]:
    return {p.relative_to(OUT_DIR).as_posix(): p.read_bytes()
            for p in sorted(OUT_DIR.rglob("*")) if p.is_file() and p != PICTURE}


def test_committed_files_are_what_the_script_writes():
    expected = make_mjcf.generate()
    committed = _committed()
    assert sorted(committed) == sorted(expected), "run `python -m vlr.models.make_mjcf`"
    stale = [name for name, data in expected.items() if committed[name] != data]
    assert not stale, f"{stale} differ from the generator: run `python -m vlr.models.make_mjcf`"


def _scene_without_its_block(path) -> mujoco.MjModel:
    """The scene file compiled without what the scene block adds (floor, light, skybox)."""
    spec = mujoco.MjSpec.from_file(str(path))
    for element in (spec.geom("floor"), spec.light("scene_light"), spec.texture("skybox"),
                    spec.material("groundplane"), spec.texture("groundplane")):
        assert element is not None
        spec.delete(element)
    return spec.compile()


def _with_shared_meshes(root) -> mujoco.MjModel:
    """The sim's model (a `dm_control.mjcf` root), its fingers' copies of one mesh file made
    one mesh (the builder names an asset by its content's hash, so copies share a name)."""
    spec = mujoco.MjSpec.from_string(root.to_xml_string(), assets=root.get_assets())
    first: dict[str, str] = {}
    for mesh in list(spec.meshes):
        kept = first.setdefault(mesh.file, mesh.name)
        if kept != mesh.name:
            for geom in spec.geoms:
                if geom.meshname == mesh.name:
                    geom.meshname = kept
            spec.delete(mesh)
    return spec.compile()


def _assert_same_model(ours: mujoco.MjModel, sims: mujoco.MjModel) -> None:
    """Every number equal, and the same elements in the same order, named as the sim names
    them less its scopes."""
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
    assert sims.nbody > 1 and sims.njnt > 1 and sims.ntendon and sims.nu and sims.nmesh
    for kind, count in _NAMED.items():
        sims_names = [mujoco.mj_id2name(sims, kind, i) for i in range(getattr(sims, count))]
        assert [mujoco.mj_id2name(ours, kind, i) for i in range(getattr(ours, count))] == \
            [None if n is None else clean_name(n) for n in sims_names], kind.name


@pytest.mark.parametrize("hand, obj", scene_pairs(), ids=SCENES)
def test_scene_file_compiles_to_the_sims_model(hand, obj):
    from vlr.sim.model import build_scene

    from vlr.spec import load_hand, load_object

    ours = _scene_without_its_block(OUT_DIR / scene_file(hand, obj))
    sims = _with_shared_meshes(build_scene(load_hand(hand), load_object(obj)))
    assert sims.neq == 1
    _assert_same_model(ours, sims)


@pytest.mark.parametrize("hand", HANDS)
def test_hand_file_compiles_to_the_sims_hand(hand):
    from vlr.sim.model import build_hand

    from vlr.spec import load_hand

    ours = mujoco.MjModel.from_xml_path(str(OUT_DIR / hand / f"{hand}.xml"))
    _assert_same_model(ours, _with_shared_meshes(build_hand(load_hand(hand))))


def test_names_lose_their_scopes_one_to_one():
    assert clean_name("thumb/proximal") == "thumb_proximal"
    assert clean_name("thumb/") == "thumb_frame"
    assert clean_name("object/object") == "object"
    assert clean_name("object/object_free/") == "object_free"
    assert clean_name("palm") == "palm"


@pytest.mark.parametrize("name", SCENES)
def test_scene_loads_from_any_folder_with_floor_light_and_sky(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_path(os.path.relpath(OUT_DIR / name, tmp_path))
    assert mujoco.mjtGeom.mjGEOM_PLANE in model.geom_type
    assert model.nlight >= 1
    assert any(model.light_type[i] == mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
               and model.light_dir[i][2] < 0 for i in range(model.nlight))
    assert mujoco.mjtTexture.mjTEXTURE_SKYBOX in model.tex_type


@pytest.mark.parametrize("name", XML_FILES)
def test_no_name_is_scoped_and_each_mesh_file_is_declared_once(name):
    root = ET.parse(OUT_DIR / name).getroot()
    # No scoped name, nor a reference to one, nor a path out of the folder or into assets/.
    slashed = [(el.tag, k, v) for el in root.iter() for k, v in el.attrib.items() if "/" in v]
    assert not slashed, slashed
    declared = Counter(el.get("file") for el in root.iter("mesh"))
    assert all(n == 1 for n in declared.values()), declared
    # Compiled, with the hand file a scene includes.
    model = mujoco.MjModel.from_xml_path(str(OUT_DIR / name))
    assert not [n for n in model.names.split(b"\0") if b"/" in n]
    files = [model.paths[model.mesh_pathadr[i]:].split(b"\0")[0] for i in range(model.nmesh)]
    assert model.nmesh and len(files) == len(set(files)), files


@pytest.mark.parametrize("hand", HANDS)
def test_assets_folder_holds_one_file_per_asset_used(hand):
    folder = OUT_DIR / hand
    used = set()
    for path in folder.glob("*.xml"):
        root = ET.parse(path).getroot()
        used |= {el.get("file") for el in root.iter()
                 if el.tag in ("mesh", "texture") and el.get("file")}
        if path.name.startswith("scene"):
            assert [el.get("file") for el in root.iter("include")] == [f"{hand}.xml"]
    assert (folder / "scene.xml").is_file()
    files = sorted((folder / "assets").iterdir())
    assert sorted(p.name for p in files) == sorted(used)
    contents = [p.read_bytes() for p in files]
    assert len(set(contents)) == len(contents), "two asset files are copies"
    compiler = ET.parse(folder / f"{hand}.xml").getroot().find("compiler")
    assert compiler.get("meshdir") == "assets" and compiler.get("texturedir") == "assets"


def _assert_picture(path) -> None:
    image = cv2.imread(str(path))
    assert image is not None and image.shape == (480, 640, 3)
    assert path.stat().st_size < 200_000
    assert image.std() > 20  # not a blank frame


def test_committed_picture_is_a_small_png():
    assert PICTURE.is_file(), "run `python -m vlr.models.make_mjcf --picture`"
    _assert_picture(PICTURE)


def test_picture_renders_from_the_model_os_main_scene(tmp_path):
    assert make_mjcf.PICTURE_SCENE == OUT_DIR / scene_file("modelo", "apple")
    _assert_picture(make_mjcf.render_picture(out=tmp_path / "modelo.png"))


@pytest.mark.parametrize("name", XML_FILES)
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
