"""A results directory trusts nothing it did not write, and a trial that measured nothing is not a result.

Each ``trials.csv`` row carries a checksum of its cells: an edited cell, a repeated trial, a row of another scenario
file, a row with a cell too few or a byte that is not UTF-8 is refused on ``--resume`` with its file and line, and
``--drop-bad-rows`` drops it (one warning each) and plays its trial again; a torn last line (a kill) is still dropped
silently. ``run.json`` is read as strictly as a scenario. The output paths are checked before any trial is played.
A simulation that blows up ends its trial with the outcome ``diverged`` and no absurd number in the summary; a
controller whose period is longer than the trial, never asked to act, is a controller error.
"""

import csv
import dataclasses
import json
import math
import re
import shutil
import textwrap

import numpy as np
import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.divergence import DivergenceCheck, SimulationDiverged
from wbc.arena.report import format_table, summarize
from wbc.arena.runner import run_episode
from wbc.arena.sim_trial import run_trial
from wbc.arena.trial_record import MACHINE_TIMED, TrialRecord, checksum_of, scan_csv
from wbc.cli.main import main
from wbc.control.registry import get_controller
from wbc.errors import ConfigError, RecordError, ResultsDirError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.scenario.scenario import load_scenario
from wbc.scenario.trial import CommandSchedule
from wbc.types import BaseTruth, RobotState


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """A finished run of ``stand`` on the short scenario, 2 trials: (scenario path, results directory)."""
    tmp = tmp_path_factory.mktemp("trust")
    scenario = tmp / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    run_arena(_config(scenario, tmp / "o"))
    return scenario, tmp / "o"


def _config(scenario, out, **changes):
    return ArenaConfig(controllers=("stand",), scenario=scenario, seeds=(0,), trials=2, out_dir=out, workers=1,
                       progress=False, **changes)


@pytest.fixture
def copy(stored, tmp_path):
    """A copy of the stored run to damage: (scenario, directory, its trials.csv lines without their newlines)."""
    scenario, out = stored
    mine = tmp_path / "o"
    shutil.copytree(out, mine)
    return scenario, mine


def _lines(out):
    return (out / "trials.csv").read_bytes().decode("utf-8").split("\r\n")[:-1]


def _write(out, lines):
    (out / "trials.csv").write_text("\r\n".join(lines) + "\r\n", encoding="utf-8", newline="")


def _edit(line, field, value):
    """`line` (a trials.csv row) with one cell replaced, its checksum left as it was."""
    cells = next(csv.reader([line]))
    cells[TrialRecord.header().index(field)] = value
    return ",".join(cells)


def _stable(record):
    skip = {TrialRecord.header().index(n) for n in MACHINE_TIMED}
    return [c for i, c in enumerate(record.to_row()) if i not in skip]


@pytest.mark.parametrize(("field", "value", "why"), [
    ("success", "False", "success False contradicts outcome 'success'"),  # refused before its checksum is looked at
    ("ttf", "0.5", "checksum '[0-9a-f]{16}' does not match the row's cells"),
    ("ttf", "-5.0", r"TrialRecord\.ttf must be a fraction of the episode in \[0, 1\], got -5\.0"),
])
def test_an_edited_cell_is_refused_with_its_line(copy, field, value, why):
    scenario, out = copy
    lines = _lines(out)
    lines[2] = _edit(lines[2], field, value)
    _write(out, lines)
    where = f"{out / 'trials.csv'}:3: "
    with pytest.raises(RecordError) as caught:
        run_arena(_config(scenario, out, resume=True))
    assert str(caught.value).startswith(where) and "--drop-bad-rows" in str(caught.value)
    assert re.search(why, str(caught.value))
    assert _lines(out)[2] == lines[2]  # refused, not rewritten


def test_a_repeated_trial_and_a_row_of_another_scenario_are_refused(copy):
    scenario, out = copy
    lines = _lines(out)
    _write(out, [*lines, lines[1]])
    with pytest.raises(RecordError, match=r"trials\.csv:2: repeats the trial \(controller stand, band soft, seed 0, "
                                          r"trial 0\) of line\(s\) 4 \(and 1 more refused row\(s\), line\(s\) 4\); "
                                          r"pass --drop-bad-rows"):
        run_arena(_config(scenario, out, resume=True))
    (first,) = scan_csv(out / "trials.csv").records
    other = dataclasses.replace(first, scenario_hash="ab" * 32)
    _write(out, [lines[0], lines[1], ",".join(other.to_row())])
    with pytest.raises(RecordError, match=r"trials\.csv:3: played on scenario hash 'abab"):
        run_arena(_config(scenario, out, resume=True))


