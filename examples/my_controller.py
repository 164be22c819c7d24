"""Your own controller in the arena, in one file: copy this one, change `act`, and compare it with ours.

    wbc compare examples.my_controller:make stand --scenario scenarios/push.toml --trials 4
    wbc check-controller examples.my_controller:make
    python examples/my_controller.py          # the contract check, then one push trial against `stand`

Nothing registers it: the arena imports ``examples.my_controller`` when the name is given (from the working
directory, here a checkout's root) and calls ``make`` with the robot's description to build the controller. A
`--controller-config FILE.toml` table is passed to the factory as a dict (its keys here: `leg_kp`, `leg_kd`,
`arm_kp`, `arm_kd`, `level_gain`, `tilt_alarm_deg`).

What it does: a stiffer PD stand than ``stand`` with a levelling reflex. The IMU's gravity direction says how the
trunk is tilted; the legs on the low side are lengthened and those on the high side shortened (thigh -a, calf +2a
keeps each foot under its hip), so the trunk levels itself after a push. It counts the ticks the trunk spent tilted
beyond `tilt_alarm_deg`; `counters()` is how a controller reports events, and they land in every results row.

A controller sees what a real robot gives it (`RobotState`: joint encoders, IMU, foot forces) and the operator's
`VelocityCommand`, and returns a `MotorCommand` per joint in the house order (legs FR, FL, RR, RL x hip, thigh,
calf; then the arm's waist, shoulder, elbow when it is actuated). The motors apply
tau = kp (q* - q) + kd (dq* - dq) + tau_ff at every physics step.
"""

import numpy as np

from wbc.control import ControllerPlugin
from wbc.robots.description import RobotDescription, joint_gains
from wbc.types import MotorCommand, RobotState, VelocityCommand

DEFAULTS = {"leg_kp": 80.0, "leg_kd": 2.5, "arm_kp": 20.0, "arm_kd": 0.5, "level_gain": 0.3, "tilt_alarm_deg": 15.0}

RIGHT, FRONT = np.array([1.0, -1.0, 1.0, -1.0]), np.array([1.0, 1.0, -1.0, -1.0])  # FR, FL, RR, RL: +1 right, front
THIGH, CALF = np.array([1, 4, 7, 10]), np.array([2, 5, 8, 11])  # joint indices of each leg's thigh and calf


class LevellingStand:
    """PD hold of the nominal pose, legs lengthened on the low side (the docstring above says how)."""

    rate_hz = 100.0  # [Hz]; the period must be a whole number of 2 ms physics steps

    def __init__(self, desc: RobotDescription, gains: dict) -> None:
        self.nominal_q = desc.nominal_q
        self.kp, self.kd = joint_gains(desc.num_joints, gains["leg_kp"], gains["leg_kd"], gains["arm_kp"],
                                       gains["arm_kd"])
        self.level_gain = gains["level_gain"]  # [rad of leg extension per unit of gravity tilt]
        self.tilt_alarm = np.sin(np.radians(gains["tilt_alarm_deg"]))
        self.zeros = np.zeros(desc.num_joints)
        self.tilted_ticks = 0

    def reset(self) -> None:
        self.tilted_ticks = 0

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        w, x, y, z = state.imu_quat
        gravity_x = -2.0 * (x * z - w * y)  # unit gravity in the body frame (x forward, y left): nose down -> > 0
        gravity_y = -2.0 * (y * z + w * x)  # right side down -> < 0
        if np.hypot(gravity_x, gravity_y) > self.tilt_alarm:
            self.tilted_ticks += 1
        extend = self.level_gain * (FRONT * gravity_x - RIGHT * gravity_y)  # per leg [rad]; > 0 lengthens
        q = self.nominal_q.copy()
        q[THIGH] -= extend
        q[CALF] += 2.0 * extend
        return MotorCommand(q=q, dq=self.zeros, kp=self.kp, kd=self.kd, tau=self.zeros)

    def counters(self) -> dict[str, int]:
        return {"tilted_ticks": self.tilted_ticks}


def build(desc: RobotDescription, config: dict | None = None) -> LevellingStand:
    """Build the controller for `desc`; `config` is the --controller-config table (missing keys: DEFAULTS)."""
    config = config or {}
    unknown = sorted(set(config) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"unknown keys {unknown}; valid keys: {', '.join(DEFAULTS)}")
    return LevellingStand(desc, {**DEFAULTS, **config})


make = ControllerPlugin(make=build, summary="example: a stiffer PD stand that levels the trunk after a push",
                        arm_modes=("actuated", "locked", "none"))
"""What `examples.my_controller:make` names: the factory, a summary, and the arm modes it can drive (the arena
plays the first; `wbc check-controller` builds every one)."""


if __name__ == "__main__":
    import dataclasses

    from wbc.arena.sim_trial import run_trial
    from wbc.control import check_controller
    from wbc.control.registry import get_controller
    from wbc.scenario import load_scenario

    spec = get_controller("examples.my_controller:make")
    check = check_controller(spec)
    print(f"contract check: {'passed' if check.passed else 'FAILED'}")
    for outcome in check.failed():
        print(f"  {outcome.check} on {outcome.robot}/{outcome.arm_mode}: {outcome.detail}")
    trial = load_scenario("scenarios/push.toml").trial("in", 0, 0)
    trial = dataclasses.replace(trial, duration_s=6.0)  # the first push or two
    for controller in (spec, "stand"):
        record, _ = run_trial(trial, controller)
        print(f"{record.controller}: {'stood' if record.success else f'fell at {record.fall_time_s:.2f} s'}, "
              f"max roll {record.max_roll_deg:.1f} deg, pushes up to {record.push_force_n:.0f} N")
