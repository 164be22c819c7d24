"""The WidowX 200 on its Dynamixel bus: servo IDs, Interbotix's EEPROM values, and ticks to model joint angles.

The bus: seven XM430-W350 servos on a U2D2 at 1 Mbps. The shoulder has two servos in tandem. The shadow (ID 3) is
mounted mirrored, set to reverse drive mode and given Secondary ID 2. It therefore executes every write addressed to
the shoulder (ID 2) in the same direction, and it never answers one. The EEPROM values below are Interbotix's
(``interbotix_xsarm_control/config/wx200.yaml``): drive modes, position limits, velocity limit 131 and return delay 0.

The model (`wbc.robots.wx200`) moves waist, shoulder and elbow (house joints 12, 13, 14); wrist angle, wrist rotate
and gripper are lumped into the forearm, and their servos are held in position. The mapping from ticks to the
model's angle is ``q = sign * (ticks - 2048) * 2 pi / 4096 + offset``, with sign +1 and offset 0 on all three joints.
This is Interbotix's convention: its driver reports exactly that as the URDF joint angle, with the drive modes below,
and the model's joints share that URDF's axes (waist z, shoulder y, elbow y). The numbers agree. The model's elbow
limits (-108 deg, 93 deg) are ticks 819 and 3106, the EEPROM limits. Its shoulder upper limit (113 deg) is tick 3333.
Its stowed pose [0, -1.3, 1.5] rad is Interbotix's sleep pose [0, -1.35, 1.5] within 0.05 rad. One thing can only be
checked on an arm: that tick 2048 is the URDF zero on every joint. Interbotix assembles the horns at the middle of
the range. If an arm differs, measure it and set `ArmJointMap.offset`.
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.errors import UnknownNameError
from wbc.hardware.dynamixel.control_table import DRIVE_MODE_REVERSE
from wbc.hardware.dynamixel.units import CENTER_TICKS, RAD_PER_TICK

__all__ = [
    "WX200_ARM_JOINTS",
    "WX200_BAUD_RATE",
    "WX200_SERVOS",
    "ArmJointMap",
    "ServoSpec",
    "servo_spec",
]

WX200_BAUD_RATE = 1_000_000
"""The bus's baud rate [bit/s] (Baud Rate register value 3)."""


@dataclass(frozen=True, kw_only=True)
class ServoSpec:
    """One servo of the arm and the EEPROM values Interbotix writes into it.

    Attributes:
        name: the Interbotix motor name.
        id: its ID (also its place in a sync read: joints first, in this order).
        drive_mode: Drive Mode (10): `DRIVE_MODE_REVERSE` or 0.
        secondary_id: Secondary ID (12), 255 = none.
        min_position: Min Position Limit (52) [ticks].
        max_position: Max Position Limit (48) [ticks].
        velocity_limit: Velocity Limit (44) [0.229 rpm].
        return_delay_time: Return Delay Time (9) [2 us].
        baud_rate: Baud Rate (8) register value (3 = 1 Mbps).
    """

    name: str
    id: int
    drive_mode: int
    secondary_id: int
    min_position: int
    max_position: int
    velocity_limit: int = 131
    return_delay_time: int = 0
    baud_rate: int = 3

    @property
    def reverse(self) -> bool:
        """True if the drive mode's reverse bit is set."""
        return bool(self.drive_mode & DRIVE_MODE_REVERSE)


WX200_SERVOS = (
    ServoSpec(name="waist", id=1, drive_mode=0, secondary_id=255, min_position=0, max_position=4095),
    ServoSpec(name="shoulder", id=2, drive_mode=0, secondary_id=255, min_position=819, max_position=3333),
    ServoSpec(name="shoulder_shadow", id=3, drive_mode=DRIVE_MODE_REVERSE, secondary_id=2, min_position=819,
              max_position=3333),
    ServoSpec(name="elbow", id=4, drive_mode=DRIVE_MODE_REVERSE, secondary_id=255, min_position=819,
              max_position=3106),
    ServoSpec(name="wrist_angle", id=5, drive_mode=DRIVE_MODE_REVERSE, secondary_id=255, min_position=910,
              max_position=3447),
    ServoSpec(name="wrist_rotate", id=6, drive_mode=0, secondary_id=255, min_position=0, max_position=4095),
    ServoSpec(name="gripper", id=7, drive_mode=0, secondary_id=255, min_position=0, max_position=4095),
)
"""The arm's seven servos, by ID."""


def servo_spec(name_or_id: str | int) -> ServoSpec:
    """The WX200 servo with this Interbotix name or ID.

    Raises:
        UnknownNameError: no such servo; the message lists them.
    """
    for spec in WX200_SERVOS:
        if name_or_id in (spec.name, spec.id):
            return spec
    raise UnknownNameError("WX200 servo", str(name_or_id), [f"{s.name} (ID {s.id})" for s in WX200_SERVOS])


@dataclass(frozen=True, kw_only=True)
class ArmJointMap:
    """How one model joint reads its servo: ``q = sign * (ticks - 2048) * RAD_PER_TICK + offset``.

    Attributes:
        name: the model's joint (``waist``, ``shoulder``, ``elbow``).
        house_index: its index in a 15-joint command (12, 13, 14).
        servo_id: the ID the host reads and writes (the primary servo).
        servo_ids: every servo that drives the joint (the shoulder's shadow included), primary first.
        sign: +1 or -1, the register direction against the model's.
        offset: the model angle at tick 2048 [rad].
    """

    name: str
    house_index: int
    servo_id: int
    servo_ids: tuple[int, ...]
    sign: int = 1
    offset: float = 0.0

    def to_rad(self, ticks: float) -> float:
        """Model joint angle [rad] of a Present Position (or Goal Position) value."""
        return self.sign * (ticks - CENTER_TICKS) * RAD_PER_TICK + self.offset

    def to_ticks(self, q: float) -> int:
        """The nearest Goal Position value for model joint angle `q` [rad]."""
        return CENTER_TICKS + round(self.sign * (q - self.offset) / RAD_PER_TICK)


WX200_ARM_JOINTS = (
    ArmJointMap(name="waist", house_index=12, servo_id=1, servo_ids=(1,)),
    ArmJointMap(name="shoulder", house_index=13, servo_id=2, servo_ids=(2, 3)),
    ArmJointMap(name="elbow", house_index=14, servo_id=4, servo_ids=(4,)),
)
"""The model's three arm joints on the bus, in house order (see the module docstring for the convention)."""
