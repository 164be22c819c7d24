"""`UdpTransport`: the UDP socket under a Unitree low-level link, and the `Transport` protocol a backend needs.

Unlike the vendor SDK's ``UDP`` class, the socket is bound explicitly to the address asked for (a busy port raises
`PortBusyError` instead of running silently on an ephemeral port, deaf to the robot), datagrams from any address
but the target are dropped and counted (not silently), every queued datagram is handed to the caller (the SDK keeps
only the newest, so a good frame followed by a corrupt one is lost), and `close` really closes the socket.
"""

from __future__ import annotations

import errno
import select
import socket
from typing import Protocol, runtime_checkable

from wbc.errors import PortBusyError, RobotLinkError
from wbc.hardware.unitree.target import check_target

__all__ = ["MAX_DATAGRAM", "Transport", "UdpTransport"]

MAX_DATAGRAM = 65535  # [B] receive buffer: a longer-than-expected frame arrives whole, to be rejected by length
_MAX_DRAIN = 256  # datagrams taken per `receive` call, so a flood cannot hold the link thread
_NETWORK_GONE = frozenset(getattr(errno, name) for name in ("ENETUNREACH", "EHOSTUNREACH", "ENETDOWN", "EHOSTDOWN",
                                                            "ENOBUFS", "EADDRNOTAVAIL") if hasattr(errno, name))
"""Send errors of a network that is down or unreachable for a while: the frame is dropped, the link goes on."""


@runtime_checkable
class Transport(Protocol):
    """What a low-level link needs from its datagram channel (a UDP socket, or a test's fake).

    Attributes:
        foreign: datagrams dropped so far because they came from another address than the target.
    """

    foreign: int

    def send(self, frame: bytes) -> None:
        """Send one datagram to the target."""

    def receive(self) -> list[bytes]:
        """Every datagram queued from the target, oldest first, without blocking (empty if none)."""

    def wait_readable(self, timeout: float) -> bool:
        """Block up to `timeout` seconds until a datagram is queued; True if one is."""

    def close(self) -> None:
        """Release the channel. Idempotent."""


class UdpTransport:
    """A UDP socket bound to `local` that talks to `target` only.

    Args:
        local: ``(host, port)`` to bind; port 0 picks a free one (read it back from `local_address`).
        target: ``(host, port)`` that frames are sent to and accepted from.
        allow_hardware: allow addresses outside 127.0.0.0/8 (`wbc.hardware.unitree.target.check_target`).

    Raises:
        TargetRefusedError: `local` or `target` is outside 127.0.0.0/8 and `allow_hardware` is False.
        PortBusyError: the local port is held by another socket.
        RobotLinkError: the socket could not be created or bound for another reason.
    """

    def __init__(self, local: tuple[str, int], target: tuple[str, int], *, allow_hardware: bool = False) -> None:
        check_target(target[0], target[1], allow_hardware=allow_hardware, what="target")
        check_target(local[0], 1, allow_hardware=allow_hardware, what="local address")
        self.target = (str(target[0]), int(target[1]))
        self.foreign = 0  # datagrams dropped because they came from another address than the target
        self.unsent = 0  # frames dropped because the network was down or unreachable (`send`)
        self.last_send_error = ""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((local[0], int(local[1])))
        except OSError as exc:
            sock.close()
            if exc.errno in (errno.EADDRINUSE, errno.EACCES):
                raise PortBusyError(local[0], int(local[1]), exc.strerror or str(exc)) from None
            raise RobotLinkError(f"cannot bind UDP {local[0]}:{local[1]}: {exc}") from None
        sock.setblocking(False)
        self._sock: socket.socket | None = sock
        self.local_address: tuple[str, int] = sock.getsockname()[:2]

    @property
    def closed(self) -> bool:
        """True once `close` ran."""
        return self._sock is None

    def _socket(self) -> socket.socket:
        if self._sock is None:
            raise RobotLinkError(f"UdpTransport {self.local_address}: the socket is closed")
        return self._sock

    def send(self, frame: bytes) -> None:
        """Send `frame` to the target (a full send buffer or an unreachable port drops it, as UDP does).

        A network that is down or unreachable for a while (an unplugged cable, an interface that restarts) drops the
        frame too, counted in `unsent` with its reason in `last_send_error`: the link keeps its period, its state
        stream goes stale (the safety layer damps), and the damping reaches the robot as soon as the network is back.
        Any other error of the socket ends the link.
        """
        try:
            self._socket().sendto(frame, self.target)
        except (BlockingIOError, ConnectionRefusedError):
            pass
        except OSError as exc:
            if exc.errno not in _NETWORK_GONE:
                raise
            self.unsent += 1
            self.last_send_error = exc.strerror or str(exc)

    def receive(self) -> list[bytes]:
        """Every datagram queued from the target (at most 256), oldest first; others are counted in `foreign`."""
        sock = self._socket()
        out: list[bytes] = []
        for _ in range(_MAX_DRAIN):
            try:
                data, source = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:  # an ICMP "port unreachable" for an earlier send
                continue
            if source[:2] != self.target:
                self.foreign += 1
                continue
            out.append(data)
        return out

    def wait_readable(self, timeout: float) -> bool:
        """Block up to `timeout` seconds for a datagram; True if one is queued.

        ``select`` rather than ``selectors``' epoll: epoll's timeout is whole milliseconds, which would make a 2 ms
        link period jitter by up to 1 ms.
        """
        readable, _, _ = select.select([self._socket()], [], [], max(0.0, timeout))
        return bool(readable)

    def close(self) -> None:
        """Close the socket (the port is free again at once). Idempotent."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None
