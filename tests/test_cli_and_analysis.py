"""The command line, the tail analysis, the arm-momentum study, the benches' loop observers, optional extras."""

import json
from pathlib import Path

import numpy as np
import pytest

from wbc.cli.main import main
from wbc.errors import MissingExtraError
from wbc.optional import require
from wbc.robots import get_robot
from wbc.tools.tail import analyze_tail

PUSH = Path(__file__).resolve().parent.parent / "scenarios" / "push-v1.toml"  # pushes held 0.06 s


@pytest.mark.parametrize("robot", ["a1-wx200", "go1-arm"])
def test_analyze_tail_prints_the_named_robots_figures_as_json_and_as_a_table(robot, capsys):
    want = analyze_tail(get_robot(robot, "actuated"))
    assert main(["analyze", "tail", "--robot", robot, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out == want.as_dict()
    for key in ("ccom_shift_m", "ccom_shift_m_exact", "alpha_ratio", "alpha_ratio_exact"):  # the documented keys
        assert isinstance(out[key], float)
    assert out["paper_ccom_shift_m"] == 0.022 and out["paper_alpha_ratio"] == -0.378  # the paper's Section VIII
    assert main(["analyze", "tail", "--robot", robot]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"Arm as a tail: {robot}"
    # each quantity's row reads: rod model, exact, paper
    rows = {line[:36].strip(): [float(v) for v in line[36:].split()] for line in lines[3:5]}
    assert rows["CoM shift by arm rotation [m]"] == pytest.approx(
        [want.ccom_shift_m, want.ccom_shift_m_exact, want.paper_ccom_shift_m], abs=1e-4)
    assert rows["body/arm angular acceleration"] == pytest.approx(
        [want.alpha_ratio, want.alpha_ratio_exact, want.paper_alpha_ratio], abs=1e-3)


def test_tail_rod_model_uses_the_models_numbers():
    desc = get_robot("a1-wx200")
    res = analyze_tail(desc)
    m_a = desc.arm.moving_mass
    assert res.arm_mass_moving == pytest.approx(m_a)
    assert res.ccom_shift_m == pytest.approx(m_a / (m_a + res.body_mass) * res.arm_length / 2)
    # the arm swings the body the other way, and a light arm moves the CoM by centimetres only
    assert -1.0 < res.alpha_ratio_exact < 0.0
    assert 0.0 < res.ccom_shift_m_exact < 0.05
    # a heavier arm turns the body more
    heavy = analyze_tail(get_robot("a1-wx200", arm_mass_scale=2.0))
    assert heavy.alpha_ratio_exact < res.alpha_ratio_exact


def test_exact_alpha_ratio_agrees_with_mujocos_mass_matrix():
    """The floating-base solve on the Pinocchio model gives the same ratio from MuJoCo's mass matrix."""
    import mujoco

    from wbc.hardware.mujoco.scene import build_scene
    from wbc.scenario.terrain import TerrainConfig

    desc = get_robot("a1-wx200")
    res = analyze_tail(desc)
    model = build_scene(desc, TerrainConfig())
    model.opt.gravity[:] = 0
    model.dof_damping[:] = 0
    model.dof_frictionloss[:] = 0
    data = mujoco.MjData(model)
    s = np.pi / 2 - np.arctan2(0.2, 0.05)
    data.qpos[:7] = [0, 0, 3.0, 1, 0, 0, 0]
    data.qpos[7:] = np.r_[desc.leg_nominal_q, np.pi / 2, s, -s]
    mujoco.mj_forward(model, data)
    data.qacc[:] = 0
    data.qacc[6 + 13] = 1.0  # shoulder; solve for the base acceleration with zero base force
    m = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, m)
    a_base = -np.linalg.solve(m[:6, :6], m[:6, 6 + 13])
    alpha_b = a_base[3:] @ np.array([-1.0, 0.0, 0.0])
    assert alpha_b / (1 + alpha_b) == pytest.approx(res.alpha_ratio_exact, rel=1e-6)


def test_unknown_names_list_the_valid_ones(capsys):
    assert main(["analyze", "tail", "--robot", "spot"]) == 2
    assert "a1-wx200 (or a1), go1-arm (or go1)" in capsys.readouterr().err
    assert main(["bench", "sim", "--arm", "floppy"]) == 2
    assert "actuated, locked, none" in capsys.readouterr().err


def test_missing_extra_names_the_extra_to_install():
    with pytest.raises(MissingExtraError, match=r"wbc\[train\]"):
        require("torch_module_that_does_not_exist", "train")
    with pytest.raises(MissingExtraError, match=r"wbc\[hardware\]"):
        require("dynamixel_sdk_missing_for_test", "hardware")
    assert require("json") is json


def test_arm_momentum_study_measures_the_arm_against_the_push():
    from wbc.tools.arm_momentum import arm_momentum_study

    actuated = arm_momentum_study(str(PUSH), "mpc", band="ood", trials=1, duration_s=3.5)
    locked = arm_momentum_study(str(PUSH), "mpc-locked", band="ood", trials=1, duration_s=3.5)
    a, b = actuated[0], locked[0]
    # the same push (same trial) on both; 300-400 N for 0.06 s at up to 0.12 m off the trunk's centre
    assert a.push_angular_impulse == pytest.approx(b.push_angular_impulse, rel=0.05)
    assert 0.0 < a.push_angular_impulse < 400 * 0.06 * 0.4
    assert b.arm_momentum_peak == 0.0 and b.arm_travel_rad == 0.0
    assert a.arm_momentum_peak > 0.0 and a.arm_travel_rad > 0.0
    # a locked arm has no bound and no alignment; an actuated one holds at most what its servos' speeds allow
    assert b.arm_momentum_bound == 0.0 and np.isnan(b.bound_fraction) and np.isnan(b.alignment)
    assert 0.05 < a.arm_momentum_bound < 1.0 and 0.0 < a.bound_fraction < 1.0 and -1.0 <= a.alignment <= 1.0


def test_arm_momentum_says_in_words_what_it_cannot_measure(capsys):
    """No arm, or a band with no push: a sentence that says so, not nan % and 0 % lines; the JSON holds null."""
    turn = PUSH.parent / "turn.toml"
    assert main(["analyze", "arm-momentum", "--controller", "stand-noarm", "--trials", "1"]) == 0
    out = capsys.readouterr().out
    assert "stand-noarm has no arm (arm mode none): no arm moves to take up the pushes' angular momentum" in out
    assert "nan" not in out and "% of" not in out
    assert main(["analyze", "arm-momentum", "--scenario", str(turn), "--band", "1.0", "--controller", "stand",
                 "--trials", "1"]) == 0
    out = capsys.readouterr().out
    assert f"band 1.0 of {turn} has no push: there is no push's angular impulse to set the arm's momentum against" \
        in out
    assert "nan" not in out and "% of" not in out
    assert main(["analyze", "arm-momentum", "--controller", "stand-noarm", "--trials", "1", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["arm_mode"] == "none" and row["bound_fraction"] is None and row["alignment"] is None


def test_a_trial_that_fell_before_its_push_is_left_out_of_the_arm_momentum_means(limp, capsys):
    import dataclasses

    from wbc.cli.printers import print_arm_momentum
    from wbc.tools.arm_momentum import arm_momentum_study

    # the limp robot is down within a second; band ood trial 0's first push starts at 2.334 s
    (fell,) = arm_momentum_study(str(PUSH.parent / "push.toml"), limp, band="ood", trials=1)
    assert not fell.survived and fell.pushes > 0 and fell.pushes_measured == 0
    assert np.isnan(fell.push_angular_impulse) and np.isnan(fell.arm_momentum_peak)
    reached = dataclasses.replace(fell, trial=1, survived=True, pushes_measured=fell.pushes, arm_travel_rad=2.0,
                                  push_angular_impulse=1.0, arm_momentum_peak=0.2, arm_momentum_mean=0.05,
                                  arm_momentum_bound=0.4, bound_fraction=0.5, alignment=0.8)
    print_arm_momentum([reached, fell], controller=limp, scenario="push.toml", band="ood")
    out = capsys.readouterr().out
    assert "1 of 2 trials fell before their first push and are left out of the means" in out
    # the means are the trial that reached its push's, not halved by a zero impulse and a zero peak
    assert ("mean over the 1 trial that reached a push: travel 2.0 rad, push angular impulse 1.000 N m s, arm "
            "momentum peak 0.200 N m s (20 % of the impulse), mean 0.050 N m s") in out
    assert "bound from its pose at each push: 0.400 N m s; its peak reached 50 % of it" in out and "nan" not in out
    print_arm_momentum([fell], controller=limp, scenario="push.toml", band="ood")
    assert "no trial lasted to its first push: nothing to average" in capsys.readouterr().out


def test_the_arms_momentum_bound_is_the_largest_over_its_speed_box():
    """The bound from the corners of the speed box is the maximum over the whole box, on a grid of it."""
    import pinocchio as pin

    from wbc.robots.description import ARM_JOINTS
    from wbc.robots.joint_table import joint_table
    from wbc.robots.pinocchio_model import build_pinocchio
    from wbc.tools.arm_momentum import arm_momentum_bound

    desc = get_robot("a1-wx200", "actuated")
    pinr = build_pinocchio(desc)
    vmax = joint_table(desc).velocity_limit[ARM_JOINTS]
    grid = np.stack(np.meshgrid(*[np.linspace(-v, v, 21) for v in vmax]), axis=-1).reshape(-1, 3)
    for arm_q in (desc.arm.nominal_q, np.array([0.0, -1.15, -1.25]), np.array([1.2, 0.3, 0.5])):
        q = pin.neutral(pinr.model)
        q[7:] = np.asarray(desc.nominal_q)[pinr.joints.pin_from_house]
        q[7 + pinr.joints.house_from_pin[ARM_JOINTS]] = arm_q
        pin.computeCentroidalMap(pinr.model, pinr.data, q)
        a_arm = pinr.data.Ag[3:, 6 + pinr.joints.house_from_pin[ARM_JOINTS]]
        brute = np.linalg.norm(grid @ a_arm.T, axis=1).max()  # the grid holds the corners too
        assert arm_momentum_bound(a_arm, vmax) == pytest.approx(brute, rel=1e-12)


class _TimedStand:
    """A stand controller that reports a tick breakdown as `HasTickTimings` asks: an MPC update every 5th tick."""

    rate_hz = 50.0

    def __init__(self, desc):
        from wbc.control.stand import StandController

        self._inner = StandController(desc)
        self.resets, self.tick = 0, 0

    def reset(self):
        self.resets += 1
        self.tick = 0

    def act(self, state, command):
        self._timings = {"whole_body_s": 50e-6}
        if self.tick % 5 == 0:
            self._timings.update(mpc_setup_s=2e-3, mpc_solve_s=1e-3)
        self.tick += 1
        return self._inner.act(state, command)

    def counters(self):
        return {"fallbacks": 0, "ticks": self.tick}

    def tick_timings(self):
        return self._timings


def _walk_watched(inner, seconds=0.2):
    from wbc.arena.runner import run_episode
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.scenario.trial import CommandSchedule
    from wbc.tools.bench.mpc import TickTimingLog

    log = TickTimingLog()
    with MujocoRobot(MujocoRobotConfig()) as robot:
        robot.reset(seed=0)
        episode = run_episode(robot, inner, CommandSchedule(vx=0.3), seconds, observer=log)
    return log, episode


def test_bench_mpc_files_each_tick_of_the_runner_loop_by_the_controllers_breakdown():
    from wbc.hardware.mujoco.robot import MujocoRobotConfig

    inner = _TimedStand(MujocoRobotConfig().description())
    log, episode = _walk_watched(inner)
    # the runner reset the controller once and played every tick; the log filed each by the breakdown
    assert inner.resets == 1 and len(episode.t) == 10 and inner.counters() == {"fallbacks": 0, "ticks": 10}
    assert len(log.mpc_solve_s) == 2 and len(log.whole_body_s) == 10
    assert log.plain_ticks == [1, 2, 3, 4, 6, 7, 8, 9] and np.all(episode.act_s > 0)
    figures = log.figures(episode)
    assert figures.mpc_solve_ms_median == pytest.approx(1.0)
    assert figures.mpc_setup_ms_median == pytest.approx(2.0)
    assert figures.wbc_tick_us_median == pytest.approx(50.0)
    assert 0 < figures.control_tick_us_median < 1e5


def test_bench_mpc_reports_nan_for_what_a_controller_without_a_breakdown_cannot_tell():
    from wbc.control.stand import StandController
    from wbc.hardware.mujoco.robot import MujocoRobotConfig

    log, episode = _walk_watched(StandController(MujocoRobotConfig().description()))
    assert len(episode.t) == 10 and not log.plain_ticks and np.all(episode.act_s > 0)
    assert all(np.isnan(v) for v in log.figures(episode).as_dict().values())


def test_bench_mpc_refuses_a_controller_that_is_not_an_mpc(capsys):
    argv = ["bench", "mpc", "--controller", "stand", "--seconds", "0.1", "--threaded-blas", "--no-reference"]
    assert main(argv) == 2
    assert "use one of: mpc, mpc-tail, mpc-locked, mpc-noarm, mpc-wbqp" in capsys.readouterr().err


@pytest.fixture
def no_worker(monkeypatch):
    """Fail if ``bench mpc`` spawns its worker: what is tested must be refused before it."""
    import wbc.tools.bench.mpc as bench

    def spawn(*args, **kwargs):
        raise AssertionError("bench mpc spawned its worker before it checked its options")

    monkeypatch.setattr(bench, "spawn_pool", spawn)


@pytest.mark.parametrize(("option", "value", "message"), [
    ("--controller", "nosuch", "wbc: error: unknown controller 'nosuch'; valid controllers: "),
    ("--robot", "foo", "wbc: error: unknown robot 'foo'; valid robots: a1-wx200 (or a1), go1-arm (or go1)"),
])
def test_bench_mpc_refuses_an_unknown_name_before_it_spawns_its_worker(option, value, message, no_worker, capsys):
    assert main(["bench", "mpc", option, value, "--seconds", "0.1", "--rounds", "1", "--no-reference"]) == 2
    assert capsys.readouterr().err.startswith(message)


def test_bench_mpc_refuses_another_qp_backend_for_the_tail_mpc_which_solves_its_own_qp(no_worker, capsys):
    argv = ["bench", "mpc", "--controller", "mpc-tail", "--qp-solver", "proxsuite", "--seconds", "0.1", "--rounds", "1",
            "--no-reference"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("wbc: error: --qp-solver proxsuite: mpc-tail solves its tail MPC's QP with daqp only")
    assert "leave --qp-solver out or give daqp" in err


def test_bench_mpc_of_the_tail_mpc_says_why_it_compares_no_qp_backends(capsys):
    argv = ["bench", "mpc", "--controller", "mpc-tail", "--seconds", "0.1", "--rounds", "1", "--no-reference",
            "--threaded-blas", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["qp_solver"].startswith("daqp ") and not any(key.startswith("qp_daqp_") for key in out)
    assert out["qp_comparison_skipped"].startswith("mpc-tail solves its tail MPC's QP with DAQP directly")


def test_bench_mpc_times_a_variant_built_from_its_settings_file(tmp_path, capsys):
    """--controller-config: a variant of the MPC's settings is timed as `wbc compare` plays it, and said."""
    settings = tmp_path / "h12.toml"
    settings.write_text("[mpc]\nhorizon = 12\n")
    argv = ["bench", "mpc", "--controller", "wbc.mpc.config_table:make", "--controller-config", str(settings),
            "--seconds", "0.1", "--rounds", "1", "--no-reference", "--threaded-blas"]
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["horizon"] == 12 and out["controller_config"] == str(settings)
    assert main(argv) == 0
    assert f"wbc.mpc.config_table:make (settings {settings}) on a1-wx200" in capsys.readouterr().out


def test_bench_mpc_times_a_variant_on_the_qp_backend_its_file_sets_and_keeps_the_files_name(tmp_path, capsys):
    """No --qp-solver: the file's ``[mpc] qp_solver`` is the walk's backend, and the result names the file."""
    settings = tmp_path / "proxsuite.toml"
    settings.write_text('[mpc]\nqp_solver = "proxsuite"\n')
    argv = ["bench", "mpc", "--controller", "wbc.mpc.config_table:make", "--controller-config", str(settings),
            "--seconds", "0.1", "--rounds", "1", "--no-reference", "--threaded-blas", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["qp_solver"].startswith("proxsuite ") and out["controller_config"] == str(settings)


@pytest.mark.parametrize(("sets", "given"), [("proxsuite", "daqp"), ("daqp", "proxsuite")])
def test_bench_mpc_refuses_a_qp_backend_other_than_the_one_its_settings_file_sets(tmp_path, no_worker, capsys, sets,
                                                                                 given):
    settings = tmp_path / "variant.toml"
    settings.write_text(f'[mpc]\nqp_solver = "{sets}"\n')
    assert main(["bench", "mpc", "--controller", "wbc.mpc.config_table:make", "--controller-config", str(settings),
                 "--qp-solver", given, "--seconds", "0.1", "--rounds", "1", "--no-reference"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"wbc: error: --qp-solver {given}: {settings} sets [mpc] qp_solver = '{sets}'"), err
    assert "leave --qp-solver out" in err


def test_bench_mpc_refuses_a_settings_file_for_a_registered_controller_before_it_spawns(tmp_path, no_worker, capsys):
    settings = tmp_path / "h12.toml"
    settings.write_text("[mpc]\nhorizon = 12\n")
    assert main(["bench", "mpc", "--controller-config", str(settings), "--seconds", "0.1", "--no-reference"]) == 2
    assert f"--controller-config {settings}: mpc takes no configuration table" in capsys.readouterr().err


def test_arm_momentum_plays_a_variant_built_from_its_settings_file(tmp_path, capsys):
    """--controller-config reaches the plug-in that plays the trials: its settings are the ones measured."""
    settings = tmp_path / "held.toml"
    settings.write_text("use_arm_momentum = false\n")
    argv = ["analyze", "arm-momentum", "--controller", "wbc.mpc.config_table:make", "--controller-config",
            str(settings), "--trials", "1"]
    assert main(argv) == 0
    assert f"wbc.mpc.config_table:make (settings {settings}), scenarios/push.toml band ood" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text("[mpc]\nhorizn = 12\n")
    assert main(["analyze", "arm-momentum", "--controller", "wbc.mpc.config_table:make", "--controller-config",
                 str(bad), "--trials", "1"]) == 2
    assert "horizn" in capsys.readouterr().err


def test_bench_mpc_takes_the_name_equals_file_form_that_compare_prints(tmp_path, capsys):
    settings, name = tmp_path / "h8.toml", "wbc.mpc.config_table:make@h8"
    settings.write_text("[mpc]\nhorizon = 8\n")
    assert main(["bench", "mpc", "--controller", name, "--controller-config", f"{name}={settings}", "--seconds",
                 "0.1", "--rounds", "1", "--no-reference", "--threaded-blas", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["horizon"] == 8 and out["controller_config"] == str(settings)


@pytest.mark.parametrize("command", [["bench", "mpc", "--seconds", "0.1", "--no-reference"],
                                     ["analyze", "arm-momentum", "--trials", "1"]])
def test_a_one_controller_command_refuses_a_file_named_for_another_controller(tmp_path, no_worker, capsys, command):
    settings = tmp_path / "h8.toml"
    settings.write_text("[mpc]\nhorizon = 8\n")
    given = f"wbc.mpc.config_table:make@h9={settings}"
    assert main([*command, "--controller", "wbc.mpc.config_table:make@h8", "--controller-config", given]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"wbc: error: --controller-config {given}: wbc.mpc.config_table:make@h9 is not the "
                          "controller here (wbc.mpc.config_table:make@h8)"), err


def test_arm_momentum_takes_the_name_equals_file_form_and_its_json_names_the_file(tmp_path, capsys):
    settings, name = tmp_path / "held.toml", "wbc.mpc.config_table:make@held"
    settings.write_text("use_arm_momentum = false\n")
    assert main(["analyze", "arm-momentum", "--controller", name, "--controller-config", f"{name}={settings}",
                 "--trials", "1", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [(r["controller"], r["controller_config"]) for r in rows] == [(name, str(settings))]


def test_every_command_of_the_parser_has_a_handler():
    import argparse

    from wbc.cli.main import HANDLERS
    from wbc.cli.parser import build_parser

    def handlers(parser):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    yield from handlers(sub)
        if "handler" in parser._defaults:
            yield parser._defaults["handler"]

    assert sorted(handlers(build_parser())) == sorted(HANDLERS)


def test_bench_arm_help_says_what_runs_whatever_its_rates_and_how_long(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "arm", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Then, whatever --rates and --seconds say: the elbow's closed-loop step response at 200 Hz" in text
    assert "the reactions at 200 Hz" in text and "about 20 s more than the rates' own time" in text
    assert "the step responses and the reactions run at 200 Hz whatever it says" in text


def test_every_option_of_every_command_has_a_help_line_that_names_its_default():
    import argparse

    from wbc.cli.parser import build_parser

    def options(parser, path):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from options(sub, f"{path} {name}")
            elif action.option_strings and not isinstance(action, argparse._HelpAction):
                yield path, action

    missing = [f"{path} {action.option_strings[0]}" for path, action in options(build_parser(), "wbc")
               if not action.help
               or action.default not in (None, False) and "default" not in action.help]
    assert not missing, f"options without help, or whose help does not name their default: {missing}"


def test_a_trunk_without_a_collision_box_is_an_error_that_says_what_to_add(monkeypatch, capsys):
    import wbc.tools.tail as tail

    monkeypatch.setattr(tail, "robot_urdf", lambda desc: '<robot name="r"><link name="trunk"/></robot>')
    assert main(["analyze", "tail"]) == 2
    assert "give that link a <collision><geometry><box" in capsys.readouterr().err


def test_a_reader_that_closes_the_output_ends_the_command_quietly() -> None:
    """``wbc controllers | head -1``: the reader closes the pipe before the list is written. The command ends as one
    that SIGPIPE ends (141), without a word: it printed a BrokenPipeError traceback and exited 1, read by a script as
    a controller's failure."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # buffered: written at the end, as usual
    proc = subprocess.Popen([sys.executable, "-m", "wbc.cli", "controllers"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=root, env=env)
    proc.stdout.close()  # before the interpreter has even started: every line meets a closed pipe
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.wait(timeout=60) == 141 and err == ""


def test_a_broken_pipe_that_is_not_the_output_is_not_taken_for_a_closed_reader(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib

    cli = importlib.import_module("wbc.cli.main")

    def broken(args):
        raise BrokenPipeError("a socket's")

    monkeypatch.setitem(cli.HANDLERS, "controllers", broken)
    with pytest.raises(BrokenPipeError, match="a socket's"):
        main(["controllers"])


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_while_the_command_loads_ends_it_with_one_line(signum: str) -> None:
    """The console script's entry: a Ctrl-C, SIGTERM or SIGHUP that comes while the command's modules load ends it in
    one line with status 130, as one that comes later does. A Ctrl-C printed the import's traceback; SIGTERM and
    SIGHUP ended the command without a word (143, 129). The signal is sent from within the import of the command."""
    import subprocess
    import sys
    import tomllib

    root = Path(__file__).resolve().parents[1]
    (entry,) = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"].values()
    module, function = entry.split(":")
    script = f"""
import os, signal, sys

# as a command started from a terminal has them: a suite run under nohup, or in the background of a script, ignores
# SIGHUP or SIGINT, and its children inherit that
signal.signal(signal.SIGHUP, signal.SIG_DFL)
signal.signal(signal.SIGINT, signal.default_int_handler)

class SignalWhileLoading:
    def find_spec(self, name, path=None, target=None):
        if name == "wbc.cli":
            os.kill(os.getpid(), signal.{signum})
        return None

sys.meta_path.insert(0, SignalWhileLoading())
from {module} import {function}
sys.exit({function}())
"""
    done = subprocess.run([sys.executable, "-c", script, "controllers"], cwd=root, capture_output=True, text=True,
                          timeout=120)
    assert (done.returncode, done.stderr, done.stdout) == (130, "wbc: interrupted while starting: nothing was done\n",
                                                           "")


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("module", ["wbc.cli", "wbc"])
def test_a_signal_while_python_dash_m_loads_the_command_ends_it_with_one_line(module: str, signum: str,
                                                                              tmp_path: Path) -> None:
    """``python -m wbc.cli`` and ``python -m wbc`` end as the console script does when a Ctrl-C or SIGTERM comes while
    the command's modules load. ``python -m wbc.cli`` printed the import's traceback and died of the signal: its
    package loads the command before its ``__main__`` runs. The signal is sent from within the import of the command's
    main module, by a ``sitecustomize`` that the interpreter loads at its start."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "sitecustomize.py").write_text(f"""
import os, signal, sys

signal.signal(signal.SIGHUP, signal.SIG_DFL)  # as a command started from a terminal has them
signal.signal(signal.SIGINT, signal.default_int_handler)

class SignalWhileLoading:
    def find_spec(self, name, path=None, target=None):
        if name == "wbc.cli.main":
            os.kill(os.getpid(), signal.{signum})
        return None

sys.meta_path.insert(0, SignalWhileLoading())
""")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(root)])}
    done = subprocess.run([sys.executable, "-m", module, "controllers"], cwd=root, capture_output=True, text=True,
                          timeout=120, env=env)
    assert (done.returncode, done.stderr, done.stdout) == (130, "wbc: interrupted while starting: nothing was done\n",
                                                           "")
