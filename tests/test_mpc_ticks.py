"""The MPC controller's motor commands, tick by tick, on fixed closed-loop episodes, against a committed recording.

`tests/golden/mpc_ticks.npz` holds, for each case below, every tick's command (q, dq, kp, kd, tau) on a sample of ticks
and a weighted sum of each tick's command on every tick. A change that only moves work around (compiles it, fuses it,
stops allocating) must give the same commands: the same floating-point operations in the same order give the same bits,
and a closed loop carries any difference, however small, into every later tick, so the last ticks compared are the most
sensitive. The tolerance admits rounding alone (`RTOL`). ``make golden`` re-records (``WBC_RECORD_GOLDEN=1`` in one
process, `golden_recording`; only for a deliberate change of the controller's behaviour, said in the commit message);
like the other goldens, the recording is exact only under the locked versions of tests/golden/versions.json.
"""

from pathlib import Path

import numpy as np
import pytest
from golden_recording import recording

from wbc.arena.divergence import DivergenceCheck
from wbc.arena.runner import run_episode
from wbc.control.registry import get_controller
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.scenario.push import Push
from wbc.scenario.trial import CommandSchedule
from wbc.types import MotorCommand, RobotState, VelocityCommand

GOLDEN = Path(__file__).resolve().parent / "golden" / "mpc_ticks.npz"
SAMPLE_EVERY = 8
"""Ticks between the full commands stored (the weighted sums cover every tick)."""
RTOL = 1e-9
"""Largest relative difference of a command entry, against the row's largest magnitude: rounding only.

Bit-identical arithmetic gives 0; a reordered sum changes a result by ~1e-16 relative, which the closed loop (contacts
landing a hair earlier or later) grows by a few orders of magnitude over these 1.6 s; a changed formula moves the
commands by far more than 1e-9 within a few ticks."""

CASES = {
    # walking and turning (the arm planned through its momentum), pushed sideways mid-walk: the MPC updates, foothold
    # refreshes, the step-out (footholds clipped to the legs' reach), the estimator's slip test and the leg layer's
    # torque scaling all run
    "a1-walk-push": dict(controller="mpc", robot="a1-wx200", seconds=1.6,
                         schedule=CommandSchedule(vx=0.5, yaw_rate=0.5, ramp_s=0.3),
                         push=Push(force_in_world=np.array([0.0, 380.0, 0.0]),
                                   offset_in_base=np.array([0.05, 0.0, 0.0]), start=0.9, duration=0.09)),
    # the tail MPC: the arm on its planned path with its torque fed forward, the momentum observer on every tick, a
    # push it detects (an update out of turn)
    "a1-tail-push": dict(controller="mpc-tail", robot="a1-wx200", seconds=1.6,
                         schedule=CommandSchedule(vx=0.5, yaw_rate=0.5, ramp_s=0.3),
                         push=Push(force_in_world=np.array([0.0, 300.0, 0.0]),
                                   offset_in_base=np.array([0.05, 0.0, 0.0]), start=0.9, duration=0.09)),
    # no arm joints (12 motors), sideways and turning the other way
    "go1-noarm": dict(controller="mpc-noarm", robot="go1-arm", seconds=0.8,
                      schedule=CommandSchedule(vx=0.2, vy=-0.2, yaw_rate=-0.8, ramp_s=0.2), push=None),
}


class _Recording:
    """A controller that hands every tick to the MPC and keeps the command's rows."""

    def __init__(self, controller) -> None:
        self.controller = controller
        self.rate_hz = controller.rate_hz
        self.rows: list[np.ndarray] = []

    def reset(self) -> None:
        self.controller.reset()

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        out = self.controller.act(state, command)
        self.rows.append(np.array(out.rows))
        return out


def _play(case: dict) -> np.ndarray:
    """Every tick's command rows of one case, shape (ticks, 5, n)."""
    spec = get_controller(case["controller"])
    robot = MujocoRobot(MujocoRobotConfig(robot=case["robot"], arm_mode=spec.arm_mode))
    recording = _Recording(spec.make(robot.desc))
    with robot:
        robot.reset(seed=0)
        if case["push"] is not None:
            robot.apply_push(case["push"])
        episode = run_episode(robot, recording, case["schedule"], case["seconds"], divergence=DivergenceCheck())
    assert not episode.fell
    return np.stack(recording.rows)


def _weights(n: int) -> np.ndarray:
    """Fixed weights of a tick's (5, n) entries for its checksum: distinct, so that swapped entries show."""
    return 1.0 + np.arange(5 * n, dtype=np.float64).reshape(5, n) / (5 * n)


def _summary(rows: np.ndarray) -> dict[str, np.ndarray]:
    return {"sampled": rows[::SAMPLE_EVERY], "checksum": np.einsum("tij,ij->t", rows, _weights(rows.shape[2]))}


def _record() -> None:
    out = {}
    for name, case in CASES.items():
        for key, value in _summary(_play(case)).items():
            out[f"{name}/{key}"] = value
    np.savez_compressed(GOLDEN, **out)


_RECORDED: list[object] = []


@pytest.mark.parametrize("name", sorted(CASES))
def test_mpc_commands_match_the_recording(name):
    if recording() and not _RECORDED:  # the first case this session runs records every case, once
        _record()
        _RECORDED.append(GOLDEN)
    golden = np.load(GOLDEN)
    got = _summary(_play(CASES[name]))
    want_sampled, want_checksum = golden[f"{name}/sampled"], golden[f"{name}/checksum"]
    assert got["sampled"].shape == want_sampled.shape
    # per entry, relative to the largest magnitude of its row in that tick (a torque near zero is judged on the
    # torques' scale)
    scale = np.maximum(np.abs(want_sampled).max(axis=2, keepdims=True), 1.0)
    error = np.abs(got["sampled"] - want_sampled) / scale
    tick, row, joint = np.unravel_index(int(np.argmax(error)), error.shape)
    assert error.max() <= RTOL, (f"{name}: tick {tick * SAMPLE_EVERY}, row {'q dq kp kd tau'.split()[row]}, joint "
                                 f"{joint}: {got['sampled'][tick, row, joint]!r} against "
                                 f"{want_sampled[tick, row, joint]!r}")
    checksum_error = np.abs(got["checksum"] - want_checksum) / np.maximum(np.abs(want_checksum), 1.0)
    first = int(np.argmax(checksum_error > RTOL))
    assert checksum_error.max() <= RTOL, f"{name}: the commands differ from tick {first} on"
