"""`MpcController`: the model-based contender, registered as ``mpc``, ``mpc-locked`` and ``mpc-noarm``.

Every tick (500 Hz) it orchestrates the pieces of this package:

1. the IMU and leg kinematics update the base estimator (`wbc.estimation.BaseEstimator`, `RobotKinematics`);
2. the leashed xy and yaw targets advance by the command (`MotionReference`);
3. the swing feet's footholds are re-planned (`FootholdPlanner`, the gait's phase from `GaitScheduler`);
4. every `replan_every` ticks the centroidal MPC (with arm momentum when the arm is actuated) plans contact forces
   and arm velocities over the horizon (`CentroidalMpc`), warm-started from the previous plan;
5. the whole-body QP (`WholeBodyQp`) tracks the plan (`PlanTargets`) and the swing trajectories, or the leg-level
   layer (`LegLayer`) does when it is chosen or the QP fails;
6. the motor command: those torques, joint damping, and the arm held by PD on its planned path.

With the leg layer, most ticks run steps 1-3, 5 and 6 as one compiled call (`wbc.mpc.compiled.control_tick`, the
stages the other ticks call one by one, to the same bits); a tick that makes an MPC update calls it around the
update, whose inputs are one compiled call too (`wbc.mpc.compiled.update_inputs`). The command's rows are checked
(finite, gains non-negative) in the call that fills them, so the command is built without a second check; the robot
clamps it to its motors' limits before anything reaches a motor.

Ground truth is never used unless the explicit debug switch `use_ground_truth` is thrown (``wbc run --debug-truth``,
recorded in the results): the controller sees only `RobotState`. A failed MPC solve falls back to the previous
plan, shifted in time, and is counted (``fallbacks``); a failed whole-body QP falls back to the leg layer
(``wbc_failures``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from wbc.config_checks import check_number
from wbc.errors import ConfigError
from wbc.estimation import BaseEstimator, EstimatorConfig
from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc import compiled as tick_stages
from wbc.mpc.centroidal_model import ARM_Q, COM, COM_VEL, MOMENTUM, NX, RPY
from wbc.mpc.centroidal_mpc import CentroidalMpc, MpcConfig, MpcSolution, MpcSolveError
from wbc.mpc.compiled import command_rows, contact_trust, control_tick, update_inputs
from wbc.mpc.footholds import MIN_CAPTURE_HEIGHT_M, FootholdConfig, FootholdPlanner, ground_height
from wbc.mpc.gait import TROT, GaitConfig, GaitScheduler, gait_fits_steps
from wbc.mpc.leg_layer import FORCE_BEFORE_PLAN, LegLayer
from wbc.mpc.plan_targets import PlanTargets
from wbc.mpc.reference import XY_LEASH_M, YAW_LEASH_RAD, MotionReference
from wbc.mpc.whole_body import WholeBodyConfig, WholeBodyQp
from wbc.robots.description import ARM_JOINTS, FOOT_NAMES, RobotDescription, joint_gains
from wbc.robots.euler import rpy_of, yaw_of
from wbc.robots.joint_table import joint_table
from wbc.types import BaseTruth, MotorCommand, RobotState, VelocityCommand

__all__ = ["MpcControllerConfig", "MpcController", "WHOLE_BODY_LAYERS"]

WHOLE_BODY_LAYERS = ("qp", "legs")
"""Valid values of `MpcControllerConfig.whole_body`."""


@dataclass(frozen=True, kw_only=True)
class MpcControllerConfig:
    """Settings of the MPC controller.

    Attributes:
        rate_hz: control rate [Hz].
        replan_every: ticks between MPC updates; one MPC step (16 at 500 Hz: every MPC step of 32 ms).
        foothold_every: ticks between foothold updates of the swing feet.
        mpc: the MPC's settings.
        gait: the gait.
        footholds: foothold heuristic settings.
        estimator: estimator noise settings.
        body_height: CoM height above the ground to hold [m].
        swing_height: swing apex [m].
        swing_kp: Cartesian swing stiffness of the leg layer [N/m].
        swing_kd: Cartesian swing damping of the leg layer [N s/m].
        stance_kd: Cartesian damping of the stance feet's world velocity in the leg layer [N s/m].
        touchdown_depth: the swing trajectory ends this far below the foothold, so a foot that lags its path still
            lands on time [m].
        joint_kd: motor damping on every leg joint [N m s/rad].
        arm_kp: arm joint stiffness [N m/rad].
        arm_kd: arm joint damping [N m s/rad].
        use_arm_momentum: let the MPC plan arm motion through its momentum (off: the arm is held).
        contact_force: foot sensor force at which a scheduled stance foot is fully trusted by the estimator [N].
        slip_speed: a trusted stance foot moving faster than this over the ground is slipping: the estimator drops
            it [m/s].
        velocity_ki: integral gain on the horizontal velocity error [1/s] (0: off). The MPC's model leaves out
            what slows the real robot down (the legs' swing, joint friction and damping, feet that roll and slide),
            so at speed it settles below its command (0.08 m/s short of 1.5 m/s in turn.toml's slow turns, its
            own estimate and the simulator agreeing). The error of the estimated velocity against the command,
            in the yaw-aligned frame, is integrated into an offset that the MPC's reference adds to the command.
        velocity_error_clip: the error is clipped to this, per axis, before it is integrated [m/s], so that the
            seconds of a push (errors of 1-2 m/s) add little: the offset learns the steady shortfall, not the
            disturbance.
        velocity_offset_limit: the largest offset, per axis [m/s].
        whole_body: ``legs`` (the leg-level layer, `LegLayer`: stance feet -J^T f, swing feet Cartesian PD,
            gravity compensation; also the fallback when the QP fails) or ``qp`` (PlaCo's inverse-dynamics QP,
            `WholeBodyQp`; it fell in fast turns, see docs/mpc-notes.md).
        wbc: the whole-body QP's gains and weights.
        xy_leash: the CoM target's leash around the measured CoM, per horizontal axis (`wbc.mpc.reference`) [m];
            0 tracks the commanded velocity alone, forgetting where the command would have put the robot.
        yaw_leash: the yaw target's leash around the measured yaw [rad]; 0 tracks the commanded yaw rate alone.

    Raises:
        ConfigError: a number that is not finite, a rate, height, force or speed that is not positive, a negative
            gain, depth or leash, an unknown `whole_body`, update intervals that are not whole numbers of ticks from
            one, an MPC step that is not `replan_every` ticks, or gait transitions that fall inside MPC steps.
    """

    rate_hz: float = 500.0
    replan_every: int = 16
    foothold_every: int = 5
    mpc: MpcConfig = field(default_factory=MpcConfig)
    gait: GaitConfig = TROT
    footholds: FootholdConfig = field(default_factory=FootholdConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    body_height: float = 0.28
    swing_height: float = 0.07
    swing_kp: float = 700.0
    swing_kd: float = 20.0
    stance_kd: float = 10.0
    touchdown_depth: float = 0.02
    joint_kd: float = 0.5
    arm_kp: float = 20.0
    arm_kd: float = 0.5
    use_arm_momentum: bool = True
    contact_force: float = 15.0
    slip_speed: float = 0.3
    velocity_ki: float = 1.0
    velocity_error_clip: float = 0.15
    velocity_offset_limit: float = 0.5
    whole_body: str = "legs"
    wbc: WholeBodyConfig = field(default_factory=WholeBodyConfig)
    xy_leash: float = XY_LEASH_M
    yaw_leash: float = YAW_LEASH_RAD

    def __post_init__(self) -> None:
        # a division by the rate, the contact force or a foot's speed, and the gains written into every command,
        # are refused here, where the value is given, rather than failing (or falling) in the controller
        for name in ("rate_hz", "body_height", "contact_force", "slip_speed"):
            check_number(f"MpcControllerConfig.{name}", getattr(self, name), above=0.0)
        for name in ("swing_height", "swing_kp", "swing_kd", "stance_kd", "touchdown_depth", "joint_kd", "arm_kp",
                     "arm_kd", "velocity_ki", "velocity_error_clip", "velocity_offset_limit", "xy_leash",
                     "yaw_leash"):
            check_number(f"MpcControllerConfig.{name}", getattr(self, name), at_least=0.0)
        if self.whole_body not in WHOLE_BODY_LAYERS:
            raise ConfigError(f"MpcControllerConfig.whole_body must be 'qp' (PlaCo's whole-body QP) or 'legs' (the "
                              f"leg-level layer), got {self.whole_body!r}; pass one of {', '.join(WHOLE_BODY_LAYERS)}")
        check_number("MpcControllerConfig.replan_every", self.replan_every, integer=True)
        check_number("MpcControllerConfig.foothold_every", self.foothold_every, integer=True)
        if self.replan_every < 1 or self.foothold_every < 1:
            raise ConfigError(f"MpcControllerConfig.replan_every and foothold_every count ticks between updates and "
                              f"must be at least 1, got {self.replan_every} and {self.foothold_every}; use 1 to "
                              "update every tick")
        if abs(self.replan_every / self.rate_hz - self.mpc.dt) > 1e-9:
            raise ConfigError(f"MpcControllerConfig: an MPC update every {self.replan_every} ticks at {self.rate_hz} "
                              f"Hz is not one MPC step of {self.mpc.dt} s; set replan_every = mpc.dt * rate_hz")
        if not gait_fits_steps(self.gait, self.mpc.dt):
            raise ConfigError(f"MpcControllerConfig: the gait (period {self.gait.period} s, duty {self.gait.duty}, "
                              f"offsets {self.gait.offsets}) lifts or lands feet inside MPC steps of {self.mpc.dt} s; "
                              "make the stance and swing of every foot whole numbers of MPC steps (e.g. period = 10 "
                              "mpc.dt, duty 0.5, offsets 0 and 0.5)")


def leg_length(model: pin.Model) -> float:
    """The shortest leg's length, straight: thigh (hip to knee) plus calf (knee to foot) [m]."""
    lengths = []
    for foot in FOOT_NAMES:
        frame = model.frames[model.getFrameId(foot)]
        knee = frame.parentJoint
        lengths.append(float(np.linalg.norm(model.jointPlacements[knee].translation)
                             + np.linalg.norm(frame.placement.translation)))
    return min(lengths)


class MpcController:
    """Centroidal MPC + whole-body QP (or leg-level layer) + estimator.

    Capabilities (structural, see `wbc.control.protocol`): `debug_plan` (HasDebugPlan), `use_ground_truth`
    (TruthSwitch), `tick_timings` (HasTickTimings).

    Args:
        desc: the robot it drives.
        config: settings.
    """

    def __init__(self, desc: RobotDescription, config: MpcControllerConfig | None = None) -> None:
        self.desc = desc
        self.config = cfg = config or MpcControllerConfig()
        self.rate_hz = cfg.rate_hz
        self.dt = 1.0 / self.rate_hz
        self.kin = RobotKinematics(desc)
        reach = leg_length(self.kin.robot.model)
        if not cfg.body_height < reach:
            raise ConfigError(f"MpcControllerConfig.body_height must be below {desc.name}'s straight leg (thigh + "
                              f"calf, {reach:.3f} m), which cannot hold the CoM higher; got {cfg.body_height!r}")
        table = joint_table(desc.with_arm_mode("actuated"))
        self.has_arm = desc.arm_mode == "actuated"
        arm_moves = self.has_arm and cfg.use_arm_momentum
        vmax = table.velocity_limit[ARM_JOINTS] if arm_moves else np.zeros(3)
        self.mpc = CentroidalMpc(cfg.mpc, table.lower[ARM_JOINTS], table.upper[ARM_JOINTS], vmax)
        self.gait = GaitScheduler(cfg.gait)
        self.estimator = BaseEstimator(self.dt, cfg.estimator)
        self.reference = MotionReference(control_dt=self.dt, horizon=cfg.mpc.horizon, step_s=cfg.mpc.dt,
                                         body_height=cfg.body_height, arm_q=desc.arm.nominal_q,
                                         xy_leash=cfg.xy_leash, yaw_leash=cfg.yaw_leash)
        self.feet = FootholdPlanner(cfg.gait, cfg.footholds, cfg.swing_height, cfg.touchdown_depth)
        self.targets = PlanTargets(horizon=cfg.mpc.horizon, step_s=cfg.mpc.dt, arm_moves=arm_moves)
        self.wbc = WholeBodyQp(desc, cfg.wbc) if cfg.whole_body == "qp" else None
        self.legs = LegLayer(swing_kp=cfg.swing_kp, swing_kd=cfg.swing_kd,
                             torque_limit=joint_table(desc).torque_limit, stance_kd=cfg.stance_kd)
        self._truth: Callable[[], BaseTruth] | None = None
        # the legs are torque-controlled (kp 0, a little joint damping); an actuated arm is position-controlled
        self._gains = joint_gains(self.kin.n, 0.0, cfg.joint_kd, cfg.arm_kp, cfg.arm_kd)
        self._arm_first = ARM_JOINTS.start if self.has_arm else -1  # `command_rows`: where the arm's joints start
        self._arm_moves = arm_moves
        self._arm_hold = np.zeros(3)  # the arm's velocity while no plan moves it
        self._inv_contact_force = 1.0 / cfg.contact_force
        self._slip2 = cfg.slip_speed * cfg.slip_speed
        self._ki, self._velocity_clip, self._velocity_limit = (cfg.velocity_ki, cfg.velocity_error_clip,
                                                               cfg.velocity_offset_limit)
        self.velocity_offset = (0.0, 0.0)
        """The offset added to the commanded (vx, vy), yaw-aligned frame [m/s] (`MpcControllerConfig.velocity_ki`)."""
        # the arrays of a tick live in three buffers that `control_tick` is handed whole (`wbc.mpc.compiled`'s
        # `tick_floats`, `tick_flags`, `tick_constant_arrays`); this controller's own are views of them from here on,
        # those of its parts are moved into them (`_hold_tick_arrays`)
        ts, n = tick_stages, self.kin.n
        self._tick_floats, self._tick_flags = np.zeros(ts.TICK_FLOATS + n), np.zeros(ts.TICK_FLAGS, dtype=bool)
        self._float_views, self._flag_views = ts.tick_floats(self._tick_floats), ts.tick_flags(self._tick_flags)
        # the gait's state at this tick, the estimator's trust in each foot and the feet it dropped at the last tick
        # (they slide), the arm's target, the compiled tick's results and torques
        (self._progress, self._touchdown, self._trust, _, _, _, _, _, _, _, self._arm_target, self._tick_out, _,
         self._tau) = self._float_views
        self._contact, self.slipping = self._flag_views[0:2]
        self._contact[:] = True
        self._arm_target[:] = desc.arm.nominal_q
        self._hold_tick_arrays()
        self._tick_constants = self._make_tick_constants()
        self.reset()
        self._load_compiled()

    def _tick_owners(self) -> tuple[tuple[object, str], ...]:
        """Who holds each of `tick_floats`' and then `tick_flags`' arrays, under which attribute."""
        feet = self.feet
        return ((self, "_progress"), (self, "_touchdown"), (self, "_trust"), (self.reference, "targets"),
                (feet, "liftoff"), (feet, "footholds"), (feet, "_parts"), (feet, "_swing_pos"), (feet, "_swing_vel"),
                (self.legs, "scale"), (self, "_arm_target"), (self, "_tick_out"), (self.estimator, "x"),
                (self, "_tau"), (self, "_contact"), (self, "slipping"), (feet, "_was_stance"), (feet, "_lifted"),
                (feet, "_clip"))

    def _hold_tick_arrays(self) -> None:
        """Make every array `control_tick` works on a view of its buffers (their values copied in), where it is not.

        Run when the controller is made and at the first compiled tick of every episode, so that an array a reset
        replaced (a subclass's, say) is moved back in before the tick writes the buffers.
        """
        for view, (owner, name) in zip((*self._float_views, *self._flag_views), self._tick_owners(), strict=True):
            held = getattr(owner, name)
            if held is not view:
                view[...] = held
                setattr(owner, name, view)

    def _make_tick_constants(self) -> np.ndarray:
        """`control_tick`'s constants buffer (`wbc.mpc.compiled.tick_constant_arrays`), from the settings and parts."""
        cfg, ts, n = self.config, tick_stages, self.kin.n
        buffer = np.zeros(ts.tick_constants_size(n))
        out, offsets, limit, kp, kd, *steady = ts.tick_constant_arrays(buffer, n)
        offsets[:], limit[:] = self.gait.clock[3], self.legs.limit
        kp[:], kd[:] = self._gains
        if self.estimator.config.gain == "steady":  # the full gain has no steady step (no compiled tick either)
            for view, matrices in zip(steady, self.estimator.steady_arrays()[1:], strict=True):
                view[...] = matrices
        out[ts.C_ARM_FIRST] = self._arm_first
        out[ts.C_PERIOD], out[ts.C_DUTY], out[ts.C_MARGIN] = self.gait.clock[:3]
        out[ts.C_INV_FORCE], out[ts.C_SLIP2], out[ts.C_DT] = self._inv_contact_force, self._slip2, self.dt
        out[ts.C_XY_LEASH], out[ts.C_YAW_LEASH] = cfg.xy_leash, cfg.yaw_leash
        out[ts.C_STANCE_S], out[ts.C_CAPTURE] = cfg.gait.stance_s, cfg.footholds.capture_gain
        out[ts.C_CENTRIPETAL], out[ts.C_MAX_OFFSET] = cfg.footholds.centripetal_gain, cfg.footholds.max_offset
        out[ts.C_MIN_HEIGHT], out[ts.C_BELOW_Z] = MIN_CAPTURE_HEIGHT_M, float(cfg.touchdown_depth)
        out[ts.C_SWING_S], out[ts.C_APEX] = cfg.gait.swing_s, cfg.swing_height
        out[ts.C_SWING_KP], out[ts.C_SWING_KD], out[ts.C_STANCE_KD] = self.legs.swing_kp, self.legs.swing_kd, \
            self.legs.stance_kd
        return buffer

    def _load_compiled(self) -> None:
        """Play two ticks (one with an MPC update) on a synthetic standing frame, then forget them.

        The tick's compiled functions load at their first call in a process (~1 s in all; seconds more to compile on
        a machine's first run): here, when the controller is made, not at the first tick of a robot that is waiting
        for its commands at 500 Hz. Nothing of the two ticks survives: `reset`, and the kinematics measure the CoM
        again at the first real tick.
        """
        n = self.kin.n
        state = RobotState(tick=0, time=0.0, q=np.asarray(self.desc.nominal_q, dtype=np.float64)[:n].copy(),
                           dq=np.zeros(n), tau_est=np.zeros(n), imu_quat=np.array([1.0, 0.0, 0.0, 0.0]),
                           gyro_in_body=np.zeros(3), accel_in_body=np.array([0.0, 0.0, 9.81]),
                           foot_force=np.full(4, 40.0))
        for _ in range(2):
            self.act(state, VelocityCommand())
        self.kin.forget_com()
        self.reset()

    def use_ground_truth(self, truth: Callable[[], BaseTruth]) -> None:
        """Debug switch: take the base position and velocity from `truth` (the simulator) instead of the estimator.

        For isolating estimation errors only; the simulated trial records it in its `TrialRecord` (``debug_truth``).
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
        self._x0 = np.zeros(NX)
        self._started = False
        self._warm_start: np.ndarray | None = None
        self._arm_target[:] = self.desc.arm.nominal_q
        self._timings: dict[str, float] = {}
        self.slipping[:] = False
        self.velocity_offset = (0.0, 0.0)
        self._tick_args: tuple | None = None  # `_tick_arrays`, gathered at the first compiled tick of the episode
        self.reference.reset()
        self.feet.reset()
        self.targets.reset()

    def counters(self) -> dict[str, int]:
        """MPC solves, MPC fallbacks and whole-body QP failures (which fell back to the leg-level layer) so far."""
        return {"fallbacks": self.fallbacks, "mpc_solves": self.solves, "wbc_failures": self.wbc_failures}

    def settings(self) -> dict[str, object]:
        """Every field of its `MpcControllerConfig`, nested settings as dicts (`HasSettings`)."""
        return dataclasses.asdict(self.config)

    def tick_timings(self) -> Mapping[str, float]:
        """Where the time of the last `act` went [s].

        Returns:
            ``mpc_setup_s`` (linearise, condense, constraints) and ``mpc_solve_s`` (the QP) on a tick that made an
            MPC update (a failed update, counted in ``fallbacks``, reports neither); ``whole_body_s``, the
            whole-body layer's time: PlaCo's QP every tick; the leg layer on the ticks due for an MPC update and
            the first of an episode, where it runs apart (on the others it runs inside the tick's one compiled call,
            `_compiled_act`, and is not timed apart). Empty before the first tick.
        """
        return dict(self._timings)

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
            "com_path_in_world": self.plan.states[:, COM].copy(),
            "footholds_in_world": self.feet.footholds.copy(),
            "contact_schedule": self.gait.contact_table(self.plan_t, mcfg.dt, mcfg.horizon),
            "forces_in_world": self.plan.forces.copy(),
            "arm_q_plan": self.plan.states[:, ARM_Q].copy(),
            "plan_age_s": np.array(self.t - self.plan_t),
        }

    # -- one tick -------------------------------------------------------------------------------------------------
    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """Estimate, (re)plan, and turn the plan into motor commands."""
        self._timings.clear()
        if self._ki > 0.0 and self._started:
            self._integrate_velocity(command)
        if self._started and self.wbc is None and self._truth is None and self.kin.com_known and \
                self.estimator.config.gain == "steady":
            return self._compiled_act(state, command)
        return self._staged_act(state, command)

    def _offset(self, command: VelocityCommand) -> VelocityCommand:
        """The command the MPC tracks: the operator's plus the velocity offset (`velocity_ki`; none when off)."""
        if self._ki <= 0.0:
            return command
        ox, oy = self.velocity_offset
        return VelocityCommand(vx=command.vx + ox, vy=command.vy + oy, yaw_rate=command.yaw_rate)

    def _integrate_velocity(self, command: VelocityCommand) -> None:
        """Integrate the last tick's velocity error into `velocity_offset` (`velocity_ki`).

        The error is the command's against the base velocity the last tick planned from (the estimate, or the
        simulator's with the debug truth), both in the frame of the yaw measured then; the offset is kept in that
        frame, so it turns with the robot. A few floats a tick: the command object with the offset is made only
        where a Python stage reads it (`_offset`).
        """
        v, yaw = self.kin.base_velocity, self.reference.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        vx_world, vy_world = v.item(0), v.item(1)
        clip, limit, gain = self._velocity_clip, self._velocity_limit, self._ki * self.dt
        ex = command.vx - (c * vx_world + s * vy_world)
        ey = command.vy - (-s * vx_world + c * vy_world)
        ox = self.velocity_offset[0] + gain * min(max(ex, -clip), clip)
        oy = self.velocity_offset[1] + gain * min(max(ey, -clip), clip)
        self.velocity_offset = (min(max(ox, -limit), limit), min(max(oy, -limit), limit))

    def _staged_act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """The tick stage by stage: each stage one call (most of them compiled, `wbc.mpc.compiled`).

        Every tick of a controller on PlaCo's whole-body QP, with the debug truth or the full-gain estimator, and
        the first tick of an episode (which measures the CoM and starts the estimator) run this way; the others run
        `_compiled_act`, the same stages in one compiled call, to the same bits.
        """
        cfg, kin = self.config, self.kin
        command = self._offset(command)
        kin.tick(state.imu_quat, state.q, state.dq, state.gyro_in_body)
        if not self._started:
            self._start()
        replan = self._replan_due()
        contact, progress = self._contact, self._progress
        self.gait.state_into(self.t, contact, progress, self._touchdown)
        self._estimate(state, contact)
        if replan:
            kin.centroidal()
        v_cmd_xy = self.reference.update(yaw_of(kin.rot), kin.com.item(0), kin.com.item(1), command)
        self.feet.update(kin, contact, self._touchdown, v_cmd_xy, command.yaw_rate,
                         refresh=self.tick % cfg.foothold_every == 0)
        if replan:
            self._replan(state, command)
        step = self._plan_step() if self.plan is not None else 0
        tau = self._whole_body(contact, progress) if self.wbc is not None else None
        if tau is None:
            tau = self._leg_torques(contact, progress, step)
        return self._command(state, tau, step)

    def _tick_arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays `control_tick` takes after the plan's forces and arm velocity, up to the command's rows."""
        self._hold_tick_arrays()
        return (*self.kin.compiled_arrays(), self._tick_floats, self._tick_flags, self._tick_constants)

    def _compiled_act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """The tick as `_staged_act` plays it, its stages in `control_tick`: one compiled call on most ticks.

        A tick that makes an MPC update calls it twice, around the centroidal quantities (between the estimate and
        the reference), then makes the update and ends as the staged tick does (the leg layer timed apart). Where a
        stage stops for the Python law (`control_tick`), the Python stage runs and the call resumes after it.
        """
        ts, kin, out = tick_stages, self.kin, self._tick_out
        if self._tick_args is None:
            self._tick_args = self._tick_arrays()
        replan = self._replan_due()
        refresh = self.tick % self.config.foothold_every == 0
        vx, vy, yaw_rate = float(command.vx), float(command.vy), float(command.yaw_rate)
        if self._ki > 0.0:  # what `_offset` gives the Python stages, to the bit
            vx += self.velocity_offset[0]
            vy += self.velocity_offset[1]
        rows = np.empty((5, kin.n))  # a new array each tick: it becomes the command's (immutable) storage
        head = (state.imu_quat, state.gyro_in_body, state.q, state.dq, state.accel_in_body, state.foot_force, self.t,
                vx, vy, yaw_rate, refresh)
        tail = (*self._tick_args, rows)
        step, forces, v_arm = self._step_inputs()
        if replan:
            control_tick(ts.STAGE_FRONT, ts.STAGE_REFERENCE, *head, forces, v_arm, *tail)
            kin.centroidal()
            stage = control_tick(ts.STAGE_REFERENCE, ts.STAGE_LEGS, *head, forces, v_arm, *tail)
        else:
            stage = control_tick(ts.STAGE_FRONT, ts.STAGE_DONE, *head, forces, v_arm, *tail)
        if stage < ts.STAGE_LEGS:  # a stage handed to the Python law
            self._python_stages(stage, self._offset(command), refresh)
            stage = ts.STAGE_LEGS
        if replan:
            self._replan(state, self._offset(command))
            step = self._plan_step() if self.plan is not None else 0
            return self._command(state, self._leg_torques(self._contact, self._progress, step), step)
        if stage < ts.STAGE_DONE:
            stage = control_tick(stage, ts.STAGE_DONE, *head, forces, v_arm, *tail)
        valid = self._arm_rows(rows, step) and out[ts.OUT_VALID] == 1.0
        self.t += self.dt
        self.tick += 1
        return MotorCommand.trusted(rows) if valid else MotorCommand.from_rows(rows)

    def _step_inputs(self) -> tuple[int, np.ndarray, np.ndarray]:
        """The plan's step at this tick, its contact forces (4, 3) [N] and the arm's velocity (3,) [rad/s]."""
        plan = self.plan
        if plan is None:
            return 0, FORCE_BEFORE_PLAN, self._arm_hold
        step = self._plan_step()
        return step, plan.forces[step], plan.arm_velocity[step] if self._arm_moves else self._arm_hold

    def _python_stages(self, stage: int, command: VelocityCommand, refresh: bool) -> None:
        """The stages from `stage` (where `control_tick` stopped) to the legs, by the Python law."""
        ts, kin, out = tick_stages, self.kin, self._tick_out
        if stage == ts.STAGE_REFERENCE:
            out[ts.OUT_V_CMD_X], out[ts.OUT_V_CMD_Y] = self.reference.update(
                yaw_of(kin.rot), kin.com.item(0), kin.com.item(1), command)
            stage = ts.STAGE_FOOTHOLDS
        if stage == ts.STAGE_FOOTHOLDS:
            self.feet.update(kin, self._contact, self._touchdown, (out.item(0), out.item(1)), command.yaw_rate,
                             refresh=refresh)
        elif stage == ts.STAGE_CLIP:
            self.feet.clip_left(out.item(ts.OUT_GROUND))

    def _start(self) -> None:
        """First tick of an episode: the estimator starts with the feet on the ground at z = 0."""
        kin = self.kin
        base0 = np.array([0.0, 0.0, -kin.feet_rel[:, 2].mean()])
        self.estimator.reset(base0, kin.feet_rel + base0)
        self.reference.start(yaw_of(kin.rot))
        self._started = True

    def _estimate(self, state: RobotState, contact: np.ndarray) -> None:
        """Update the base estimate from the IMU and this tick's leg kinematics, and place the kinematics there.

        A foot is trusted as a stance foot when the gait says so, its force sensor agrees, and it does not slide: a
        late touchdown, an early lift-off or a slipping foot would otherwise feed a moving foot into the velocity
        estimate (on ground of friction 0.4-0.5 a pushed robot's feet slide at up to 2 m/s).
        """
        kin = self.kin
        if self._truth is not None:
            # debug switch: the simulator's base position and velocity replace the estimate
            truth = self._truth()
            kin.place(truth.base_position_in_world, truth.base_linvel_in_world)
            return
        estimator = self.estimator
        x = estimator.x
        # the points in contact, not the foot frames: a loaded foot rolls on its sphere
        contact_trust(contact, state.foot_force, kin.contact_vel_rel, x.item(3), x.item(4), self._inv_contact_force,
                      self._slip2, self._trust, self.slipping)
        estimator.update(kin.rot, state.accel_in_body, kin.feet_rel, kin.contact_vel_rel, self._trust)
        x = estimator.x
        kin.place(x[0:3], x[3:6])

    # -- planning -------------------------------------------------------------------------------------------------
    def _replan_due(self) -> bool:
        """Whether this tick makes an MPC update: the first tick, then every `replan_every` ticks."""
        return self.plan is None or self.tick % self.config.replan_every == 0

    def _update_inputs(self, state: RobotState, command: VelocityCommand) -> tuple[np.ndarray, ...]:
        """An MPC update's current state x0 (15,), reference x_ref (N, 15), contact table (N, 4) and feet (N, 4, 3).

        One compiled call (`wbc.mpc.compiled.update_inputs`) but for the reference's momentum rows; the statements
        below it where that call leaves the inputs to Python (a foot's height past what its exact sum takes).
        """
        cfg, kin, reference = self.config, self.kin, self.reference
        n, dt = cfg.mpc.horizon, cfg.mpc.dt
        arm_q = state.q[ARM_JOINTS] if self.has_arm else self.desc.arm.nominal_q
        x0, x_ref = np.empty(NX), np.zeros((n, NX))
        contact, feet = np.empty((n, 4), dtype=bool), np.empty((n, 4, 3))
        if update_inputs(self.t, dt, float(command.vx), float(command.vy), float(command.yaw_rate),
                         reference.body_height, reference.step_times, *self.gait.clock, kin.compiled_arrays()[2],
                         self.feet.footholds, reference.targets, reference.arm_q, kin.momentum, arm_q, x0, x_ref,
                         contact, feet):
            x_ref[:, MOMENTUM] = kin.params.inertia_world @ np.array([0.0, 0.0, command.yaw_rate])
            return x0, x_ref, contact, feet
        x0 = np.zeros(NX)
        x0[COM] = kin.com
        x0[COM_VEL] = kin.com_vel
        rpy = rpy_of(kin.rot)
        x0[RPY] = (rpy[0], rpy[1], reference.yaw)
        x0[MOMENTUM] = kin.momentum
        x0[ARM_Q] = arm_q
        ground = ground_height(kin.feet, self.gait.contact(self.t))
        x_ref = reference.trajectory(command, ground, kin.params.inertia_world)
        contact = self.gait.contact_table(self.t, dt, n)
        # a foot stands where it is until it first lifts; from then on (in swing, and after it lands within the
        # horizon) it is at its foothold
        lifted = np.cumsum(~contact, axis=0) > 0
        feet = np.where(lifted[:, :, None], self.feet.footholds[None], kin.feet[None])
        return x0, x_ref, contact, feet

    def _replan(self, state: RobotState, command: VelocityCommand) -> None:
        cfg, kin = self.config, self.kin
        x0, x_ref, contact, feet = self._update_inputs(state, command)
        params = kin.params
        if not (self.has_arm and cfg.use_arm_momentum):
            params = type(params)(mass=params.mass, inertia_world=params.inertia_world,
                                  arm_momentum_matrix=np.zeros((3, 3)), feet_world=params.feet_world)
        try:
            plan = self.mpc.plan(x0, x_ref, contact, feet, params, self._warm_start)
        except MpcSolveError:
            self._warm_start = None  # the next update starts cold
            self.fallbacks += 1  # keep following the previous plan, which `_plan_step` shifts by time
            return
        self.plan = plan
        self.plan_t = self.t
        self._x0 = x0
        self._warm_start = plan.warm_start()
        self.solves += 1
        self._timings["mpc_setup_s"] = plan.setup_s
        self._timings["mpc_solve_s"] = plan.solve_s

    def _plan_step(self) -> int:
        k = int((self.t - self.plan_t) / self.config.mpc.dt)
        return min(k, self.config.mpc.horizon - 1)

    # -- whole-body layer -----------------------------------------------------------------------------------------
    def _whole_body(self, contact: np.ndarray, progress: np.ndarray) -> np.ndarray | None:
        """Torques from the whole-body QP tracking the plan; None (and counted) when it fails."""
        plan, kin = self.plan, self.kin
        if plan is None or kin.params is None:
            return None
        target = self.targets.at(plan, self._x0, self.t - self.plan_t, kin)
        swing_pos, swing_vel = self.feet.swing_targets(contact, progress)
        arm_q = self._arm_target if self.has_arm else None
        t0 = time.perf_counter()
        result = self.wbc.solve(kin.q_pin, kin.v_pin, contact, com=target.com, com_vel=target.com_vel,
                                com_acc=target.com_acc, rot=target.rot, omega_world=target.omega,
                                domega_world=target.domega, feet_pos=swing_pos, feet_vel=swing_vel,
                                arm_q=arm_q, arm_dq=target.arm_dq if self.has_arm else None, with_forces=False)
        self._timings["whole_body_s"] = time.perf_counter() - t0
        if not result.success:
            self.wbc_failures += 1
            return None
        return result.tau

    def _leg_torques(self, contact: np.ndarray, progress: np.ndarray, step: int) -> np.ndarray:
        """The leg-level layer's torques: the plan's forces on the scheduled stance feet, swing feet on their paths."""
        forces = self.plan.forces[step] if self.plan is not None else None
        pos, vel = self.feet.swing_targets(contact, progress)
        t0 = time.perf_counter()
        tau = self.legs.torques(self.kin, contact, forces, pos, vel)
        self._timings["whole_body_s"] = time.perf_counter() - t0
        return tau

    def _arm_rows(self, rows: np.ndarray, step: int) -> bool:
        """A subclass's own arm rows, written over those `_command` filled; whether what it wrote is finite.

        Here: nothing (the arm follows the plan's velocity, as `_command` wrote it).
        """
        return True

    def _command(self, state: RobotState, tau: np.ndarray, step: int) -> MotorCommand:
        """The motor command: the legs push `tau`, an actuated arm follows its target along the plan.

        The legs hold their measured pose under no stiffness; the arm's target advances along the plan's arm velocity
        of this tick's step when the plan moves it. One compiled call fills the rows and checks them (finite, gains
        non-negative): a command that passes is built without checking it again (`MotorCommand.trusted`; the robot
        still clamps it to the motors' limits), one that fails is refused by the constructor, which names the fault.
        """
        kp, kd = self._gains
        moves = self._arm_moves and self.plan is not None
        v_arm = self.plan.arm_velocity[step] if moves else self._arm_hold
        rows = np.empty((5, self.kin.n))  # a new array each tick: it becomes the command's (immutable) storage
        valid = command_rows(state.q, tau, kp, kd, self._arm_first, self._arm_target, v_arm, self.dt, rows)
        valid = self._arm_rows(rows, step) and valid
        self.t += self.dt
        self.tick += 1
        return MotorCommand.trusted(rows) if valid else MotorCommand.from_rows(rows)
