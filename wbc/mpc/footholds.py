"""Foothold planning: the Raibert heuristic with a capture-point correction, so a push can be stepped out.

A swing foot lands at

    p = hip at touchdown + v_cmd T_stance / 2 + k sqrt(h / g) (v - v_cmd) + (w_cmd x r_hip) T_stance / 2
        + k_c sqrt(h / g) (v x w_cmd),

its offset from the hip clipped to `FootholdConfig.max_offset`, where the hip at touchdown is the hip now moved by the
CoM velocity and turned by the commanded yaw rate about the CoM for the remaining swing time, r_hip its horizontal
lever about the CoM, h the CoM's height above the stance feet (at least `MIN_CAPTURE_HEIGHT_M`), v the CoM velocity
and T_stance the stance duration. `FootholdPlanner` keeps, for the four feet, where each lifted off and where it will
land (placed at lift-off and refreshed while it swings), and the swing targets between the two. Its arithmetic is
compiled (`wbc.mpc.compiled`: `liftoffs` every tick, `plan_footholds` when feet are placed, `swing_targets`); the
norm of an offset near the limit is Python's ``math.hypot``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wbc.config_checks import check_number
from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.compiled import liftoffs, plan_footholds, swing_targets
from wbc.mpc.gait import GaitConfig

__all__ = ["MIN_CAPTURE_HEIGHT_M", "FootholdConfig", "FootholdPlanner", "ground_height"]

MIN_CAPTURE_HEIGHT_M = 0.05
"""Floor on the CoM height h in the capture-point time constant sqrt(h / g) [m].

