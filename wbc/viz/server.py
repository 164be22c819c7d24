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
import os
import queue
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from wbc.viz.errors import ViewerError

__all__ = ["MeshcatServer", "ServerConfig", "serve"]

LOOPBACK = "127.0.0.1"


@dataclass(frozen=True, kw_only=True)
class ServerConfig:
    """Where the viewer listens.

    Attributes:
        host: address the web page (HTTP + websocket) is served on; 127.0.0.1 keeps it on this machine.
        start_timeout_s: how long to wait for the child process to report its URLs [s].
    """

    host: str = LOOPBACK
    start_timeout_s: float = 20.0


class MeshcatServer:
    """A meshcat server in a child process; a context manager that stops it on exit.

    Args:
        config: where to listen.

    Attributes:
        zmq_url: the command socket (``tcp://127.0.0.1:PORT``), for ``meshcat.Visualizer(zmq_url=...)``.
        web_url: the page to open in a browser.
        web_port: the HTTP port.
    """

    def __init__(self, config: ServerConfig | None = None) -> None:
        self.config = config or ServerConfig()
        self.zmq_url = ""
        self.web_url = ""
        self.web_port = 0
        self._proc: subprocess.Popen | None = None

    @property
    def pid(self) -> int | None:
        """Process id of the server (None when stopped)."""
        return self._proc.pid if self._proc is not None else None

    def start(self) -> MeshcatServer:
        """Start the child process and wait until it reports its URLs.

        Raises:
            ViewerError: the server exited or did not report its URLs within ``start_timeout_s``.
        """
        cfg = self.config
        cmd = [sys.executable, "-u", "-m", "wbc.viz.server", "--host", cfg.host, "--parent", str(os.getpid())]
        # the child imports this very package, wherever it was imported from
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
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
        self.zmq_url, self.web_url, self.web_port = urls["zmq_url"], urls["web_url"], int(urls["web_port"])
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
