"""`TailMpcController`: the MPC controller that uses its arm as a tail, registered as ``mpc-tail``.

It is `wbc.mpc.controller.MpcController` (estimator, gait, footholds, leg layer) with three differences:

1. the plan comes from `wbc.mpc.tail_mpc.TailMpc`: the arm's joint accelerations are inputs bounded by its servos,
   its momentum matrix is evaluated along the horizon at the arm's planned poses, and its reference is the ready
   pose chosen for its leverage (`wbc.mpc.tail_model.choose_ready_pose`, computed once per robot);
2. a momentum-residual observer (`wbc.mpc.observer.MomentumObserver`) re-plans at once when it detects a push,
   instead of waiting for the next MPC step;
3. the arm follows its planned trajectory (position, speed) under PD with the torque of its planned acceleration
   fed forward, from the arm's rows of the equations of motion (M_aa ddq_a + b_a).
"""

from __future__ import annotations

import functools
import time
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np
import pinocchio as pin

from wbc.config_checks import check_number
from wbc.errors import ConfigError
from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.centroidal_mpc import MpcConfig, MpcSolveError
from wbc.mpc.controller import MpcController, MpcControllerConfig
from wbc.mpc.footholds import ground_height
from wbc.mpc.observer import MomentumObserver, ObserverConfig
from wbc.mpc.tail_compiled import arm_path_rows
from wbc.mpc.tail_model import ArmTail, ArmTailPath, arm_leverage, arm_tail_path, choose_ready_pose
from wbc.mpc.tail_mpc import ARM_DQ, ARM_Q, TNX, TailMpc, TailMpcConfig, TailPlan
from wbc.robots.description import ARM_JOINTS, RobotDescription
from wbc.robots.euler import rpy_of
from wbc.robots.joint_table import joint_table
from wbc.types import RobotState, VelocityCommand

__all__ = ["OVERRIDDEN", "TAIL_YAW_LEASH_RAD", "OverriddenSettingError", "TailControllerConfig", "TailMpcController",
           "check_not_overridden", "ready_pose"]


TAIL_YAW_LEASH_RAD = 0.1
"""`mpc-tail`'s yaw leash (`MpcControllerConfig.yaw_leash`) [rad], a third of the base MPC's.

Measured on dev trials of ``turn.toml`` band 1.5 m/s (seeds 100-101, 12 trials; docs/mpc-notes.md): with the base
MPC's 0.3 rad the fast turns ask the feet for the sideways forces that take the robot back to its yaw target, the
friction octagon binds sideways and the forward push falls short (V_lin err 0.099 m/s, V_ang err 0.175 rad/s); at
0.1 rad both errors are smaller (0.082, 0.171); below it the speed is tracked better still and the yaw rate worse
(0.05 rad: 0.076, 0.216; 0: 0.075, 0.294). Push v2 and push-low-friction band ood: every dev trial survived at 0.05
and 0.1 rad."""


