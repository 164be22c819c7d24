"""The address policy of a hardware link: loopback unless a real robot is asked for in so many words.

A test, an emulator run or a benchmark must never put a byte on a real network by accident, and the robot's
factory address (Go1 192.168.123.10:8007) is never used implicitly: a link names its target, and a target outside
127.0.0.0/8 is refused unless its config says ``allow_hardware=True``.
"""

from __future__ import annotations

import ipaddress
import sys

from wbc.errors import TargetRefusedError

__all__ = ["announce_hardware_target", "check_target", "is_loopback"]


def is_loopback(host: str) -> bool:
    """True if `host` is an IPv4 literal in 127.0.0.0/8 (names are not resolved: ``localhost`` is refused)."""
    try:
        return ipaddress.IPv4Address(host) in ipaddress.IPv4Network("127.0.0.0/8")
    except ValueError:
        return False


def check_target(host: str, port: int, *, allow_hardware: bool, what: str = "target") -> None:
    """Refuse a target the policy does not allow.

    Args:
        host: IPv4 address literal.
        port: UDP port, 1..65535.
        allow_hardware: whether an address outside 127.0.0.0/8 (a real robot) is allowed.
        what: the config field, for the message.

    Raises:
        TargetRefusedError: `host` is not an IPv4 literal, `port` is out of range, or `host` is not loopback and
            hardware is not allowed.
    """
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        raise TargetRefusedError(f"{what} {host!r} is not an IPv4 address literal (names are not resolved); give "
                                 "one such as 127.0.0.1") from None
    if not 0 < int(port) < 65536:
        raise TargetRefusedError(f"{what} port {port} is out of range 1..65535")
    if not allow_hardware and not is_loopback(host):
        raise TargetRefusedError(
            f"{what} {host}:{port} is outside 127.0.0.0/8: refusing to send to a real network. To drive a real "
            "robot, set allow_hardware=True in the config (for instance UnitreeRobotConfig(..., "
            "allow_hardware=True))"
        )


def announce_hardware_target(host: str, port: int, robot: str) -> None:
    """Print, once per link, the non-loopback address a link is about to send to (to stderr)."""
    if not is_loopback(host):
        print(f"wbc: {robot} low-level link sending to HARDWARE at {host}:{port} (allow_hardware=True)",
              file=sys.stderr, flush=True)