@pytest.mark.parametrize(("change", "why"), [
    ({"trial": 2}, r"trial 2 is not one of this run's \(0 to 1 per band and seed\)"),
    ({"seed": 7}, r"seed 7 is not one of this run's \(0\)"),
    ({"band": "zzz"}, r"band 'zzz' is not one of this run's \(soft"),
])
def test_a_row_of_a_trial_outside_the_run_is_refused_with_its_line(copy, change, why):
    # its checksum is right (written by hand, or by another run into this directory): before, a trial beyond the
    # run's broke the push breakdown with a message naming no file, and another band's rows were kept unread
    scenario, out = copy
    lines = _lines(out)
    (first, _) = scan_csv(out / "trials.csv").records
    _write(out, [*lines, ",".join(dataclasses.replace(first, **change).to_row())])
    with pytest.raises(RecordError, match=rf"trials\.csv:4: {why}"):
        run_arena(_config(scenario, out, resume=True))


def test_a_row_with_a_cell_too_few_or_a_byte_not_utf8_is_refused_and_the_cli_says_so_cleanly(copy, capsys):
    scenario, out = copy
    lines = _lines(out)
    _write(out, [lines[0], lines[1].rsplit(",", 2)[0] + "," + lines[1].rsplit(",", 1)[1], lines[2]])
    n = len(TrialRecord.header())
    with pytest.raises(RecordError, match=rf"trials\.csv:2: {n - 1} cells, expected {n}"):
        run_arena(_config(scenario, out, resume=True))
    rows = [line.encode() for line in lines]
    rows[1] = rows[1].replace(b"stand", b"st\xffnd", 1)
    (out / "trials.csv").write_bytes(b"\r\n".join(rows) + b"\r\n")
    code = main(["run", "stand", "--scenario", str(scenario), "--trials", "2", "--workers", "1", "--out", str(out),
                 "--resume", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert f"{out / 'trials.csv'}:2: byte 0xff is not UTF-8" in err and "--drop-bad-rows" in err


def test_drop_bad_rows_drops_each_with_a_warning_and_plays_the_trials_again(copy, stored, capsys):
    scenario, out = copy
    original = TrialRecord.read_csv(stored[1] / "trials.csv")
    lines = _lines(out)
    _write(out, [lines[0], _edit(lines[1], "ttf", "0.25"), lines[2], lines[2]])
    with pytest.raises(RecordError, match="--drop-bad-rows"):
        run_arena(_config(scenario, out, resume=True))
    result = run_arena(_config(scenario, out, resume=True, drop_bad_rows=True))
    warnings = [w for w in capsys.readouterr().err.splitlines() if "row dropped (--drop-bad-rows)" in w]
    assert [w.split(": ")[2].split(":")[-1] for w in warnings] == ["2", "3", "4"]
    assert result.played == 2  # the edited trial and the repeated one
    again = TrialRecord.read_csv(out / "trials.csv")  # every row verifies
    assert sorted(map(_stable, again)) == sorted(map(_stable, original))
    with pytest.raises(ConfigError, match="--drop-bad-rows .* pass it with --resume"):
        run_arena(_config(scenario, out, drop_bad_rows=True))


def test_a_torn_last_line_is_still_dropped_silently_and_rows_without_a_checksum_are_another_versions(copy):
    scenario, out = copy
    lines = _lines(out)
    (out / "trials.csv").write_text("\r\n".join(lines) + "\r\nstand,short,ab", encoding="utf-8", newline="")
    assert run_arena(_config(scenario, out, resume=True)).played == 0
    # a file without the checksum column: another version's, refused before any row is trusted
    header = lines[0].rsplit(",", 1)[0]
    _write(out, [header, *(line.rsplit(",", 1)[0] for line in lines[1:])])
    with pytest.raises(RecordError, match=r"trials\.csv: columns .* another version of wbc"):
        scan_csv(out / "trials.csv")
    with pytest.raises(RecordError, match="another version of wbc: resume it with that version"):
        run_arena(_config(scenario, out, resume=True))


def test_a_corrupt_or_unknown_run_json_is_a_clean_error(copy):
    scenario, out = copy
    run = json.loads((out / "run.json").read_text())
    (out / "run.json").write_bytes(b'{"config": \xff}')
    unreadable = r"run\.json: unreadable run configuration \(at 1: byte 0xff .* not UTF-8.*another --out"
    with pytest.raises(ResultsDirError, match=unreadable):
        run_arena(_config(scenario, out, resume=True))
    run["config"]["trails"] = 2
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(RecordError, match=r"run\.json: field trails: not a field"):
        run_arena(_config(scenario, out, resume=True))
    del run["config"]["trails"]
    run["extra"] = 1
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(RecordError, match=r"run\.json: field extra: not a field of run\.json"):
        run_arena(_config(scenario, out, resume=True))
    (out / "run.json").unlink()
    with pytest.raises(ResultsDirError, match=r"run\.json: missing, so the run the 2 stored trial"):
        run_arena(_config(scenario, out, resume=True))


@pytest.mark.parametrize("blocked", ["out", "summary.json", "report.md", "trials.csv"])
def test_an_output_path_that_cannot_be_written_is_refused_before_any_trial(stored, tmp_path, blocked):
    scenario, _ = stored
    out = tmp_path / "o"
    if blocked == "out":
        out.write_text("not a directory")
    else:
        (out / blocked).mkdir(parents=True)
    with pytest.raises(ResultsDirError, match="--out") as caught:
        run_arena(_config(scenario, out))
    assert str(caught.value).startswith(str(out if blocked == "out" else out / blocked))
    assert not (tmp_path / "o" / "run.json").exists()  # refused before the store was opened: nothing played


def test_the_checksum_separates_cells_whatever_they_hold():
    assert checksum_of(["a,b", "c"]) != checksum_of(["a", "b,c"]) != checksum_of(["a", "b", "c"])
    assert len(checksum_of(["x"])) == 16 and checksum_of(["x"]) == checksum_of(("x",))


def test_the_divergence_check_finds_impossible_states_only():
    check = DivergenceCheck()
    ok = BaseTruth(np.array([0.0, 0.0, 0.3]), np.array([1.0, 0.0, 0.0, 0.0]), np.array([3.0, 0.0, -4.0]),
                   np.array([0.0, 20.0, 0.0]))
    assert check.truth(ok) is None
    assert "not finite" in check.truth(dataclasses.replace(ok, base_quat=np.array([np.nan, 0.0, 0.0, 0.0])))
    assert "moves at 25 m/s" in check.truth(dataclasses.replace(ok, base_linvel_in_world=np.array([15., 20., 0.])))
    assert "spins at" in check.truth(dataclasses.replace(ok, base_angvel_in_body=np.array([0.0, 0.0, 1e3])))
    assert "through the floor" in check.truth(dataclasses.replace(ok, base_position_in_world=np.array([0, 0, -2.])))


def test_the_divergence_check_finds_impossible_joints_only():
    check = DivergenceCheck()  # the joints' speeds as one vector's norm: 500 rad/s
    n = 15

    def joints(q=None, dq=None):
        return RobotState(tick=0, time=0.0, q=np.zeros(n) if q is None else q, dq=np.zeros(n) if dq is None else dq,
                          tau_est=np.zeros(n), imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.zeros(3),
                          accel_in_body=np.zeros(3), foot_force=np.zeros(4))

    fast = np.zeros(n)
    fast[[2, 9]] = 300.0, 400.0  # the norm exactly at the limit
    assert check.state(joints(q=np.full(n, 3.0), dq=fast)) is None
    for bad in (np.nan, np.inf, -np.inf):
        q = np.zeros(n)
        q[n - 1] = bad
        assert check.state(joints(q=q)) == "a joint position or speed is not finite"
        assert check.state(joints(dq=-q)) is not None
    fast[0] = 1.0
    assert check.state(joints(dq=fast)).startswith("the joints turn at 500 rad/s")


def test_a_diverging_simulation_ends_as_diverged_with_no_absurd_number_in_the_summary(stored, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its instability warning to MUJOCO_LOG.TXT in the working directory
    scenario, out = stored
    loaded = load_scenario(scenario)
    (trial,) = loaded.trials(loaded.bands, [0], 1)
    # a friction no scenario may ask for (the loader refuses it): MuJoCo's contact blows up under the MPC's stance
    domain = dataclasses.replace(trial.domain)
    object.__setattr__(domain, "friction", 1e-10)
    blown, _ = run_trial(dataclasses.replace(trial, domain=domain, pushes=(), duration_s=0.5), "mpc")
    assert blown.outcome == "diverged" and blown.success is False and 0.0 < blown.ttf < 1.0
    assert "simulation diverged at tick" in blown.error and "(limit " in blown.error
    assert all(math.isnan(blown[m]) for m in ("vlin_err", "vang_err", "max_roll_deg", "energy_j", "power_w"))
    assert blown.vlin_err_by_s == "" and math.isnan(blown.fall_time_s)
    # stored and read back like any row
    assert scan_csv_roundtrip(blown, out.parent) == blown
    stand = TrialRecord.read_csv(out / "trials.csv")
    mine = dataclasses.replace(blown, controller="mpc", band="soft", trial=0, scenario_hash=stand[0].scenario_hash)
    summary = summarize([*stand, mine], scenario_name="short", scenario_hash=stand[0].scenario_hash,
                        controllers=["stand", "mpc"], bands=["soft"], errors=[])
    cell = summary.to_json()["controllers"]["mpc"]["bands"]["soft"]
    assert cell["outcomes"]["diverged"] == 1 and cell["outcomes"]["fall"] == 0
    numbers = [v for v in _numbers(summary.to_json()) if v is not None]
    assert max(abs(v) for v in numbers) < 1e4  # no 1e6 m/s tracking error anywhere
    header = next(line for line in format_table(summary).splitlines() if line.strip().startswith("controller"))
    assert "diverged" in header.split()


def test_a_simulator_that_resets_itself_after_a_failed_step_ends_the_episode_as_diverged(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its instability warning to MUJOCO_LOG.TXT in the working directory
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none"))
    spec = get_controller("stand-noarm")

    def kick(t, robot, controller, command):
        if math.isclose(t, 0.2):  # a force MuJoCo cannot integrate in the next step: it warns, resets, carries on
            robot.data.qfrc_applied[8] = 1e15

    with sim:
        sim.reset(seed=0)
        calm = run_episode(sim, spec.make(sim.desc), CommandSchedule(), 0.3, divergence=DivergenceCheck())
        sim.reset(seed=0)
        # without the check, the reset robot stands at its initial pose again, and the episode looks like a success
        unchecked = run_episode(sim, spec.make(sim.desc), CommandSchedule(), 0.5, observer=kick)
        assert not unchecked.fell and sim.instability() is not None
        sim.reset(seed=0)
        assert sim.instability() is None  # a reset clears what the simulator reported
        with pytest.raises(SimulationDiverged) as diverged:
            run_episode(sim, spec.make(sim.desc), CommandSchedule(), 0.5, observer=kick, divergence=DivergenceCheck())
    assert not calm.fell
    message = str(diverged.value)
    assert message.startswith("simulation diverged at tick 10 (t = 0.220 s): MuJoCo could not integrate an "
                              "acceleration")
    assert "reset its own state" in message
    assert len(diverged.value.episode.t) == 11  # the tick that stepped into it included


def scan_csv_roundtrip(record, where):
    path = where / "one.csv"
    with path.open("w", encoding="utf-8", newline="") as f:
        csv.writer(f).writerows([TrialRecord.header(), record.to_row()])
    (back,) = TrialRecord.read_csv(path)
    return back


def _numbers(value):
    if isinstance(value, dict):
        for v in value.values():
            yield from _numbers(v)
    elif isinstance(value, list):
        for v in value:
            yield from _numbers(v)
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield value


def test_a_controller_never_asked_to_act_is_a_controller_error(stored, plugin_package, tmp_path):
    scenario, _ = stored
    source = textwrap.dedent(STAND_PLUGIN.format(doc="acts every 4 s", reset="pass", act="pass",
                                                 counters="return {}"))
    plugin_package("lazypkg", {"lazy": source.replace("self.rate_hz = self.inner.rate_hz", "self.rate_hz = 0.25")})
    result = run_arena(dataclasses.replace(_config(scenario, tmp_path / "o"), controllers=("lazypkg.lazy:make",)))
    assert [r.outcome for r in result.records] == ["controller_error", "controller_error"]
    for r in result.records:
        assert r.success is False and r.ticks == 0 and r.ttf == 0.0
        assert "never asked to act: its period 1/0.25 Hz is longer than the 1 s trial" in r.error
        assert "or make the trial at least 4 s long" in r.error
    assert result.summary.to_json()["controllers"]["lazypkg.lazy:make"]["bands"]["soft"]["outcomes"][
        "controller_error"] == 2


def test_resume_refuses_a_plugin_whose_code_changed_since_the_run_began(plugin_package, tmp_path, capsys):
    # the rows already stored were played by the module as it was: a resumed run would mix two versions of it
    root = plugin_package("editpkg", {"hold": STAND_PLUGIN.format(doc="The stand hold.", reset="pass", act="pass",
                                                                  counters="return {}")})
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    argv = ["run", "editpkg.hold:make", "--scenario", str(scenario), "--trials", "2", "--workers", "1", "--out",
            str(tmp_path / "o"), "--quiet"]
    assert main(argv) == 0
    run = json.loads((tmp_path / "o" / "run.json").read_text())
    assert len(run["controllers"]["editpkg.hold:make"]["plugin"]["module_sha256"]) == 64
    assert main([*argv, "--resume"]) == 0  # the same code: nothing to play, nothing refused
    module = root / "editpkg" / "hold.py"
    module.write_text(module.read_text() + "\nGAIN = 2.0\n")
    capsys.readouterr()
    assert main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err
    assert f"controller editpkg.hold:make's module {module}" in err and "changed since the run began" in err
