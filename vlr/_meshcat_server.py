"""The meshcat server that `vlr.view.FilterView` starts: meshcat's own bridge, bound to one
address and tied to the process that started it.

meshcat 0.3.2's server (`python -m meshcat.servers.zmqserver`) binds its zmq socket to
127.0.0.1 but lets tornado listen on every interface (`app.listen(port)` without an
address), unauthenticated, and has no option to change either; it also runs on after its
parent dies (it is started in a session of its own). This module runs the same
`ZMQWebSocketBridge` with the web page on `--host` and the zmq port (meshcat's unauthenticated
drawing commands) always on the loopback of that address's family, and exits when
its parent does: at once on Linux (PR_SET_PDEATHSIG), within a second elsewhere (the parent
pid is polled).

Usage (by `vlr.view`, not by hand):

    python -m vlr._meshcat_server --host 127.0.0.1 --parent-pid PID

prints `zmq_url=...` (the address to connect to) and `web_url=...` (the bound page), one a
line, then serves until killed or orphaned.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import warnings
from typing import Any

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def connect_host(address: str) -> str:
    """The address a local client connects to for a server bound to `address`: a wildcard
    bind is reached on the loopback of its family."""
    return {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(address, address)


def loopback(address: str) -> str:
    """The loopback address of `address`'s family, where the zmq port is bound."""
    return "::1" if ":" in address else "127.0.0.1"


def url_host(address: str) -> str:
    """`address` as the host part of a URL (IPv6 in brackets)."""
    return f"[{address}]" if ":" in address else address


def die_with_parent(parent: int) -> None:
    """Ask the kernel for SIGTERM when the parent dies (Linux), then check that it is still
    alive: had it died between our fork and here, that signal would never come.

    This runs in the server itself, first thing, rather than in a `preexec_fn` of the
    parent's Popen: a `preexec_fn` is not safe in a parent with threads (numba's, BLAS's),
    and the check on the parent pid closes the window between fork and prctl either way.
    """
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # no prctl: the poll in `serve` still ends the server
    if os.getppid() != parent:
        sys.exit(0)


def _bridge_class() -> Any:
    # pyzmq warns that meshcat's zmq.eventloop.ioloop import is deprecated: meshcat's business.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import zmq
        from meshcat.servers.zmqserver import ZMQStream, ZMQWebSocketBridge

    class Bridge(ZMQWebSocketBridge):
        """meshcat's bridge with tornado listening on `address` only (meshcat passes no
        address to `app.listen`) and zmq on the loopback, IPv6 included: the page may be
        served to the network, the channel that draws in it never is."""

        def __init__(self, address: str) -> None:
            self.address = address  # before the base __init__, which calls make_app
            super().__init__(host=url_host(address))

        def make_app(self) -> Any:
            app = super().make_app()
            listen, address = app.listen, self.address
            app.listen = lambda port, **kw: listen(port, address=address, **kw)
            return app

        def setup_zmq(self, url: str) -> Any:
            url = url.replace(url_host(self.address), url_host(loopback(self.address)), 1)
            sock = self.context.socket(zmq.REP)
            if ":" in self.address:
                sock.setsockopt(zmq.IPV6, 1)
            try:
                sock.bind(url)
            except zmq.ZMQError:
                sock.close(linger=0)  # the base class tries the next port
                raise
            stream = ZMQStream(sock)
            stream.on_recv(self.handle_zmq)
            return sock, stream, url

    return Bridge


def serve(address: str, parent: int) -> None:
    """Start the bridge on `address`, print its URLs, serve until orphaned or killed."""
    import tornado.ioloop

    bridge = _bridge_class()(address)
    port = int(bridge.zmq_url.rsplit(":", 1)[1])
    print(f"zmq_url=tcp://{url_host(loopback(address))}:{port}")
    print(f"web_url={bridge.web_url}", flush=True)
    # Nobody reads our output after this: keep later prints from filling the pipe.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())

    def orphaned() -> None:
        if os.getppid() != parent:
            os._exit(0)

    tornado.ioloop.PeriodicCallback(orphaned, 1000).start()
    bridge.run()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m vlr._meshcat_server",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1", help="a numeric address to bind")
    parser.add_argument("--parent-pid", type=int, required=True)
    args = parser.parse_args(argv)
    die_with_parent(args.parent_pid)
    serve(args.host, args.parent_pid)


if __name__ == "__main__":
    main()
