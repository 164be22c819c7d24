"""`MpcController`: the model-based contender, registered as ``mpc``, ``mpc-locked`` and ``mpc-noarm``.

Every tick (500 Hz): the IMU and leg kinematics update the base estimator; every `replan_every` ticks the centroidal
MPC (with arm momentum when the arm is actuated) plans contact forces and arm velocities over the horizon, with
footholds from the Raibert + capture-point heuristic for the feet in swing. The leg-level whole-body layer maps the
plan to motor commands: stance feet get tau = -J^T f (the planned ground reaction), swing feet a Cartesian PD along
their swing trajectory, the arm a PD on the integrated planned velocity; joints are damped by the motor drivers.

Ground truth is never used unless the explicit debug switch `use_ground_truth` is thrown (``wbc run --debug-truth``,
recorded in the results): the controller sees only `RobotState`. A failed MPC solve falls back to the previous
plan, shifted, and is counted (``fallbacks``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wbc.estimation import BaseEstimator, EstimatorConfig
from wbc.mpc.centroidal_mpc import CentroidalMpc, MpcConfig, MpcSolution, MpcSolveError
from wbc.mpc.footholds import FootholdConfig, plan_foothold
from wbc.mpc.gait import TROT, GaitConfig, GaitScheduler
from wbc.mpc.kinematics import RobotKinematics
from wbc.mpc.swing import swing_point
from wbc.mpc.whole_body import WholeBodyConfig, WholeBodyQp
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import RobotDescription
from wbc.robots.joint_table import joint_table
from wbc.types import BaseTruth, MotorCommand, RobotState, VelocityCommand

__all__ = ["MpcControllerConfig", "MpcController"]


@dataclass(frozen=True, kw_only=True)
class MpcControllerConfig:
    """Settings of the MPC controller.

    Attributes:
        rate_hz: control rate [Hz].
        replan_every: ticks between MPC updates (20 at 500 Hz: every MPC step of 40 ms).
        foothold_every: ticks between foothold updates of the swing feet.
        mpc: the MPC's settings.
        gait: the gait.
        footholds: foothold heuristic settings.
        estimator: estimator noise settings.
        body_height: CoM height above the ground to hold [m].
        swing_height: swing apex [m].
        swing_kp: Cartesian swing stiffness [N/m].
        swing_kd: Cartesian swing damping [N s/m].
        joint_kd: motor damping on every leg joint [N m s/rad].
        arm_kp: arm joint stiffness [N m/rad].
        arm_kd: arm joint damping [N m s/rad].
        use_arm_momentum: let the MPC plan arm motion through its momentum (off: the arm is held).
        contact_force: foot sensor force at which a scheduled stance foot is fully trusted by the estimator [N].
        whole_body: ``qp`` (PlaCo's inverse-dynamics QP, `WholeBodyQp`) or ``legs`` (the leg-level layer: stance
            feet -J^T f, swing feet Cartesian PD; also the fallback when the QP fails).
        wbc: the whole-body QP's gains and weights.
    """

    rate_hz: float = 500.0
    replan_every: int = 20
    foothold_every: int = 5
    mpc: MpcConfig = field(default_factory=MpcConfig)
    gait: GaitConfig = TROT
    footholds: FootholdConfig = field(default_factory=FootholdConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    body_height: float = 0.28
    swing_height: float = 0.07
    swing_kp: float = 400.0
    swing_kd: float = 12.0
    joint_kd: float = 0.5
    arm_kp: float = 20.0
    arm_kd: float = 0.5
    use_arm_momentum: bool = True
    contact_force: float = 15.0
    whole_body: str = "qp"
    wbc: WholeBodyConfig = field(default_factory=WholeBodyConfig)

    def __post_init__(self) -> None:
        if self.whole_body not in ("qp", "legs"):
            raise ValueError(f"MpcControllerConfig.whole_body must be 'qp' or 'legs', got {self.whole_body!r}")


def _yaw_of(rot: np.ndarray) -> float:
    return math.atan2(rot.item(1, 0), rot.item(0, 0))


def _rotation_from_rpy(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), the MPC's Euler convention."""
    roll, pitch, yaw = rpy.tolist()
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _ground_height(feet: np.ndarray, stance: np.ndarray) -> float:
    """Mean height of the stance feet (the lowest foot when none stands) [m]."""
    heights = feet[:, 2].tolist()
    down = [z for z, s in zip(heights, stance.tolist(), strict=True) if s]
    return math.fsum(down) / len(down) if down else min(heights)