@dataclass(frozen=True, kw_only=True)
class TailControllerConfig:
    """Settings of `TailMpcController`.

    Attributes:
        base: the MPC controller's settings (estimator, gait, footholds, leg layer, leashes). The tail controller
            sets the rest itself, so these are refused unless at their defaults (`OVERRIDDEN`): every field of
            ``base.mpc`` (the tail MPC's own are `tail`'s: ``tail.mu``, ``tail.horizon`` ...), ``base.arm_kp`` and
            ``base.arm_kd`` (this class's `arm_kp`, `arm_kd`), ``base.replan_every`` (one MPC step of ``tail.dt``)
            and ``base.use_arm_momentum`` (``tail.arm_moves``). The default base's yaw leash is
            `TAIL_YAW_LEASH_RAD`; a settings table's ``base`` edits that default base, but a `MpcControllerConfig`
            given here replaces it whole, so its yaw leash is the base MPC's 0.3 rad unless it sets ``yaw_leash``
            (``MpcControllerConfig(velocity_ki=2.0, yaw_leash=TAIL_YAW_LEASH_RAD)`` keeps the tail's).
        tail: the tail MPC's settings.
        ready_q: the arm's ready pose (waist, shoulder, elbow) [rad]; None: chosen for its leverage (`ready_pose`).
        observer: the push detector's settings.
        replan_on_push: re-plan at the tick a push is detected (off: on the MPC's clock only).
        arm_kp: arm joint stiffness around the planned path [N m/rad].
        arm_kd: arm joint damping around the planned speed [N m s/rad].

    Raises:
        ConfigError: a `ready_q` that is not 3 finite angles, an arm gain that is negative or not finite, a ``base``
            setting the tail controller overrides that is not at its default (the message names each and where its
            tail equivalent is), or a ``tail.dt`` that is not a whole number of control ticks (the nested settings
            check their own fields).
    """

    base: MpcControllerConfig = field(default_factory=lambda: MpcControllerConfig(yaw_leash=TAIL_YAW_LEASH_RAD))
    tail: TailMpcConfig = field(default_factory=TailMpcConfig)
    ready_q: tuple[float, float, float] | None = None
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    replan_on_push: bool = True
    arm_kp: float = 20.0
    arm_kd: float = 0.5

    def __post_init__(self) -> None:
        if self.ready_q is not None:
            try:
                check_number("TailControllerConfig.ready_q", self.ready_q, size=3)
            except ConfigError:  # a single number, a list of another length, or a value not finite
                raise ConfigError(f"TailControllerConfig.ready_q must be 3 finite angles (waist, shoulder, elbow) "
                                  f"[rad], got {self.ready_q!r}") from None
        check_number("TailControllerConfig.arm_kp", self.arm_kp, at_least=0.0)
        check_number("TailControllerConfig.arm_kd", self.arm_kd, at_least=0.0)
        check_not_overridden([name for name in OVERRIDDEN if _given(self.base, name)])
        rate = self.base.rate_hz
        if abs(round(self.tail.dt * rate) / rate - self.tail.dt) > 1e-9:
            raise ConfigError(f"TailControllerConfig.tail.dt must be a whole number of control ticks (1 / base.rate_hz"
                              f" = {1.0 / rate:g} s: the MPC updates every tail.dt * base.rate_hz ticks), got "
                              f"{self.tail.dt}; set tail.dt to a multiple of {1.0 / rate:g} s, e.g. "
                              f"{max(1, round(self.tail.dt * rate)) / rate:g}")


_BASE = MpcControllerConfig()
OVERRIDDEN = {
    **{f"base.mpc.{f.name}": (f"use tail.{f.name}" if f.name in {g.name for g in fields(TailMpcConfig)}
                              else "the tail MPC solves with DAQP" if f.name == "qp_solver"
                              else "the tail MPC has no such setting")
       for f in fields(MpcConfig)},
    "base.arm_kp": "use arm_kp", "base.arm_kd": "use arm_kd",
    "base.replan_every": "the MPC updates every tail.dt * base.rate_hz ticks: use tail.dt",
    "base.use_arm_momentum": "use tail.arm_moves",
}
"""The `MpcControllerConfig` settings (``base.``...) that `TailMpcController` sets itself, and where their tail
equivalents are; `TailControllerConfig` refuses any of them that is not at its default."""


class OverriddenSettingError(ConfigError):
    """Base settings given that the tail controller sets itself (`check_not_overridden`)."""


def check_not_overridden(names: list[str]) -> None:
    """Refuse the base settings `names` (keys of `OVERRIDDEN`), naming each and where its tail equivalent is.

    Raises:
        OverriddenSettingError: `names` is not empty.
    """
    if names:
        raise OverriddenSettingError("TailControllerConfig: the tail MPC controller sets these base settings itself, "
                                     "so they would be ignored: "
                                     + "; ".join(f"{name} ({OVERRIDDEN[name]})" for name in names))


def _given(base: MpcControllerConfig, name: str) -> bool:
    """Whether the setting `name` (``base.mpc.mu``, ``base.arm_kp`` ...) of `base` differs from its default."""
    path = name.split(".")[1:]
    value, default = base, _BASE
    for part in path:
        value, default = getattr(value, part), getattr(default, part)
    return value != default


