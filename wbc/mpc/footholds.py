"""Foothold planning: the Raibert heuristic with a capture-point correction, so a push can be stepped out.

`plan_foothold` places one swing foot; `FootholdPlanner` keeps, for the four feet, where each lifted off and where it
will land (refreshed while it swings), and the swing targets between the two (`wbc.mpc.compiled.swing_targets`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wbc.mpc.compiled import swing_targets
from wbc.mpc.gait import GaitConfig
from wbc.mpc.kinematics import RobotKinematics
from wbc.robots.conventions import G

__all__ = ["MIN_CAPTURE_HEIGHT_M", "FootholdConfig", "FootholdPlanner", "ground_height", "plan_foothold"]

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
    """

    capture_gain: float = 1.0
    centripetal_gain: float = 0.1
    max_offset: float = 0.30


def plan_foothold(hip_now: np.ndarray, com_now: np.ndarray, v_com: np.ndarray, v_cmd: np.ndarray,
                  yaw_rate_cmd: float,
                  time_to_touchdown: float, stance_s: float, height: float, ground_z: float,
                  config: FootholdConfig) -> np.ndarray:
    """Where a swing foot should land.

    p = hip at touchdown + v_cmd T_stance / 2 + k sqrt(h / g) (v - v_cmd) + (w_cmd x r_hip) T_stance / 2
    + k_c sqrt(h / g) (v x w_cmd), clipped around the hip, where the hip at touchdown is the hip now moved by the CoM
    velocity and turned by the commanded yaw rate about the CoM for the remaining swing time, and r_hip its horizontal
    lever about the CoM.

    Args:
        hip_now: hip position projected to the ground, world (3,) [m].
        com_now: CoM position, world (3,) [m].
        v_com: CoM velocity, world (3,) [m/s].
        v_cmd: commanded horizontal velocity, world (3,) [m/s] (z ignored).
        yaw_rate_cmd: commanded yaw rate [rad/s].
        time_to_touchdown: remaining swing time [s].
        stance_s: stance duration [s].
        height: CoM height above the ground [m].
        ground_z: ground height at the foothold [m].
        config: settings.
    """
    # a few dozen scalar operations: Python floats, not 3-vectors of numpy calls (this runs for every swing foot
    # at every foothold refresh)
    hx, hy, hz = np.asarray(hip_now, dtype=np.float64).tolist()
    cx, cy, cz = np.asarray(com_now, dtype=np.float64).tolist()
    vx, vy = float(v_com[0]), float(v_com[1])
    vcx, vcy = float(v_cmd[0]), float(v_cmd[1])
    w, t = float(yaw_rate_cmd), float(time_to_touchdown)
    # the hip at touchdown: carried by the CoM and turned about it by the yaw rate over the remaining swing
    c, s = math.cos(w * t), math.sin(w * t)
    rx, ry = hx - cx, hy - cy
    lever_x, lever_y = c * rx - s * ry, s * rx + c * ry
    hip_x, hip_y = cx + vx * t + lever_x, cy + vy * t + lever_y
    root = math.sqrt(max(height, MIN_CAPTURE_HEIGHT_M) / G)
    half = stance_s / 2
    off_x = vcx * half + config.capture_gain * root * (vx - vcx)
    off_y = vcy * half + config.capture_gain * root * (vy - vcy)
    # v x (0, 0, w) = (w v_y, -w v_x, 0)
    off_x += config.centripetal_gain * root * w * vy
    off_y -= config.centripetal_gain * root * w * vx
    # turning: over half a stance the hip sweeps by yaw_rate x (hip - CoM)
    off_x -= w * lever_y * half  # (0, 0, w) x (l_x, l_y, 0) = (-w l_y, w l_x, 0)
    off_y += w * lever_x * half
    norm = math.hypot(off_x, off_y)
    if norm > config.max_offset:
        off_x *= config.max_offset / norm
        off_y *= config.max_offset / norm
    return np.array([hip_x + off_x, hip_y + off_y, float(ground_z)])


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
        self.reset()

    def reset(self) -> None:
        """Start a new episode: every foot standing."""
        self.liftoff = np.zeros((4, 3))
        self.footholds = np.zeros((4, 3))
        self._was_stance = [True] * 4

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
        stance = contact.tolist()
        was = self._was_stance
        ground = None
        for i in range(4):
            if stance[i]:
                continue
            lifted = was[i]
            if lifted:
                self.liftoff[i] = kin.feet[i]
            if refresh or lifted:
                if ground is None:
                    ground = ground_height(kin.feet, contact)
                    v_cmd_world = np.array([v_cmd_xy[0], v_cmd_xy[1], 0.0])
                hip = kin.hip_positions()[i].copy()
                self.footholds[i] = plan_foothold(hip, kin.com, kin.com_vel, v_cmd_world, yaw_rate,
                                                  float(touchdown[i]), self.gait.stance_s, kin.com[2] - ground,
                                                  ground, self.config)
        np.copyto(self.footholds, kin.feet, where=contact[:, None])
        self._was_stance = stance

    def swing_targets(self, contact: np.ndarray, progress: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity targets of the swing feet, from lift-off to foothold (zeros for stance feet).

        Args:
            contact: stance flags (4,).
            progress: progress of each foot through its swing, in [0, 1] (4,).

        Returns:
            (positions, velocities), world, shape (4, 3) each [m], [m/s].
        """
        pos, vel = np.empty((4, 3)), np.empty((4, 3))
        swing_targets(contact, progress, self.liftoff, self.footholds, self._below_z, self.gait.swing_s,
                      self.swing_height, pos, vel)
        return pos, vel