def _rpy(rot: np.ndarray) -> np.ndarray:
    return np.array([math.atan2(rot[2, 1], rot[2, 2]), -math.asin(max(-1.0, min(1.0, rot[2, 0]))), _yaw_of(rot)])


class MpcController:
    """Centroidal MPC + leg-level whole-body layer + estimator.

    Args:
        desc: the robot it drives.
        config: settings.
    """

    def __init__(self, desc: RobotDescription, config: MpcControllerConfig | None = None) -> None:
        self.desc = desc
        self.config = config or MpcControllerConfig()
        self.rate_hz = self.config.rate_hz
        self.dt = 1.0 / self.rate_hz
        self.kin = RobotKinematics(desc)
        table = joint_table(desc.with_arm_mode("actuated"))
        self.has_arm = desc.arm_mode == "actuated"
        vmax = table.velocity_limit[12:] if (self.has_arm and self.config.use_arm_momentum) else np.zeros(3)
        self.mpc = CentroidalMpc(self.config.mpc, table.lower[12:], table.upper[12:], vmax)
        self.gait = GaitScheduler(self.config.gait)
        self.estimator = BaseEstimator(self.dt, self.config.estimator)
        self.wbc = WholeBodyQp(desc, self.config.wbc) if self.config.whole_body == "qp" else None
        self._truth: Callable[[], BaseTruth] | None = None
        self._gains: tuple[np.ndarray, np.ndarray] | None = None
        self.reset()

    def use_ground_truth(self, truth: Callable[[], BaseTruth]) -> None:
        """Debug switch: take the base position and velocity from `truth` (the simulator) instead of the estimator.

        For isolating estimation errors only; the runner records it in every results row (``debug_truth``).
        """
        self._truth = truth

    def reset(self) -> None:
        """Start a new episode."""
        self.t = 0.0
        self.tick = 0
        self.plan: MpcSolution | None = None
        self.plan_t = 0.0
        self.fallbacks = 0
        self.solves = 0
        self.wbc_failures = 0
        self._x0 = np.zeros(15)
        self._started = False
        self._yaw_unwrapped = 0.0
        self._yaw_target = 0.0
        self._xy_target = np.zeros(2)
        self._liftoff = np.zeros((4, 3))
        self._footholds = np.zeros((4, 3))
        self._was_stance = [True] * 4
        self._arm_target = self.desc.arm.nominal_q.copy()
        self._wbc_key: tuple[object, ...] | None = None
        self._warm_start: np.ndarray | None = None

    def counters(self) -> dict[str, int]:
        """MPC solves, MPC fallbacks and whole-body QP failures (which fell back to the leg-level layer) so far."""
        return {"fallbacks": self.fallbacks, "mpc_solves": self.solves, "wbc_failures": self.wbc_failures}

    def debug_plan(self) -> dict[str, np.ndarray] | None:
        """The current plan, for viewers and debugging (None before the first solve).

        Returns:
            ``com_path_in_world`` (N, 3) predicted CoM [m]; ``footholds_in_world`` (4, 3) planned footholds (the
            current foot position for stance feet), house leg order FR, FL, RR, RL [m]; ``contact_schedule``
            (N, 4) bool; ``forces_in_world`` (N, 4, 3) planned contact forces [N]; ``arm_q_plan`` (N, 3) predicted
            arm joint positions [rad]; ``plan_age_s`` time since the plan was made [s].
        """
        if self.plan is None:
            return None
        mcfg = self.config.mpc
        return {
            "com_path_in_world": self.plan.states[:, 0:3].copy(),
            "footholds_in_world": self._footholds.copy(),
            "contact_schedule": self.gait.contact_table(self.plan_t, mcfg.dt, mcfg.horizon),
            "forces_in_world": self.plan.forces.copy(),
            "arm_q_plan": self.plan.states[:, 12:15].copy(),
            "plan_age_s": np.array(self.t - self.plan_t),
        }

    # -- one tick -------------------------------------------------------------------------------------------------
    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """Estimate, (re)plan, and turn the plan into motor commands."""
        cfg = self.config
        rot = quat_to_matrix(state.imu_quat)
        kin = self.kin
        if not self._started:
            kin.update(np.zeros(3), state.imu_quat, state.q, state.dq, np.zeros(3), state.gyro_in_body,
                       centroidal=False, rot=rot)
            base0 = np.array([0.0, 0.0, -kin.feet[:, 2].mean()])
            self.estimator.reset(base0, kin.feet + base0)
            self._yaw_unwrapped = _yaw_of(rot)
            self._yaw_target = self._yaw_unwrapped
            self._started = True
        # one kinematics pass at the predicted base state serves the estimator, then is shifted by its correction
        replan = self.plan is None or self.tick % cfg.replan_every == 0
        contact, progress, touchdown = self.gait.state(self.t)
        if self._truth is not None:
            # debug switch: the simulator's base position and velocity replace the estimate
            truth = self._truth()
            kin.update(truth.base_position_in_world, state.imu_quat, state.q, state.dq, truth.base_linvel_in_world,
                       state.gyro_in_body, centroidal=replan, rot=rot)
        else:
            estimator = self.estimator
            p_prior, v_prior = estimator.position, estimator.velocity
            kin.update(p_prior, state.imu_quat, state.q, state.dq, v_prior, state.gyro_in_body, centroidal=replan,
                       rot=rot)
            # a foot is trusted as a stance foot when the gait says so and its force sensor agrees: a late
            # touchdown or an early lift-off would otherwise feed a moving foot into the velocity estimate
            trust = contact * np.minimum(np.maximum(state.foot_force * (1.0 / cfg.contact_force), 0.0), 1.0)
            estimator.update(rot, state.accel_in_body, kin.feet - p_prior, kin.feet_vel - v_prior, trust)
            kin.shift(estimator.x[0:3] - p_prior, estimator.x[3:6] - v_prior)
        # the references, in Python floats: a handful of scalars per tick
        yaw = _yaw_of(rot)
        self._yaw_unwrapped += math.remainder(yaw - self._yaw_unwrapped, 2 * math.pi)
        cy, sy = math.cos(self._yaw_unwrapped), math.sin(self._yaw_unwrapped)
        vx_world = cy * command.vx - sy * command.vy
        vy_world = sy * command.vx + cy * command.vy
        com_x, com_y = kin.com[0].item(), kin.com[1].item()
        # keep the references from running away from a robot that was pushed far
        tx = self._xy_target[0].item() + vx_world * self.dt
        ty = self._xy_target[1].item() + vy_world * self.dt
        self._xy_target = np.array([com_x + min(max(tx - com_x, -0.15), 0.15),
                                    com_y + min(max(ty - com_y, -0.15), 0.15)])
        yaw_off = self._yaw_target + command.yaw_rate * self.dt - self._yaw_unwrapped
        self._yaw_target = self._yaw_unwrapped + min(max(yaw_off, -0.3), 0.3)
        self._update_footholds(contact, touchdown, (vx_world, vy_world), command.yaw_rate)
        if replan:
            self._replan(rot, state, command)
        tau = self._whole_body(contact, progress) if self.wbc is not None else None
        if tau is None:
            tau = self._leg_torques(contact)
        return self._command(state, tau)

    # -- planning -------------------------------------------------------------------------------------------------
    def _replan(self, rot: np.ndarray, state: RobotState, command: VelocityCommand) -> None:
        cfg, kin = self.config, self.kin
        mcfg = cfg.mpc
        n, dt = mcfg.horizon, mcfg.dt
        x0 = np.zeros(15)
        x0[0:3] = kin.com
        x0[3:6] = kin.com_vel
        rpy = _rpy(rot)
        x0[6:9] = (rpy[0], rpy[1], self._yaw_unwrapped)
        x0[9:12] = kin.momentum
        x0[12:15] = state.q[12:15] if self.has_arm else self.desc.arm.nominal_q
        ground = _ground_height(kin.feet, self.gait.contact(self.t))
        x_ref = np.zeros((n, 15))
        steps = np.arange(1, n + 1) * dt
        # while turning, the commanded body-frame velocity turns with the yaw reference along the horizon
        yaw_k = self._yaw_target + command.yaw_rate * steps
        vx_k = np.cos(yaw_k) * command.vx - np.sin(yaw_k) * command.vy
        vy_k = np.sin(yaw_k) * command.vx + np.cos(yaw_k) * command.vy
        x_ref[:, 0] = self._xy_target[0] + np.cumsum(vx_k) * dt
        x_ref[:, 1] = self._xy_target[1] + np.cumsum(vy_k) * dt
        x_ref[:, 2] = ground + cfg.body_height
        x_ref[:, 3] = vx_k
        x_ref[:, 4] = vy_k
        x_ref[:, 8] = yaw_k
        x_ref[:, 9:12] = kin.params.inertia_world @ np.array([0.0, 0.0, command.yaw_rate])
        x_ref[:, 12:15] = self.desc.arm.nominal_q
        contact = self.gait.contact_table(self.t, dt, n)
        # a foot stands where it is until it first lifts; from then on (in swing, and after it lands within the
        # horizon) it is at its foothold
        lifted = np.cumsum(~contact, axis=0) > 0
        feet = np.where(lifted[:, :, None], self._footholds[None], kin.feet[None])
        params = kin.params
        if not (self.has_arm and cfg.use_arm_momentum):
            params = type(params)(mass=params.mass, inertia_world=params.inertia_world,
                                  arm_momentum_matrix=np.zeros((3, 3)), feet_world=params.feet_world)
        try:
            self.plan = self.mpc.plan(x0, x_ref, contact, feet, params, self._warm_start)
            self.plan_t = self.t
            self._x0 = x0
            self._warm_start = self.plan.warm_start()
            self.solves += 1
        except MpcSolveError:
            self._warm_start = None  # the next update starts cold
            self.fallbacks += 1  # keep following the previous plan, which `_plan_step` shifts by time

    def _plan_step(self) -> int:
        k = int((self.t - self.plan_t) / self.config.mpc.dt)
        return min(k, self.config.mpc.horizon - 1)

    def _update_footholds(self, contact: np.ndarray, touchdown: np.ndarray, v_cmd_xy: tuple[float, float],
                          yaw_rate: float) -> None:
        """Lift-off points and footholds of the swing feet; a stance foot's foothold is where it stands."""
        cfg, kin = self.config, self.kin
        refresh = self.tick % cfg.foothold_every == 0
        stance = contact.tolist()
        was = self._was_stance
        ground = None
        for i in range(4):
            if stance[i]:
                continue
            lifted = was[i]
            if lifted:
                self._liftoff[i] = kin.feet[i]
            if refresh or lifted:
                if ground is None:
                    ground = _ground_height(kin.feet, contact)
                    v_cmd_world = np.array([v_cmd_xy[0], v_cmd_xy[1], 0.0])
                hip = kin.hip_positions()[i].copy()
                self._footholds[i] = plan_foothold(hip, kin.com, kin.com_vel, v_cmd_world, yaw_rate,
                                                   float(touchdown[i]), cfg.gait.stance_s, kin.com[2] - ground,
                                                   ground, cfg.footholds)
        np.copyto(self._footholds, kin.feet, where=contact[:, None])
        self._was_stance = stance

    # -- whole-body layer -----------------------------------------------------------------------------------------
    def _swing_targets(self, contact: np.ndarray, progress: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        pos = np.zeros((4, 3))
        vel = np.zeros((4, 3))
        s = progress.tolist()
        for i, stance in enumerate(contact.tolist()):
            if not stance:
                pos[i], vel[i] = swing_point(self._liftoff[i], self._footholds[i], s[i], cfg.gait.swing_s,
                                             cfg.swing_height)
        return pos, vel

    def _plan_terms(self, k: int) -> tuple[np.ndarray, ...]:
        """What the whole-body targets need from MPC step `k` of the current plan, built once per step.

        The planned state is blended linearly between the step's start and end; the trunk's angular acceleration
        is I^-1 sum_i (p_i - c) x f_i = I^-1 ([F]x c - sum_i [f_i]x p_i), linear in the CoM c and the feet p_i, so
        its two matrices are built here and the per-tick work is two products.
        """
        plan, params = self.plan, self.kin.params
        start = self._x0 if k == 0 else plan.states[k - 1]
        span = plan.states[k] - start
        forces = plan.forces[k]
        inertia_inv = params.inverse_inertia
        com_acc = forces.sum(axis=0) / params.mass + np.array([0.0, 0.0, -9.81])
        skews = np.zeros((3, 12))  # [ [f_0]x ... [f_3]x ]
        fx, fy, fz = forces[:, 0], forces[:, 1], forces[:, 2]
        skews[0, 1::3], skews[0, 2::3] = -fz, fy
        skews[1, 0::3], skews[1, 2::3] = fz, -fx
        skews[2, 0::3], skews[2, 1::3] = -fy, fx
        total_skew = skews.reshape(3, 4, 3).sum(axis=1)
        arm_v = plan.arm_velocity[k] if self.has_arm and self.config.use_arm_momentum else np.zeros(3)
        omega0 = inertia_inv @ (start[9:12] - params.arm_momentum_matrix @ arm_v)
        omega1 = inertia_inv @ span[9:12]
        return (start, span, com_acc, inertia_inv @ total_skew, inertia_inv @ skews, omega0, omega1, arm_v)

    def _whole_body(self, contact: np.ndarray, progress: np.ndarray) -> np.ndarray | None:
        """Torques from the whole-body QP tracking the plan; None (and counted) when it fails."""
        plan, kin = self.plan, self.kin
        if plan is None or kin.params is None:
            return None
        s = (self.t - self.plan_t) / self.config.mpc.dt
        k = min(int(s), self.config.mpc.horizon - 1)
        a = min(s - k, 1.0)
        cached = self._wbc_key
        if cached is None or cached[0] is not plan or cached[1] is not kin.params or cached[2] != k:
            self._wbc_terms, self._wbc_key = self._plan_terms(k), (plan, kin.params, k)
        start, span, com_acc, w_com, w_feet, omega0, omega1, arm_v = self._wbc_terms
        x = start + a * span
        domega = w_com @ kin.com - w_feet @ kin.feet.ravel()
        swing_pos, swing_vel = self._swing_targets(contact, progress)
        arm_q = self._arm_target if self.has_arm else None
        result = self.wbc.solve(kin.q_pin, kin.v_pin, contact, com=x[0:3], com_vel=x[3:6], com_acc=com_acc,
                                rot=_rotation_from_rpy(x[6:9]), omega_world=omega0 + a * omega1,
                                domega_world=domega, feet_pos=swing_pos, feet_vel=swing_vel,
                                arm_q=arm_q, arm_dq=arm_v if self.has_arm else None, with_forces=False)
        if not result.success:
            self.wbc_failures += 1
            return None
        return result.tau

    def _leg_torques(self, contact: np.ndarray) -> np.ndarray:
        cfg, kin = self.config, self.kin
        tau = np.zeros(kin.n)
        jacobians = kin.compute_jacobians()
        k = self._plan_step()
        progress = self.gait.swing_progress(self.t)
        for i in range(4):
            jac = jacobians[i][:, 3 * i:3 * i + 3]
            if contact[i]:
                f = self.plan.forces[k, i] if self.plan is not None else np.array([0.0, 0.0, 35.0])
                tau[3 * i:3 * i + 3] = -jac.T @ f
            else:
                pos, vel = swing_point(self._liftoff[i], self._footholds[i], float(progress[i]),
                                       cfg.gait.swing_s, cfg.swing_height)
                force = cfg.swing_kp * (pos - kin.feet[i]) + cfg.swing_kd * (vel - kin.feet_vel[i])
                tau[3 * i:3 * i + 3] = jac.T @ force
        return tau

    def _command(self, state: RobotState, tau: np.ndarray) -> MotorCommand:
        cfg = self.config
        if self._gains is None:
            n = self.kin.n
            kp, kd = np.zeros(n), np.full(n, cfg.joint_kd)
            if self.has_arm:
                kp[12:15], kd[12:15] = cfg.arm_kp, cfg.arm_kd
            self._gains = (kp, kd)  # MotorCommand copies its arrays, so these are shared safely
        kp, kd = self._gains
        q = state.q.copy()
        dq_des = np.zeros(self.kin.n)
        if self.has_arm:
            if self.plan is not None and cfg.use_arm_momentum:
                v_arm = self.plan.arm_velocity[self._plan_step()]
                self._arm_target = self._arm_target + v_arm * self.dt
                dq_des[12:15] = v_arm
            q[12:15] = self._arm_target
        self.t += self.dt
        self.tick += 1
        return MotorCommand(q=q, dq=dq_des, kp=kp, kd=kd, tau=tau)
