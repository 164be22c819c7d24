"""`LoggedCommand`: one LowCmd frame as an emulator decoded it off the wire, with when it arrived.

A fault-injection test reads these to check what a backend really sent (not what it meant to send).
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.hardware.unitree.wire_command import WireCommand

__all__ = ["LoggedCommand"]


@dataclass(frozen=True, kw_only=True)
class LoggedCommand:
    """A decoded command frame.

    Attributes:
        time: arrival time on the emulator's clock (`UnitreeEmulator.clock`: the monotonic clock behind its UDP
            server, the test's clock behind an in-process `EmulatorTransport`) [s].
        sim_time: the emulated robot's simulation time when it arrived [s].
        wire: the frame's leg-motor block, dequantised.
        dropped_before: datagrams the emulator's socket dropped, its receive buffer full, before this one arrived
            (the kernel's count, on Linux; 0 elsewhere and in process). A frame's place in what its sender sent is
            its place in the log plus this, when one sender sent them all.
    """

    time: float
    sim_time: float
    wire: WireCommand
    dropped_before: int = 0

    @property
    def damping(self) -> bool:
        """True if every motor is asked for pure damping (Kp 0, Kd > 0, no feed-forward torque)."""
        w = self.wire
        return bool((w.kp == 0).all() and (w.kd > 0).all() and (w.tau == 0).all())
