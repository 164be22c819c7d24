"""The control channel between a controller's process and its I/O process: JSON lines over a socket pair.

Requests go one way (``{"op": "link_stats"}``, ``{"op": "close"}``), replies and the I/O process's own reports the
other (``{"connected": ...}``, ``{"link_stats": ...}``, ``{"closed": true}``, ``{"error": ...}``). An exception of the
I/O process travels as its class name, message and plain attributes (`error_report`) and is raised again in the
controller's process as the same `wbc` error class with the same message (`rebuild_error`); an exception that is not
a `wbc` error arrives as a `RobotLinkError` naming it. End of file on the channel means the other process is gone.
"""

from __future__ import annotations

import json
import select
import socket
import time

import wbc.errors
from wbc.errors import RobotLinkError, WbcError

__all__ = ["ChannelClosed", "LineChannel", "error_report", "rebuild_error"]


class ChannelClosed(Exception):
    """The other end of the channel closed (its process exited)."""


class LineChannel:
    """JSON lines over a connected stream socket.

    Args:
        sock: one end of a socket pair (blocking).
    """

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._buf = b""

    def fileno(self) -> int:
        """The socket's descriptor (for `select`)."""
        return self.sock.fileno()

    def send(self, message: dict) -> None:
        """Send one message as one line.

        Raises:
            ChannelClosed: the other end is gone.
        """
        try:
            self.sock.sendall(json.dumps(message).encode() + b"\n")
        except OSError as exc:
            raise ChannelClosed(str(exc)) from None

    def pending(self) -> bool:
        """True when a whole line is buffered already."""
        return b"\n" in self._buf

    def receive(self, timeout: float | None) -> dict | None:
        """The next message, waiting at most `timeout` seconds (None: forever); None when none came in time.

        Raises:
            ChannelClosed: the other end closed before a whole line came.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while b"\n" not in self._buf:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not select.select([self.sock], [], [], remaining)[0]:
                return None
            try:
                chunk = self.sock.recv(65536)
            except OSError as exc:
                raise ChannelClosed(str(exc)) from None
            if not chunk:
                raise ChannelClosed("end of file")
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return json.loads(line)

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


def error_report(exc: BaseException) -> dict:
    """An exception as a message: its class, its text and its plain attributes (numbers, strings, None)."""
    attrs = {k: v for k, v in vars(exc).items() if not k.startswith("_") and isinstance(v, int | float | str | None)}
    return {"error": type(exc).__name__, "message": str(exc), "attrs": attrs}


def rebuild_error(report: dict, *, where: str) -> WbcError:
    """The exception `error_report` described, as the same `wbc` error class with the same message.

    An exception that is no `wbc` error (an `OSError` of the serial layer ...) becomes a `RobotLinkError` that names
    its class. `where` prefixes nothing: the message is the I/O process's own, so that it reads as in-process; it
    names the process only for a foreign class.
    """
    name, message = str(report.get("error")), str(report.get("message", ""))
    cls = getattr(wbc.errors, name, None)
    if not (isinstance(cls, type) and issubclass(cls, WbcError)):
        return RobotLinkError(f"{where}: {name}: {message}")
    exc = cls.__new__(cls)
    Exception.__init__(exc, message)  # the class's own __init__ would rebuild the message from its parts
    for key, value in dict(report.get("attrs", {})).items():
        setattr(exc, key, value)
    return exc
