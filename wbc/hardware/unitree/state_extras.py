"""`LowStateExtras`: what a LowState frame holds beyond `RobotState`.

`decode_state` returns a `RobotState` (what every controller reads, the same record the simulator gives) and this
record (what a hardware backend's safety layer and logs read: motor modes and temperatures, the remote, the
battery, the IMU's own Euler angles). `encode_state` takes both back, so an emulator writes frames a real robot
would; together they hold every field the golden frames exercise, so decode then encode reproduces a frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wbc.hardware.unitree.battery import Battery
from wbc.hardware.unitree.layout import NUM_LEG_MOTORS
from wbc.hardware.unitree.remote import Remote

__all__ = ["LowStateExtras"]


@dataclass(frozen=True, kw_only=True)
class LowStateExtras:
    """One LowState's fields that `RobotState` does not hold; motor arrays in house order, shape (12,).

    The frame's tick is `RobotState.tick` (a freshness counter only: its unit is not verified).

    Attributes:
        motor_mode: each leg motor's reported mode (0x0A servo, 0 damping/off; anything else is a motor error
            code), uint8.
        motor_temperature: each leg motor's temperature [degC], int8 (the sensor lags the winding).
        ddq_counts: each leg motor's acceleration field as the wire's int16 counts. Its scale is not verified
            against the SDK, so it is not converted; it is kept so that a frame re-encodes exactly.
        imu_rpy: the IMU's roll, pitch, yaw, shape (3,) [rad].
        imu_temperature: the IMU's temperature [degC].
        foot_force_est: the footForceEst field, FR, FL, RR, RL, shape (4,), the wire's int16 values as floats. The
            A1 SDK 3.3.1 never copies this field to its users (they read 0); what A1 firmware sends there is
            unverified, so do not rely on it on an A1.
        remote: the wireless-remote block (buttons, sticks, `Remote.l2_b`).
        battery: the Go1's battery-management block; None on the A1, which has none.
    """

    motor_mode: np.ndarray = field(default_factory=lambda: np.zeros(NUM_LEG_MOTORS, dtype=np.uint8))
    motor_temperature: np.ndarray = field(default_factory=lambda: np.zeros(NUM_LEG_MOTORS, dtype=np.int8))
    ddq_counts: np.ndarray = field(default_factory=lambda: np.zeros(NUM_LEG_MOTORS, dtype=np.int16))
    imu_rpy: np.ndarray = field(default_factory=lambda: np.zeros(3))
    imu_temperature: int = 0
    foot_force_est: np.ndarray = field(default_factory=lambda: np.zeros(4))
    remote: Remote = field(default_factory=Remote)
    battery: Battery | None = None
