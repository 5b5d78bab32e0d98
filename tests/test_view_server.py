"""The live view's server (vlr.view, vlr._meshcat_server): where it listens, and that it never
outlives the process that opened it."""

import contextlib
import importlib.util
import signal
import socket
import subprocess
import sys
import textwrap
import time
import urllib.request
from pathlib import Path

import pytest

from vlr import view as view_mod
from vlr.cli import main
from vlr.kinematics import HandModel
from vlr.spec import load_hand
from vlr.view import FilterView

pytestmark = pytest.mark.skipif(importlib.util.find_spec("meshcat") is None,
                                reason="meshcat is not installed (pip install -e '.[view]')")
psutil = pytest.importorskip("psutil", reason="psutil lists the server's sockets")

ROOT = Path(__file__).resolve().parent.parent


def _model() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def _listening(pid: int) -> list[tuple[str, int]]:
    return sorted((c.laddr.ip, c.laddr.port) for c in psutil.Process(pid).net_connections("inet")
                  if c.status == psutil.CONN_LISTEN)


def _external_address() -> str | None:
    """An IPv4 address of this machine that is not loopback (None: there is none)."""
    for addrs in psutil.net_if_addrs().values():
        for a in addrs:
            if a.family == socket.AF_INET and not a.address.startswith("127."):
                return a.address
    return None


def _web_port(view: FilterView) -> int:
    return int(view.url.rsplit(":", 1)[1].split("/")[0])


def _refused(host: str, port: int) -> bool:
    try:
        socket.create_connection((host, port), timeout=2).close()
    except OSError:
        return True
    return False


def test_server_listens_on_loopback_only_and_catches_sigterm_while_open():
    before = signal.getsignal(signal.SIGTERM)
    with FilterView(_model()) as v:
        listening = _listening(v.server_process.pid)
        # The web page and the zmq port, both on the loopback, nothing on any other address.
        assert len(listening) == 2 and {ip for ip, _ in listening} == {"127.0.0.1"}, listening
        assert v.url.startswith("http://127.0.0.1:") and v.host == "127.0.0.1"
        assert urllib.request.urlopen(v.url, timeout=10).status == 200
        outside = _external_address()
        if outside is not None:
            assert _refused(outside, _web_port(v))
        assert signal.getsignal(signal.SIGTERM) is view_mod._terminate
    assert signal.getsignal(signal.SIGTERM) is before


def test_view_host_opts_in_to_the_network():
    with FilterView(_model(), host="0.0.0.0") as v:
        listening = _listening(v.server_process.pid)
        # The page on every interface; meshcat's drawing channel (zmq) still on loopback.
        assert sorted(ip for ip, _ in listening) == ["0.0.0.0", "127.0.0.1"], listening
        assert _web_port(v) in {port for ip, port in listening if ip == "0.0.0.0"}
        assert v.url.startswith("http://127.0.0.1:")  # where this machine's browser finds it
        outside = _external_address()
        if outside is not None:
            url = f"http://{outside}:{_web_port(v)}/static/"
            assert urllib.request.urlopen(url, timeout=10).status == 200


def test_identify_view_host_flag_reaches_the_server(tmp_path, monkeypatch, capsys):
    views = []
    init = FilterView.__init__

    def spy(self, *a, **k):
        init(self, *a, **k)
        views.append((self, _listening(self.server_process.pid)))

    monkeypatch.setattr(view_mod.FilterView, "__init__", spy)
    rc = main(["identify", "--backend", "synthetic", "--particles", "200", "--max-iterations",
               "1", "--out", str(tmp_path / "run"), "--quiet", "--view", "--view-host",
               "0.0.0.0"])
    assert rc == 0
    (view, listening), = views
    assert "0.0.0.0" in {ip for ip, _ in listening} and view.server_process.poll() is not None
    out = capsys.readouterr().out
    assert f"view: {view.url}" in out and "reachable from the network" in out


def test_identify_names_a_view_host_it_cannot_listen_on(tmp_path, capsys):
    rc = main(["identify", "--backend", "synthetic", "--particles", "200", "--max-iterations",
               "1", "--out", str(tmp_path / "run"), "--quiet", "--view", "--view-host",
               "no-such-host.invalid"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'no-such-host.invalid'" in err[0], err


_OPENER = textwrap.dedent("""
    import sys, time
    from vlr.kinematics import HandModel
    from vlr.spec import load_hand
    from vlr.view import FilterView

    try:
        with FilterView(HandModel.from_spec(load_hand("modelo"))) as v:
            print(v.url, v.server_process.pid, flush=True)
            time.sleep(60)
    except KeyboardInterrupt as exc:  # SIGTERM unwinds through the view's close
        print("interrupted", exc.signum, v.server_process.poll() is not None, flush=True)
        sys.exit(3)
""")


def _gone(pid: int, port: int) -> bool:
    """The server has exited and its web port is closed. A zombie counts as exited (nobody
    may reap it here), but its first thread turns zombie before the others have ended and
    closed its sockets, hence the port too."""
    try:
        exited = psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        exited = True
    return exited and _refused("127.0.0.1", port)


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_viewer_dies_with_the_process_that_opened_it(sig):
    parent = subprocess.Popen([sys.executable, "-c", _OPENER], cwd=ROOT, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    server = None
    try:
        url, server_pid = parent.stdout.readline().split()
        server = int(server_pid)
        port = int(url.rsplit(":", 1)[1].split("/")[0])
        assert psutil.Process(server).status() != psutil.STATUS_ZOMBIE
        assert not _refused("127.0.0.1", port)
        parent.send_signal(sig)
        rest, _ = parent.communicate(timeout=20)
        deadline = time.monotonic() + 5
        while not _gone(server, port) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _gone(server, port), "the viewer outlived its parent"
        if sig == signal.SIGTERM:  # the close path ran, and stopped the server itself
            assert rest.split() == ["interrupted", str(int(sig)), "True"], rest
            assert parent.returncode == 3
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.communicate()
        if server is not None:
            with contextlib.suppress(psutil.NoSuchProcess):
                psutil.Process(server).kill()
