"""Episode metrics: named pure functions of an `Episode` (definitions follow the paper where it gives one).

- ``success``: the episode reached its end without the trunk or a non-foot link touching the ground, and its robot's
  safety layer did not stop it (a trip, an e-stop).
- ``ttf`` (time to fall): fraction of the episode survived, survived time / episode length; an episode that ended
  early without a fall (a safety layer's trip or e-stop, `Episode.stopped`) counts the time it played
  (`Episode.survived_s`), as the record counts an interruption or a controller's error, and has no fall time
  (``fall_time_s`` NaN).
- ``vlin_err``: mean over the survived ticks of the L2 distance between the base's horizontal velocity (in the
  yaw-aligned frame) and the commanded (vx, vy) [m/s].
- ``vang_err``: mean over the survived ticks of |base yaw rate - commanded yaw rate| [rad/s].
- ``max_roll_deg`` / ``max_pitch_deg``: largest |roll| / |pitch| [deg].
- ``energy_j``: mechanical work of all motors, sum over ticks of sum_i |tau_i dq_i| dt [J].
- ``power_w``: mean mechanical power over the time played, energy_j / (ticks dt) [W]: the per-second form of
  ``energy_j``, which grows with the time survived (a controller that falls early spends less energy).
- ``vlin_err_by_s`` / ``vang_err_by_s``: the tracking errors' means over each whole second played, as text
  (`profile_text`); the arena averages them over a window every compared controller survived
  (`wbc.arena.windows`), since ``vlin_err`` and ``vang_err``, averaged over each trial's own survived time, favour a
  controller that falls before the hard part.
- ``ticks``: control ticks played.
- ``clamped_ticks``: ticks whose command lay outside the motors' limits and was clamped before it was sent.
- ``clamped_rows``: the ticks each command row (q, dq, kp, kd, tau) was clamped on, as ``row=ticks`` pairs joined by
  ``;`` (rows never clamped left out).
- ``arm_travel_rad``: total arm joint travel, sum over ticks and arm joints of |delta q| [rad].
- ``safety_trips``: times the robot's safety layer latched its damping (0 without a safety layer).
- ``deadline_misses``: control ticks whose ``controller.act`` took longer than the control period (wall time).
- ``act_ms_p50`` / ``act_ms_p99`` / ``act_ms_max``: median, 99th percentile and largest ``controller.act`` wall
  time [ms].
- ``write_deadline_ramps``: times a robot's device damped itself on its write deadline during the episode and its
  safety layer ramped it again (the layer's ``write_deadline`` events; 0 without one).

The last five depend on the machine that played the episode, as its wall time does.
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
    "act_ms_max",
    "write_deadline_ramps",
    "power_w",
    "vlin_err_by_s",
    "vang_err_by_s",
    "ticks",
    "clamped_ticks",
    "clamped_rows",
    "per_second",
    "profile_text",
    "compute_metrics",
]


def success(ep: Episode) -> bool:
    """Played the whole episode: no fall, and no safety layer's stop (`Episode.stopped`)."""
    return not ep.fell and not ep.stopped


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


def act_ms_max(ep: Episode) -> float:
    """Largest ``controller.act`` wall time [ms]."""
    return float(np.max(ep.act_s) * 1e3) if len(ep.act_s) else float("nan")


def write_deadline_ramps(ep: Episode) -> int:
    """Times a device damped itself on its write deadline and the safety layer ramped the robot again."""
    return int(np.count_nonzero(ep.safety_events.reason == "write_deadline"))


def power_w(ep: Episode) -> float:
    """Mean mechanical power of the motors over the time played [W]; NaN when nothing was played."""
    return float(np.mean(ep.power)) if len(ep.t) else float("nan")


def per_second(values: np.ndarray, control_dt: float) -> np.ndarray:
    """The mean of `values` (one per control tick) over each whole second, the last partial second left out.

    A second holds ``round(1 / control_dt)`` ticks.
    """
    per = max(1, int(round(1.0 / control_dt)))
    whole = len(values) // per
    return np.asarray(values[: whole * per], dtype=float).reshape(whole, per).mean(axis=1)


def profile_text(values: np.ndarray) -> str:
    """Per-second means as a record stores them: space-separated, 6 significant digits each."""
    return " ".join(f"{float(v):.6g}" for v in values)


def vlin_err_by_s(ep: Episode) -> str:
    """The horizontal velocity tracking error's mean over each whole second played, as text [m/s]."""
    if not len(ep.t):
        return ""
    return profile_text(per_second(np.linalg.norm(ep.v_base_in_yaw - ep.command[:, :2], axis=1), ep.control_dt))


def vang_err_by_s(ep: Episode) -> str:
    """The yaw-rate tracking error's mean over each whole second played, as text [rad/s]."""
    if not len(ep.t):
        return ""
    return profile_text(per_second(np.abs(ep.yaw_rate - ep.command[:, 2]), ep.control_dt))


def ticks(ep: Episode) -> int:
    """Control ticks played."""
    return len(ep.t)


def clamped_ticks(ep: Episode) -> int:
    """Ticks whose command the robot clamped to its motors' limits."""
    return int(ep.clamped_ticks)


def clamped_rows(ep: Episode) -> str:
    """Ticks each command row was clamped on, as text: ``q=53;tau=2`` (rows never clamped left out)."""
    names = ("q", "dq", "kp", "kd", "tau")
    return ";".join(f"{n}={int(c)}" for n, c in zip(names, ep.clamped_rows, strict=True) if c)


METRICS: dict[str, Callable[[Episode], float | bool | int | str]] = {
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
    "act_ms_max": act_ms_max,
    "write_deadline_ramps": write_deadline_ramps,
    "power_w": power_w,
    "vlin_err_by_s": vlin_err_by_s,
    "vang_err_by_s": vang_err_by_s,
    "ticks": ticks,
    "clamped_ticks": clamped_ticks,
    "clamped_rows": clamped_rows,
}


def compute_metrics(ep: Episode) -> dict[str, float | bool | int | str]:
    """Every metric of `METRICS` for one episode."""
    out = {name: fn(ep) for name, fn in METRICS.items()}
    out["fall_time_s"] = float(ep.fall_time_s)
    return out
