"""An episode interrupted while it plays (`wbc.arena.runner.EpisodeInterrupted`): a `KeyboardInterrupt` that carries
the episode played up to the last complete tick, so that a hardware trial keeps it; the interruption itself whenever
that episode cannot be had.

Every episode here is the stand controller on the simulator, 50 Hz, deterministic: an interrupted episode's ticks are
the uninterrupted one's first ticks, bit for bit.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from wbc.arena.episode import Episode, EpisodeBuffer
from wbc.arena.runner import EpisodeInterrupted, run_episode
from wbc.control.stand import StandController
from wbc.errors import IoProcessStopped, RobotLinkError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.scenario.trial import CommandSchedule

SECONDS = 1.0  # 50 ticks
DT = 0.02  # the stand controller's period


@pytest.fixture(scope="module")
def whole() -> Episode:
    """The episode played to its end, uninterrupted."""
    return _play()


def _play(**kwargs: object) -> Episode:
    sim = MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="none"))
    with sim:
        sim.reset(seed=0)
        return run_episode(sim, StandController(sim.desc), CommandSchedule(), SECONDS, **kwargs)


def _interrupting_at(tick: int, raised: BaseException):
    """An observer that raises `raised` after tick `tick` (0-based) was played and stored: `tick` + 1 ticks whole."""
    def observe(t: float, robot: object, controller: object, command: object) -> None:
        if round(t / DT) == tick + 1:
            raise raised
    return observe


def test_ctrl_c_while_the_episode_plays_carries_the_ticks_played_whole(whole: Episode) -> None:
    """Ctrl-C in the observer after the 20th tick: an `EpisodeInterrupted`, still a `KeyboardInterrupt` (a simulated
    run or an arena's worker stops as before), carrying exactly the first 20 ticks of the uninterrupted episode; the
    interruption is its cause. It was a bare `KeyboardInterrupt`, and the 20 ticks were lost."""
    pressed = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt) as stopped:
        _play(observer=_interrupting_at(19, pressed))
    assert isinstance(stopped.value, EpisodeInterrupted)
    interrupted = stopped.value
    assert interrupted.__cause__ is pressed
    assert (interrupted.tick, interrupted.time_s, interrupted.duration_s) == (20, pytest.approx(20 * DT), SECONDS)
    played = interrupted.episode
    assert len(played.t) == 20 and not played.fell and played.duration_s == SECONDS
    np.testing.assert_array_equal(played.t, whole.t[:20])
    np.testing.assert_array_equal(played.qpos, whole.qpos[:20])
    np.testing.assert_array_equal(played.roll, whole.roll[:20])  # the derived metrics too, of those ticks alone
    # it crosses a process boundary as itself (an arena's worker hands its exceptions back pickled)
    again = pickle.loads(pickle.dumps(interrupted))
    assert isinstance(again, EpisodeInterrupted) and again.tick == 20 and len(again.episode.t) == 20


def test_ctrl_c_inside_a_ticks_store_keeps_the_ticks_stored_whole(whole: Episode,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C lands between any two bytecodes: here inside the 31st tick's `EpisodeBuffer.add`, its row stored, its
    time and command not yet. The half-stored tick belongs to no complete tick: the episode carried holds the 30
    before it, consistent (as many times as rows)."""
    add = EpisodeBuffer.add

    def cut(self: EpisodeBuffer, t: float, *args: object) -> None:
        if round(t / DT) == 31:
            self._rows.append(args[-1])  # the row, then the interruption before its scalars
            raise KeyboardInterrupt
        add(self, t, *args)

    monkeypatch.setattr(EpisodeBuffer, "add", cut)
    with pytest.raises(EpisodeInterrupted) as stopped:
        _play()
    played = stopped.value.episode
    assert stopped.value.tick == 30 and len(played.t) == len(played.qpos) == len(played.act_s) == 30
    np.testing.assert_array_equal(played.qpos, whole.qpos[:30])


def test_an_interruption_whose_episode_cannot_be_built_goes_on_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    """Building the partial episode fails: the original `KeyboardInterrupt` is raised as it was, never masked by
    that failure (nor changed into an `EpisodeInterrupted` without its episode)."""
    def broken(self: EpisodeBuffer, **kwargs: object) -> Episode:
        raise ValueError("rows that do not stack")

    monkeypatch.setattr(EpisodeBuffer, "finish", broken)
    pressed = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt) as stopped:
        _play(observer=_interrupting_at(9, pressed))
    assert stopped.value is pressed and type(stopped.value) is KeyboardInterrupt
    assert stopped.value.__cause__ is None and stopped.value.__context__ is None


class _MeantOtherwise(KeyboardInterrupt):
    """A subclass of `KeyboardInterrupt` that means something else (as a training run's stop after an iteration)."""


def test_a_subclass_of_keyboard_interrupt_goes_on_as_it_is() -> None:
    raised = _MeantOtherwise()
    with pytest.raises(_MeantOtherwise) as stopped:
        _play(observer=_interrupting_at(4, raised))
    assert stopped.value is raised and not isinstance(stopped.value, EpisodeInterrupted)


def test_a_robot_error_that_means_a_request_to_end_ends_the_episode_as_an_interruption(whole: Episode) -> None:
    """A hardware trial's I/O process stopped by SIGTERM (`IoProcessStopped`, given as `stopped_by`) ends the episode
    as Ctrl-C does, with the ticks played; not given, it goes on as the robot's error it is, and so does any other."""
    gone = IoProcessStopped("SIGTERM", connected=True)
    with pytest.raises(EpisodeInterrupted) as stopped:
        _play(observer=_interrupting_at(14, gone), stopped_by=(IoProcessStopped,))
    assert stopped.value.__cause__ is gone and stopped.value.tick == 15
    np.testing.assert_array_equal(stopped.value.episode.qpos, whole.qpos[:15])
    with pytest.raises(IoProcessStopped) as as_it_is:
        _play(observer=_interrupting_at(14, gone))
    assert as_it_is.value is gone
    died = RobotLinkError("the I/O process died")
    with pytest.raises(RobotLinkError) as failed:
        _play(observer=_interrupting_at(14, died), stopped_by=(IoProcessStopped,))
    assert failed.value is died


def test_the_interruption_is_handed_over_before_the_episode_is_built(monkeypatch: pytest.MonkeyPatch) -> None:
    """`on_interrupt` (a hardware trial's damping) comes first: building a long episode takes tens of milliseconds,
    during which a robot would keep its controller's last command. What it raises goes on, the interruption its
    context."""
    order: list[str] = []
    finish = EpisodeBuffer.finish

    def finishing(self: EpisodeBuffer, **kwargs: object) -> Episode:
        order.append("built")
        return finish(self, **kwargs)

    monkeypatch.setattr(EpisodeBuffer, "finish", finishing)
    pressed = KeyboardInterrupt()
    handed: list[BaseException] = []

    def damp(exc: BaseException) -> None:
        handed.append(exc)
        order.append("damped")

    with pytest.raises(EpisodeInterrupted) as stopped:
        _play(observer=_interrupting_at(9, pressed), on_interrupt=damp)
    assert handed == [pressed] and order == ["damped", "built"] and stopped.value.tick == 10
    died = RobotLinkError("the I/O process died")

    def dead(exc: BaseException) -> None:
        raise died

    with pytest.raises(RobotLinkError) as failed:
        _play(observer=_interrupting_at(9, pressed), on_interrupt=dead)
    assert failed.value is died and failed.value.__context__ is pressed
