"""`MeshcatServer`: meshcat's ZMQ + web server, started in a child process and bound to one host address.

meshcat 0.3.2's own server (``python -m meshcat.servers.zmqserver``) prints ``http://127.0.0.1:7000/static/`` but its
web server calls tornado's ``listen(port)`` without an address, so it listens on every interface: anyone on the
network can watch, and the page's websocket accepts connections from anywhere. Here the bridge's web application is
bound to `host` (127.0.0.1 unless the user says otherwise) and the ZMQ command socket, which accepts scene
commands, is bound to 127.0.0.1 whatever `host` is. Nothing in meshcat is patched: the child process runs `serve`,
which builds meshcat's bridge through a subclass that passes the address to ``listen``.
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import queue
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass

from wbc.hardware.interpreter import wbc_interpreter_env
from wbc.viz.errors import ViewerError

__all__ = ["MeshcatServer", "ServerConfig", "host_problem", "listening_on", "serve", "web_address"]

LOOPBACK = "127.0.0.1"

_LABEL = re.compile(r"[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?")
"""One label of a host name (RFC 1123): letters, digits and inner hyphens, at most 63 characters."""


def host_problem(host: str) -> str | None:
    """Why `host` cannot be an address to listen on, or None: an IP address, or a host name by its syntax alone.

    Nothing is looked up (no DNS): a name of valid syntax passes, and the server reports one that does not resolve.
    A name of digits and dots only is read as an IPv4 address, as the system's resolver reads it.

    Args:
        host: the address given (``127.0.0.1``, ``::1``, ``localhost``).

    Returns:
        What is wrong with it, to follow the option's name in a message; None when it is well formed.
    """
    try:
        ipaddress.ip_address(host)
        return None
    except ValueError:
        pass
    if not host:
        return "is empty; give an IP address or a host name, e.g. 127.0.0.1"
    if re.fullmatch(r"[0-9.]+", host):
        return "is not an IPv4 address: give four numbers in 0..255 joined by dots, e.g. 127.0.0.1"
    if ":" in host:
        return "is not an IPv6 address (e.g. ::1)"
    name = host[:-1] if host.endswith(".") else host
    labels = name.split(".")
    if len(name) > 253 or not all(_LABEL.fullmatch(label) for label in labels) or labels[-1].isdigit():
        return ("is neither an IP address nor a host name (letters, digits and hyphens, in dot-separated parts); "
                "give an address of this machine, e.g. 127.0.0.1")
    return None


@dataclass(frozen=True, kw_only=True)
class ServerConfig:
    """Where the viewer listens.

    Attributes:
        host: address the web page (HTTP + websocket) is served on; 127.0.0.1 keeps it on this machine.
        start_timeout_s: how long to wait for the child process to report its URLs [s].
    """

    host: str = LOOPBACK
    start_timeout_s: float = 20.0


def _every_interface(host: str) -> bool:
    """Whether `host` is a wildcard address (0.0.0.0, ::, or another spelling of them): every interface."""
    try:
        return ipaddress.ip_address(host).is_unspecified
    except ValueError:  # a name, not an address
        return False


def web_address(host: str | None, port: int) -> str:
    """The viewer's page on `host` as a browser opens it: an IPv6 address in brackets, a wildcard as loopback."""
    host = host or LOOPBACK
    if _every_interface(host):
        host = LOOPBACK if ":" not in host else "::1"
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{port}/static/"


def listening_on(host: str | None) -> str:
    """Where a viewer listening on `host` can be reached from, for the line that prints its address."""
    host = host or LOOPBACK
    if _every_interface(host):
        return f"every interface ({host}): any machine that reaches this one can open it"
    return f"{host} only"


