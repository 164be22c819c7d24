"""The controller contract checker: every registered controller passes it, and a controller broken in one way fails
exactly the check for that way."""

import gc
import re
import sys
import time

import numpy as np
import pytest
from conftest import STAND_PLUGIN

from wbc.cli.main import main
from wbc.cli.printers import print_controller_check
from wbc.control import CheckConfig, ControllerCheck, ControllerSpec, check_controller
from wbc.control.controller_contract import CHECKS, CheckOutcome
from wbc.control.errors import ControllerCheckError
from wbc.control.registry import CONTROLLERS
from wbc.control.stand import stand_command
from wbc.control.watched_robot import WatchedRobot
from wbc.errors import ConfigError
from wbc.hardware.mujoco import MujocoRobot
from wbc.robots.registry import get_robot
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
        # the period of the controller's own rate on that robot, whatever its name
        assert t.period_s == 1.0 / spec.make(get_robot(t.robot, t.arm_mode)).rate_hz
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
        "rate": "period 1/300 s is not a whole number of physics steps of 0.002 s; the arena refuses it: choose a "
                "rate that divides 500 Hz: the nearest are 500 Hz and 250 Hz",
        "output": "MotorCommand.q has shape (12,); the robot has 15 joints (house order): 12 joints are the legs "
                  "alone, and this robot's arm is actuated (15 joints, the arm mode a plain factory claims): a "
                  'controller of the legs declares the arm modes it drives, ControllerPlugin(make=..., '
                  'arm_modes=("none",))',
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


class WithArm(Stand):
    def act(self, state, command):
        return MotorCommand.hold(np.zeros(15), 60.0, 2.0)  # the legs and the arm, on a robot without an arm


class FarBeyond(Stand):
    """Every target 12.5 rad past the nominal pose (a network that answers +50 at an action scale of 0.25)."""

    def act(self, state, command):
        return MotorCommand.hold(self.command.q + 12.5, self.command.kp, self.command.kd)


class Pressing(Stand):
    """Presses the front right calf 0.2 rad past its stop on every tick (as a PD policy asks for torque there)."""

    def __init__(self, desc):
        super().__init__(desc)
        q = self.command.q.copy()
        q[2] = -0.7163  # FR_calf_joint: its upper limit is -0.9163 rad
        self.command = MotorCommand.hold(q, self.command.kp, self.command.kd)


