"""The main job's pieces: progress that a CI log can read, the trial the demo suggests watching, and the template
controller entering the arena from a checkout exactly as the README shows it."""

import dataclasses
import importlib
import io
import math
import os
import shlex
import subprocess
import sys
from pathlib import Path

from conftest import HOLD_PLUGIN

from wbc.arena.compare import ArenaConfig, plan_arena
from wbc.arena.progress import LineProgress, progress
from wbc.arena.trial_record import TrialRecord
from wbc.cli import printers
from wbc.cli.parser import build_parser
from wbc.scenario.trial_file import _same_trial as same_trial
from wbc.tools.demo import TrialToWatch, trial_to_watch

cli_main = importlib.import_module("wbc.cli.main")  # the module (the package re-exports its `main`)

ROOT = Path(__file__).resolve().parent.parent


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_progress_in_a_log_is_whole_lines_at_each_tenth_and_after_a_silence():
    out, clock = io.StringIO(), _Clock()
    bar = LineProgress(20, 0, stream=out, every_s=30.0, clock=clock)
    for _ in range(20):
        clock.t += 1.0
        bar.update()
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[0] == "trials: 0/20 done, 20 to play"
    assert lines[1] == "trials: 2/20 (10 %), 2 s elapsed, about 18 s left"
    assert lines[-1] == "trials: 20/20 (100 %), 20 s elapsed"
    assert len(lines) == 11 and "\r" not in out.getvalue()
    # a slow run still says something at least every `every_s`, and a stop says where it stopped
    out, clock = io.StringIO(), _Clock()
    bar = LineProgress(1000, 10, stream=out, every_s=30.0, clock=clock)
    clock.t = 45.0
    bar.update()
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[1] == "trials: 11/1000 (1 %), 45 s elapsed, about 12.4 h left"
    assert lines[-1] == "trials: stopped at 11/1000 after 45 s"
    # a stream that is not a terminal gets lines, a disabled display nothing
    assert isinstance(progress(5, 0, True, io.StringIO()), LineProgress)
    assert progress(5, 0, False, io.StringIO()) is None


def _record(controller, trial, *, success=True, fall=math.nan, force=250.0, roll=5.0):
    return TrialRecord(controller=controller, scenario="push", scenario_hash="h", band="ood", seed=0, trial=trial,
                       success=success, ttf=1.0 if success else fall / 20.0, fall_time_s=fall, vlin_err=0.1,
                       vang_err=0.1, max_roll_deg=roll, max_pitch_deg=3.0, energy_j=100.0, arm_travel_rad=1.0,
                       push_force_n=force, n_pushes=4, vx_cmd=0.0, vy_cmd=0.0, yaw_rate_cmd=0.0, friction=0.9,
                       payload_kg=0.0, fallbacks=0, wbc_failures=0, debug_truth=False, wall_s=1.0,
                       outcome="success" if success else "fall")


def test_the_demo_suggests_the_trial_the_controllers_ended_differently():
    records = [_record("mpc", 0), _record("learned", 0), _record("mpc", 1),
               _record("learned", 1, success=False, fall=7.25), _record("mpc", 2, force=390.0)]
    watch = trial_to_watch(records, ("mpc", "learned"))
    assert (watch.controller, watch.band, watch.seed, watch.trial) == ("learned", "ood", 0, 1)
    assert watch.why == "learned fell at 7.2 s where mpc stood"
    assert (watch.other, watch.at_s) == ("mpc", 6.2)  # beside the one that stood, a second before the fall
    assert printers.ab_watch_command(watch, scenario="scenarios/push.toml", wbc="wbc") == (
        "wbc view learned mpc --scenario scenarios/push.toml --band ood --seed 0 --trial 1 --at 6.2")
    # all alike: the strongest push, with whoever rolled most
    records = [_record("mpc", 0, force=300.0, roll=4.0), _record("learned", 0, force=300.0, roll=9.0),
               _record("mpc", 1, force=380.0, roll=6.0), _record("learned", 1, force=380.0, roll=3.0)]
    watch = trial_to_watch(records, ("mpc", "learned"))
    assert (watch.controller, watch.trial) == ("mpc", 1) and "380 N" in watch.why
    assert (watch.other, watch.at_s) == ("learned", None)
    assert trial_to_watch([], ("mpc", "learned")) is None
    # a run that raised neither fell nor stood: not a trial the two ended differently, and not one to watch
    raised = dataclasses.replace(_record("learned", 0, success=False, fall=10.0), outcome="controller_error",
                                 fall_time_s=math.nan,
                                 error="learned raised RuntimeError at tick 3")
    records = [_record("mpc", 0, force=300.0), raised, _record("mpc", 1, force=200.0),
               _record("learned", 1, force=200.0, roll=9.0)]
    watch = trial_to_watch(records, ("mpc", "learned"))
    assert (watch.controller, watch.trial) == ("mpc", 0) and "nan" not in watch.why and watch.other is None
    assert trial_to_watch([raised], ("mpc", "learned")) is None
    # played without pushes: the largest roll, not "the strongest push, 0 N"
    records = [_record("mpc", 0, force=0.0, roll=2.0), _record("learned", 0, force=0.0, roll=3.0),
               _record("mpc", 1, force=0.0, roll=7.0), _record("learned", 1, force=0.0, roll=1.0)]
    watch = trial_to_watch(records, ("mpc", "learned"))
    assert (watch.controller, watch.trial, watch.why) == ("mpc", 1, "no pushes; mpc rolled 7 deg, the most of any "
                                                                    "trial")


