"""`MomentumObserver`: the external force from the momentum residual, and how fast it tells a push."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wbc.arena.runner import run_episode
from wbc.control.registry import get_controller
from wbc.errors import ConfigError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.mpc.observer import MomentumObserver, ObserverConfig, stance_force_sum
from wbc.robots.conventions import GRAVITY
from wbc.scenario.push import Push
from wbc.scenario.trial import CommandSchedule

DT = 0.002


def _exact_run(observer: MomentumObserver, force: np.ndarray, start_s: float, seconds: float) -> list[np.ndarray]:
    """A point mass standing on contact forces that cancel gravity exactly, pushed by `force` from `start_s` on."""
    m = observer.mass
    v = np.array([0.3, -0.1, 0.0])
    support = -m * GRAVITY
    residuals = []
    for k in range(int(round(seconds / DT)) + 1):
        observer.update(v, support, DT)
        residuals.append(observer.residual.copy())
        external = force if k * DT >= start_s - 1e-12 else np.zeros(3)
        v = v + external / m * DT  # the step's contact forces and gravity cancel; the push accelerates the mass
    return residuals


def test_the_residual_follows_a_force_step_with_a_first_order_lag():
    observer = MomentumObserver(15.0, ObserverConfig(gain=25.0))
    force = np.array([200.0, -100.0, 0.0])
    residuals = _exact_run(observer, force, start_s=0.1, seconds=0.5)
    assert np.allclose(residuals[50], 0.0, atol=1e-9)  # nothing but what the model knows: no residual
    # r = F (1 - (1 - K dt)^n) in discrete time, within 1 % of the continuous 1 - exp(-K t) at K dt = 0.05
    for n in (5, 20, 100):
        expected = force * (1.0 - (1.0 - 25.0 * DT) ** n)
        np.testing.assert_allclose(residuals[50 + n], expected, rtol=1e-9, atol=1e-9)
        assert np.allclose(residuals[50 + n], force * (1.0 - math.exp(-25.0 * n * DT)), rtol=0.01, atol=1.0)
    np.testing.assert_allclose(residuals[-1], force, rtol=1e-3)


def test_a_push_is_detected_once_at_the_latency_the_gain_and_threshold_give():
    cfg = ObserverConfig(gain=25.0, threshold_n=80.0)
    observer = MomentumObserver(15.0, cfg)
    detected_at = []
    m, v, support = observer.mass, np.zeros(3), -observer.mass * GRAVITY
    for k in range(400):
        if observer.update(v, support, DT):
            detected_at.append(k * DT)
        pushing = 0.2 <= k * DT < 0.29
        v = v + (np.array([300.0, 0.0, 0.0]) if pushing else np.zeros(3)) / m * DT
    # one push, one detection: the residual rises past 80 N and falls back below 40 N after the push
    assert len(detected_at) == 1 and observer.detections == 1
    # 300 N crosses 80 N after 7 samples of 2 ms (0.95^7 < 1 - 80/300; continuous: -ln(1 - 80/300) / 25 = 12.4 ms)
    assert cfg.latency_s(300.0, DT) == pytest.approx(0.014) and cfg.latency_s(60.0, DT) == math.inf
    assert detected_at[0] - 0.2 == pytest.approx(cfg.latency_s(300.0, DT), abs=1e-9)


def test_bad_settings_are_refused():
    with pytest.raises(ConfigError, match="gain"):
        ObserverConfig(gain=0.0)
    with pytest.raises(ConfigError, match="threshold_n"):
        ObserverConfig(threshold_n=float("nan"))
    with pytest.raises(ConfigError, match="mass"):
        MomentumObserver(-1.0)


def test_under_the_mpc_a_known_push_is_detected_within_20_ms_and_nothing_else_is():
    """The MPC trotting in place in the simulator, pushed 300 N forward for 0.09 s at t = 1.5 s: the observer, fed
    the controller's estimated CoM velocity and its commanded stance forces, tells the push and nothing before it."""
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    controller = get_controller("mpc").make(sim.desc)
    observer = MomentumObserver(controller.kin.mass)
    detections: list[float] = []
    peak = [0.0]

    def watch(t, robot, ctrl, command):
        contact, _, _ = ctrl.gait.state(ctrl.t - ctrl.dt)
        forces = ctrl.plan.forces[ctrl._plan_step()] if ctrl.plan is not None else np.zeros((4, 3))
        if observer.update(ctrl.kin.com_vel, (forces * contact[:, None]).sum(axis=0), ctrl.dt):
            detections.append(t)
        if t > 0.3 and t < 1.5:
            peak[0] = max(peak[0], math.hypot(*observer.residual[:2]))

    with sim:
        sim.reset(seed=0)
        sim.apply_push(Push(force_in_world=np.array([300.0, 0.0, 0.0]), offset_in_base=np.zeros(3), start=1.5,
                            duration=0.09))
        episode = run_episode(sim, controller, CommandSchedule(), 2.2, observer=watch)
    assert not episode.fell
    assert peak[0] < 0.25 * observer.config.threshold_n  # trotting in place: within a quarter of the threshold
    assert len(detections) == 1 and 0.0 < detections[0] - 1.5 <= 0.020


def test_the_compiled_stance_sum_and_sample_give_numpys_bits():
    rng = np.random.default_rng(3)
    out = np.empty(3)
    for _ in range(200):
        forces = rng.normal(0.0, 80.0, (4, 3)) * rng.choice([1e-300, 1.0, 1e300], (4, 3))
        stance = rng.random(4) < 0.5
        stance_force_sum(forces, stance, out)
        want = (forces * stance[:, None]).sum(axis=0)
        assert np.array_equal(out, want) and np.array_equal(np.signbit(out), np.signbit(want))
    # the observer's samples, against the numpy formulas they stand for
    compiled, mass, gain = MomentumObserver(13.7, ObserverConfig(gain=25.0)), 13.7, 25.0
    p0, integral, residual = None, np.zeros(3), np.zeros(3)
    weight = mass * np.asarray(GRAVITY, dtype=np.float64)
    for _ in range(100):
        v, forces, stance = rng.normal(0.0, 0.5, 3), rng.normal(0.0, 60.0, (4, 3)), rng.random(4) < 0.5
        compiled.update_stance(v, forces, stance, DT)
        if p0 is None:
            p0 = mass * v
            continue
        integral += ((forces * stance[:, None]).sum(axis=0) + weight + residual) * DT
        residual = gain * (mass * v - p0 - integral)
        assert np.array_equal(compiled.residual, residual)