def test_commands_far_beyond_the_motor_limits_fail_the_output_check_and_commands_past_a_stop_are_reported():
    spec = ControllerSpec("far", "none", FarBeyond, "targets far outside the joints' range", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert {o.check for o in result.failed()} == {"output"}, [(o.check, o.detail) for o in result.failed()]
    detail = result.failed("output")[0].detail
    for phrase in ("10 of 10 closed-loop ticks command beyond the robot's motor limits, which the robot clamps",
                   "MotorCommand.q: FR_calf_joint", "above its upper limit -0.916 (by 11.", "rad) on 10 ticks",
                   "and 9 more joints", "on 10 of them a command lies further beyond its limit than the whole "
                   "interval it limits", "the robot does not play what the controller commands"):
        assert phrase in detail, detail
    # a target past a stop, on every tick, is the controller's to command: reported, and the check passes
    spec = ControllerSpec("pressing", "none", Pressing, "presses a joint past its stop", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    result.raise_if_failed()
    (output,) = [o for o in result.outcomes if o.check == "output"]
    assert ("10 of 10 closed-loop ticks command beyond the robot's motor limits, which the robot clamps before "
            "sending (the arena counts them as clamped ticks): MotorCommand.q: FR_calf_joint -0.716 above its upper "
            "limit -0.916 (by 0.2 rad) on 10 ticks;") in output.detail, output.detail
    assert "within the motor limits on every tick" in check_controller(
        ControllerSpec("stand-a1", "none", Stand, "a stand", robots=("a1-wx200",)),
        CheckConfig(seconds=0.2)).outcomes[2].detail


def test_a_command_of_the_legs_and_the_arm_on_a_robot_without_an_arm_says_to_declare_actuated():
    spec = ControllerSpec("with-arm", "none", WithArm, "commands the arm too", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert {o.check for o in result.failed()} == {"output"}
    assert result.failed("output")[0].detail.startswith(
        "MotorCommand.q has shape (15,); the robot has 12 joints (house order): 15 joints are the legs and the arm, "
        'and this robot has no actuated arm (12 joints, arm mode "none" or "locked"): a controller that drives the '
        'arm declares it, ControllerPlugin(make=..., arm_modes=("actuated",))')


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


def test_a_make_that_returns_the_class_fails_the_build_check():
    spec = ControllerSpec("the-class", "actuated", lambda desc: Stand, "returns the class", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert {o.check for o in result.failed()} == {"build"}
    assert "make returned the class Stand, not an instance: return Stand(...)" in result.failed("build")[0].detail


def _outcomes(*passed: bool | None) -> ControllerCheck:
    return ControllerCheck(controller="c", timings=(), outcomes=tuple(
        CheckOutcome(check=check, robot="a1-wx200", arm_mode="actuated", passed=p, detail="")
        for check, p in zip(CHECKS, passed, strict=False)))


@pytest.mark.parametrize(("passed", "verdict"), [
    ((True, False, None, None, None, True), "FAILED: 1 of 6 checks failed, 3 not run"),
    ((True, True, False, True, False, True), "FAILED: 2 of 6 checks failed"),
    ((True, True, True, True, None, True), "FAILED: 1 of 6 checks not run"),
])
def test_the_verdict_counts_failed_and_not_run_checks_apart(passed, verdict, capsys):
    print_controller_check(_outcomes(*passed))
    assert capsys.readouterr().out.splitlines()[-1] == verdict


class ResetRaises(Stand):
    def reset(self):
        raise RuntimeError("no home pose")


class ResetRaisesAfterAct(Stand):
    """Its reset() fails once act() has run: the replays' reset, after the closed loop."""

    def __init__(self, desc):
        super().__init__(desc)
        self.acted = False

    def reset(self):
        if self.acted:
            raise KeyError("history")

    def act(self, state, command):
        self.acted = True
        return self.command


@pytest.mark.parametrize(("broken", "says"), [
    (ResetRaises, "reset() raised RuntimeError: no home pose at "),
    (ResetRaisesAfterAct, "reset() raised KeyError: 'history' at "),
])
def test_a_reset_that_raises_fails_the_reset_check_naming_the_exception(broken, says, capsys):
    spec = ControllerSpec("reset-raises", "actuated", broken, "reset() raises", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert not result.passed
    assert {o.check for o in result.failed()} == {"reset"}, [(o.check, o.detail) for o in result.failed()]
    assert says in result.failed("reset")[0].detail
    assert all(o.passed is not True for o in result.outcomes if o.check in ("output", "truth"))


class NanLater(Stand):
    """Builds a command with a NaN from its fourth tick: the house's MotorCommand refuses it."""

    def __init__(self, desc):
        super().__init__(desc)
        self.ticks = 0

    def reset(self):
        self.ticks = 0

    def act(self, state, command):
        self.ticks += 1
        q = self.command.q.copy()
        q[3] = np.nan if self.ticks > 3 else q[3]
        return MotorCommand(q=q, dq=self.command.dq, kp=self.command.kp, kd=self.command.kd,  # NAN-HERE
                            tau=self.command.tau)


def _line_of(marker: str) -> str:
    """``file:line`` of this file's line holding `marker` (the marker written once, apart from this call)."""
    lines = open(__file__, encoding="utf-8").read().splitlines()
    (line,) = [i for i, text in enumerate(lines, start=1) if f"# {marker}" in text]
    return f"{__file__}:{line}"


def test_a_failure_is_named_at_the_controllers_own_line_as_the_arena_names_it():
    spec = ControllerSpec("nan-later", "actuated", NanLater, "a NaN from tick 3", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(seconds=0.2))
    assert {o.check for o in result.failed()} == {"output"}
    detail = result.failed("output")[0].detail
    # the line of the controller that built the command, not the house's line in wbc/types.py that refused it
    assert detail == (f"act raised CommandError: MotorCommand.q: non-finite value at joint index 3 at "
                      f"{_line_of('NAN-HERE')} at tick 3")


RAISING_FACTORY = '''
    """A factory that refuses its settings."""
    from wbc.control.stand import StandController


    def make(desc, config=None):
        gain = (config or {}).get("gain", -1.0)
        if gain < 0:
            raise ValueError(f"gain must be >= 0, got {gain}")  # RAISES-HERE
        return StandController(desc)
'''


@pytest.mark.parametrize("with_config", [False, True])
def test_a_factory_that_raises_is_named_at_its_own_line_once(with_config, plugin_package, tmp_path, capsys):
    root = plugin_package("raisingpkg", {"factory": RAISING_FACTORY})
    path = root / "raisingpkg" / "factory.py"
    (line,) = [i for i, text in enumerate(path.read_text().splitlines(), start=1) if "# RAISES-HERE" in text]
    settings = tmp_path / "settings.toml"
    settings.write_text("gain = -2.0\n")
    config = ["--controller-config", str(settings)] if with_config else []
    assert main(["check-controller", "raisingpkg.factory:make", "--robot", "a1-wx200", *config]) == 1
    out = capsys.readouterr().out
    (build,) = [text for text in out.splitlines() if "FAIL build" in text]
    # the verdict counts the check that failed apart from those that could not run after it
    assert out.splitlines()[-1] == "FAILED: 1 of 6 checks failed, 5 not run"
    # one place, the plug-in's: not also the house's line that wrapped the error
    gain = -2.0 if with_config else -1.0
    assert build.endswith(f"ValueError: gain must be >= 0, got {gain} at {path}:{line}")
    assert build.count(" at /") == 1 and "wbc/control/plugin.py" not in build


GO1_ONLY = '''"""The stand controller, claiming go1-arm only."""
from wbc.control import ControllerPlugin
from wbc.control.stand import StandController

plugin = ControllerPlugin(make=StandController, summary="PD stand, go1-arm only", robots=("go1-arm",))
'''


def test_a_robot_the_controller_does_not_drive_is_refused_and_nothing_checked_never_passes(tmp_path, monkeypatch,
                                                                                         capsys):
    spec = ControllerSpec("hold", "actuated", Stand, "a PD hold", robots=("a1-wx200",))
    with pytest.raises(ConfigError, match=r"--robot go1-arm: controller hold drives a1-wx200, not go1-arm; check it "
                                          r"on a robot it drives \(--robot a1-wx200\)"):
        check_controller(spec, CheckConfig(seconds=0.2, robots=("go1-arm",)))
    nobody = ControllerSpec("nobody", "actuated", Stand, "claims no robot", robots=())
    with pytest.raises(ConfigError, match="controller nobody claims no robot, so there is nothing to check"):
        check_controller(nobody)
    empty = ControllerCheck(controller="hold", outcomes=(), timings=())
    assert not empty.passed and not empty.as_dict()["passed"]
    with pytest.raises(ControllerCheckError, match="no check ran"):
        empty.raise_if_failed()
    # the command line: an error naming the controller, what it drives and the robot asked for; exit status 2
    (tmp_path / "go1_only_ctl.py").write_text(GO1_ONLY)
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        for argv in (["--robot", "a1-wx200"], ["--robot", "a1-wx200", "--json"]):
            assert main(["check-controller", "go1_only_ctl:plugin", *argv]) == 2
            out, err = capsys.readouterr()
            assert "passed" not in out and "Traceback" not in err
            assert "--robot a1-wx200: controller go1_only_ctl:plugin drives go1-arm, not a1-wx200" in err
    finally:
        sys.modules.pop("go1_only_ctl", None)


# -- --seconds, --scenario -------------------------------------------------------------------------------------------
TOPPLE = """
[scenario]
name = "topple"
version = 1
description = "one push no PD stand survives"
robot = "a1-wx200"
duration_s = 1.5

[terrain]
kind = "flat"

[commands]
[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.3, 0.4]
interval_s = [5.0, 6.0]
duration_s = 0.15
offset_m = 0.0

[[bands]]
name = "hard"
push_force_n = [900.0, 950.0]
"""


def test_seconds_sets_the_closed_loop_and_a_scenario_plays_its_first_trial():
    spec = ControllerSpec("hold", "actuated", Stand, "a PD hold", robots=("a1-wx200",))
    short = check_controller(spec, CheckConfig(seconds=0.3))
    assert next(o for o in short.outcomes if o.check == "output").detail.startswith("15 ticks x 5 passes")
    assert next(o for o in check_controller(spec).outcomes if o.check == "output").detail.startswith("25 ticks")
    # the shipped scenario's first trial: its command and pushes, the robot up at the end
    result = check_controller("learned", CheckConfig(seconds=3.0, scenario="scenarios/push.toml"))
    result.raise_if_failed()
    assert {o.robot for o in result.outcomes} == {"a1-wx200"}  # the scenario's robot only
    (outcome,) = [o for o in result.outcomes if o.check == "scenario"]
    assert outcome.detail.startswith("push trial (band in, seed 0, #0) for 3 s, fractal ground")
    assert re.search(r"survived; 1 of 4 pushes met \(2\d\d N at 2\.\d\d s\)", outcome.detail)  # band in: 200-300 N
    assert next(o for o in result.outcomes if o.check == "output").detail.startswith("150 ticks")


def test_a_scenario_that_topples_the_controller_fails_that_check_only(tmp_path, capsys):
    path = tmp_path / "topple.toml"
    path.write_text(TOPPLE)
    spec = ControllerSpec("hold", "actuated", Stand, "a PD hold", robots=("a1-wx200",))
    result = check_controller(spec, CheckConfig(scenario=path))
    assert {o.check for o in result.failed()} == {"scenario"}
    detail = result.failed("scenario")[0].detail
    assert "topple trial (band hard, seed 0, #0) for 1.5 s, flat ground, command stand still: FELL at" in detail
    assert "1 of 1 pushes met (9" in detail
    fell_at = float(re.search(r"FELL at ([0-9.]+) s", detail).group(1))
    assert 0.3 < fell_at < 1.5
    # the command line: the failed check, exit status 1; the default duration is the trial's
    assert main(["check-controller", "stand", "--scenario", str(path)]) == 1
    out = capsys.readouterr().out
    assert "FAIL scenario topple trial" in out and "go1-arm" not in out


def test_a_scenario_for_a_robot_the_controller_does_not_drive_is_refused_naming_the_file(tmp_path, capsys):
    path = tmp_path / "go1.toml"
    path.write_text(TOPPLE.replace('robot = "a1-wx200"', 'robot = "go1-arm"'))
    spec = ControllerSpec("hold", "actuated", Stand, "a PD hold", robots=("a1-wx200",))
    with pytest.raises(ConfigError, match=rf"--scenario {re.escape(str(path))}: the scenario is for go1-arm .* "
                                          "drives a1-wx200"):
        check_controller(spec, CheckConfig(scenario=path))
    with pytest.raises(ConfigError, match=r"checked here: a1-wx200, as --robot asks"):
        check_controller("stand", CheckConfig(scenario=path, robots=("a1-wx200",)))
    with pytest.raises(ConfigError, match="seconds must be a positive number"):
        check_controller(spec, CheckConfig(seconds=0.0))
    for argv, says in ((["--scenario", str(path), "--robot", "a1-wx200"], f"--scenario {path}"),
                       (["--scenario", str(tmp_path / "none.toml")], f"{tmp_path / 'none.toml'}: file not found")):
        assert main(["check-controller", "stand", *argv]) == 2
        err = capsys.readouterr().err
        assert says in err and "Traceback" not in err
    with pytest.raises(SystemExit) as exit_:  # a usage error: the parser states the range
        main(["check-controller", "stand", "--seconds", "-1"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "--seconds: must be a finite number in (0, 600] s, got '-1'" in err


def test_a_controller_that_cannot_be_built_from_its_files_is_a_failed_build_in_the_json(tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    import json

    from fuzz.cases import ONNX_FRAME, ONNX_IO, onnx_linear_model

    model, io = tmp_path / "m.onnx", tmp_path / "m.toml"
    model.write_bytes(onnx_linear_model(np.zeros((ONNX_FRAME - 3, 12))))  # an input too small for the I/O file
    io.write_text(ONNX_IO)
    for broken in ("model", "io"):
        if broken == "io":
            io.write_text(ONNX_IO.replace('arm_mode = "none"', 'arm_mode = "folded"'))
        assert main(["check-controller", f"onnx:{model}", "--json"]) == 2  # the status without --json
        captured = capsys.readouterr()
        found = json.loads(captured.out)
        message = captured.err.removeprefix("wbc: error: ").rstrip("\n")
        assert found == {"controller": f"onnx:{model}", "passed": False, "timings": [],
                         "outcomes": [{"check": "build", "robot": None, "arm_mode": None, "passed": False,
                                       "detail": message}]}, broken
        assert str(io) in message
    # a usage error stays one: a line on stderr and nothing on stdout
    assert main(["check-controller", "no-such-controller", "--json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "unknown controller 'no-such-controller'" in captured.err


ENDS_ITS_PROCESS = STAND_PLUGIN.format(doc="The stand hold that ends its process, status 0, on its fifth tick.",
                                       reset="pass", counters="return {}",
                                       act="if self.ticks == 5:\n                __import__('os')._exit(0)")
HANGS = STAND_PLUGIN.format(doc="The stand hold that hangs on its fifth tick.", reset="pass",
                            act="if self.ticks == 5:\n                __import__('threading').Event().wait()",
                            counters="return {}")


def test_a_controller_that_ends_its_process_or_hangs_fails_the_check_in_its_worker(plugin_package, capsys):
    """Checked in the command's own process, a controller that called os._exit(0) ended the command with status 0
    and no word: a CI job read a pass. The checks run in a worker process of their own; its end fails them, and so,
    under --time-limit, does a controller that hangs (which stalled the command for ever)."""
    import json

    plugin_package("endingpkg", {"ends": ENDS_ITS_PROCESS, "hangs": HANGS})
    assert main(["check-controller", "endingpkg.ends:make", "--robot", "a1-wx200", "--json"]) == 1
    result = json.loads(capsys.readouterr().out)
    (outcome,) = result["outcomes"]
    assert not result["passed"] and (outcome["check"], outcome["passed"]) == ("process", False)
    assert "ended before they finished (exit status 0)" in outcome["detail"]
    # the limit is far above what the check of a stand hold takes; the hung one never finishes
    assert main(["check-controller", "endingpkg.hangs:make", "--robot", "a1-wx200", "--time-limit", "60"]) == 1
    out = capsys.readouterr().out
    assert "FAIL process" in out and "had not finished after 60 s (--time-limit)" in out
    # in this process on request (a debugger's), where a limit cannot end anything
    assert main(["check-controller", "stand", "--in-process", "--time-limit", "60"]) == 2
    assert "--in-process" in capsys.readouterr().err