def test_the_template_enters_the_arena_from_a_checkout_as_the_readme_shows(tmp_path):
    """``wbc compare examples.my_controller:make stand --scenario scenarios/push-v1.toml`` from the checkout's root.

    Push version 1, whose band in both controllers survive on this trial (its 0.06 s pushes were calibrated on the
    PD stand), so that a fall says the plug-in broke, not the push.

    Run as the console script runs: the working directory is not on sys.path (only the package is importable), so
    the plug-in is found in the working directory by the loader itself; stdout is not a terminal, so the progress is
    plain lines.
    """
    site = tmp_path / "site"
    site.mkdir()
    (site / "wbc").symlink_to(ROOT / "wbc")
    script = tmp_path / "wbc_script.py"
    # as pip writes the console script: the guard keeps a spawned worker, which imports it, from running the command
    script.write_text("import sys\nfrom wbc.cli.main import main\nif __name__ == '__main__':\n    sys.exit(main())\n")
    env = {**os.environ, "PYTHONPATH": str(site)}
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, str(script), "compare", "examples.my_controller:make", "stand",
                           "--scenario", "scenarios/push-v1.toml", "--trials", "1", "--band", "in", "--workers", "1",
                           "--out", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "examples.my_controller:make" in proc.stdout and "paired differences" in proc.stdout
    assert "trials: 2/2 (100 %)" in proc.stderr and "\r" not in proc.stderr
    records = TrialRecord.read_csv(out / "trials.csv")
    assert {r.controller for r in records} == {"examples.my_controller:make", "stand"}
    assert all(r.success for r in records)


def test_the_command_the_demo_prints_runs_as_printed(tmp_path, capsys):
    """Pasted whole into the shell that ran the demo, the watch line is a command the shell finds and wbc parses."""
    import shlex

    from wbc.cli.parser import build_parser
    from wbc.cli.printers import demo_watch_command, print_demo_end, wbc_command
    from wbc.tools.demo import TrialToWatch

    bin_dir = tmp_path / "venv" / "bin"
    bin_dir.mkdir(parents=True)
    script = bin_dir / "wbc"
    script.write_text("#!/bin/sh\n", encoding="utf-8")
    script.chmod(0o755)
    # not on the PATH (the environment is not activated): the script's path, relative to where the demo ran
    assert wbc_command(str(script), path="/usr/bin", cwd=str(tmp_path)) == "venv/bin/wbc"
    (tmp_path / "elsewhere").mkdir()
    assert wbc_command(str(script), path="/usr/bin", cwd=str(tmp_path / "elsewhere")) == str(script)
    # on the PATH: plain wbc
    assert wbc_command(str(script), path=f"{bin_dir}:/usr/bin", cwd=str(tmp_path)) == "wbc"
    # run another way (python -m wbc.cli): this interpreter
    assert wbc_command(str(ROOT / "wbc" / "cli" / "__main__.py")).endswith(" -m wbc.cli")

    watch = TrialToWatch(controller="learned", band="ood", seed=1, trial=3, why="learned fell at 2.0 s where mpc stood")
    line = demo_watch_command(watch, scenario="scenarios/push.toml", wbc="venv/bin/wbc")
    words = shlex.split(line)
    assert (tmp_path / words[0]).is_file()
    args = build_parser().parse_args(words[1:])
    assert (args.handler, args.scenario, args.band, args.seed, args.trial) == (
        "view", "scenarios/push.toml", "ood", 1, 3)

    print_demo_end(tmp_path, watch, scenario="scenarios/push.toml")
    out = capsys.readouterr().out.splitlines()
    command = next(x.strip() for x in out if " view learned " in x)
    assert command == demo_watch_command(watch, scenario="scenarios/push.toml")  # alone on its line, nothing after


def test_the_printed_watch_command_plays_the_trial_the_run_measured(plugin_package, tmp_path):
    plugin_package("holdpkg", {"hold": HOLD_PLUGIN})
    hold = "holdpkg.hold:make"
    gains = tmp_path / "my gains.toml"
    gains.write_text("leg_kp = 55.0\n")
    cfg = ArenaConfig(controllers=(hold, "stand"), scenario=Path("scenarios/push.toml"), seeds=(0, 1), trials=3,
                      out_dir=tmp_path / "r", no_push=True, debug_truth=True, controller_configs={hold: gains})
    plan = plan_arena(cfg)
    watch = TrialToWatch(controller=hold, band="ood", seed=1, trial=2, other="stand", at_s=3.0, why="a test")
    command = printers.ab_watch_command(watch, scenario="scenarios/push.toml", wbc="wbc",
                                        options=printers.arena_trial_options(cfg, (hold, "stand")))
    assert command == (f"wbc view {hold} stand --scenario scenarios/push.toml --band ood --seed 1 --trial 2 --no-push "
                       f"--debug-truth --controller-config '{hold}={gains}' --at 3")
    args = build_parser().parse_args(shlex.split(command)[1:])
    # the trial the view plays is the one the run measured: without its pushes, the plug-in with its file, truth on
    measured = next(t for t in plan.trials if (t.band, t.seed, t.index) == ("ood", 1, 2))
    viewed = cli_main._view_trial(args)
    assert measured.pushes == viewed.pushes == () and same_trial(viewed, measured)
    specs = cli_main._view_controllers(args, tuple(args.ctrl))
    assert [s.config_file for s in specs] == [plan.specs[hold].config_file, None] and specs[0].config_file == str(gains)
    assert args.debug_truth and args.no_push
    # a run that changed nothing prints none of them
    plain = dataclasses.replace(cfg, no_push=False, debug_truth=False, controller_configs={})
    assert printers.arena_trial_options(plain, (hold, "stand")) == ()
