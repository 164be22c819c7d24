"""`BaseEstimate`: the base's pose and velocity from what a real robot measures, for metrics and for the viewer.

A simulated trial takes its tracking metrics from the simulator's truth; a robot has none, so a hardware trial takes
them from the same estimator the MPC runs on (`wbc.estimation.BaseEstimator`: IMU and leg kinematics).
Orientation and angular velocity are the IMU's (quaternion and gyro); the position and velocity come from the
filter, fed with the feet's positions and velocities relative to the base from leg kinematics
(`wbc.estimation.kinematics.RobotKinematics`). A foot is trusted as standing in proportion to its force sensor's
reading, up to `contact_force`: there is no gait schedule here (the controller's is its own), and a standing foot
presses on its sensor whatever gait the controller runs.

On a real robot the foot sensors read raw counts that need calibrating per robot (see the hardware notes); until
then `contact_force` is the count at which a foot is fully trusted.
"""

from __future__ import annotations

import numpy as np

from wbc.errors import ConfigError
from wbc.estimation.filter import DEFAULT_CONTACT_FORCE, BaseEstimator, EstimatorConfig
from wbc.estimation.kinematics import RobotKinematics
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import RobotDescription
from wbc.types import BaseTruth, RobotState

__all__ = ["BaseEstimate"]


class BaseEstimate:
    """Base state from proprioception, updated once per control tick.

    The first update puts the feet on the ground at z = 0 with the base at rest above them, so positions are
    relative to where the robot stood at the start.

    Args:
        desc: the robot (its joints, as the states number them).
        dt: time between two updates [s] (the control period).
        contact_force: foot sensor reading at which a foot is fully trusted as standing [N, or sensor counts].
        config: the filter's noise settings.

    Raises:
        ConfigError: `dt` or `contact_force` is not positive.
    """

    def __init__(self, desc: RobotDescription, dt: float, *, contact_force: float = DEFAULT_CONTACT_FORCE,
                 config: EstimatorConfig | None = None) -> None:
        if not dt > 0:
            raise ConfigError(f"BaseEstimate: dt must be > 0 s, got {dt}")
        if not contact_force > 0:
            raise ConfigError(f"BaseEstimate: contact_force must be > 0, got {contact_force}")
        self.desc = desc
        self.dt = dt
        self.contact_force = contact_force
        self.kin = RobotKinematics(desc)
        self.filter = BaseEstimator(dt, config)
        self._started = False
        self._latest: BaseTruth | None = None
        self._load_compiled()

    def _load_compiled(self) -> None:
        """Fold two synthetic standing states in, then forget them: the filter's compiled step loads now.

        It loads at its first call in a process (~0.25 s): on a robot, that was the stand-up's second tick, and the
        link damped the motors for it (a write more than its 50 ms deadline after the first). Nothing of the two
        updates survives (`reset`; the kinematics measure the CoM again at their next centroidal update).
        """
        n = len(self.desc.nominal_q)
        state = RobotState(tick=0, time=0.0, q=np.asarray(self.desc.nominal_q, dtype=np.float64).copy(),
                           dq=np.zeros(n), tau_est=np.zeros(n), imu_quat=np.array([1.0, 0.0, 0.0, 0.0]),
                           gyro_in_body=np.zeros(3), accel_in_body=np.array([0.0, 0.0, 9.81]),
                           foot_force=np.full(4, 2.0 * self.contact_force))
        for _ in range(2):
            self.update(state)
        self.kin.forget_com()
        self.reset()

    def reset(self) -> None:
        """Forget the previous episode: the next update starts over at the feet's positions."""
        self._started = False
        self._latest = None

    @property
    def latest(self) -> BaseTruth | None:
        """The estimate after the last update, None before the first."""
        return self._latest

    def update(self, state: RobotState) -> BaseTruth:
        """Fold one state in and return the estimate.

        Args:
            state: the robot's state this tick.

        Returns:
            Base position and linear velocity (world) from the filter; quaternion and angular velocity (body) from
            the IMU.
        """
        kin, est = self.kin, self.filter
        quat = np.asarray(state.imu_quat, dtype=np.float64)
        rot = quat_to_matrix(quat)
        if not self._started:
            kin.update(np.zeros(3), quat, state.q, state.dq, np.zeros(3), state.gyro_in_body, centroidal=False)
            base0 = np.array([0.0, 0.0, -kin.feet[:, 2].mean()])
            est.reset(base0, kin.feet + base0)
            self._started = True
        p_prior, v_prior = est.position, est.velocity
        kin.update(p_prior, quat, state.q, state.dq, v_prior, state.gyro_in_body, centroidal=False)
        trust = np.clip(np.asarray(state.foot_force, dtype=np.float64) / self.contact_force, 0.0, 1.0)
        # the feet's points in contact, not their frames, are still on the ground: a loaded foot rolls on its sphere
        est.update(rot, state.accel_in_body, kin.feet_rel, kin.contact_vel_rel, trust)
        self._latest = BaseTruth(base_position_in_world=est.position, base_quat=quat.copy(),
                                 base_linvel_in_world=est.velocity,
                                 base_angvel_in_body=np.array(state.gyro_in_body, dtype=np.float64))
        return self._latest
