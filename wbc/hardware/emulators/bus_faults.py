"""`BusFault`: what the Dynamixel emulator can be told to do wrong on the arm's bus, and each fault's value.

The emulator keeps them in a `FaultSet` (`FaultSet(BusFault, BUS_FAULT_DEFAULTS)`), shared by the test thread that
injects and the bus thread that applies them (or, in process, the client's call that the answers go back in).
"""

from __future__ import annotations

import enum

from wbc.errors import ConfigError

__all__ = ["BUS_FAULT_DEFAULTS", "BusFault", "fault_ids"]


class BusFault(enum.Enum):
    """A fault on the arm's bus; the value each takes (`DynamixelEmulator.inject`) is in brackets.

    SILENT_ID [ID or tuple of IDs, default 4]: those servos are cut off the data line. They neither hear nor answer,
    so their bus watchdog, if armed with the torque on, trips.
    BAD_CRC [ID, tuple of IDs, or ``"all"``; default ``"all"``]: their status packets carry a CRC with one bit
    flipped (in a fast read's answer, their block's CRC).
    OVERLOAD [ID or tuple, default 4]: the servos detect an overload. Hardware Error Status gets bit 0x20, every
    status packet gets the alert bit, and the torque goes off (0x20 is in Shutdown's default). It latches in the
    servo until a REBOOT, and while the fault is active a reboot finds it again.
    OVER_TEMPERATURE [(ID or tuple, deg C), default (4, 85)]: Present Temperature reads that. Above Temperature
    Limit (80 deg C) the servo sets bit 0x04 and shuts down, latched as for OVERLOAD.
    PORT_CLOSED: the emulator closes the pseudo-terminal for good, as an unplugged adapter. The client's next
    transfer fails (`termios.error` from the SDK's flush), and the emulator must be started anew. `clear` cannot
    undo it. The servos stay powered: their bus watchdogs still trip, and the plant sees it.
    LATE_ANSWER [(ID or tuple of IDs, delay [s] in (0, 1]), default (4, 0.01)]: those servos hear and execute as
    usual, but each status packet of theirs reaches the host `delay` later than it would (a servo whose Return
    Delay Time was set too long, a host that read too early). Beyond the host's reply timeout the transfer times
    out, and the answer arrives later, where it may pass for the answer to a later request.
    """

    SILENT_ID = "silent_id"
    BAD_CRC = "bad_crc"
    OVERLOAD = "overload"
    OVER_TEMPERATURE = "over_temperature"
    PORT_CLOSED = "port_closed"
    LATE_ANSWER = "late_answer"


BUS_FAULT_DEFAULTS: dict[BusFault, object] = {
    BusFault.SILENT_ID: 4,
    BusFault.BAD_CRC: "all",
    BusFault.OVERLOAD: 4,
    BusFault.OVER_TEMPERATURE: (4, 85),
    BusFault.PORT_CLOSED: True,
    BusFault.LATE_ANSWER: (4, 0.01),
}


def fault_ids(value: object, every: tuple[int, ...]) -> frozenset[int]:
    """The servo IDs a fault's value names: an ID, a tuple of IDs, or ``"all"`` (`every`).

    Raises:
        ConfigError: anything else.
    """
    if value == "all":
        return frozenset(every)
    if isinstance(value, int) and not isinstance(value, bool):
        return frozenset((value,))
    if isinstance(value, tuple | list | frozenset | set) and all(isinstance(v, int) for v in value):
        return frozenset(value)
    raise ConfigError(f"bus fault value {value!r}: expected an ID, a tuple of IDs or 'all'")
