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
    """

    time: float
    sim_time: float
    wire: WireCommand

    @property
    def damping(self) -> bool:
        """True if every motor is asked for pure damping (Kp 0, Kd > 0, no feed-forward torque)."""
        w = self.wire
        return bool((w.kp == 0).all() and (w.kd > 0).all() and (w.tau == 0).all())
