"""Bad input on every surface is a clear one-line error (exit status 2 from the CLI), never a traceback or a result.

One test per surface: scenario files, a plug-in's ``--controller-config``, a results directory's ``run.json``, a
stored episode, and the command line's flags. Everything here is built in the test (no trial is played): fast.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from wbc.arena.episode import Episode, PushLog
from wbc.arena.executors import LocalExecutor
from wbc.arena.identity import RunIdentity, ScenarioRef, SimulatedRunIdentity
from wbc.arena.results import episode_path
from wbc.cli.main import HANDLERS, main
from wbc.cli.parser import build_parser
from wbc.control.plugin import read_controller_config
from wbc.errors import (
    BenchError,
    ConfigError,
    EpisodeError,
    EpisodeFileError,
    FileFieldError,
    InputFileError,
    RecordError,
    ScenarioError,
)
from wbc.input_files import read_toml
from wbc.scenario.domain import DomainParams
from wbc.scenario.lock import check_published
from wbc.scenario.scenario import load_scenario
from wbc.scenario.terrain import TerrainConfig
from wbc.viz.replay import frames_of

ROOT = Path(__file__).resolve().parent.parent
PUSH = (ROOT / "scenarios" / "push.toml").read_text()


def _cli_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """Run the CLI on `argv`; it must end with status 2 (returned, or a usage error's exit) and no traceback."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: a usage error
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    return err


def _scenario(tmp_path: Path, old: str, new: str, name: str = "bad.toml") -> Path:
    assert old in PUSH
    path = tmp_path / name
    path.write_text(PUSH.replace(old, new, 1))
    return path


def test_scenario_values_that_would_be_fatal_or_absurd_are_refused_with_their_range(tmp_path, capsys):
    wavelength = _scenario(tmp_path, "amplitude_m = 0.05", "amplitude_m = 0.05\nbase_wavelength_m = 0.001")
    with pytest.raises(ScenarioError) as err:
        load_scenario(wavelength)
    message = str(err.value)
    assert message.startswith(f"{wavelength}:") and err.value.field == "[terrain] base_wavelength_m"
    assert "must be in [0.4, 20] m with octaves = 4, got 0.001" in message and "GiB" in message
    err = _cli_error(capsys, ["run", "stand", "--scenario", str(wavelength), "--out", str(tmp_path / "o")])
    assert "[terrain] base_wavelength_m: must be in [0.4, 20] m" in err
    assert not (tmp_path / "o").exists()  # refused before any trial
    # the same check guards a TerrainConfig built in code
    with pytest.raises(ValueError, match="finest octave"):
        TerrainConfig(kind="fractal", base_cell=0.001)
    cases = {
        ("friction = [0.8, 1.0]", "friction = [1e-10, 1e-10]"): "[domain] friction: both ends must be in [0.05, 2]",
        ("friction = [0.8, 1.0]", "friction = [0.8, 1.0]\npayload_kg = [0.0, 15.0]"):
            "[domain] payload_kg: both ends must be in [-1, 10]",
        ("friction = [0.8, 1.0]", "friction = [0.8, 1.0]\nmotor_strength = [0.0001, 1.0]"):
            "[domain] motor_strength: both ends must be in [0.1, 2]",
        ("duration_s = 20.0", "duration_s = 0.001"): "[scenario] duration_s: must be in [0.1, 600], got 0.001",
        ("duration_s = 0.09", "duration_s = 1e-6"): "[pushes] duration_s: must be in [0.01, 1]",
        ("interval_s = [4.0, 6.0]", "interval_s = [4.0, 1e300]"): "[pushes] interval_s: both ends must be in (0, 600]",
        ("duration_s = 0.09", "duration_s = 0.6"): "#2 push_force_n: a push of 400 N for [pushes] duration_s 0.6 s "
                                                   "delivers 240 N s, more than 200 N s",
        ("amplitude_m = 0.05", "amplitude_m = 0.05\nhalf_extent_m = 1e6"):
            "[terrain] half_extent_m: must be in (1, 50]",
    }
    for (old, new), says in cases.items():
        with pytest.raises(ScenarioError) as err:
            load_scenario(_scenario(tmp_path, old, new))
        assert says in str(err.value), (new, str(err.value))
    with pytest.raises(ValueError, match=r"friction must be in \[0.05, 2\]"):
        DomainParams(friction=1e-10)
    # files that are not scenario files: a directory, a device, nesting a parser cannot follow, a 5000-digit number
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    huge = tmp_path / "huge.toml"
    huge.write_text("a = " + "1" * 5000 + "\n")
    for path, says in ((tmp_path, "cannot read the file: is a directory"),
                       (Path("/dev/zero"), "cannot read the file: not a regular file"),
                       (deep, "nested too deep"), (huge, "invalid TOML value: Exceeds the limit")):
        with pytest.raises(ScenarioError, match=says):
            load_scenario(path)
    # every shipped scenario still loads
    for shipped in sorted((ROOT / "scenarios").glob("*.toml")):
        if shipped.name != "published.toml":
            load_scenario(shipped)


def test_a_controller_config_that_cannot_be_read_is_a_clear_error(tmp_path, capsys):
    deep = tmp_path / "deep.toml"
    deep.write_text("".join(f"[{'t.' * 40}x]\n"))  # 41 tables deep
    big = tmp_path / "big.toml"
    big.write_bytes(b"# " + b"x" * (2 << 20) + b"\n")
    for path, says in ((deep, "nested more than 32 levels deep"), (big, "more than the 1 MiB a toml file may have"),
                       (Path("/dev/zero"), "not a regular file")):
        with pytest.raises(FileFieldError, match=says):
            read_controller_config(path)
        # read before the plug-in is imported: the missing module is never reached
        err = _cli_error(capsys, ["check-controller", "no_such_pkg.mod:make", "--controller-config", str(path)])
        assert says in err and str(path) in err and "no_such_pkg" not in err
    # UTF-8 with a byte-order mark (as some Windows editors save it) is read as without it, by both TOML readers
    marked = tmp_path / "bom.toml"
    marked.write_bytes(b"\xef\xbb\xbf[mpc]\nhorizon = 12\n")
    assert read_controller_config(marked) == {"mpc": {"horizon": 12}}
    assert read_toml(marked) == {"mpc": {"horizon": 12}}


def test_a_key_or_table_defined_twice_is_named_by_every_toml_reader(tmp_path, capsys):
    # the parser's "Cannot overwrite a value" names neither: each reader names the key, its table and both lines
    twice = tmp_path / "cc-dup.toml"
    twice.write_text("[mpc]\nhorizon = 12\nhorizon = 10\n")
    says = f"{twice}:3: [mpc] horizon: invalid TOML: horizon is set twice (first at line 2); keep one"
    with pytest.raises(FileFieldError) as caught:
        read_controller_config(twice)
    assert str(caught.value).startswith(says) and (caught.value.line, caught.value.field) == (3, "[mpc] horizon")
    with pytest.raises(InputFileError) as caught:
        read_toml(twice)
    assert str(caught.value).startswith(says)
    err = _cli_error(capsys, ["check-controller", "no_such_pkg.mod:make", "--controller-config", str(twice)])
    assert says in err and "no_such_pkg" not in err
    # a table twice, a key twice in an inline table, at top level; other faults keep the parser's words and column
    for text, said in (("[mpc]\na = 1\n\n[mpc]\nb = 2\n", ":4: [mpc]: invalid TOML: [mpc] names what is defined "
                                                        "already (first at line 1), as a table"),
                       ("gains = {kp = 1, kp = 2}\n", ":1: gains: invalid TOML: its inline table sets 'kp' twice"),
                       ("a = 1\nb = 2\na = 3\n", ":3: a: invalid TOML: a is set twice (first at line 1)"),
                       ("a = = 1\n", ":1: invalid TOML: Invalid value (column 5); fix the syntax")):
        twice.write_text(text)
        for read, error in ((read_controller_config, FileFieldError), (read_toml, InputFileError)):
            with pytest.raises(error) as caught:
                read(twice)
            assert str(caught.value).startswith(f"{twice}{said}"), str(caught.value)


def _identity() -> SimulatedRunIdentity:
    ref = ScenarioRef(path="scenarios/push.toml", name="push", hash="0" * 64, published=False, version=1)
    return SimulatedRunIdentity(controllers=("stand",), scenario=ref, bands=("in",), seeds=(0,), trials=1,
                                no_push=False, debug_truth=False)


def _write_run(root: Path, config: dict) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    path = root / "run.json"
    path.write_text(json.dumps({"config": config}))
    return path


def test_a_run_json_with_impossible_values_names_the_file_and_field(tmp_path, capsys):
    good = _identity().as_json()
    cases = {"trials": (0, "field trials: expected a whole number in [1, 100000], got 0"),
             "seeds": ([-1], "field seeds: expected a non-empty list of whole numbers in [0, 4294967295]")}
    for key, (value, says) in cases.items():
        path = _write_run(tmp_path / key, {**good, key: value})
        with pytest.raises(RecordError, match=rf"^{path}: {says}".replace("[", r"\[").replace("]", r"\]")):
            RunIdentity.load(path)
    # NaN and infinity are JSON to Python, not to us
    nan = tmp_path / "nan"
    nan.mkdir()
    (nan / "run.json").write_text(json.dumps({"config": {**good, "until_significant": {
        "alpha": math.nan, "pairs": []}}}))
    with pytest.raises(RecordError, match="until_significant.alpha: expected a finite number, got nan"):
        RunIdentity.load(nan / "run.json")
    # a long value is echoed shortened
    long = _write_run(tmp_path / "long", {**good, "bands": "x" * 10_000})
    with pytest.raises(RecordError, match=r"\(10002 characters\)") as err:
        RunIdentity.load(long)
    assert len(str(err.value)) < 600
    huge = tmp_path / "huge"
    huge.mkdir()
    (huge / "run.json").write_text('{"config": {"trials": ' + "1" * 5000 + "}}")
    with pytest.raises(RecordError, match="holds an integer of more than 4300 digits"):
        RunIdentity.load(huge / "run.json")
    err = _cli_error(capsys, ["view", "--episode", str(tmp_path / "trials"), "--trial", "0",
                              "--record", str(tmp_path / "x.html")])
    assert "run.json: field trials: expected a whole number in [1, 100000], got 0" in err


def _episode(k: int = 20) -> Episode:
    t = 0.02 * np.arange(1, k + 1)
    qpos = np.zeros((k, 7 + 15))
    qpos[:, 2], qpos[:, 3] = 0.3, 1.0
    zeros = np.zeros(k)
    return Episode(duration_s=1.0, control_dt=0.02, fell=False, fall_time_s=math.nan, t=t,
                   command=np.zeros((k, 3)), v_base_in_yaw=np.zeros((k, 2)), yaw_rate=zeros, roll=zeros,
                   pitch=zeros, power=zeros, arm_q=np.zeros((k, 3)), qpos=qpos, act_s=np.full(k, 1e-4))


def test_a_malformed_episode_is_refused_naming_the_field_and_never_drawn(tmp_path, capsys):
    good = tmp_path / "good.npz"
    _episode().save(str(good))
    assert len(Episode.load(str(good)).t) == 20
    with np.load(good) as z:
        fields = {k: z[k] for k in z.files}

    def broken(**changes: np.ndarray) -> Path:
        path = tmp_path / "broken.npz"
        np.savez(path, **{**fields, **changes})
        return path

    t = fields["t"].copy()
    t[5] = t[4]
    qpos_nan = fields["qpos"].copy()
    qpos_nan[3, 0] = np.nan
    qpos_zero_quat = fields["qpos"].copy()
    qpos_zero_quat[7, 3] = 0.0
    cases = [
        (dict(t=t), r"field t: not strictly increasing \(t\[4\] = 0.1, t\[5\] = 0.1\)"),
        (dict(t=np.array([0.0, np.inf])), "field t: inf at index"),
        (dict(command=fields["command"][:-1]), "field command: 19 rows, expected 20 \\(one per entry of t\\)"),
        (dict(qpos=qpos_nan), r"field qpos: nan at index \(3, 0\)"),
        (dict(qpos=qpos_zero_quat), r"field qpos: the base quaternion qpos\[7, 3:7\] has norm 0"),
        (dict(qpos=fields["qpos"][:, :5]), r"field qpos: shape \(20, 5\)"),
        (dict(duration_s=np.array([1.0, 2.0])), "field duration_s: shape \\(2,\\), expected a single number"),
        (dict(control_dt=np.array(-0.02)), "field control_dt: -0.02, expected a finite number in \\(0, 1\\]"),
        (dict(roll=np.array(["a"] * 20)), "field roll: dtype <U1, expected numbers"),
        (dict(push_start=np.array([np.nan])), "field push_start: nan"),
        # values each fine alone that no episode holds: times past its end, a position 1e300 m away, a negative count
        (dict(t=fields["t"] * 100), r"field t: runs from 2 to 40 s, outside the 1 s episode"),
        (dict(fall_time_s=np.array(999.0)), r"field fall_time_s: 999 s, after the 1 s episode"),
        (dict(qpos=np.where(qpos_nan == qpos_nan, fields["qpos"], 1e300)), r"field qpos: values beyond \+-10000"),
        (dict(clamped_ticks=np.array(2), clamped_rows=np.array([-1, 0, 0, 3, 0])),
         r"field clamped_rows: \[-1.0, 0.0, 0.0, 3.0, 0.0\]: each row's count of clamped ticks is a whole number "
         r"from 0 to clamped_ticks \(2\)"),
    ]
    for changes, says in cases:
        with pytest.raises(EpisodeFileError, match=says):
            Episode.load(str(broken(**changes)))
    # read from the file only: the source named, and a log's own check named by its fields
    with pytest.raises(EpisodeFileError, match=r"field base_source: 'bogus' is not a source; valid: truth, "
                                               r"estimator"):
        Episode.load(str(broken(base_source=np.str_("bogus"))))
    with pytest.raises(EpisodeFileError, match=r"broken.npz: fields safety_\*: "):
        Episode.load(str(broken(safety_time=np.array([0.5]))))
    one_push = {"push_start": np.array([0.5]), "push_force_in_world": np.zeros((1, 3)),
                "push_offset_in_base": np.zeros((1, 3))}
    with pytest.raises(EpisodeFileError, match=r"fields push_\*: PushLog: every push starts at 0 s or later and "
                                               r"lasts some time"):
        Episode.load(str(broken(**one_push, push_duration=np.array([-0.1]))))
    # the same checks on an episode built in memory, before any frame of it is drawn
    made = _episode()
    assert len(list(frames_of(made))) == 19  # the last row's joints were never read: no frame
    for changes, says in cases:
        if "dtype" in says or "push_start" in says:  # the dataclass holds no text arrays; pushes are a PushLog
            continue
        bad = dataclasses.replace(made, **changes)
        with pytest.raises(EpisodeError, match=says) as caught:
            next(frames_of(bad))
        assert str(caught.value).startswith("episode: field ") and not isinstance(caught.value, EpisodeFileError)
    with pytest.raises(EpisodeError, match="field push_start: nan"):
        next(frames_of(dataclasses.replace(made, pushes=PushLog(start=np.array([np.nan]), duration=np.array([0.1]),
                                                                force_in_world=np.zeros((1, 3)),
                                                                offset_in_base=np.zeros((1, 3))))))
    with pytest.raises(EpisodeFileError, match="not a readable .npz archive"):
        (tmp_path / "junk.npz").write_bytes(b"not a zip")
        Episode.load(str(tmp_path / "junk.npz"))
    # through the viewer: the malformed episode of a results directory is an error, not a replay
    root = tmp_path / "run"
    _write_run(root, _identity().as_json())
    stored = episode_path(root, "stand", "in", 0, 0)
    stored.parent.mkdir(parents=True)
    stored.write_bytes(broken(t=t).read_bytes())
    record = tmp_path / "replay.html"
    err = _cli_error(capsys, ["view", "--episode", str(root), "--trial", "0", "--record", str(record)])
    assert f"{stored}: field t: not strictly increasing" in err and not record.exists()


@pytest.mark.parametrize(("argv", "says"), [
    (["--workers", "0"], "argument --workers: must be in [1, 256], got '0'"),
    (["--workers", "-3"], "argument --workers: must be in [1, 256], got '-3'"),
    (["--seeds", "0"], "argument --seeds: must be in [1, 10000], got '0'"),
    (["--seeds", "1" * 5000], "argument --seeds: expected a whole number in [1, 10000], got '1111"),
    (["--trials", "0"], "argument --trials: must be in [1, 100000], got '0'"),
    (["--trials", "2.5"], "argument --trials: expected a whole number in [1, 100000], got '2.5'"),
    (["--speed", "nan"], "argument --speed: must be a finite number in [0, 100], got 'nan'"),
    (["--max-consecutive-errors", "-1"], "argument --max-consecutive-errors: must be in [0, 100000]"),
])
def test_run_flags_out_of_range_are_usage_errors_that_state_the_range(argv, says, tmp_path, capsys):
    err = _cli_error(capsys, ["run", "stand", "--scenario", "scenarios/push.toml", *argv])
    assert says in err and len(err.splitlines()[-1]) < 300  # a long value is echoed shortened


def test_other_flags_state_their_range_and_out_may_not_be_a_file(tmp_path, capsys):
    for argv, says in (
        (["view", "stand", "--trial", "0", "--fps", "0"], "argument --fps: must be a finite number in (0, 240]"),
        (["view", "stand", "--trial", "0", "--fps", "1000"], "argument --fps: must be a finite number in (0, 240]"),
        (["view", "stand", "--trial", "-1"], "argument --trial: must be in [0, 99999]"),
        (["view", "stand", "--trial", "0", "--speed", "inf"], "argument --speed: must be a finite number in [0, 100]"),
        (["bench", "mpc", "--seconds", "inf"], "argument --seconds: must be a finite number in (0, 14400] s"),
        (["hw", "emulate", "--seconds", "0"], "argument --seconds: must be a finite number in (0, 14400] s"),
        (["train", "--task", "push", "--teacher", "mpc", "--episode-s", "nan"],
         "argument --episode-s: must be a finite number in (0, 600] s, got 'nan'"),
        (["compare", "stand", "mpc", "--scenario", "x.toml", "--until-significant", "--alpha", "1"],
         "argument --alpha: must be a finite number in (0, 1)"),
    ):
        assert says in _cli_error(capsys, argv)
    a_file = tmp_path / "results.txt"
    a_file.write_text("not a directory")
    err = _cli_error(capsys, ["run", "stand", "--scenario", "scenarios/push.toml", "--out", str(a_file)])
    assert f"argument --out: '{a_file}' exists and is not a directory" in err
    assert a_file.read_text() == "not a directory"
    args = build_parser().parse_args(["run", "stand", "--scenario", "x.toml", "--band", "in", "--band", "ood",
                                      "--band", "in"])
    assert args.band == ["in", "ood"]
    assert "wbc: warning: --band 'in' given more than once; using it once" in capsys.readouterr().err


def test_a_run_of_more_trials_than_one_run_plays_is_refused_before_any_is_listed(tmp_path, capsys):
    # 2 controllers x 2 bands x 10,000 seeds x 100,000 trials: each flag in range, the product 4e9 trials (listing
    # them alone would fill the memory)
    err = _cli_error(capsys, ["compare", "stand", "mpc", "--scenario", "scenarios/push.toml", "--seeds", "10000",
                              "--trials", "100000", "--out", str(tmp_path / "run")])
    assert ("this run would play 4,000,000,000 trials (2 controllers x 2 bands x 10000 seeds x 100000 trials), more "
            "than the 1,000,000 one run plays") in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("name", ["onnx:", "onnx:/", "onnx:.", "policy:", "policy:/", "policy:."])
def test_a_policy_prefix_with_no_path_after_it_says_so(name, capsys):
    for argv in (["check-controller", name], ["run", name, "--scenario", "scenarios/push.toml", "--trials", "1",
                                              "--workers", "1", "--out", "runs/never-written"]):
        err = _cli_error(capsys, argv)
        prefix = name.split(":")[0] + ":"
        assert f"controller {name!r}: {prefix} needs the path of" in err
    assert not Path("runs/never-written").exists()


def test_a_saved_episodes_path_is_checked_before_the_trial_plays(tmp_path, capsys, monkeypatch):
    import wbc.viz.view as view

    monkeypatch.setattr(view, "view_trial", lambda *a, **k: pytest.fail("the trial was played"))
    (tmp_path / "adir").mkdir()
    # a missing directory (the trial played, then numpy failed); a directory or another suffix (numpy added .npz,
    # writing beside the path given, in silence)
    for bad in (tmp_path / "nodir" / "e.npz", tmp_path / "adir", tmp_path / "e.txt"):
        err = _cli_error(capsys, ["view", "stand", "--scenario", "scenarios/push.toml", "--trial", "0",
                                  "--duration", "1", "--record", str(tmp_path / "v.html"), "--save-episode", str(bad)])
        assert f"--save-episode {bad}: give an .npz file in an existing directory" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir"]


def test_a_name_in_name_equals_file_that_is_no_controller_of_the_run_is_named(tmp_path, capsys):
    toml = tmp_path / "ok.toml"
    toml.write_text("")
    for option in ("--controller-config", "--io"):
        err = _cli_error(capsys, ["compare", "stand", "examples.my_controller:make", "--scenario",
                                  "scenarios/push.toml", option, f"mpc={toml}", "--out", str(tmp_path / "o")])
        assert f"{option} mpc={toml}: mpc is not a controller of this run; NAME= names one of: stand, " \
               "examples.my_controller:make" in err
        assert "file not found" not in err


def test_a_policy_file_for_a_robot_not_here_or_with_an_unknown_key_names_the_file_and_field(tmp_path, capsys):
    src = ROOT / "wbc" / "learned" / "weights" / "a1-wx200-actuated-ppo"
    meta = json.loads(src.with_suffix(".json").read_text())
    for field, change, says in (("robot", {"robot": "spot"}, "'spot' is not a robot here; valid: a1-wx200, go1-arm"),
                                ("trainig", {"trainig": {}}, "unknown key; a network's keys are format, version")):
        stem = tmp_path / field
        stem.with_suffix(".npz").write_bytes(src.with_suffix(".npz").read_bytes())
        stem.with_suffix(".json").write_text(json.dumps({**meta, **change}))
        err = _cli_error(capsys, ["check-controller", f"policy:{stem}"])
        assert f"{stem}.json" in err and field in err and says in err


def test_compare_needs_two_controllers_each_named_once(tmp_path, capsys):
    base = ["--scenario", "scenarios/push.toml", "--out", str(tmp_path / "o")]
    assert "needs two or more controllers to compare, got stand; to play one controller, use wbc run" in \
        _cli_error(capsys, ["compare", "stand", *base])
    assert "wbc compare: stand named more than once" in _cli_error(capsys, ["compare", "stand", "mpc", "stand", *base])
    assert not (tmp_path / "o").exists()


def test_a_plug_in_that_exits_on_import_or_in_its_factory_is_an_error_naming_its_line(tmp_path, capsys, monkeypatch):
    pkg = tmp_path / "exitpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "atimport.py").write_text("import sys\nsys.exit(3)\n")
    (pkg / "infactory.py").write_text("def make(desc):\n    raise SystemExit('no robot here')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name, says in (("exitpkg.atimport:make", "importing exitpkg.atimport failed: SystemExit: 3 at "
                                                  f"{pkg / 'atimport.py'}:2"),
                       ("exitpkg.infactory:make", "raised while building the controller for a1-wx200 (arm actuated): "
                                                   f"SystemExit: no robot here at {pkg / 'infactory.py'}:2")):
        err = _cli_error(capsys, ["compare", name, "stand", "--scenario", "scenarios/push.toml", "--trials", "1",
                                  "--workers", "1", "--out", str(tmp_path / name)])
        assert says in err
        monkeypatch.delitem(__import__("sys").modules, name.split(":")[0], raising=False)


