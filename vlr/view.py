"""A live 3D view of the particle filter in meshcat, in the style of the paper's Fig. 4A.

Per filter iteration the view draws a random sample of the hypotheses (particles):

* the joint virtual links E^J (Eq. 2; base joint -> ... -> distal joint -> contact), magenta,
* the distal joints, blue points,
* the estimated contacts p_i, yellow points,
* the contact virtual links E^C (Eq. 1; every pair of {p_1..p_N, POM}), red,

each kind as ONE meshcat object per iteration (thousands of segments in one buffer, not one
object per segment), plus the observed POM frame (a triad), the hand (the true hand where the
backend knows it, else the posterior-mean hand; links as cylinders from `HandModel`
kinematics) and the object as its primitive shape.

Nothing here runs unless a view is asked for: `meshcat` is imported by `FilterView` only.

Python:

    with FilterView(model, obj=obj_spec) as view:
        identify(world, view.observing(observer), model, obj, nominal, cfg, watch=view)
        view.save_html("scene.html")

The server is meshcat-python 0.3.2's (tornado + zmq), started by `vlr._meshcat_server`
rather than by meshcat: meshcat's own listens on every interface, without authentication,
and outlives a killed parent. Ours listens on 127.0.0.1 only unless `host` says otherwise,
and dies with the process that started it (see `FilterView`). It opens no browser.
`Visualizer.close()` is broken in 0.3.2 (AttributeError), so `FilterView.close()` kills the
server process itself, and is also registered with atexit.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vlr.errors import Interrupted, MissingExtra, UserError
from vlr.kinematics import HandModel, contact_points, joint_positions

__all__ = ["COLORS", "Hypotheses", "hypotheses", "FilterView", "find_chromium", "screenshot"]

# Fig. 4A's colours (RGB in 0..1).
COLORS: dict[str, tuple[float, float, float]] = {
    "joint_links": (1.0, 0.0, 1.0),     # E^J, magenta
    "distal_joints": (0.0, 0.0, 1.0),   # blue
    "contacts": (1.0, 0.85, 0.0),       # yellow
    "contact_links": (1.0, 0.0, 0.0),   # E^C, red
}
_HAND_RGB = (0.55, 0.55, 0.6)


# --------------------------------------------------------------------------- geometry (no meshcat)

@dataclass(frozen=True)
class Hypotheses:
    """What the view draws of a particle sample, in the palm frame [m].

    Attributes:
        joint_links: (M, 2, 3) E^J segments, S*N*K of them (K per finger and particle).
        distal_joints: (S*N, 3) distal joint positions.
        contacts: (S*N, 3) contact points.
        contact_links: (L, 2, 3) E^C segments, S*(N+1)N/2 of them.
    """

    joint_links: np.ndarray
    distal_joints: np.ndarray
    contacts: np.ndarray
    contact_links: np.ndarray


def hypotheses(model: HandModel, theta: np.ndarray, normals: np.ndarray,
               segments: np.ndarray, pom: np.ndarray) -> Hypotheses:
    """The VLR of S particles (Eq. 1-3) as drawable points and segments.

    Args:
        theta: (S, N, K) joint angles [rad]; normals: (S, N, 3) pad normals in D;
        segments: (S, N, K) (`vlr.kinematics`); pom: (S, 3) POM positions [m].
    """
    q = joint_positions(model, theta, segments)                # (S, N, K, 3)
    c = contact_points(model, theta, normals, segments)        # (S, N, 3)
    # E^J: q^k -> q^{k+1} along the chain, then the distal virtual link q^K -> p_i.
    ends = np.concatenate([q[..., 1:, :], c[..., None, :]], axis=-2)
    joint_links = np.stack([q, ends], axis=-2).reshape(-1, 2, 3)
    # E^C: every pair of {p_1..p_N, p_obj} (docs/METHOD.md 2).
    pts = np.concatenate([c, np.asarray(pom)[:, None, :]], axis=1)
    i, j = np.triu_indices(pts.shape[1], k=1)
    contact_links = np.stack([pts[:, i], pts[:, j]], axis=-2).reshape(-1, 2, 3)
    return Hypotheses(joint_links=joint_links, distal_joints=q[..., -1, :].reshape(-1, 3),
                      contacts=c.reshape(-1, 3), contact_links=contact_links)


def _hand_links(model: HandModel, theta: np.ndarray,
                segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Physical links of one hand configuration: (N*K, 2, 3) segments (the last link of each
    finger ends at its pad centre) and (N, 3) pad centres [m]."""
    q = joint_positions(model, theta, segments)                               # (N, K, 3)
    pad = contact_points(model, theta, np.zeros((model.n_fingers, 3)), segments)  # n = 0
    ends = np.concatenate([q[:, 1:, :], pad[:, None, :]], axis=1)
    return np.stack([q, ends], axis=-2).reshape(-1, 2, 3), pad


