"""Controller plug-ins: ``package.module:factory`` names and ``wbc.controllers`` entry points, end to end.

A plug-in written to a temporary package plays the same trials as the built-in ``stand`` (it builds the same PD hold)
through the local pool and through Ray, and gives the same metrics; every way a plug-in can be broken ends the
command with its own message and no traceback.
"""

import hashlib
import sys
import textwrap

import numpy as np
import pytest
from conftest import HOLD_PLUGIN

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.trial_record import MACHINE_TIMED, TrialRecord
from wbc.cli.main import main
from wbc.control.errors import (
    PluginAmbiguousError,
    PluginAttributeError,
    PluginConfigError,
    PluginContractError,
    PluginFactoryError,
    PluginImportError,
    PluginNotFoundError,
)
from wbc.control.plugin import PLUGIN_GROUP
from wbc.control.registry import get_controller, list_controllers
from wbc.errors import UnknownNameError, WbcError
from wbc.robots.registry import get_robot

SMALL = """
[scenario]
name = "small"
version = 1
description = "a short push test"
robot = "a1-wx200"
duration_s = 2.0

[terrain]
kind = "fractal"
amplitude_m = 0.03

[commands]
[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.5, 0.8]
interval_s = [0.6, 0.9]
duration_s = 0.05
offset_m = 0.1

[[bands]]
name = "soft"
push_force_n = [100.0, 200.0]

[[bands]]
name = "hard"
push_force_n = [600.0, 900.0]
"""

MODULES = {
    "__init__.py": '"""Plug-ins for the tests."""\n',
    # the same PD hold as `stand`, built by a factory that takes an optional table
    "good.py": HOLD_PLUGIN,
    "boom.py": '''
        """Raises when imported."""
        raise RuntimeError("the plug-in's module is broken")
    ''',
    "needs_dep.py": '''
        """Imports a module that is not installed."""
        import wbc_no_such_dependency  # noqa: F401
    ''',
    "bad_syntax.py": "def make(desc:\n    return None\n",
    "raises.py": '''
        """A factory that raises."""


        def make(desc):
            raise ValueError("leg_kp must be positive")
    ''',
    "not_a_controller.py": '''
        """A factory that returns something else."""


        class Almost:
            rate_hz = 50.0

            def reset(self):
                pass


        def make(desc):
            return Almost()
    ''',
    "returns_class.py": '''
        """A factory that returns the controller's class, not an instance."""


        class Hold:
            rate_hz = 50.0

            def reset(self):
                pass

            def act(self, state, command):
                return None

            def counters(self):
                return {}


        def make(desc):
            return Hold
    ''',
}


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    """A package `plugpkg` on sys.path (and forgotten afterwards)."""
    root = tmp_path / "plugroot"
    pkg = root / "plugpkg"
    pkg.mkdir(parents=True)
    for name, text in MODULES.items():
        (pkg / name).write_text(textwrap.dedent(text).lstrip(), encoding="utf-8")
    monkeypatch.syspath_prepend(str(root))
    yield root
    for name in [m for m in sys.modules if m == "plugpkg" or m.startswith("plugpkg.")]:
        del sys.modules[name]