class MeshcatServer:
    """A meshcat server in a child process; a context manager that stops it on exit.

    Args:
        config: where to listen.

    Attributes:
        zmq_url: the command socket (``tcp://127.0.0.1:PORT``), for ``meshcat.Visualizer(zmq_url=...)``.
        web_url: the page to open in a browser (`web_address`).
        listening: where it can be opened from, in words (`listening_on`).
        web_port: the HTTP port.
    """

    def __init__(self, config: ServerConfig | None = None) -> None:
        self.config = config or ServerConfig()
        self.zmq_url = ""
        self.web_url = ""
        self.web_port = 0
        self._proc: subprocess.Popen | None = None

    @property
    def listening(self) -> str:
        """Where the page can be opened from (`listening_on` its host)."""
        return listening_on(self.config.host)

    @property
    def pid(self) -> int | None:
        """Process id of the server (None when stopped)."""
        return self._proc.pid if self._proc is not None else None

    def start(self) -> MeshcatServer:
        """Start the child process and wait until it reports its URLs.

        Raises:
            ViewerError: the host is not an IP address or a host name (`host_problem`), or the server exited or did
                not report its URLs within ``start_timeout_s``.
        """
        cfg = self.config
        problem = host_problem(cfg.host)
        if problem is not None:  # said at once, not after waiting start_timeout_s for a server that cannot bind
            raise ViewerError(f"the viewer's host {cfg.host!r} {problem}")
        cmd = [sys.executable, "-u", "-m", "wbc.viz.server", "--host", cfg.host, "--parent", str(os.getpid())]
        env = wbc_interpreter_env()  # the child imports this very package, wherever it was imported from
        self._proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                      start_new_session=True, env=env)
        # a thread reads the child's lines: select() on a buffered pipe misses lines already buffered
        lines: queue.Queue[str] = queue.Queue()
        stdout = self._proc.stdout
        threading.Thread(target=lambda: [lines.put(x) for x in iter(stdout.readline, "")], daemon=True).start()
        deadline = time.monotonic() + cfg.start_timeout_s
        urls: dict[str, str] = {}
        while len(urls) < 3:
            try:
                line = lines.get(timeout=0.1)
            except queue.Empty:
                if self._proc.poll() is not None or time.monotonic() > deadline:
                    self.stop()
                    raise ViewerError(f"the meshcat server on {cfg.host} did not start within "
                                      f"{cfg.start_timeout_s:.0f} s (is the address valid on this machine? "
                                      f"try --host {LOOPBACK})") from None
                continue
            key, _, value = line.strip().partition("=")
            if key in ("zmq_url", "web_url", "web_port"):
                urls[key] = value
        self.zmq_url, self.web_port = urls["zmq_url"], int(urls["web_port"])
        self.web_url = web_address(self.config.host, self.web_port)  # meshcat's own omits an IPv6 address's brackets
        return self

    def stop(self) -> None:
        """Stop the child process (idempotent)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()

    def __enter__(self) -> MeshcatServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def serve(host: str, parent: int | None = None) -> None:
    """Run meshcat's bridge in this process, its web server bound to `host` only (blocks until killed).

    Ports are meshcat's: the first free from 7000 (web) and 6000 (ZMQ). Prints ``zmq_url=...``, ``web_url=...``
    and ``web_port=...`` lines on stdout once listening. With `parent`, exits once that process is gone (a viewer
    killed without cleaning up leaves no server behind).
    """
    import functools

    import tornado.ioloop
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class _BoundBridge(ZMQWebSocketBridge):
        """meshcat's bridge: web application on ``self.host`` only, ZMQ command socket on loopback only."""

        def make_app(self):  # noqa: D102 - meshcat's hook, called by its constructor before it listens
            app = super().make_app()
            app.listen = functools.partial(app.listen, address=self.host)  # this instance only
            return app

        def setup_zmq(self, url):  # noqa: D102 - meshcat's hook; it passes tcp://<host>:<port>
            scheme, _, rest = url.partition("://")
            return super().setup_zmq(f"{scheme}://{LOOPBACK}:{rest.rsplit(':', 1)[1]}")

    bridge = _BoundBridge(host=host)
    print(f"zmq_url={bridge.zmq_url}")
    print(f"web_url={bridge.web_url}")
    print(f"web_port={bridge.fileserver_port}", flush=True)
    if parent is not None:
        def check_parent() -> None:
            if os.getppid() != parent:
                bridge.ioloop.stop()

        tornado.ioloop.PeriodicCallback(check_parent, 1000).start()
    bridge.run()


def main(argv: list[str] | None = None) -> None:
    """``python -m wbc.viz.server --host H [--parent PID]``: what `MeshcatServer` runs."""
    p = argparse.ArgumentParser(prog="python -m wbc.viz.server")
    p.add_argument("--host", default=LOOPBACK)
    p.add_argument("--parent", type=int, default=None, help="exit when this process is gone")
    args = p.parse_args(argv)
    serve(args.host, args.parent)


if __name__ == "__main__":
    main()
