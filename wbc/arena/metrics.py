"""Episode metrics: named pure functions of an `Episode` (definitions follow the paper where it gives one).

- ``success``: the episode reached its end without the trunk or a non-foot link touching the ground.
- ``ttf`` (time to fall): fraction of the episode survived, survived time / episode length.
- ``vlin_err``: mean over the survived ticks of the L2 distance between the base's horizontal velocity (in the
  yaw-aligned frame) and the commanded (vx, vy) [m/s].
- ``vang_err``: mean over the survived ticks of |base yaw rate - commanded yaw rate| [rad/s].
- ``max_roll_deg`` / ``max_pitch_deg``: largest |roll| / |pitch| [deg].
- ``energy_j``: mechanical work of all motors, sum over ticks of sum_i |tau_i dq_i| dt [J].
- ``arm_travel_rad``: total arm joint travel, sum over ticks and arm joints of |delta q| [rad].
- ``safety_trips``: times the robot's safety layer latched its damping (0 without a safety layer).
- ``deadline_misses``: control ticks whose ``controller.act`` took longer than the control period (wall time).
- ``act_ms_p50`` / ``act_ms_p99``: median and 99th percentile of the ``controller.act`` wall time [ms].

The last three depend on the machine that played the episode, as its wall time does.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wbc.arena.episode import Episode

__all__ = [
    "METRICS",
    "success",
    "ttf",
    "vlin_err",
    "vang_err",
    "max_roll_deg",
    "max_pitch_deg",
    "energy_j",
    "arm_travel_rad",
    "safety_trips",
    "deadline_misses",
    "act_ms_p50",
    "act_ms_p99",
    "compute_metrics",
]


def success(ep: Episode) -> bool:
    """Survived the whole episode."""
    return not ep.fell


def ttf(ep: Episode) -> float:
    """Fraction of the episode survived."""
    return min(1.0, ep.survived_s / ep.duration_s)


def vlin_err(ep: Episode) -> float:
    """Mean L2 error between horizontal base velocity and the commanded (vx, vy) [m/s]."""
    if not len(ep.t):
        return float("nan")
    return float(np.mean(np.linalg.norm(ep.v_base_in_yaw - ep.command[:, :2], axis=1)))


def vang_err(ep: Episode) -> float:
    """Mean absolute yaw-rate error [rad/s]."""
    if not len(ep.t):
        return float("nan")
    return float(np.mean(np.abs(ep.yaw_rate - ep.command[:, 2])))


def max_roll_deg(ep: Episode) -> float:
    """Largest |roll| [deg]."""
    return float(np.degrees(np.max(np.abs(ep.roll)))) if len(ep.t) else float("nan")


def max_pitch_deg(ep: Episode) -> float:
    """Largest |pitch| [deg]."""
    return float(np.degrees(np.max(np.abs(ep.pitch)))) if len(ep.t) else float("nan")


def energy_j(ep: Episode) -> float:
    """Mechanical work of the motors [J]."""
    return float(np.sum(ep.power) * ep.control_dt)


def arm_travel_rad(ep: Episode) -> float:
    """Total arm joint travel [rad]."""
    if len(ep.t) < 2:
        return 0.0
    return float(np.sum(np.abs(np.diff(ep.arm_q, axis=0))))


def safety_trips(ep: Episode) -> int:
    """Times the safety layer latched its damping during the episode."""
    return int(np.count_nonzero(ep.safety_events.to_state == "damped"))


def deadline_misses(ep: Episode) -> int:
    """Ticks whose ``controller.act`` took longer than the control period."""
    return ep.deadline_misses()


def act_ms_p50(ep: Episode) -> float:
    """Median ``controller.act`` wall time [ms]."""
    return float(np.percentile(ep.act_s, 50) * 1e3) if len(ep.act_s) else float("nan")


def act_ms_p99(ep: Episode) -> float:
    """99th percentile of the ``controller.act`` wall time [ms]."""
    return float(np.percentile(ep.act_s, 99) * 1e3) if len(ep.act_s) else float("nan")


METRICS: dict[str, Callable[[Episode], float | bool | int]] = {
    "success": success,
    "ttf": ttf,
    "vlin_err": vlin_err,
    "vang_err": vang_err,
    "max_roll_deg": max_roll_deg,
    "max_pitch_deg": max_pitch_deg,
    "energy_j": energy_j,
    "arm_travel_rad": arm_travel_rad,
    "safety_trips": safety_trips,
    "deadline_misses": deadline_misses,
    "act_ms_p50": act_ms_p50,
    "act_ms_p99": act_ms_p99,
}


def compute_metrics(ep: Episode) -> dict[str, float | bool | int]:
    """Every metric of `METRICS` for one episode."""
    out = {name: fn(ep) for name, fn in METRICS.items()}
    out["fall_time_s"] = float(ep.fall_time_s)
    return out