@functools.lru_cache(maxsize=4)
def ready_pose(robot: str) -> tuple[float, float, float]:
    """The arm's ready pose for `robot`, a registry name of a robot with an arm.

    The reachable pose, on a 0.05 rad grid of shoulder and elbow 0.05 rad inside their limits, with the most
    leverage about the weaker of roll and pitch among those held with at most half the servos' stall torque
    (`choose_ready_pose`).
    """
    from wbc.robots.registry import get_robot

    desc = get_robot(robot, "actuated")
    kin = RobotKinematics(desc)
    table = joint_table(desc)
    lo, hi = table.lower[ARM_JOINTS] + 0.05, table.upper[ARM_JOINTS] - 0.05
    q = pin.neutral(kin.robot.model)
    q[2] = desc.stand_height
    q[7:] = desc.nominal_q[kin.robot.joints.pin_from_house]
    grid = [desc.arm.nominal_q, *(np.array([0.0, s, e]) for s in np.arange(lo[1], hi[1], 0.05)
                                  for e in np.arange(lo[2], hi[2], 0.05))]
    poses = arm_leverage(kin.robot, q, kin.arm_v, np.array(grid), table.velocity_limit[ARM_JOINTS],
                         table.torque_limit[ARM_JOINTS])
    return tuple(float(v) for v in np.round(choose_ready_pose(poses).arm_q, 4))