def _segment_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """4x4 transform taking meshcat's unit cylinder (height 1 along y, centred) onto a -> b."""
    d = b - a
    length = float(np.linalg.norm(d))
    y = d / length if length > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.eye(3)[int(np.argmin(np.abs(y)))]  # the axis least aligned with y
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    t = np.eye(4)
    t[:3, 0], t[:3, 1], t[:3, 2] = x, y * max(length, 1e-6), z
    t[:3, 3] = 0.5 * (a + b)
    return t


def _pose_matrix(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = position
    return t


def _hex(rgb: Sequence[float]) -> int:
    r, g, b = (int(round(255 * float(v))) for v in rgb[:3])
    return (r << 16) | (g << 8) | b


def _meshcat() -> Any:
    # pyzmq warns that meshcat's zmq.eventloop.ioloop import is deprecated; that is
    # meshcat's business, and a test run with -W error must not fail on it.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            import meshcat
            import meshcat.geometry  # noqa: F401
        except ImportError as exc:
            raise MissingExtra(exc.name or "meshcat", "view", "the 3D view") from exc
    return meshcat


# --------------------------------------------------------------------------- the server

_SERVER_START_S = 60.0  # a start takes about a second; past this it is stuck, not slow


def bind_address(host: str) -> str:
    """The numeric address the view's server binds for `host` (a name or an address; IPv4
    first), checked by binding a probe socket to it, so that a host this machine cannot
    listen on is one clear line and not a server that tries a thousand ports.

    Raises:
        UserError: `host` does not resolve, or is not an address of this machine.
    """
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError, ValueError) as exc:
        raise UserError(f"view host {host!r} is not an address or a known host name "
                        f"({exc})") from None
    infos.sort(key=lambda info: info[0] != socket.AF_INET)
    family, address = infos[0][0], str(infos[0][4][0])
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        try:
            probe.bind((address, 0))
        except OSError as exc:
            raise UserError(f"view host {host!r}: this machine cannot listen on {address} "
                            f"({exc.strerror or exc})") from None
    return address


def _start_server(address: str) -> tuple[subprocess.Popen, Any, str, str]:
    """Start `vlr._meshcat_server` on `address`: (process, its stderr file, zmq URL to
    connect to, web URL it serves). Its own session, so that a terminal's Ctrl-C reaches
    only us and we stop it in order; it exits by itself when this process dies."""
    from vlr._meshcat_server import connect_host, url_host

    meshcat_root = Path(_meshcat().__file__).resolve().parent.parent
    vlr_root = Path(__file__).resolve().parent.parent
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(vlr_root), str(meshcat_root)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH")
                                              else []))
    err = tempfile.TemporaryFile()  # read only if the start fails; never fills a pipe
    cmd = [sys.executable, "-u", "-m", "vlr._meshcat_server", "--host", address,
           "--parent-pid", str(os.getpid())]
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=err, env=env, bufsize=0, start_new_session=True)
    urls: dict[str, str] = {}
    deadline = time.monotonic() + _SERVER_START_S
    try:
        while len(urls) < 2:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([proc.stdout], [], [], left)[0]:
                raise RuntimeError(f"the meshcat server did not start within "
                                   f"{_SERVER_START_S:.0f} s")
            line = proc.stdout.readline()  # unbuffered: select sees every line
            if not line:
                err.seek(0)
                tail = err.read().decode(errors="replace").strip()[-2000:]
                raise RuntimeError(f"the meshcat server exited on start (exit "
                                   f"{proc.wait(timeout=10)}): {tail}")
            key, _, value = line.decode(errors="replace").strip().partition("=")
            if key in ("zmq_url", "web_url"):
                urls[key] = value
    except BaseException:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        proc.stdout.close()
        err.close()
        raise
    proc.stdout.close()  # the server sends nothing more (its stdout is /dev/null now)
    bound, local = url_host(address), url_host(connect_host(address))
    web = urls["web_url"].replace(f"//{bound}:", f"//{local}:", 1)
    return proc, err, urls["zmq_url"], web


