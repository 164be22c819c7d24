"""The controller contract checker: every registered controller passes it, and a controller broken in one way fails
exactly the check for that way."""

import gc
import re
import time

import pytest

from wbc.cli.main import main
from wbc.control import CheckConfig, ControllerSpec, check_controller
from wbc.control.check import CHECKS
from wbc.control.errors import ControllerCheckError
from wbc.control.registry import CONTROLLERS
from wbc.control.stand import stand_command
from wbc.control.watched_robot import WatchedRobot
from wbc.hardware.mujoco import MujocoRobot
from wbc.types import MotorCommand


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_every_registered_controller_meets_the_contract_on_every_robot_it_claims(name):
    result = check_controller(name)
    result.raise_if_failed()
    spec = CONTROLLERS[name]
    assert {(o.robot, o.arm_mode) for o in result.outcomes} == set(spec.claims())
    assert len(result.outcomes) == len(CHECKS) * len(spec.claims())
    assert len(result.timings) == len(spec.claims())
    for t in result.timings:
        assert t.period_s == (0.002 if name.startswith("mpc") else 0.02)
        assert 0 < t.p50_s <= t.p99_s <= t.max_s and t.ticks > 0


def test_the_template_meets_the_contract_in_all_three_arm_modes():
    result = check_controller("examples.my_controller:make")
    result.raise_if_failed()
    assert {o.arm_mode for o in result.outcomes} == {"actuated", "locked", "none"}


# -- controllers broken one way each -----------------------------------------------------------------------------
class Stand:
    """A correct PD stand; the broken ones below change one thing."""

    rate_hz = 50.0

    def __init__(self, desc):
        self.command = stand_command(desc)

    def reset(self):
        pass

    def act(self, state, command):
        return self.command

    def counters(self):
        return {}


def _unbuildable(desc):
    raise RuntimeError("no gains for this robot")


class OddRate(Stand):
    rate_hz = 300.0  # 3.33 ms: not a whole number of 2 ms physics steps


class WrongLength(Stand):
    def act(self, state, command):
        return MotorCommand.hold(self.command.q[:12], 60.0, 2.0)  # the legs only, on a robot with an arm


class Unreset(Stand):
    """Drifts with every tick since it was built; reset() forgets nothing."""

    def __init__(self, desc):
        super().__init__(desc)
        self.ticks = 0

    def act(self, state, command):
        self.ticks += 1
        return MotorCommand.hold(self.command.q + 1e-4 * self.ticks, self.command.kp, self.command.kd)


def _the_simulator() -> MujocoRobot:
    """What a cheating controller would do: find the simulated robot it runs on in the process's memory."""
    return next(o for o in gc.get_objects() if isinstance(o, WatchedRobot) and o.is_connected)


class Peeking(Stand):
    """Finds the simulator in memory and leans with the trunk's true velocity (what a robot cannot measure)."""

    def __init__(self, desc):
        super().__init__(desc)
        self.sim = None

    def act(self, state, command):
        if self.sim is None:
            self.sim = _the_simulator()
        lean = 0.1 * self.sim.base_truth().base_linvel_in_world[0]
        return MotorCommand.hold(self.command.q + lean, self.command.kp, self.command.kd)


class Slow(Stand):
    rate_hz = 500.0

    def act(self, state, command):
        time.sleep(0.003)  # 1.5 periods
        return self.command


BROKEN = {
    "build": _unbuildable,
    "rate": OddRate,
    "output": WrongLength,
    "reset": Unreset,
    "truth": Peeking,
    "timing": Slow,
}


@pytest.mark.parametrize("check", CHECKS)
def test_a_controller_broken_one_way_fails_that_check_only(check):
    spec = ControllerSpec(f"broken-{check}", "actuated", BROKEN[check], "a controller broken on purpose",
                          robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert not result.passed
    failed = {o.check for o in result.failed()}
    assert failed == {check}, [(o.check, o.detail) for o in result.failed()]
    detail = result.failed(check)[0].detail
    expected = {
        "build": "make raised RuntimeError: no gains for this robot",
        "rate": "period 1/300 s is not a whole number of physics steps",
        "output": "MotorCommand.q has shape (12,); the robot has 15 joints",
        "reset": "the same states and commands gave different motor commands",
        "truth": "act() read the simulator's truth (MujocoRobot.base_truth",
        "timing": "the median call does not fit the period",
    }[check]
    assert expected in detail
    # a check that cannot be judged after a failure is reported as not run, never as passed
    if check in ("build", "output"):
        assert all(o.passed is None for o in result.outcomes if o.check not in (check, "build", "rate"))
    pattern = f"broken-{check} fails its contract: .*{check} on a1-wx200/actuated: .*{re.escape(expected)}"
    with pytest.raises(ControllerCheckError, match=pattern):
        result.raise_if_failed()


def test_reading_the_simulator_without_its_accessors_is_caught_by_moving_it():
    class Raw(Stand):
        """Reads MuJoCo's data directly, past the accessors the checker watches."""

        def __init__(self, desc):
            super().__init__(desc)
            self.sim = None

        def act(self, state, command):
            if self.sim is None:
                self.sim = _the_simulator()
            return MotorCommand.hold(self.command.q + 0.1 * self.sim.data.qpos[0], self.command.kp, self.command.kd)

    spec = ControllerSpec("raw", "actuated", Raw, "reads MjData", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert {o.check for o in result.failed()} == {"truth"}
    assert "changed when only the simulator's hidden state did" in result.failed("truth")[0].detail


def test_check_controller_on_the_command_line(capsys):
    assert main(["check-controller", "stand", "--robot", "a1-wx200", "--seconds", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "a1-wx200, arm actuated" in out and "passed" in out and "act p50" in out and "go1-arm" not in out
    assert main(["check-controller", "stand", "--robot", "a1-wx200", "--seconds", "0.2", "--json"]) == 0
    assert '"passed": true' in capsys.readouterr().out
    assert main(["check-controller", "no_such_pkg.x:make"]) == 2
    assert "Traceback" not in capsys.readouterr().err