class TailMpcController(MpcController):
    """The MPC with the arm as a tail (see the module).

    Args:
        desc: the robot it drives (an actuated arm).
        config: settings.
    """

    def __init__(self, desc: RobotDescription, config: TailControllerConfig | None = None) -> None:
        cfg = config or TailControllerConfig()
        tail = cfg.tail
        # a held arm (`TailMpcConfig.arm_moves` off) stays at its target under the base controller's PD
        base = replace(cfg.base, mpc=replace(cfg.base.mpc, horizon=tail.horizon, dt=tail.dt), arm_kp=cfg.arm_kp,
                       arm_kd=cfg.arm_kd, replan_every=round(tail.dt * cfg.base.rate_hz),
                       use_arm_momentum=tail.arm_moves)
        table = joint_table(desc.with_arm_mode("actuated"))
        self.tail_config = cfg
        self.tail_mpc = TailMpc(tail, table.lower[ARM_JOINTS], table.upper[ARM_JOINTS],
                                table.velocity_limit[ARM_JOINTS], table.torque_limit[ARM_JOINTS])
        self.ready_q = np.array(cfg.ready_q if cfg.ready_q is not None else ready_pose(desc.name))
        lower, upper = table.lower[ARM_JOINTS], table.upper[ARM_JOINTS]
        if not np.all((lower <= self.ready_q) & (self.ready_q <= upper)):
            ranges = ", ".join(f"[{a:.2f}, {b:.2f}]" for a, b in zip(lower, upper, strict=True))
            raise ConfigError(f"TailControllerConfig.ready_q must be within {desc.name}'s arm joint limits (waist, "
                              f"shoulder, elbow: {ranges} rad), got {cfg.ready_q!r}")
        self.observer: MomentumObserver | None = None  # made with the kinematics, in the base's constructor
        self._tail_now: ArmTail | None = None
        self._push_pending = False
        self.pushes_detected = 0
        self.push_replans = 0
        super().__init__(desc, base)
        self.reference.arm_q = self.ready_q
        self.reset()

    # -- episode and counters -------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Start a new episode."""
        super().reset()
        if self.observer is None and hasattr(self, "kin"):
            self.observer = MomentumObserver(self.kin.mass, self.tail_config.observer)
        if self.observer is not None:
            self.observer.reset()
        self._arm_target[:] = self.ready_q  # where a held arm stays
        self._tail_now = None
        self._push_pending = False
        self.pushes_detected = 0
        self.push_replans = 0

    def counters(self) -> dict[str, int]:
        """The MPC's counters, and the pushes the observer detected and the updates they triggered."""
        return {**super().counters(), "pushes_detected": self.pushes_detected, "push_replans": self.push_replans}

    def settings(self) -> dict[str, object]:
        """Its `TailControllerConfig` as it runs (`HasSettings`).

        ``ready_q`` is the pose it holds (`ready_pose`'s when the settings leave it out), ``base`` the MPC controller's
        settings with those the tail sets in place.
        """
        return {**asdict(self.tail_config), "ready_q": self.ready_q.tolist(), "base": asdict(self.config)}

    # -- planning -------------------------------------------------------------------------------------------------
    def _replan_due(self) -> bool:
        if super()._replan_due():
            self._push_pending = False
            return True
        if self._push_pending and self.tail_config.replan_on_push:
            self._push_pending = False
            self.push_replans += 1
            return True
        return False

    def _replan(self, state: RobotState, command: VelocityCommand) -> None:
        cfg, kin = self.tail_config.tail, self.kin
        n = cfg.horizon
        x0 = np.zeros(TNX)
        x0[0:3], x0[3:6] = kin.com, kin.com_vel
        rpy = rpy_of(kin.rot)
        x0[6:9] = (rpy[0], rpy[1], self.reference.yaw)
        x0[9:12] = kin.momentum
        x0[ARM_Q], x0[ARM_DQ] = state.q[ARM_JOINTS], state.dq[ARM_JOINTS]
        if not cfg.arm_moves:
            x0[ARM_DQ] = 0.0  # a held arm: the plan keeps it still where it is
        ground = ground_height(kin.feet, self.gait.contact(self.t))
        x_ref = np.zeros((n, TNX))
        x_ref[:, :15] = self.reference.trajectory(command, ground, kin.params.inertia_world)
        contact = self.gait.contact_table(self.t, cfg.dt, n)
        lifted = np.cumsum(~contact, axis=0) > 0
        feet = np.where(lifted[:, :, None], self.feet.footholds[None], kin.feet[None])
        t0 = time.perf_counter()
        path = self._steps(x0)
        path_s = time.perf_counter() - t0
        try:
            plan = self.tail_mpc.plan(x0, x_ref, contact, feet, path, self._warm_start)
        except MpcSolveError:
            self._warm_start = None
            self.fallbacks += 1
            return
        self.plan = plan
        self.plan_t = self.t
        self._x0 = x0
        self._tail_now = path.tail(0)
        self._warm_start = plan.warm_start()
        self.solves += 1
        # the setup is the arm's model along the horizon (Pinocchio, `_steps`) and the QP's build
        self._timings["mpc_setup_s"] = path_s + plan.setup_s
        self._timings["mpc_solve_s"] = plan.solve_s

    def _steps(self, x0: np.ndarray) -> ArmTailPath:
        """Each step's arm pose and speed (the previous plan's, from where it now is; held at first) and its tail."""
        n, kin = self.tail_config.tail.horizon, self.kin
        plan = self.plan if isinstance(self.plan, TailPlan) else None
        if plan is None:
            arm = np.tile(x0[12:], (n, 1))
        else:
            shift = min(self._plan_step() + 1, n - 1)
            ahead = plan.states[shift:, 12:]
            arm = np.vstack([x0[12:], ahead, np.repeat(ahead[-1:], n - 1 - len(ahead), axis=0)])[:n]
        return arm_tail_path(kin.robot, kin.q_pin, kin.v_pin, kin.arm_v, arm[:, :3], arm[:, 3:])

    # -- the arm's command ----------------------------------------------------------------------------------------
    def _arm_rows(self, rows: np.ndarray, step: int) -> bool:
        """The arm on its planned path: position and speed within the current step; the observer's update.

        The planned acceleration's torque is fed forward (M_aa ddq_a + b_a at the pose of the last update). A held
        arm keeps the rows the base controller wrote (its target, under PD).
        """
        plan = self.plan
        if not isinstance(plan, TailPlan) or self._tail_now is None:
            return True  # before the first plan: the arm holds its target, as the base controller wrote it
        if self.tail_config.tail.arm_moves:
            k = step
            tau = self.t + self.dt - self.plan_t - k * self.tail_config.tail.dt  # into step k, at this command's end
            start = self._x0[12:] if k == 0 else plan.states[k - 1, 12:]
            acc = plan.arm_acceleration[k]
            torque = self._tail_now.mass_matrix @ acc + self._tail_now.bias
            finite = arm_path_rows(rows, ARM_JOINTS.start, start, acc, tau, torque)
        else:
            finite = bool(np.isfinite(rows[:, ARM_JOINTS]).all())
        self._observe(step)
        return finite

    def _observe(self, step: int) -> None:
        """Feed the observer this tick's estimate and the forces the plan asks of the stance feet.

        The stance flags are the gait's at this tick, as the tick's gait stage wrote them (`gait.contact(self.t)`).
        """
        if self.observer is None or self.plan is None:
            return
        if self.observer.update_stance(self.kin.com_vel, self.plan.forces[step], self._contact, self.dt):
            self.pushes_detected += 1
            self._push_pending = True