def _terminate(signum: int, frame: object) -> None:
    """SIGTERM while a view is open: unwind like Ctrl-C, so that `finally` blocks and
    `FilterView.close` run (the default action ends the process on the spot). Later ones
    are ignored: the close path must not be cut short."""
    signal.signal(signum, signal.SIG_IGN)
    raise Interrupted(signum)


# --------------------------------------------------------------------------- the view

class FilterView:
    """A meshcat scene of the filter's hypotheses; use as `identify(..., watch=view)`.

    Args:
        model: the hand model the filter uses.
        obj: the object's `ObjectSpec`, to draw its primitive shape (None: no object).
        sample: particles drawn per iteration (a uniform sample of the equally weighted,
            resampled set; 500-2000 reads well).
        seed: seed of the sampling Generator.
        truth: optional callable returning the current ground truth (`vlr.synthetic.Truth`);
            the hand and object are then drawn where they really are. Drawing only.
        palm_radius, palm_thickness: the palm disc [m] (HandSpec's; None: from the mounts).
        zmq_url: an already running meshcat server (None: start one, and own it).
        host: the address (or host name) the started server's web page listens on (its
            zmq port stays on the loopback). 127.0.0.1 by default: the page has no
            authentication, so serving it
            to the network ("0.0.0.0", an interface's address) is the caller's choice.

    The server started is stopped by `close()` (also at exit), and dies with this process
    whatever ends it: on Linux the kernel sends it SIGTERM when the thread that opened the
    view exits (PR_SET_PDEATHSIG; SIGKILL and out-of-memory kills included), elsewhere it
    notices within a second. While the view is open in the main thread, SIGTERM raises
    `vlr.errors.Interrupted` (a KeyboardInterrupt) so that the run's `finally` blocks and
    `close()` run; a SIGTERM handler the program set itself is left alone, and the one found
    is restored on close.

    Raises:
        UserError: `host` does not resolve or is not an address of this machine.
    """

    def __init__(self, model: HandModel, obj: Any = None, *, sample: int = 1000,
                 seed: int = 0, truth: Callable[[], Any] | None = None,
                 palm_radius: float | None = None, palm_thickness: float = 0.02,
                 zmq_url: str | None = None, host: str = "127.0.0.1") -> None:
        if sample < 1:
            raise ValueError(f"sample {sample} must be >= 1")
        self.model, self.obj, self.sample, self.truth = model, obj, sample, truth
        self._rng = np.random.default_rng(seed)
        self._last_observation: Any = None
        self._camera_set = False
        self._closed = False
        self._stderr: Any = None
        self._old_sigterm: Any = None
        meshcat = _meshcat()
        self._g = meshcat.geometry
        if zmq_url is not None:  # join a server someone else runs (and stops)
            self.host: str | None = None
            with contextlib.redirect_stdout(io.StringIO()):  # it prints its URL
                self._vis = meshcat.Visualizer(zmq_url=zmq_url)
            self._url = self._vis.url()
        else:
            self.host = bind_address(host)
            proc, self._stderr, zmq_url, self._url = _start_server(self.host)
            try:
                if ":" in self.host:  # zmq sockets are IPv4-only unless told
                    import zmq

                    meshcat.visualizer.ViewerWindow.context.setsockopt(zmq.IPV6, 1)
                with contextlib.redirect_stdout(io.StringIO()):  # it prints the server's URL
                    window = meshcat.visualizer.ViewerWindow(
                        zmq_url=zmq_url, start_server=False, server_args=[])
            except BaseException:
                proc.kill()
                proc.wait(timeout=10)
                self._stderr.close()
                raise
            window.server_proc = proc
            self._vis = meshcat.Visualizer(window=window)
        self._root = self._vis["vlr"]  # everything we draw, in the palm frame
        atexit.register(self.close)  # the server must not outlive us, whatever happens
        self._catch_sigterm()
        self.iteration: int | None = None
        try:
            self._static_scene(palm_radius, palm_thickness)
        except BaseException:
            self.close()
            raise

    # ---- lifecycle

    @property
    def url(self) -> str:
        """The page to open in a browser on this machine (a server on every interface is
        shown at its loopback address)."""
        return self._url

    @property
    def server_process(self) -> subprocess.Popen | None:
        """The meshcat server process this view started (None if it joined a server)."""
        return getattr(self._vis.window, "server_proc", None)

    def close(self) -> None:
        """Stop the meshcat server this view started; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        self._restore_sigterm()
        window = self._vis.window
        sock = getattr(window, "zmq_socket", None)
        if sock is not None:
            sock.close(linger=0)
        proc = self.server_process
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        for stream in (getattr(proc, "stdout", None), getattr(proc, "stderr", None),
                       self._stderr):
            if stream is not None:
                stream.close()

    def _catch_sigterm(self) -> None:
        """SIGTERM -> `Interrupted` while open (see the class), from the main thread only
        (where Python runs signal handlers) and only over the default action."""
        if threading.current_thread() is not threading.main_thread():
            return
        if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
            self._old_sigterm = signal.signal(signal.SIGTERM, _terminate)

    def _restore_sigterm(self) -> None:
        old, self._old_sigterm = self._old_sigterm, None
        if old is None or threading.current_thread() is not threading.main_thread():
            return
        if signal.getsignal(signal.SIGTERM) in (_terminate, signal.SIG_IGN):  # still ours
            signal.signal(signal.SIGTERM, old)

    def __enter__(self) -> FilterView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- hooks for vlr.identify

    def observing(self, observer: Callable[[], Any]) -> Callable[[], Any]:
        """Wrap an observer so that the view sees each observed POM pose it returns."""
        def observe() -> Any:
            obs = observer()
            if obs is not None:
                self._last_observation = obs
            return obs
        return observe

    def __call__(self, pf: Any, rec: Any) -> None:
        """The `watch(pf, rec)` hook of `vlr.identify.identify`: draw this iteration."""
        truth = self.truth() if self.truth is not None else None
        self.draw(pf.state, observation=self._last_observation, truth=truth,
                  iteration=getattr(rec, "iteration", None))

    # ---- drawing

    def draw(self, state: Any, observation: Any = None, truth: Any = None,
             iteration: int | None = None) -> None:
        """Draw a sample of `state` (a `vlr.motion.ParticleState`), the observed POM frame
        (anything with .position and .rotation) and the hand (truth, else posterior mean)."""
        vis, m = self._root, self.model
        ok = np.asarray(state.valid, dtype=bool) & np.all(
            np.isfinite(state.theta.reshape(state.n, -1)), axis=1)
        pool = np.flatnonzero(ok)
        if pool.size == 0:
            return
        idx = np.sort(self._rng.choice(pool, size=min(self.sample, pool.size), replace=False))
        h = hypotheses(m, state.theta[idx], state.normals[idx], state.segments[idx],
                       state.pos[idx])
        self._lines("particles/joint_links", h.joint_links, COLORS["joint_links"])
        self._lines("particles/contact_links", h.contact_links, COLORS["contact_links"])
        self._points("particles/distal_joints", h.distal_joints, COLORS["distal_joints"],
                     0.003)
        self._points("particles/contacts", h.contacts, COLORS["contacts"], 0.003)
        if observation is not None:
            vis["pom/observed"].set_transform(_pose_matrix(
                np.asarray(observation.position, float), np.asarray(observation.rotation,
                                                                     float)))
            self._show("pom")
        # The hand: where it really is when known, else the identified (mean) hand.
        if truth is not None:
            theta, segments = np.asarray(truth.theta), np.asarray(truth.segments)
            pose = (np.asarray(truth.position), np.asarray(truth.rotation))
        else:
            theta = state.theta[idx].mean(axis=0)
            segments = state.segments[idx].mean(axis=0)
            pose = ((np.asarray(observation.position), np.asarray(observation.rotation))
                    if observation is not None else None)
        links, pads = _hand_links(m, theta, segments)
        for j, (a, b) in enumerate(links):
            vis[f"hand/link{j}"].set_transform(_segment_matrix(a, b))
        for i, p in enumerate(pads):
            vis[f"hand/pad{i}"].set_transform(_pose_matrix(p, np.eye(3)))
        if pose is not None and self.obj is not None:
            vis["object"].set_transform(_pose_matrix(*pose))
            self._show("object")
        if not self._camera_set:
            # Midway between the palm and the grasp, a little up: the object sits above.
            centre = 0.5 * (h.contacts.mean(axis=0) + m.base_pos.mean(axis=0))
            centre[2] += 0.015
            self._aim_camera(centre)
        self.iteration = iteration

    def _show(self, path: str) -> None:
        """Show a node hidden until it had a pose (else it would sit at the palm origin)."""
        if path in self._hidden:
            self._root[path].set_property("visible", True)
            self._hidden.discard(path)

    def _lines(self, path: str, segments: np.ndarray, rgb: Sequence[float]) -> None:
        g = self._g
        pos = np.ascontiguousarray(segments.reshape(-1, 3).T, dtype=np.float32)
        self._root[path].set_object(g.LineSegments(g.PointsGeometry(pos),
                                                  g.LineBasicMaterial(color=_hex(rgb))))

    def _points(self, path: str, points: np.ndarray, rgb: Sequence[float],
                size: float) -> None:
        g = self._g
        pos = np.ascontiguousarray(points.T, dtype=np.float32)
        # meshcat's PointsMaterial always uses vertex colours, so give every point its colour.
        col = np.repeat(np.asarray(rgb, np.float32)[:, None], pos.shape[1], axis=1)
        self._root[path].set_object(g.Points(g.PointsGeometry(pos, col),
                                            g.PointsMaterial(size=size)))

    def _static_scene(self, palm_radius: float | None, palm_thickness: float) -> None:
        """Background, palm, link and pad shapes, object shape, POM triad: set once; per
        iteration only transforms and the particle buffers change."""
        g, vis, m = self._g, self._root, self.model
        self._vis["/Grid"].set_property("visible", False)  # 0.5 m cells: no use at hand size
        self._vis["/Axes"].set_property("visible", False)
        self._vis["/Background"].set_property("top_color", [1.0, 1.0, 1.0])
        self._vis["/Background"].set_property("bottom_color", [0.82, 0.84, 0.88])
        r = palm_radius or float(np.max(np.linalg.norm(m.base_pos[:, :2], axis=1)) + 0.015)
        palm = np.eye(4)
        palm[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # cylinder axis y -> palm z
        palm[2, 3] = -palm_thickness / 2                   # top face at z = 0
        vis["hand/palm"].set_object(g.Cylinder(palm_thickness, r),
                                    g.MeshLambertMaterial(color=_hex(_HAND_RGB), opacity=0.5))
        vis["hand/palm"].set_transform(palm)
        hand_mat = g.MeshLambertMaterial(color=_hex(_HAND_RGB), opacity=0.35)
        for j in range(m.n_fingers * m.n_joints):
            vis[f"hand/link{j}"].set_object(g.Cylinder(1.0, 0.004), hand_mat)
        for i in range(m.n_fingers):
            vis[f"hand/pad{i}"].set_object(g.Sphere(float(m.pad_radius[i])), hand_mat)
        vis["pom/observed"].set_object(g.triad(0.02))
        if self.obj is not None:
            vis["object/shape"].set_object(*self._object_shape())
        self._hidden = {"pom", "object"}
        for path in self._hidden:
            vis[path].set_property("visible", False)

    def _object_shape(self) -> tuple[Any, Any]:
        """The object's primitive in O (origin at the tag, z into the object). Translucent,
        so the hypotheses inside stay visible; a glass's stem or a screwdriver's shaft are
        left out."""
        g, o = self._g, self.obj
        size, ext = tuple(o.size), getattr(o, "extras", {}) or {}
        t = np.eye(4)
        if o.shape == "sphere":
            geom, t[2, 3] = g.Sphere(size[0]), size[0]
        elif o.shape == "cylinder":
            rad, half = size[:2]
            geom = g.Cylinder(2 * half, rad)
            if ext.get("horizontal"):  # axis along x_O
                t[:3, :3] = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
                t[2, 3] = rad
            else:  # axis along z_O
                t[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
                t[2, 3] = half
        else:  # box, or a mesh's bounding half-extents
            hx, hy, hz = size[:3] if len(size) >= 3 else (size[0],) * 3
            geom, t[2, 3] = g.Box([2 * hx, 2 * hy, 2 * hz]), hz
        self._root["object/shape"].set_transform(t)
        return geom, g.MeshLambertMaterial(color=_hex(o.rgba), opacity=0.3)

    def _aim_camera(self, centre: np.ndarray) -> None:
        """Orbit about the grasp, seen obliquely from the side. meshcat's orbit controls look
        at the world origin, so the scene root moves the grasp centre there; the camera node
        is y-up (rotated about x), hence the swapped offset."""
        t = np.eye(4)
        t[:3, 3] = -centre
        self._root.set_transform(t)
        wx, wy, wz = 0.09, -0.115, 0.06  # camera offset from the centre, palm frame [m]
        self._vis["/Cameras/default/rotated/<object>"].set_property("position", [wx, wz, -wy])
        self._camera_set = True

    # ---- export

    def static_html(self) -> str:
        """A standalone page of the current scene (meshcat's static HTML; works offline)."""
        return self._vis.static_html()

    def save_html(self, path: str | Path) -> Path:
        """Write `static_html()` to `path` atomically (temp file in the folder, then rename)."""
        from vlr.io import write_text_atomic

        return write_text_atomic(path, self.static_html())


# --------------------------------------------------------------------------- headless screenshots

def find_chromium() -> str | None:
    """A Chromium (or Chrome) executable on PATH, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot(target: str | Path, path: str | Path, *, size: tuple[int, int] = (1000, 700),
               wait_ms: int = 6000, browser: str | None = None, timeout: float = 180) -> Path:
    """Screenshot a URL or an HTML file with headless Chromium (for tests and docs).

    WebGL runs in software (SwiftShader): there is no GPU. `wait_ms` of virtual time lets
    the page load its script, connect its websocket and render.

    Raises:
        FileNotFoundError: no Chromium on PATH (and none given).
        RuntimeError: Chromium failed or wrote no picture.
    """
    exe = browser or find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium on PATH (Debian: apt-get install chromium)")
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    url = str(target)
    if "://" not in url:
        url = Path(url).resolve().as_uri()
    with tempfile.TemporaryDirectory(prefix="vlr-chromium-") as profile:
        cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu",
               "--enable-unsafe-swiftshader",  # software WebGL, opted in (no GPU here)
               "--disable-background-networking", "--disable-component-update",
               "--disable-default-apps", "--disable-extensions", "--no-first-run",
               "--hide-scrollbars", f"--user-data-dir={profile}",
               f"--window-size={size[0]},{size[1]}", f"--virtual-time-budget={wait_ms}",
               f"--screenshot={path}", url]
        if path.exists():
            path.unlink()
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if run.returncode != 0 or not path.exists():
        raise RuntimeError(f"chromium failed (exit {run.returncode}): {run.stderr[-500:]}")
    return path
