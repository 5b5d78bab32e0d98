"""The live 3D view (vlr.view): geometry, server lifecycle, and what headless Chromium shows."""

import importlib.util
import subprocess
import sys

import numpy as np
import pytest

from vlr import view as view_mod
from vlr.cli import main
from vlr.filter import FilterConfig
from vlr.identify import LoopConfig, identify
from vlr.kinematics import HandModel, contact_points, joint_positions
from vlr.motion import MotionConfig, ObjectParams
from vlr.spec import load_hand, load_object
from vlr.synthetic import SyntheticConfig, SyntheticWorld, nominal_grasp
from vlr.view import COLORS, FilterView, find_chromium, hypotheses, screenshot

# The server tests need the `view` extra; the geometry and the headless path do not.
needs_meshcat = pytest.mark.skipif(importlib.util.find_spec("meshcat") is None,
                                   reason="meshcat is not installed (pip install -e '.[view]')")


def _model():
    return HandModel.from_spec(load_hand("modelo"))


def test_hypotheses_are_the_vlr_of_each_particle():
    m = _model()
    rng = np.random.default_rng(0)
    s, n, k = 7, m.n_fingers, m.n_joints
    theta = rng.uniform(-0.3, 1.0, (s, n, k))
    normals = rng.normal(size=(s, n, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    segments = np.broadcast_to(m.segments, (s, n, k)).copy()
    pom = rng.normal(0, 0.01, (s, 3)) + [0, 0, 0.07]
    h = hypotheses(m, theta, normals, segments, pom)
    q = joint_positions(m, theta, segments)
    c = contact_points(m, theta, normals, segments)
    # E^J: K links per finger and particle, from the base joint to the contact (Eq. 2).
    ej = h.joint_links.reshape(s, n, k, 2, 3)
    np.testing.assert_allclose(ej[:, :, 0, 0], np.broadcast_to(m.base_pos, (s, n, 3)))
    np.testing.assert_allclose(ej[:, :, :-1, 1], q[:, :, 1:])
    np.testing.assert_allclose(ej[:, :, -1, 1], c)
    np.testing.assert_allclose(h.distal_joints.reshape(s, n, 3), q[:, :, -1])
    np.testing.assert_allclose(h.contacts.reshape(s, n, 3), c)
    # E^C: every pair of {p_1..p_N, POM} (Eq. 1): (N+1)N/2 per particle, each POM used N times.
    ec = h.contact_links.reshape(s, (n + 1) * n // 2, 2, 3)
    touches_pom = np.all(np.isclose(ec, pom[:, None, None, :]), axis=-1).any(axis=-1)
    assert (touches_pom.sum(axis=1) == n).all()


def _trial(view: FilterView, iterations: int = 3, particles: int = 1500) -> None:
    m = _model()
    obj = ObjectParams.from_spec(load_object("apple"))
    world = SyntheticWorld(m, obj, SyntheticConfig(seed=1))
    view.truth = world.truth
    # The synthetic world's own model (pinned contacts), its prior about the pads' contacts.
    cfg = FilterConfig(particles=particles, motion=MotionConfig(rolling=False),
                       contact_prior="pad")
    identify(world, view.observing(world.observe), m, obj,
             nominal_grasp(m, obj, SyntheticConfig()), cfg,
             LoopConfig(max_iterations=iterations), seed=1, watch=view)


@needs_meshcat
def test_view_serves_exports_and_always_stops_its_server(tmp_path):
    with pytest.raises(RuntimeError, match="boom"), FilterView(_model()) as v:
        proc = v.server_process
        assert proc.poll() is None and v.url.startswith("http://")
        raise RuntimeError("boom")
    assert proc.poll() is not None  # stopped on the way out of an exception too
    with FilterView(_model(), obj=load_object("apple"), sample=200) as v:
        _trial(v, iterations=1, particles=300)
        assert v.iteration == 1
        page = v.save_html(tmp_path / "scene.html")
        proc = v.server_process
    assert proc.poll() is not None
    v.close()  # twice is fine
    html = page.read_text()
    assert "MeshCat.Viewer" in html and len(html) > 500_000  # the viewer script is inlined
    assert [p.name for p in tmp_path.iterdir()] == ["scene.html"]  # no temp file left


def test_headless_identify_never_imports_meshcat(tmp_path):
    code = ("import sys; from vlr.cli import main; "
            f"rc = main(['identify', '--backend', 'synthetic', '--particles', '200', "
            f"'--max-iterations', '1', '--quiet', '--out', {str(tmp_path)!r}]); "
            "assert rc == 0; assert 'meshcat' not in sys.modules and 'zmq' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, timeout=300)
    assert (tmp_path / "particles.png").stat().st_size > 1000


def test_view_without_meshcat_names_the_extra_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "meshcat", None)  # `import meshcat` raises ImportError
    rc = main(["identify", "--backend", "synthetic", "--particles", "200", "--max-iterations",
               "1", "--out", str(tmp_path), "--quiet", "--view"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the 3D view needs meshcat" in err[0] and ".[view]" in err[0], err


@needs_meshcat
def test_identify_view_flags_serve_then_save_and_stop(tmp_path, monkeypatch, capsys):
    views = []
    init = FilterView.__init__

    def spy(self, *a, **k):
        init(self, *a, **k)
        views.append(self)

    monkeypatch.setattr(view_mod.FilterView, "__init__", spy)
    page = tmp_path / "page" / "scene.html"
    rc = main(["identify", "--backend", "synthetic", "--particles", "300", "--max-iterations",
               "2", "--out", str(tmp_path / "run"), "--quiet", "--view", "--view-html",
               str(page)])
    assert rc == 0
    out = capsys.readouterr().out
    assert f"view: {views[0].url}" in out and str(page) in out
    assert views[0].server_process.poll() is not None
    assert "MeshCat.Viewer" in page.read_text()
    assert (tmp_path / "run" / "particles.png").stat().st_size > 1000


@needs_meshcat
def test_the_view_draws_the_ukfs_sigma_points(tmp_path, monkeypatch):
    drawn = []
    draw = FilterView.draw

    def spy(self, state, *a, **k):
        drawn.append((state.n, int(np.asarray(state.valid).sum())))
        return draw(self, state, *a, **k)

    monkeypatch.setattr(view_mod.FilterView, "draw", spy)
    page = tmp_path / "scene.html"
    rc = main(["identify", "--backend", "synthetic", "--estimator", "ukf", "--max-iterations",
               "1", "--out", str(tmp_path / "run"), "--quiet", "--view-html", str(page)])
    assert rc == 0 and "MeshCat.Viewer" in page.read_text()
    # One scene per update, of the 2D + 1 = 25 sigma points (those that settled).
    assert len(drawn) == 2 and all(n == 25 and valid > 12 for n, valid in drawn)


# --------------------------------------------------------------------------- in a browser

def _colour_pixels(png, rgb) -> int:
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    want = np.array(rgb) * 255
    return int(np.all(np.abs(img - want) <= 40, axis=-1).sum())


def _check_drawn(png) -> None:
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape[0] >= 500 and img.std() > 10, "blank canvas"
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 200, "blank canvas"
    # The hypotheses' colours (Fig. 4A): thousands of magenta E^J and red E^C pixels.
    assert _colour_pixels(png, COLORS["joint_links"]) > 300
    assert _colour_pixels(png, COLORS["contact_links"]) > 300


@pytest.fixture(scope="module")
def chromium():
    exe = find_chromium()
    if exe is None:
        pytest.skip("chromium is not installed (Debian: apt-get install chromium; "
                    ".ci/run installs it)")
    return exe


@needs_meshcat
def test_live_view_and_static_page_draw_in_headless_chromium(chromium, tmp_path):
    with FilterView(_model(), obj=load_object("apple"), sample=1000) as v:
        _trial(v)
        live = screenshot(v.url, tmp_path / "live.png", browser=chromium)
        page = v.save_html(tmp_path / "scene.html")
        proc = v.server_process
    assert proc.poll() is not None
    _check_drawn(live)
    # The static page is standalone: it draws with the server gone.
    _check_drawn(screenshot(page, tmp_path / "static.png", browser=chromium))