Keeps the capture and centripetal terms finite and non-zero when the height above the stance feet is estimated near
zero or negative (a collapsing or badly estimated robot). A tuning value; no measurement behind it is recorded."""


@dataclass(frozen=True, kw_only=True)
class FootholdConfig:
    """Foothold heuristic settings.

    Attributes:
        capture_gain: multiplies the capture-point term sqrt(h / g) (v - v_cmd).
        centripetal_gain: multiplies the turning term sqrt(h / g) (v x w_cmd): while turning the feet land outside
            the hips so the legs lean into the turn and carry the centripetal force; too much rolls the body into
            the turn, none lets it tip outward (tuning: docs/mpc-notes.md).
        max_offset: largest horizontal distance from the hip's projection [m]: about the leg's reach (the A1's and
            Go1's 0.4 m legs reach 0.29 m out from a hip 0.28 m up). A 2 m/s push needs a capture step of ~0.35 m;
            at the former 0.22 m the feet landed short and the robot fell over them (docs/mpc-notes.md).

    Raises:
        ConfigError: a setting that is negative or not a finite number (0 switches a gain off, or keeps the feet
            under the hips).
    """

    capture_gain: float = 1.0
    centripetal_gain: float = 0.1
    max_offset: float = 0.30

    def __post_init__(self) -> None:
        for name in ("capture_gain", "centripetal_gain", "max_offset"):
            check_number(f"FootholdConfig.{name}", getattr(self, name), at_least=0.0)


def ground_height(feet: np.ndarray, stance: np.ndarray) -> float:
    """Mean height of the stance feet (the lowest foot when none stands) [m].

    Args:
        feet: foot positions, world, shape (4, 3) [m].
        stance: stance flags (4,).
    """
    heights = feet[:, 2].tolist()
    down = [z for z, s in zip(heights, stance.tolist(), strict=True) if s]
    return math.fsum(down) / len(down) if down else min(heights)


class FootholdPlanner:
    """Lift-off points and footholds of the four feet; a stance foot's foothold is where it stands.

    Args:
        gait: the gait (its stance and swing durations).
        config: foothold heuristic settings.
        swing_height: swing apex [m].

    Attributes:
        liftoff: where each foot last lifted off, world, shape (4, 3) [m].
        footholds: where each swing foot will land (a stance foot: where it stands), world, shape (4, 3) [m].
    """

    def __init__(self, gait: GaitConfig, config: FootholdConfig, swing_height: float,
                 touchdown_depth: float = 0.0) -> None:
        self.gait = gait
        self.config = config
        self.swing_height = swing_height
        self._below_z = float(touchdown_depth)
        self._stance_s = gait.stance_s
        self._clip, self._parts = np.zeros(4, dtype=bool), np.zeros((4, 4))  # `plan_footholds`' feet left to clip
        # allocated once and reset in place: the MPC controller's compiled tick moves them into its buffers
        self.liftoff = np.zeros((4, 3))
        self.footholds = np.zeros((4, 3))
        self._was_stance = np.ones(4, dtype=bool)
        self._lifted = np.zeros(4, dtype=bool)  # the feet that lifted off at this tick
        self._swing_pos, self._swing_vel = np.zeros((4, 3)), np.zeros((4, 3))

    def reset(self) -> None:
        """Start a new episode: every foot standing."""
        self.liftoff[:] = 0.0
        self.footholds[:] = 0.0
        self._was_stance[:] = True
        self._lifted[:] = False
        self._swing_pos[:] = 0.0
        self._swing_vel[:] = 0.0

    def update(self, kin: RobotKinematics, contact: np.ndarray, touchdown: np.ndarray,
               v_cmd_xy: tuple[float, float], yaw_rate: float, *, refresh: bool) -> None:
        """Record the lift-offs of this tick and place the swing feet's footholds.

        Args:
            kin: the robot's kinematics at this tick.
            contact: scheduled stance flags (4,).
            touchdown: time until each swing foot's touchdown (4,) [s].
            v_cmd_xy: commanded horizontal velocity, world [m/s].
            yaw_rate: commanded yaw rate [rad/s].
            refresh: re-plan every swing foot's foothold (otherwise only those that lifted off at this tick).
        """
        lifted = liftoffs(contact, self._was_stance, kin.feet, self.liftoff, self.footholds, self._lifted)
        if not (refresh or lifted):
            return
        cfg, ground = self.config, ground_height(kin.feet, contact)
        # floats throughout (a whole number would compile another version of the kernel at its first call)
        if plan_footholds(contact, self._lifted, refresh, kin.hips_rel, kin.base_position, kin.com, kin.com_vel,
                          float(v_cmd_xy[0]), float(v_cmd_xy[1]), float(yaw_rate), touchdown, self._stance_s, ground,
                          cfg.capture_gain, cfg.centripetal_gain, cfg.max_offset, MIN_CAPTURE_HEIGHT_M, self.footholds,
                          self._parts, self._clip):
            self.clip_left(ground)

    def clip_left(self, ground: float) -> None:
        """Place the feet `plan_footholds` left, their offsets from the hip clipped to `FootholdConfig.max_offset`.

        Args:
            ground: the ground height the placement used [m].
        """
        limit = self.config.max_offset
        for i in np.flatnonzero(self._clip).tolist():
            hip_x, hip_y, off_x, off_y = self._parts[i].tolist()
            norm = math.hypot(off_x, off_y)
            if norm > limit:
                off_x *= limit / norm
                off_y *= limit / norm
            self.footholds[i] = (hip_x + off_x, hip_y + off_y, ground)

    def swing_targets(self, contact: np.ndarray, progress: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity targets of the swing feet, from lift-off to foothold (zeros for stance feet).

        Args:
            contact: stance flags (4,).
            progress: progress of each foot through its swing, in [0, 1] (4,).

        Returns:
            (positions, velocities), world, shape (4, 3) each [m], [m/s]: the planner's own arrays, overwritten by the
            next call.
        """
        pos, vel = self._swing_pos, self._swing_vel
        swing_targets(contact, progress, self.liftoff, self.footholds, self._below_z, self.gait.swing_s,
                      self.swing_height, pos, vel)
        return pos, vel