def test_viewing_a_controller_that_cannot_be_built_says_why_and_writes_no_page(tmp_path, capsys, monkeypatch):
    pkg = tmp_path / "brokenview"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "mod.py").write_text("def make(desc, config=None):\n    raise ValueError('no calibration file')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    page = tmp_path / "v.html"
    err = _cli_error(capsys, ["view", "brokenview.mod:make", "--scenario", "scenarios/push.toml", "--trial", "0",
                              "--duration", "1", "--record", str(page)])
    assert "nothing to show: controller brokenview.mod:make, band in, seed 0, trial 0: building it raised" in err
    assert f"ValueError: no calibration file at {pkg / 'mod.py'}:2" in err and not page.exists()


def test_resume_needs_the_results_directory_of_a_run(tmp_path, capsys):
    base = ["--scenario", "scenarios/push.toml", "--trials", "1", "--workers", "1", "--resume"]
    missing = tmp_path / "typo"
    for argv in (["run", "stand", *base, "--out", str(missing)], ["compare", "stand", "mpc", *base, "--out",
                                                                  str(missing)],
                 ["paper", "table3", "--trials", "1", "--seeds", "1", "--resume", "--out", str(missing)]):
        err = _cli_error(capsys, argv)
        assert f"--resume --out {missing}: no such results directory, so nothing to finish" in err
    assert "--resume finishes the run in --out: give its results directory" in _cli_error(capsys, ["run", "stand",
                                                                                                    *base])
    assert not missing.exists()


def test_demo_resumes_and_refuses_a_results_directory_before_its_analysis(tmp_path, capsys):
    out = tmp_path / "demo"
    out.mkdir()
    (out / "trials.csv").write_text("")
    err = _cli_error(capsys, ["demo", "--trials", "1", "--seeds", "1", "--out", str(out)])
    assert f"{out}: already holds results; pass --resume to finish that run" in err
    parser = build_parser()
    args = parser.parse_args(["demo", "--out", str(out), "--resume", "--drop-bad-rows"])
    assert args.resume and args.drop_bad_rows


def test_analysis_and_bench_options_are_refused_naming_the_option_or_the_scenario(tmp_path, capsys):
    # the default band of a command is not every scenario's: the scenario and its bands are named
    err = _cli_error(capsys, ["bench", "act", "stand", "--scenario", "scenarios/turn.toml"])
    assert "scenario 'turn': unknown band 'in'; valid bands: 1.0, 1.25, 1.5" in err
    assert "more than the 1,000,000 one run plays" in _cli_error(
        capsys, ["analyze", "arm-momentum", "--trials", "100000", "--seeds", "10000"])
    assert "argument --terrain: invalid choice: 'fractal'" in _cli_error(capsys, ["bench", "train", "--terrain",
                                                                                  "fractal"])


def test_posture_takes_an_episode_shorter_than_its_default_ramp():
    from wbc.tools.posture import posture_study

    rows = posture_study(["stand"], duration_s=0.4)  # the command's ramp shortens to half the episode
    assert [r.fell for r in rows] == [False, False]


def test_options_that_would_do_nothing_are_refused_naming_what_they_need(tmp_path, capsys, monkeypatch):
    base = ["--scenario", "scenarios/push.toml", "--trials", "1", "--out", str(tmp_path / "o")]
    assert "--speed sets how --view shows the run, and nothing is viewed: add --view, or leave it out" in _cli_error(
        capsys, ["run", "stand", *base, "--speed", "0.5"])
    assert "--host and --speed set how --view shows the run" in _cli_error(
        capsys, ["compare", "stand", "mpc", *base, "--host", "127.0.0.1", "--speed", "0"])
    assert "--host sets how --view shows the run" in _cli_error(
        capsys, ["hw", "run", "stand", "--robot", "go1", "--scenario", "scenarios/push.toml", "--trial", "0", "--sim",
                 "--host", "127.0.0.1"])
    sim = ["hw", "run", "stand", "--robot", "go1", "--scenario", "scenarios/push.toml", "--trial", "0", "--sim"]
    assert "--rate, --transport, --no-io-process, --no-realtime with --sim: the simulator plays the trial in this " \
        "process" in _cli_error(capsys, [*sim, "--rate", "200", "--transport", "udp", "--no-io-process",
                                         "--no-realtime"])
    assert "--allow-hardware, --yes with --sim" in _cli_error(capsys, [*sim, "--allow-hardware", "--yes"])
    assert "--yes confirms using real hardware, which --allow-hardware asks for" in _cli_error(
        capsys, ["hw", "check", "--robot", "go1", "--target", "127.0.0.1:9", "--yes", "--seconds", "0.1"])
    assert "--rt-priority and --rt-cpu with --no-realtime" in _cli_error(
        capsys, ["hw", "emulate", "--robot", "go1", "--seconds", "0.1", "--no-realtime", "--rt-priority", "50",
                 "--rt-cpu", "0"])
    assert "--stand times a stand through the safety layer, which --no-safety leaves out" in _cli_error(
        capsys, ["bench", "hw", "--seconds", "0.1", "--stand", "0.5", "--no-safety", "--no-realtime"])
    assert "--robot names the wire's robot, and --no-wire measures no wire" in _cli_error(
        capsys, ["bench", "latency", "--no-wire", "--robot", "a1", "--controllers", "stand", "--trials", "1"])
    assert "--workers 2 with --view: a viewed run plays its trials one by one in this process" in _cli_error(
        capsys, ["run", "stand", *base, "--view", "--workers", "2"])
    assert "--alpha sets the significance level at which --until-significant stops" in _cli_error(
        capsys, ["compare", "stand", "mpc", *base, "--alpha", "0.01"])
    assert "--address auto names a Ray cluster, which the local executor does not use: add --executor ray" in \
        _cli_error(capsys, ["run", "stand", *base, "--address", "auto"])
    assert "--workers 1 with --address auto: a Ray cluster's CPUs are its own" in _cli_error(
        capsys, ["run", "stand", *base, "--executor", "ray", "--address", "auto", "--workers", "1"])
    # wbc view: what a stored replay, an A / B page or a recording without --live does not use
    assert "--duration with --episode: a stored episode replays the run stored, whole" in _cli_error(
        capsys, ["view", "--episode", str(tmp_path), "--trial", "0", "--duration", "1"])
    assert "--scenario and --duration with --episode" in _cli_error(
        capsys, ["view", "stand", "--episode", str(tmp_path), "--scenario", "scenarios/push.toml", "--trial", "0",
                 "--duration", "1", "--record", str(tmp_path / "r.html")])
    assert "--controller-config and --save-episode with --episode" in _cli_error(
        capsys, ["view", "--episode", str(tmp_path), "--trial", "0", "--controller-config", "x.toml",
                 "--save-episode", str(tmp_path / "e.npz")])
    trial = ["--scenario", "scenarios/push.toml", "--trial", "0", "--duration", "0.1"]
    assert "--controller picks whose stored run --episode replays" in _cli_error(
        capsys, ["view", "stand", *trial, "--controller", "mpc", "--record", str(tmp_path / "r.html")])
    assert "--save-episode and --live with two controllers" in _cli_error(
        capsys, ["view", "stand", "mpc", *trial, "--save-episode", str(tmp_path / "e.npz"), "--live"])
    assert "--speed and --pause-at and --paused plays no part here: this view is only recorded" in _cli_error(
        capsys, ["view", "stand", *trial, "--record", str(tmp_path / "r.html"), "--speed", "0.5", "--paused",
                 "--pause-at", "0.05"])
    assert "--host and --wait plays no part here" in _cli_error(
        capsys, ["view", "stand", "mpc", *trial, "--host", "127.0.0.1", "--wait"])
    assert "--live streams a recorded view as well" in _cli_error(capsys, ["view", "stand", *trial, "--live"])
    assert "--at opens a recorded page at a moment" in _cli_error(capsys, ["view", "stand", *trial, "--at", "1"])
    assert not list(tmp_path.glob("*.html")) and not list(tmp_path.glob("*.npz"))
    assert not (tmp_path / "o").exists()
    # without --address, --workers sizes the Ray this machine starts
    made = []

    class Recorder(LocalExecutor):  # plays the trials in a local pool, so that the run finishes as on Ray
        def __init__(self, address, num_cpus):
            made.append((address, num_cpus))
            super().__init__(1, None)

        def connect(self):  # the arena connects a Ray executor before it touches the results directory
            made.append("connected")

        def describe(self):
            return "ray (recorded)"

        def close(self):
            pass

    monkeypatch.setattr("wbc.arena.compare.RayExecutor", Recorder)
    assert main(["run", "stand", *base, "--executor", "ray", "--workers", "1", "--band", "in", "--quiet"]) == 0
    assert made == [(None, 1), "connected"]


def test_an_interrupted_command_says_so_in_one_line_and_how_a_run_is_finished(tmp_path, capsys, monkeypatch):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setitem(HANDLERS, "run", interrupted)
    monkeypatch.setitem(HANDLERS, "bench sim", interrupted)
    out = tmp_path / "o"
    assert main(["run", "stand", "--scenario", "scenarios/push.toml", "--trials", "1", "--out", str(out)]) == 130
    assert capsys.readouterr().err == (f"wbc: interrupted; no trial was stored yet ({out} holds no trials.csv): the "
                                       "same command starts the run afresh\n")
    out.mkdir()
    (out / "trials.csv").write_text("")  # the run had begun to store its trials there, and none had finished
    assert main(["run", "stand", "--scenario", "scenarios/push.toml", "--trials", "1", "--out", str(out)]) == 130
    assert capsys.readouterr().err == (f"wbc: interrupted; no trial had finished ({out} holds the run's plan only): "
                                       "the same command with --resume plays it\n")
    assert main(["bench", "sim"]) == 130
    assert capsys.readouterr().err == "wbc: interrupted\n"


def test_an_edited_copy_of_a_published_scenario_is_warned_about_by_every_command_that_plays_it(tmp_path, capsys,
                                                                                                monkeypatch):
    import importlib

    import wbc.viz.view as view

    cli = importlib.import_module("wbc.cli.main")  # the module (the package's name `main` is the function)
    # push.toml edited beside a copy of the lock: its version is listed, with the hash it was published with
    edited = _scenario(tmp_path, "duration_s = 20.0", "duration_s = 19.0", "push.toml")
    (tmp_path / "published.toml").write_text((ROOT / "scenarios" / "published.toml").read_text())
    warning = "wbc: warning: " + str(pytest.raises(ScenarioError, check_published, load_scenario(edited)).value)
    assert "changed without a version bump" in warning

    def stop(*args, **kwargs):
        raise ScenarioError(edited, "stopped by the test before any trial")

    for name in ("arm_momentum_study", "bench_act", "bench_latency", "check_controller", "_check_apart"):
        monkeypatch.setattr(cli, name, stop)
    monkeypatch.setattr(view, "view_trial", stop)
    commands = (["analyze", "arm-momentum", "--trials", "1"], ["bench", "act", "stand"],
                ["bench", "latency", "--controllers", "stand", "--no-wire"],
                ["view", "stand", "--trial", "0", "--record", str(tmp_path / "v.html")], ["check-controller", "stand"])
    for argv in commands:
        err = _cli_error(capsys, [*argv, "--scenario", str(edited)])
        assert err.startswith(warning), argv  # said before anything plays
    # the published file itself is played without a warning
    for argv in commands:
        assert "warning" not in _cli_error(capsys, [*argv, "--scenario", str(ROOT / "scenarios" / "push.toml")])


def _nothing_plays(monkeypatch) -> None:
    """Make playing a trial, or starting the viewer's server, fail the test."""
    import wbc.viz.server as server
    import wbc.viz.view as view

    for name in ("view_trial", "view_ab"):
        monkeypatch.setattr(view, name, lambda *a, **k: pytest.fail("the trial was played"))
    monkeypatch.setattr(server.subprocess, "Popen", lambda *a, **k: pytest.fail("a server was started"))


_VIEWED = ["--scenario", "scenarios/push.toml", "--trial", "0"]


def test_a_recording_path_that_is_a_directory_is_refused_before_the_trial_plays(tmp_path, capsys, monkeypatch):
    _nothing_plays(monkeypatch)
    (tmp_path / "adir.html").mkdir()
    for ctrls in (["stand"], ["stand", "mpc"]):
        # the trial played, then the page could not be written
        err = _cli_error(capsys, ["view", *ctrls, *_VIEWED, "--record", str(tmp_path / "adir.html")])
        assert f"--record {tmp_path / 'adir.html'} is a directory: give an .html file in it, e.g. " \
               f"{tmp_path / 'adir.html' / 'view.html'}" in err
        err = _cli_error(capsys, ["view", *ctrls, *_VIEWED, "--record", str(tmp_path / "nodir" / "v.html")])
        assert f"--record {tmp_path / 'nodir' / 'v.html'}: give an .html file in an existing directory" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir.html"]


def test_a_moment_past_the_trials_end_is_refused_before_the_trial_plays(tmp_path, capsys, monkeypatch):
    _nothing_plays(monkeypatch)
    for ctrls in (["stand"], ["stand", "mpc"]):
        # the address printed opened the page at no moment of the trial
        err = _cli_error(capsys, ["view", *ctrls, *_VIEWED, "--record", str(tmp_path / "v.html"), "--at", "500"])
        assert "--at 500 s is past the end of the trial, which lasts 20 s: give --at in [0, 20]" in err
        err = _cli_error(capsys, ["view", *ctrls, *_VIEWED, "--duration", "2", "--record", str(tmp_path / "v.html"),
                                  "--at", "3"])
        assert "--at 3 s is past the end of the trial, which lasts 2 s (its --duration): give --at in [0, 2]" in err
    assert not list(tmp_path.iterdir())


def test_a_host_that_is_no_address_is_refused_before_the_viewer_starts(tmp_path, capsys, monkeypatch):
    _nothing_plays(monkeypatch)
    # refused at once, not after the server's 20 s start timeout
    for host, says in (("999.1.1.1", "is not an IPv4 address: give four numbers in 0..255 joined by dots"),
                       ("bad_host", "is neither an IP address nor a host name"), ("::g", "is not an IPv6 address")):
        assert f"--host {host} {says}" in _cli_error(capsys, ["view", "stand", *_VIEWED, "--host", host])
        assert f"--host {host} {says}" in _cli_error(capsys, ["run", "stand", *_VIEWED[:2], "--view", "--host", host,
                                                              "--out", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.0.2", "0.0.0.0", "::1", "localhost", "viewer-1.lab.example",
                                  "example.org."])
def test_a_host_of_valid_syntax_is_not_refused_and_nothing_is_looked_up(host):
    from wbc.viz.server import host_problem

    assert host_problem(host) is None


@pytest.mark.parametrize("host", ["", "999.1.1.1", "1.2.3", "1.2.3.4.5", "-a.example", "a..b", "a_b", "x" * 64,
                                  "1:2:3", "example.123"])
def test_a_host_of_invalid_syntax_is_refused_by_the_server_at_once(host, monkeypatch):
    import wbc.viz.server as server

    monkeypatch.setattr(server.subprocess, "Popen", lambda *a, **k: pytest.fail("a server was started"))
    with pytest.raises(server.ViewerError, match="the viewer's host"):
        server.MeshcatServer(server.ServerConfig(host=host)).start()


def test_bench_sim_refuses_a_batch_whose_rollout_buffers_would_not_fit_before_allocating_them(monkeypatch, capsys):
    import wbc.tools.bench.batched_rollout as batched
    import wbc.tools.bench.sim as sim

    def allocate(*args, **kwargs):
        raise AssertionError("the rollout's buffers were allocated before the memory was checked")

    monkeypatch.setattr(batched, "available_memory_bytes", lambda: 4 * 10**9)
    monkeypatch.setattr(sim, "BatchedRollout", allocate)
    err = _cli_error(capsys, ["bench", "sim", "--batch", "65536", "--threads", "1"])
    # 65536 x 500 steps of the robot's state (44 numbers) and the bare A1's (38), 8 bytes each
    assert re.search(r"^wbc: error: --batch 65536: the batched rollouts' buffers \(65536 environments x 500 steps\) "
                     r"need about 21\.\d GB, more than 50% of the memory available \(4\.0 GB\); give --batch 6\d{3} "
                     r"or less$", err, re.MULTILINE)
    err = _cli_error(capsys, ["bench", "sim", "--batch", "65536", "--threads", "1", "--no-reference"])
    assert re.search(r"need about 11\.\d GB, more than 50% of the memory available \(4\.0 GB\); give --batch "
                     r"11\d{3} or less$", err, re.MULTILINE)


def test_bench_train_refuses_envs_whose_buffers_would_not_fit_before_allocating_them(monkeypatch, capsys):
    import wbc.tools.bench.batched_rollout as batched
    import wbc.tools.bench.train as train

    built = []
    real_env = train.BatchedEnv

    def env(config):
        if config.num_envs != 1:  # the sizes are read from an env of one environment; no other is built
            raise AssertionError(f"an env of {config.num_envs} environments was built before the memory was checked")
        built.append(config.num_envs)
        return real_env(config)

    def allocate(*args, **kwargs):
        raise AssertionError("the reference's rollout buffers were allocated before the memory was checked")

    monkeypatch.setattr(batched, "available_memory_bytes", lambda: 10**9)
    monkeypatch.setattr(train, "BatchedEnv", env)
    monkeypatch.setattr(train, "BatchedRollout", allocate)
    err = _cli_error(capsys, ["bench", "train", "--envs", "65536", "--threads", "1", "--no-reference"])
    # per environment, 8 bytes x (twice the env's state, controls, rollout states, sensor data and torques: 2196
    # numbers; the bench's 50 x 15 random actions and its copies: 1438): 46640 bytes
    assert re.search(r"^wbc: error: --envs 65536: the training env's buffers and the bench's \(65536 environments, 50 "
                     r"steps of random actions\) need about 3\.\d GB, more than 50% of the memory available \(1\.0 "
                     r"GB\); give --envs 10\d{3} or less$", err, re.MULTILINE)
    assert built == [1]
    err = _cli_error(capsys, ["bench", "train", "--envs", "64", "--threads", "1", "--steps", "1000000"])
    assert "(64 environments, 1000000 steps of random actions) need about 7" in err and "give --envs 4 or less" in err
    monkeypatch.setattr(batched, "available_memory_bytes", lambda: 10**8)
    err = _cli_error(capsys, ["bench", "train", "--envs", "64", "--threads", "1", "--steps", "1000000"])
    assert err.rstrip().endswith("give fewer --steps, or free some memory (no environment fits in what is left)")
    assert built == [1, 1, 1]


def test_the_rollout_memory_check_reads_meminfo_and_refuses_nothing_where_the_system_does_not_tell(tmp_path,
                                                                                                monkeypatch):
    from wbc.tools.bench import batched_rollout as batched
    from wbc.tools.bench.references import reference_a1

    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       16000000 kB\nMemAvailable:    2000000 kB\n")
    assert batched.available_memory_bytes(meminfo) == 2_048_000_000
    meminfo.write_text("MemTotal:       16000000 kB\n")
    assert batched.available_memory_bytes(meminfo) is None
    assert batched.available_memory_bytes(tmp_path / "missing") is None
    model, _ = reference_a1()
    monkeypatch.setattr(batched, "available_memory_bytes", lambda: None)
    batched.check_rollout_memory([model], 65536, 500)  # unknown: not refused
    monkeypatch.setattr(batched, "available_memory_bytes", lambda: 10**5)
    with pytest.raises(ConfigError, match="free some memory"):
        batched.check_rollout_memory([model], 65536, 500)


def test_bench_arm_names_the_option_at_fault_and_its_help_gives_the_rates_range(monkeypatch, capsys):
    import wbc.tools.bench.arm as arm

    def start(*args, **kwargs):
        raise AssertionError("the emulator was started before the settings were checked")

    monkeypatch.setattr(arm, "_start_emulator", start)
    err = _cli_error(capsys, ["bench", "arm", "--rates", "0,200,2000", "--seconds", "0.2", "--no-realtime"])
    assert ("wbc: error: bench arm: --rates: each bus rate must be in 10..1000 Hz, got 0, 2000; give comma-separated "
            "rates, e.g. 100,200,400,1000") in err
    assert "--seconds" not in err
    with pytest.raises(BenchError, match=r"^bench arm: --seconds must be > 0 s, got 0$"):
        arm.bench_arm(rates=(200.0,), seconds=0.0)
    with pytest.raises(SystemExit):
        main(["bench", "arm", "--help"])
    usage = " ".join(capsys.readouterr().out.split())
    assert "--rates RATES bus rates to run, comma-separated, each 10..1000 Hz" in usage


def test_bench_mpc_names_seconds_when_the_walk_is_shorter_than_a_control_tick(capsys):
    err = _cli_error(capsys, ["bench", "mpc", "--seconds", "0.001", "--rounds", "1", "--no-reference",
                              "--threaded-blas"])
    assert ("wbc: error: --seconds 0.001: the walk must hold at least one control tick of mpc (0.002 s at 500 Hz); "
            "give --seconds 0.002 or more") in err
    assert "give it a rate" not in err