@pytest.fixture
def small(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    return path


def _metrics(records, controller):
    """Each record's stored cells but the controller's name and those timed on the machine's clock, by trial."""
    skip = {TrialRecord.header().index(name) for name in ("controller", *MACHINE_TIMED)}
    return {r.pair_key: [c for i, c in enumerate(r.to_row()) if i not in skip] for r in records
            if r.controller == controller}


def test_a_plugin_plays_the_same_trials_as_stand_on_the_local_pool_and_on_ray(plugins, small, tmp_path):
    pytest.importorskip("ray")
    name = "plugpkg.good:make"
    results = {}
    for executor, workers in (("local", ["--workers", "2"]), ("ray", [])):
        assert main(["compare", name, "stand", "--scenario", str(small), "--trials", "2", "--executor", executor,
                     *workers, "--out", str(tmp_path / executor), "--quiet"]) == 0
        results[executor] = TrialRecord.read_csv(tmp_path / executor / "trials.csv")
    for records in results.values():
        # the plug-in builds the very PD hold `stand` is, so every metric of every trial is the same
        assert len(records) == 2 * 2 * 2
        assert _metrics(records, name) == _metrics(records, "stand")
    # and the executors agree with each other: Ray's workers imported the package from where the parent found it
    assert _metrics(results["local"], name) == _metrics(results["ray"], name)
    assert not all(r.success for r in results["local"])  # the hard band topples it: the trials are not trivial


def test_the_config_table_reaches_the_factory(plugins, tmp_path, small, capsys):
    config = tmp_path / "gains.toml"
    config.write_text("leg_kp = 80.0\n")
    spec = get_controller("plugpkg.good:make", config=config)
    assert spec.kind == "plug-in" and spec.config_file == str(config) and spec.arm_mode == "actuated"
    ctrl = spec.make(get_robot("a1-wx200", "actuated"))
    assert np.all(ctrl.command.kp[:12] == 80.0)
    # through the command line: a key the factory refuses comes back as the factory's own message
    config.write_text("leg_kd = 3.0\n")
    assert main(["run", "plugpkg.good:make", "--scenario", str(small), "--trials", "1", "--band", "soft",
                 "--controller-config", str(config), "--out", str(tmp_path / "o"), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "plugpkg.good:make raised" in err and "unknown keys ['leg_kd']; valid: leg_kp" in err
    assert "Traceback" not in err
    # a run records the file it was configured with
    config.write_text("leg_kp = 60.0\n")
    out = tmp_path / "c"
    assert main(["compare", "plugpkg.good:make", "stand", "--scenario", str(small), "--trials", "1", "--band", "soft",
                 "--controller-config", f"plugpkg.good:make={config}", "--out", str(out), "--quiet",
                 "--workers", "1"]) == 0
    assert str(config) in (out / "run.json").read_text()
    # a table for a controller that takes none, or with nothing to take it, is refused by name
    assert main(["run", "stand", "--scenario", str(small), "--controller-config", str(config)]) == 2
    assert "no controller here is a plug-in" in capsys.readouterr().err
    with pytest.raises(PluginConfigError, match="stand takes no configuration table"):
        get_controller("stand", config=config)
    with pytest.raises(PluginConfigError, match=r"takes no config argument .*no_config\(desc\)"):
        get_controller("plugpkg.good:no_config", config=config)


BROKEN = [
    ("plugpkg.nowhere:make", PluginNotFoundError,
     ["no module named 'plugpkg.nowhere'", "package.module:factory", "wbc.controllers"]),
    ("plugpkg.boom:make", PluginImportError,
     ["importing plugpkg.boom failed: RuntimeError: the plug-in's module is broken", "boom.py:2"]),
    ("plugpkg.needs_dep:make", PluginImportError,
     ["No module named 'wbc_no_such_dependency'", "needs_dep.py:2", "install it"]),
    ("plugpkg.bad_syntax:make", PluginImportError, ["SyntaxError", "bad_syntax.py:1"]),
    ("plugpkg.good:mak", PluginAttributeError,
     ["has no attribute 'mak'", "did you mean 'make'?", "Factories defined there: Hold, make, no_args, no_config"]),
    ("plugpkg.good:GAIN", PluginAttributeError, ["GAIN is a float, not a factory", "Hold, make"]),
    ("plugpkg.good:no_args", PluginFactoryError, ["cannot be called as factory(desc)", "no_args()"]),
    ("plugpkg.raises:make", PluginFactoryError,
     ["plugpkg.raises:make raised while building the controller for a1-wx200", "ValueError: leg_kp must be positive",
      "raises.py:5"]),
    ("plugpkg.not_a_controller:make", PluginContractError,
     ["returned a Almost, which is not a wbc.control.Controller", "it has no act", "it has no counters"]),
    ("plugpkg.returns_class:make", PluginContractError,
     ["factory plugpkg.returns_class:make returned the class Hold, not an instance: return Hold(...)"]),
]


@pytest.mark.parametrize(("name", "error", "phrases"), BROKEN, ids=[b[0].split(".")[1] for b in BROKEN])
def test_a_broken_plugin_says_what_is_wrong_without_a_traceback(plugins, small, tmp_path, capsys, name, error,
                                                                phrases):
    with pytest.raises(error) as caught:
        spec = get_controller(name)
        spec.make(get_robot("a1-wx200", "actuated"))  # the two last kinds fail only when the factory is called
    for phrase in phrases:
        assert phrase in str(caught.value)
    # the command line says the same, before any trial is played, and exits with status 2
    assert main(["run", name, "--scenario", str(small), "--trials", "1", "--out", str(tmp_path / "o"),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and phrases[0] in err
    assert not (tmp_path / "o" / "trials.csv").exists() or len((tmp_path / "o" / "trials.csv").read_text()
                                                                .splitlines()) == 1


def test_an_unknown_name_lists_every_kind_of_valid_name(tmp_path, capsys):
    with pytest.raises(UnknownNameError) as caught:
        get_controller("walker")
    text = str(caught.value)
    for valid in ("stand", "mpc", "learned", "policy:PATH", "onnx:PATH", "package.module:factory"):
        assert valid in text
    assert main(["view", "no.such.module:make", "--scenario", "scenarios/push.toml", "--trial", "0",
                 "--record", str(tmp_path / "x.html")]) == 2
    assert "Traceback" not in capsys.readouterr().err


MALFORMED = [
    ("mypkg.good.make", ["no colon between the module and the factory", "did you mean 'mypkg.good:make'?"]),
    ("mypkg/good.py:make", ["a file path", "dotted import path", "did you mean 'mypkg.good:make'?"]),
    ("mypkg.good:", ["nothing after the colon"]),
    (":make", ["nothing before the colon"]),
    ("mypkg.good::make", ["2 colons", "did you mean 'mypkg.good:make'?"]),
    ("mypkg.good:make()", ["parentheses", "did you mean 'mypkg.good:make'?"]),
    ("my-pkg.good:make", ["'my-pkg' is not a Python identifier"]),
    ("runs/pi3.onnx", ["a .onnx file is named onnx:PATH", "did you mean 'onnx:runs/pi3.onnx'?"]),
]


@pytest.mark.parametrize(("name", "phrases"), MALFORMED, ids=[m[0] for m in MALFORMED])
def test_a_malformed_plugin_name_says_what_is_wrong_with_it(name, phrases, capsys):
    with pytest.raises(PluginNotFoundError) as caught:
        get_controller(name)
    text = str(caught.value)
    assert text.startswith(f"{name!r} is not a plug-in name: "), text
    assert "write package.module:factory" in text and "unknown controller" not in text
    for phrase in phrases:
        assert phrase in text, text
    assert main(["check-controller", name]) == 2
    err = capsys.readouterr().err
    assert "is not a plug-in name" in err and "Traceback" not in err


def test_the_other_name_forms_are_not_taken_for_malformed_plugin_names(tmp_path):
    for name in (f"onnx:{tmp_path / 'none.onnx'}", f"policy:{tmp_path / 'none'}"):
        with pytest.raises(WbcError) as caught:
            get_controller(name)
        assert "not a plug-in name" not in str(caught.value) and "file not found" in str(caught.value)
    with pytest.raises(UnknownNameError, match="unknown controller 'standd'; did you mean 'stand'"):
        get_controller("standd")
    # a registry name written with a dot or an underscore is a typo of that name, not a malformed plug-in
    for typo in ("mpc.tail", "mpc_tail", "learned.locked"):
        with pytest.raises(UnknownNameError, match=f"did you mean '{typo.replace('.', '-').replace('_', '-')}'"):
            get_controller(typo)
    with pytest.raises(UnknownNameError, match="a scenario goes after --scenario"):  # wbc run push.toml
        get_controller("push.toml")


def test_a_typo_of_a_dotted_entry_point_name_is_offered_that_name(plugins):
    dist = plugins / "dotdist-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: dotdist\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[{PLUGIN_GROUP}]\nmy.dotted = plugpkg.good:make\n")
    assert get_controller("my.dotted").kind == "entry point"
    with pytest.raises(UnknownNameError, match="did you mean 'my.dotted'"):
        get_controller("my.dottd")


def test_an_entry_point_is_listed_with_its_summary_and_plays_by_its_name(plugins, small, tmp_path, capsys):
    dist = plugins / "plugdist-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: plugdist\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[{PLUGIN_GROUP}]\ntest-hold = plugpkg.good:make\n"
                                           "test-broken = plugpkg.boom:make\n")
    rows = {r.name: r for r in list_controllers()}
    assert rows["test-hold"].summary == "Hold the nominal pose (a test plug-in)."
    assert rows["test-hold"].target == "plugpkg.good:make" and rows["test-hold"].loaded
    assert not rows["test-broken"].loaded and "RuntimeError" in rows["test-broken"].summary
    assert main(["controllers"]) == 0
    out = capsys.readouterr().out
    assert "test-hold" in out and "Hold the nominal pose (a test plug-in)." in out and "cannot be loaded" in out
    spec = get_controller("test-hold")
    assert spec.kind == "entry point"
    cfg = ArenaConfig(controllers=("test-hold", "stand"), scenario=small, seeds=(0,), trials=1, bands=("soft",),
                      out_dir=tmp_path / "ep", progress=False, workers=1)
    records = TrialRecord.read_csv(run_arena(cfg).out_dir / "trials.csv")
    assert _metrics(records, "test-hold") == _metrics(records, "stand")
    # an entry point that cannot be loaded fails when named, with the plug-in's own message
    assert main(["run", "test-broken", "--scenario", str(small), "--out", str(tmp_path / "b")]) == 2
    assert "the plug-in's module is broken" in capsys.readouterr().err


def _declare(root, dist, version, lines):
    """A distribution `dist` installed in `root` that declares the entry points `lines` (name = value)."""
    info = root / f"{dist}-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n")
    (info / "entry_points.txt").write_text(f"[{PLUGIN_GROUP}]\n" + "".join(f"{line}\n" for line in lines))


def test_an_entry_point_name_two_distributions_declare_is_ambiguous(plugins, small, tmp_path, capsys):
    _declare(plugins, "plugdist", "1.0", ["test-hold = plugpkg.good:make", "test-mine = plugpkg.good:make"])
    _declare(plugins, "otherdist", "2.0", ["test-hold = plugpkg.good:Hold"])
    with pytest.raises(PluginAmbiguousError) as caught:
        get_controller("test-hold")
    text = str(caught.value)
    for phrase in ("controller 'test-hold' is ambiguous", "plugdist 1.0 (plugpkg.good:make)",
                   "otherdist 2.0 (plugpkg.good:Hold)", "name the one you mean by its package.module:factory"):
        assert phrase in text, text
    assert get_controller("test-mine").kind == "entry point"  # the other names stay usable
    assert get_controller("plugpkg.good:make").name == "plugpkg.good:make"  # and so does the target itself
    rows = {r.name: r for r in list_controllers()}
    assert not rows["test-hold"].loaded and rows["test-hold"].kind == "entry point"
    assert "plugdist 1.0 (plugpkg.good:make)" in rows["test-hold"].summary
    assert "otherdist 2.0 (plugpkg.good:Hold)" in rows["test-hold"].summary
    assert rows["test-mine"].loaded
    assert main(["controllers"]) == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if "test-hold" in line)
    assert "ambiguous" in line and "plugdist" in line and "otherdist" in line
    assert main(["run", "test-hold", "--scenario", str(small), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "is ambiguous" in err and "Traceback" not in err


def test_an_entry_point_named_in_a_form_resolved_before_entry_points_is_listed_as_not_usable(plugins, capsys):
    names = {"onnx:evil": "has the form onnx:PATH, which names an ONNX policy ('evil'), never an entry point",
             "policy:mine": "has the form policy:PATH, which names a policy file ('mine'), never an entry point",
             "plugpkg.good:make": "has the form package.module:factory, which imports the module 'plugpkg.good', "
                                  "never an entry point"}
    _declare(plugins, "plugdist", "1.0", [f"{name} = plugpkg.good:make" for name in names]
             + ["test-hold = plugpkg.good:make"])
    rows = {r.name: r for r in list_controllers()}
    for name, reason in names.items():
        assert not rows[name].loaded and rows[name].kind == "entry point", rows[name]
        assert rows[name].summary == f"not usable: {name!r} {reason}; declare it under a name without a colon"
    assert rows["test-hold"].loaded
    assert main(["controllers"]) == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if "onnx:evil" in line)
    assert "not usable" in line and "never an entry point" in line
    with pytest.raises(UnknownNameError) as caught:  # nor offered among the valid names
        get_controller("walker")
    assert not set(names) & set(caught.value.valid) and "test-hold" in caught.value.valid


def test_an_entry_point_with_no_factory_says_so_and_how_to_write_it(plugins, capsys):
    _declare(plugins, "plugdist", "1.0", ["no-attr = plugpkg.good", "test-hold = plugpkg.good:make"])
    phrases = ("entry point 'no-attr' of the 'wbc.controllers' group in plugdist 1.0 points at module plugpkg.good "
               "with no factory", 'write "plugpkg.good:make"')
    with pytest.raises(PluginAttributeError) as caught:
        get_controller("no-attr")
    for phrase in phrases:
        assert phrase in str(caught.value), str(caught.value)
    assert "None" not in str(caught.value)
    rows = {r.name: r for r in list_controllers()}
    assert not rows["no-attr"].loaded and phrases[0] in rows["no-attr"].summary
    assert rows["no-attr"].target == "plugpkg.good" and rows["test-hold"].loaded
    assert main(["controllers"]) == 0
    assert phrases[0] in capsys.readouterr().out
    assert main(["check-controller", "no-attr"]) == 2
    err = capsys.readouterr().err
    assert phrases[0] in err and "Traceback" not in err


def test_an_unknown_name_lists_each_valid_name_once(plugins):
    _declare(plugins, "plugdist", "1.0", ["stand = plugpkg.good:make", "test-hold = plugpkg.good:make"])
    _declare(plugins, "otherdist", "2.0", ["test-hold = plugpkg.good:Hold"])
    with pytest.raises(UnknownNameError) as caught:
        get_controller("walker")
    assert caught.value.valid.count("stand") == 1 and "test-hold" not in caught.value.valid  # shadowed, ambiguous
    assert "stand, stand," not in str(caught.value)
    assert UnknownNameError("robot", "x", ("go1-arm", "a1-wx200", "go1-arm")).valid == ("a1-wx200", "go1-arm")


def test_a_plugin_is_watched_in_the_viewer_like_any_controller(plugins, small, tmp_path, capsys):
    out = tmp_path / "plugin.html"
    assert main(["view", "plugpkg.good:make", "--scenario", str(small), "--trial", "0", "--duration", "0.5",
                 "--record", str(out)]) == 0
    assert "recorded 25 frames" in capsys.readouterr().out and out.stat().st_size > 100_000


# -- provenance: what a run records of a plug-in -------------------------------------------------------------------
def test_a_plugin_records_its_target_module_file_and_that_no_distribution_installed_it(plugins):
    prov = get_controller("plugpkg.good:make").provenance()
    assert (prov["name"], prov["kind"], prov["arm_mode"], prov["files"]) == ("plugpkg.good:make", "plug-in",
                                                                           "actuated", [])
    module = plugins / "plugpkg" / "good.py"
    assert prov["plugin"] == {"target": "plugpkg.good:make", "module_file": str(module),
                              "module_sha256": hashlib.sha256(module.read_bytes()).hexdigest(),
                              "entry_point": None, "distribution": None,
                              "distribution_note": "not installed as a distribution"}
    # a module an installed distribution provides names it (wbc's own classes, as a plug-in)
    own = get_controller("wbc.control.stand:StandController").provenance()["plugin"]
    assert own["distribution"] == {"name": "wbc", "version": own["distribution"]["version"]}
    assert own["distribution"]["version"] == get_controller("stand").provenance()["wbc_version"]


def test_an_entry_point_records_the_distribution_that_declares_it(plugins, tmp_path):
    import hashlib
    import json

    dist = plugins / "plugdist-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: plugdist\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[{PLUGIN_GROUP}]\ntest-hold = plugpkg.good:make\n")
    (dist / "RECORD").write_text("plugpkg/__init__.py,,\nplugpkg/good.py,,\nplugdist-1.0.dist-info/METADATA,,\n")
    config = tmp_path / "gains.toml"
    config.write_text("leg_kp = 80.0\n")
    prov = get_controller("test-hold", config=config).provenance()
    assert prov["kind"] == "entry point"
    module = plugins / "plugpkg" / "good.py"
    assert prov["plugin"] == {"target": "plugpkg.good:make", "module_file": str(module),
                              "module_sha256": hashlib.sha256(module.read_bytes()).hexdigest(),
                              "entry_point": "test-hold", "distribution": {"name": "plugdist", "version": "1.0"}}
    assert prov["files"] == [{"role": "config", "path": str(config.resolve()),
                              "sha256": hashlib.sha256(config.read_bytes()).hexdigest()}]
    json.dumps(prov)  # JSON-ready, for run.json
    # the same module named as module:factory is credited to the distribution whose RECORD lists its file
    assert get_controller("plugpkg.good:make").provenance()["plugin"]["distribution"] == {"name": "plugdist",
                                                                                         "version": "1.0"}


# -- labels: two settings of one plug-in in one run ------------------------------------------------------------------
SOFT, STIFF = "plugpkg.good:make@soft", "plugpkg.good:make@stiff"


def _labelled_compare(small, out, soft, stiff, *more):
    return main(["compare", SOFT, STIFF, "--scenario", str(small), "--trials", "1", "--band", "soft",
                 "--controller-config", f"{SOFT}={soft}", "--controller-config", f"{STIFF}={stiff}",
                 "--out", str(out), "--quiet", "--workers", "1", *more])


def test_one_plugin_plays_under_two_labels_with_a_config_each_resumes_and_replays(plugins, small, tmp_path, capsys):
    import json

    soft, stiff = tmp_path / "soft.toml", tmp_path / "stiff.toml"
    soft.write_text("leg_kp = 30.0\n")
    stiff.write_text("leg_kp = 80.0\n")
    out = tmp_path / "labels"
    assert _labelled_compare(small, out, soft, stiff, "--save-episodes") == 0
    records = TrialRecord.read_csv(out / "trials.csv")
    assert [r.controller for r in records] == [SOFT, STIFF]
    # each label played its own file: the two gains hold the pose differently
    assert _metrics(records, SOFT) != _metrics(records, STIFF)
    assert set(json.loads((out / "summary.json").read_text())["controllers"]) == {SOFT, STIFF}
    run = json.loads((out / "run.json").read_text())
    assert run["config"]["controllers"] == [SOFT, STIFF]
    assert {name: f["path"] for name, f in run["config"]["controller_files"].items()} == {SOFT: str(soft),
                                                                                           STIFF: str(stiff)}
    for name in (SOFT, STIFF):  # known by the labelled name, the code it runs recorded apart from it
        assert run["controllers"][name]["name"] == name
        assert run["controllers"][name]["plugin"]["target"] == "plugpkg.good:make"
    assert SOFT in (out / "report.md").read_text()
    episodes = sorted(p.name for p in (out / "episodes").iterdir())
    assert episodes == ["plugpkg.good_make_soft", "plugpkg.good_make_stiff"]
    # resumed with the same labels and files: nothing to play again
    csv = (out / "trials.csv").read_text()
    assert _labelled_compare(small, out, soft, stiff, "--resume") == 0
    assert (out / "trials.csv").read_text() == csv
    # a label given the other's file is a change of configuration, refused as any plug-in's changed file is
    capsys.readouterr()
    assert _labelled_compare(small, out, stiff, soft, "--resume") == 2
    err = capsys.readouterr().err
    assert "--resume with a different configuration (differs in: controller_files)" in err
    assert f"controller_files.{SOFT}.sha256" in err and (out / "trials.csv").read_text() == csv
    # a labelled controller's stored episode replays by its name
    page = tmp_path / "soft.html"
    assert main(["view", "--episode", str(out), "--trial", "0", "--controller", SOFT, "--record", str(page)]) == 0
    assert "plugpkg.good_make_soft" in capsys.readouterr().out and page.stat().st_size > 100_000


def test_the_mpc_settings_table_plays_arm_momentum_on_and_off_under_two_labels(tmp_path):
    scenario = tmp_path / "short.toml"
    scenario.write_text(SMALL.replace("duration_s = 2.0", "duration_s = 0.6").replace("[0.5, 0.8]", "[0.2, 0.3]"))
    configs = {}
    for label, value in (("arm", "true"), ("noarm", "false")):
        configs[label] = tmp_path / f"{label}.toml"
        configs[label].write_text(f"use_arm_momentum = {value}\n")
    names = [f"wbc.mpc.config_table:make@{label}" for label in configs]
    out = tmp_path / "mpc"
    assert main(["compare", *names, "--scenario", str(scenario), "--trials", "1", "--band", "hard",
                 *[arg for label, name in zip(configs, names, strict=True)
                   for arg in ("--controller-config", f"{name}={configs[label]}")],
                 "--out", str(out), "--quiet", "--in-process"]) == 0
    records = TrialRecord.read_csv(out / "trials.csv")
    assert [r.controller for r in records] == names
    assert _metrics(records, names[0]) != _metrics(records, names[1])


def test_a_run_records_each_variants_table_and_the_settings_it_played_with_and_resumes_a_run_without_them(tmp_path):
    """run.json holds each settings file's table and the settings resolved from it (the tail MPC's ready pose,
    computed when the file leaves it out); the report lists each file with the keys it sets."""
    import json

    from wbc.mpc.tail_controller import ready_pose

    scenario = tmp_path / "short.toml"
    scenario.write_text(SMALL.replace("duration_s = 2.0", "duration_s = 0.3").replace("[0.5, 0.8]", "[0.1, 0.2]"))
    h8, held = tmp_path / "h8.toml", tmp_path / "held.toml"
    h8.write_text("[mpc]\nhorizon = 8\n")
    held.write_text("[tail]\narm_moves = false\n")
    mpc, tail = "wbc.mpc.config_table:make@h8", "wbc.mpc.config_table:make_tail@ready"
    out = tmp_path / "run"
    argv = ["compare", mpc, tail, "--scenario", str(scenario), "--trials", "1", "--band", "hard",
            "--controller-config", f"{mpc}={h8}", "--controller-config", f"{tail}={held}", "--out", str(out),
            "--quiet", "--in-process"]
    assert main(argv) == 0
    run = json.loads((out / "run.json").read_text())
    mine = run["controllers"][mpc]["settings"]
    assert mine["table"] == {"mpc": {"horizon": 8}} and mine["resolved"]["mpc"]["horizon"] == 8
    theirs = run["controllers"][tail]["settings"]
    assert theirs["table"] == {"tail": {"arm_moves": False}} and theirs["resolved"]["tail"]["arm_moves"] is False
    assert theirs["resolved"]["ready_q"] == list(ready_pose("a1-wx200"))
    report = (out / "report.md").read_text()
    assert f"{mpc}: `{h8}: sets [mpc] horizon`" in report and f"{tail}: `{held}: sets [tail] arm_moves`" in report
    # a directory whose run.json predates the settings resumes, and gets them
    csv = (out / "trials.csv").read_text()
    for name in (mpc, tail):
        del run["controllers"][name]["settings"]
    (out / "run.json").write_text(json.dumps(run, indent=2))
    assert main([*argv, "--resume"]) == 0
    assert (out / "trials.csv").read_text() == csv
    assert json.loads((out / "run.json").read_text())["controllers"][mpc]["settings"] == mine
    assert main([*argv, "--resume"]) == 0 and (out / "trials.csv").read_text() == csv


def test_controllers_that_would_play_with_identical_settings_are_warned_of_before_anything_plays(small, tmp_path,
                                                                                                 capsys):
    from wbc.arena.compare import plan_arena

    a, b, h9 = tmp_path / "a.toml", tmp_path / "b.toml", tmp_path / "h9.toml"
    a.write_text("[mpc]\nhorizon = 8\n")
    b.write_text("[mpc]\nhorizon = 8\n")
    h9.write_text("[mpc]\nhorizon = 9\n")
    names = [f"wbc.mpc.config_table:make@{label}" for label in ("a", "b", "h9", "plain")]
    files = {names[0]: a, names[1]: b, names[2]: h9}
    plan = plan_arena(ArenaConfig(controllers=("mpc", *names), scenario=small, out_dir=tmp_path / "o",
                                  controller_configs=files))
    # the byte-identical files, and the label with no file beside the registry's mpc it equals; not h9
    assert plan.identical == (("mpc", names[3]), (names[0], names[1]))
    err = capsys.readouterr().err
    assert (f"wbc: warning: {names[0]} and {names[1]} run the same controller with identical settings on the same "
            "robot: they play bit-identical trials and only add tests to the verdict's family") in err
    assert f"wbc: warning: mpc and {names[3]} run the same controller with identical settings" in err
    assert not plan_arena(ArenaConfig(controllers=("mpc", names[2]), scenario=small, out_dir=tmp_path / "o",
                                      controller_configs={names[2]: h9})).identical
    assert "identical settings" not in capsys.readouterr().err
    # and the report's Run section says it
    scenario = tmp_path / "short.toml"
    scenario.write_text(SMALL.replace("duration_s = 2.0", "duration_s = 0.3").replace("[0.5, 0.8]", "[0.1, 0.2]"))
    out = tmp_path / "run"
    assert main(["compare", "mpc", names[3], "--scenario", str(scenario), "--trials", "1", "--band", "hard",
                 "--out", str(out), "--quiet", "--in-process"]) == 0
    assert (f"- **identical settings**: mpc and {names[3]} run the same controller with identical settings"
            in (out / "report.md").read_text())


RULE = "a label is a letter or digit, then letters, digits, '_', '.' or '-', at most 40 characters"
LABEL_ERRORS = [
    ("plugpkg.good:make@", ["nothing follows the '@'", RULE]),
    ("plugpkg.good:make@_x", ["its label '_x' is not one", RULE]),
    ("plugpkg.good:make@a/b", ["its label 'a/b' is not one", RULE]),
    ("plugpkg.good:make@a@b", ["it has 2 '@'", RULE]),
    ("plugpkg.good:make@" + "x" * 41, ["has 41 characters", RULE]),
    ("stand@x", ["stand is the registry's", "a label means nothing there: name it 'stand', once"]),
    ("nothing@x", ["'nothing' is not a plug-in's package.module:factory",
                   "the registry's controllers, policy:PATH and onnx:PATH take no label"]),
    ("plugpkg.good.make@x", ["did you mean 'plugpkg.good:make'?"]),  # what is wrong before the label too
]


@pytest.mark.parametrize(("name", "phrases"), LABEL_ERRORS, ids=[e[1][0][:24] for e in LABEL_ERRORS])
def test_a_malformed_or_misplaced_label_says_what_a_label_is_and_where_it_goes(plugins, small, tmp_path, capsys,
                                                                              name, phrases):
    with pytest.raises(PluginNotFoundError) as caught:
        get_controller(name)
    for phrase in (*phrases, "package.module:factory@"):  # each says where a label goes
        assert phrase in str(caught.value)
    assert main(["run", name, "--scenario", str(small), "--trials", "1", "--out", str(tmp_path / "o"),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert phrases[0] in err and "Traceback" not in err and not (tmp_path / "o" / "trials.csv").exists()


def test_an_entry_point_or_a_policy_file_takes_no_label(plugins, tmp_path):
    _declare(plugins, "plugdist", "1.0", ["test-hold = plugpkg.good:make"])
    with pytest.raises(PluginNotFoundError, match="test-hold is an entry point.*label the plug-in it declares, "
                                                  "plugpkg.good:make@x"):
        get_controller("test-hold@x")
    model = tmp_path / "model.onnx"
    model.write_bytes(b"not read: the label is refused first")
    with pytest.raises(WbcError, match=f"a label means nothing there: name it onnx:{model}$"):
        get_controller(f"onnx:{model}@x")
    policy = tmp_path / "policy"
    policy.with_suffix(".npz").write_bytes(b"")
    with pytest.raises(WbcError, match=f"a policy file takes no settings.*name it policy:{policy}$"):
        get_controller(f"policy:{policy}@x")


def test_a_plugin_named_twice_is_told_to_label_each_setting(plugins, small, capsys):
    assert main(["compare", "plugpkg.good:make", "plugpkg.good:make", "--scenario", str(small)]) == 2
    err = capsys.readouterr().err
    assert "plugpkg.good:make named more than once" in err
    assert ("wbc compare plugpkg.good:make@A plugpkg.good:make@B --controller-config plugpkg.good:make@A=a.toml "
            "--controller-config plugpkg.good:make@B=b.toml") in err
    assert main(["compare", "stand", "stand", "--scenario", str(small)]) == 2
    assert "label" not in capsys.readouterr().err  # the registry's controllers take none


def test_a_labelled_plugin_is_checked_and_played_on_the_robot_protocol_by_its_name(plugins, small, tmp_path,
                                                                                  monkeypatch, capsys):
    import json

    config = tmp_path / "gains.toml"
    config.write_text("leg_kp = 50.0\n")
    assert main(["check-controller", SOFT, "--controller-config", str(config), "--robot", "a1-wx200",
                 "--seconds", "0.2", "--json"]) == 0
    check = json.loads(capsys.readouterr().out)
    assert check["controller"] == SOFT and check["passed"]
    monkeypatch.chdir(tmp_path)  # hw run's default results directory is under runs/ here
    assert main(["hw", "run", SOFT, "--controller-config", str(config), "--scenario", str(small), "--trial", "0",
                 "--sim", "--seconds", "0.5"]) == 0
    (out,) = (tmp_path / "runs").iterdir()
    assert out.name.startswith("hw-small-plugpkg.good_make@soft-")
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.controller == SOFT
    assert json.loads((out / "run.json").read_text())["controllers"][SOFT]["plugin"]["target"] == "plugpkg.good:make"


def test_two_names_whose_episodes_would_share_a_folder_are_refused_before_anything_plays(small, tmp_path):
    # '@' and ':' are both written '_' in a folder's name
    with pytest.raises(WbcError, match=r"would store their episodes in one folder, episodes/pkg.mod_make_x "):
        ArenaConfig(controllers=("pkg.mod:make@x", "pkg.mod:make_x"), scenario=small, out_dir=tmp_path / "o",
                    save_episodes=True)
    ArenaConfig(controllers=("pkg.mod:make@x", "pkg.mod:make_x"), scenario=small, out_dir=tmp_path / "o")


def test_two_labels_that_differ_only_in_case_are_refused_with_save_episodes(small, tmp_path):
    # one folder on a case-insensitive file system (macOS, Windows), where one would overwrite the other's episodes
    with pytest.raises(WbcError, match=r"^pkg.mod:make@H8 and pkg.mod:make@h8 would store their episodes in one "
                                       r"folder, episodes/pkg.mod_make_h8 and episodes/pkg.mod_make_H8, one folder "
                                       r"where case is not told apart"):
        ArenaConfig(controllers=("pkg.mod:make@H8", "pkg.mod:make@h8"), scenario=small, out_dir=tmp_path / "o",
                    save_episodes=True)
    ArenaConfig(controllers=("pkg.mod:make@H8", "pkg.mod:make@h8"), scenario=small, out_dir=tmp_path / "o")


def test_two_labels_of_one_plugin_are_viewed_side_by_side(plugins, small, tmp_path, monkeypatch, capsys):
    soft, stiff = tmp_path / "soft.toml", tmp_path / "stiff.toml"
    soft.write_text("leg_kp = 30.0\n")
    stiff.write_text("leg_kp = 80.0\n")
    monkeypatch.chdir(tmp_path)  # the page's default name, in the working directory
    assert main(["view", SOFT, STIFF, "--scenario", str(small), "--trial", "0", "--controller-config",
                 f"{SOFT}={soft}", "--controller-config", f"{STIFF}={stiff}"]) == 0
    (page,) = tmp_path.glob("ab-*.html")
    assert page.name == "ab-plugpkg.good_make_soft-plugpkg.good_make_stiff-small-soft-s0-t0.html"
    assert f"{SOFT} vs {STIFF} (ghost)" in capsys.readouterr().out
