"""Ray cluster runs: a worker checks it runs what the driver recorded; the cluster's failures stop the run, plainly.

A worker node with another wbc or package version, or a controller file that differs or is missing there, is the
cluster's fault, not the controller's: the run stops with a message naming the node, the file or package and both
values, and no trial is recorded for it (`wbc.arena.worker_check`). The tests with a real Ray start one in this
process (node address 127.0.0.1; Ray 2.60's servers listen on every interface all the same: docs/limitations.md)
and stop it after; those of Ray's failures that no test can cause at will play against `FakeRay`.
"""

import dataclasses
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
import types
from pathlib import Path

import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.arena import executors, worker_check
from wbc.arena.compare import ArenaConfig, plan_arena, play_arena, run_arena
from wbc.arena.executors import RayExecutor, TrialTask
from wbc.arena.trial_record import TrialRecord
from wbc.arena.worker_check import Expectation, check_worker, fingerprint
from wbc.control.registry import get_controller
from wbc.control.spec import SourceFile, sha256_file
from wbc.errors import ClusterError, ConfigError
from wbc.scenario import load_scenario

STANDS = STAND_PLUGIN.format(doc="The stand hold.", reset="pass", act="pass", counters="return {}")


class _Lost(Exception):
    """A Ray error of the cluster's (the fake's stand-in for ``ray.exceptions.NodeDiedError``)."""


class FakeRay:
    """Enough of the ``ray`` module for `RayExecutor`: a task's record is ``("played", task)``, or the error queued
    for it (`fail`: a list of exceptions per trial index, raised one per attempt)."""

    def __init__(self, fail=None):
        self.fail = fail or {}
        self.attempts = []
        self.inits = []
        self.initialized = False
        names = ("WorkerCrashedError", "OutOfMemoryError", "RayTaskError", "ObjectLostError", "RaySystemError",
                 "RuntimeEnvSetupError", "LocalRayletDiedError")
        self.exceptions = types.SimpleNamespace(NodeDiedError=_Lost,
                                                **{n: type(n, (Exception,), {}) for n in names})

    def is_initialized(self):
        return self.initialized

    def init(self, **kwargs):
        self.inits.append(kwargs)
        self.initialized = True

    def shutdown(self):
        self.initialized = False

    def cluster_resources(self):
        return {"CPU": 1.0}

    def remote(self, **options):
        fake = self

        class Remote:
            def remote(self, task, *rest):
                fake.attempts.append(task)
                return len(fake.attempts) - 1

        return lambda fn: Remote()

    def wait(self, refs, num_returns=1):
        return refs[:num_returns], refs[num_returns:]

    def get(self, ref):
        task = self.attempts[ref]
        queued = self.fail.get(task.trial.index, [])
        if queued:
            raise queued.pop(0)
        return ("played", task), None  # the record, and no episode to save

    def cancel(self, ref, force=False):
        pass


def _tasks(scenario, n):
    spec = get_controller("stand")
    return [TrialTask(trial=t, controller=spec) for t in load_scenario(scenario).trials(["soft"], [0], n)]


def test_a_node_lost_under_a_trial_plays_it_again_and_keeps_its_record(scenario, monkeypatch):
    fake = FakeRay(fail={0: [_Lost("node died"), _Lost("node died")]})
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    got = list(RayExecutor().run(_tasks(scenario, 2)))
    assert sorted(t.trial.index for _, t in got) == [0, 1] and all(what == "played" for what, _ in got)
    assert [t.trial.index for t in fake.attempts].count(0) == 3  # the third time it gave its record


def test_a_cluster_that_keeps_failing_a_trial_stops_the_run_without_a_controller_error(scenario, monkeypatch):
    fake = FakeRay(fail={1: [_Lost("\x1b[31mnode 5e1f died\x1b[0m")] * 3})
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    got = []
    with pytest.raises(ClusterError) as err:
        got.extend(RayExecutor().run(_tasks(scenario, 2)))
    said = str(err.value)
    assert "failed the task of controller stand, band soft, seed 0, trial 1 3 times" in said
    assert "node 5e1f died" in said and "\x1b[" not in said and "--resume" in said
    assert [t.trial.index for _, t in got] == [0]  # the trial before it kept; none recorded for the lost one


def test_ray_address_in_the_environment_is_the_cluster_played_on(scenario, monkeypatch, capsys):
    # as under `ray job submit`: RAY_ADDRESS set, no --address; the head is a socket on this machine that listens
    fake = FakeRay()
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    with socket.socket() as head:
        head.bind(("127.0.0.1", 0))
        head.listen()
        address = f"127.0.0.1:{head.getsockname()[1]}"
        monkeypatch.setenv("RAY_ADDRESS", address)
        executor = RayExecutor()
        assert len(list(executor.run(_tasks(scenario, 1)))) == 1
    assert fake.inits[0]["address"] == address and "num_cpus" not in fake.inits[0]
    assert f"cluster at {address} that RAY_ADDRESS names" in capsys.readouterr().err
    assert executor.describe() == f"ray (cluster at {address}, from RAY_ADDRESS)"
    assert RayExecutor("auto").describe() == "ray (cluster at auto, from --address)"
    with pytest.raises(ConfigError, match=f"--workers 2 with RAY_ADDRESS={address} set"):
        RayExecutor(None, 2)


def test_a_ray_started_here_is_a_new_local_one_whatever_cluster_this_machine_runs(scenario, monkeypatch):
    """Without an address, ``ray.init`` would join the cluster a `ray start` left on this machine
    (``/tmp/ray/ray_current_cluster``), and then refuse the CPU count it is given: wbc asks for a new local Ray."""
    fake = FakeRay()
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert len(list(RayExecutor(None, 1).run(_tasks(scenario, 1)))) == 1
    assert fake.inits[0]["address"] == "local" and fake.inits[0]["num_cpus"] == 1


def test_an_address_that_cannot_be_reached_is_refused_before_the_results_directory(scenario, tmp_path,
                                                                                  monkeypatch):
    fake = FakeRay()
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    with socket.socket() as closed:  # a port nothing listens on: bound, never listened to
        closed.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{closed.getsockname()[1]}"
        with pytest.raises(ClusterError, match=f"cannot reach the Ray cluster at {address} \\(--address\\)"):
            run_arena(ArenaConfig(controllers=("stand",), scenario=scenario, trials=1, out_dir=tmp_path / "out",
                                  executor="ray", address=address, progress=False))
    assert fake.inits == [] and not (tmp_path / "out").exists()  # the same command runs again once it is fixed


class _Refused(Exception):
    """What ``ray.init`` raises for a cluster that refuses this driver (another authentication token)."""


def test_a_cluster_that_refuses_the_connection_is_said_plainly_before_the_results_directory(scenario, tmp_path,
                                                                                            monkeypatch):
    fake = FakeRay()

    def refuse(**kwargs):
        raise _Refused("\x1b[31mauthentication token mismatch\x1b[0m")

    fake.init = refuse
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    with pytest.raises(ClusterError) as err:
        run_arena(ArenaConfig(controllers=("stand",), scenario=scenario, trials=1, out_dir=tmp_path / "out",
                              executor="ray", address="auto", progress=False))
    assert str(err.value) == ("cannot connect to the Ray cluster at auto (--address): _Refused: authentication token "
                              "mismatch; nothing was played")
    assert not (tmp_path / "out").exists()


def test_a_fault_on_a_ray_worker_is_raised_as_itself_without_colour_codes(scenario, monkeypatch):
    fake = FakeRay()
    fault = fake.exceptions.RayTaskError("\x1b[36mray::_run_checked()\x1b[39m (pid=1)\nValueError: a bug")
    fault.cause = ValueError("a bug")
    fake.fail = {0: [fault]}
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    with pytest.raises(ValueError, match="a bug") as err:
        list(RayExecutor().run(_tasks(scenario, 1)))
    assert err.value.__notes__ == ["raised on a Ray worker:\nray::_run_checked() (pid=1)\nValueError: a bug"]


def test_a_trial_time_limit_is_refused_on_ray_before_any_task_is_sent(scenario, monkeypatch):
    fake = FakeRay()
    monkeypatch.setattr(executors, "require", lambda *a: fake)
    tasks = [dataclasses.replace(t, time_limit_s=10.0) for t in _tasks(scenario, 1)]
    with pytest.raises(ConfigError, match="leave --trial-time-limit out with --executor ray"):
        list(RayExecutor().run(tasks))
    assert fake.attempts == []


@pytest.fixture
def scenario(tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SHORT_SCENARIO)
    return path


@pytest.fixture(scope="module")
def local_ray():
    """A Ray in this process, on 127.0.0.1 with one CPU; its workers see no PYTHONPATH set by a test."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=1, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False,
             configure_logging=False)
    try:
        yield ray
    finally:
        ray.shutdown()


def test_a_worker_refuses_a_controller_file_that_differs_or_is_missing(tmp_path):
    weights = tmp_path / "pi.onnx"
    weights.write_bytes(b"the driver's weights")
    recorded = sha256_file(weights)
    check_worker(Expectation(environment=fingerprint(), files=((str(weights), recorded),)))  # the same: it plays
    weights.write_bytes(b"another export")
    with pytest.raises(ClusterError) as err:
        check_worker(Expectation(environment=fingerprint(), files=((str(weights), recorded),)))
    said = str(err.value)
    assert str(weights) in said and recorded in said and sha256_file(weights) in said
    assert worker_check.node_name() in said and "--resume" in said
    weights.unlink()
    with pytest.raises(ClusterError, match=f"has no controller file {weights}"):
        check_worker(Expectation(environment=fingerprint(), files=((str(weights), recorded),)))


def test_a_worker_finds_the_shipped_weights_in_its_own_wbc_package_wherever_it_is_installed(tmp_path, monkeypatch):
    """The shipped weights are recorded by their path within the wbc package: a node with the same wbc installed
    elsewhere (a container's /home/ray/wbc) plays `learned`; its sha256 is still checked there."""
    import shutil

    expected = worker_check.expectation(get_controller("learned"))
    shipped = [path for path, _ in expected.files if path.startswith("wbc-package:")]
    assert shipped and all(path.startswith("wbc-package:learned/weights/") for path in shipped)
    elsewhere = tmp_path / "home" / "ray" / "wbc"
    for path in shipped:
        source = worker_check._PACKAGE / path.split(":", 1)[1]
        target = elsewhere / path.split(":", 1)[1]
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
    monkeypatch.setattr(worker_check, "_PACKAGE", elsewhere)
    check_worker(expected)  # the same files, another install path: it plays
    damaged = elsewhere / shipped[0].split(":", 1)[1]
    damaged.write_bytes(damaged.read_bytes() + b"\0")
    with pytest.raises(ClusterError, match=f"has another controller file {damaged}"):
        check_worker(expected)


def test_a_worker_refuses_another_wbc_revision_or_package_version():
    env = dict(fingerprint())
    for what, other in (("wbc git revision", "0" * 40), ("package mujoco", "0.0.1")):
        driver = tuple((k, other if k == what else v) for k, v in env.items())
        with pytest.raises(ClusterError) as err:
            check_worker(Expectation(environment=driver))
        said = str(err.value)
        assert what in said and other in said and str(env[what]) in said and worker_check.node_name() in said


def test_a_worker_refuses_a_plugin_module_missing_from_the_drivers_path(tmp_path):
    missing = tmp_path / "nosuchpkg" / "mod.py"
    with pytest.raises(ClusterError, match=f"has no plug-in module nosuchpkg.mod file {missing}"):
        check_worker(Expectation(environment=fingerprint(), module=("nosuchpkg.mod", str(missing), "ab")))


def test_on_ray_a_controller_file_that_differs_on_the_worker_stops_the_run(local_ray, scenario, tmp_path):
    weights = tmp_path / "weights.bin"
    weights.write_bytes(b"what the worker reads")
    # the driver recorded another content for the file (it changed on the worker's disk)
    spec = dataclasses.replace(get_controller("stand"), files=(SourceFile(role="weights", path=str(weights),
                                                                           sha256="f" * 64),))
    trial = load_scenario(scenario).trials(["soft"], [0], 1)[0]
    with pytest.raises(ClusterError) as err:
        list(RayExecutor().run([TrialTask(trial=trial, controller=spec)]))
    said = str(err.value)
    assert str(weights) in said and "f" * 64 in said and sha256_file(weights) in said and "\x1b[" not in said


def test_on_ray_a_plugin_missing_on_the_worker_stops_the_run_and_records_no_trial(local_ray, plugin_package,
                                                                                   scenario, tmp_path):
    root = plugin_package("hiddenpkg", {"stands": STANDS})
    config = ArenaConfig(controllers=("hiddenpkg.stands:make",), scenario=scenario, trials=2,
                         out_dir=tmp_path / "out", executor="ray", progress=False)
    plan = plan_arena(config)
    plan.specs["hiddenpkg.stands:make"].provenance()  # as the run's record (run.json) reads it when it begins
    # then the worker's node lacks the module the driver found (a node with a disk of its own)
    module = root / "hiddenpkg" / "stands.py"
    module.rename(tmp_path / "elsewhere.py")
    with pytest.raises(ClusterError) as err:
        play_arena(plan)
    assert f"has no plug-in module hiddenpkg.stands file {module}" in str(err.value)
    assert TrialRecord.read_csv(tmp_path / "out" / "trials.csv") == []  # not the controller's error: nothing recorded
    (tmp_path / "elsewhere.py").rename(module)  # the node fixed: --resume plays the run's trials
    resumed = play_arena(plan_arena(dataclasses.replace(config, resume=True)))
    assert len(resumed.records) == 2
    assert not any(r.outcome == "controller_error" for r in resumed.records)


HANGS = STAND_PLUGIN.format(doc="The stand hold that hangs in its first tick, once it has left the file $STARTED.",
                            reset="pass",
                            act="open(__import__('os').environ['STARTED'], 'w').close()\n"
                                "            __import__('threading').Event().wait()",
                            counters="return {}")


def test_sigterm_on_ray_interrupts_the_run_as_on_the_local_pool(tmp_path):
    pytest.importorskip("ray")
    (tmp_path / "hangs.py").write_text(textwrap.dedent(HANGS).lstrip())
    (tmp_path / "short.toml").write_text(SHORT_SCENARIO)
    started = tmp_path / "started"
    env = dict(os.environ, STARTED=str(started))
    run = subprocess.Popen([sys.executable, "-m", "wbc.cli", "run", "hangs:make", "--scenario", "short.toml",
                            "--trials", "1", "--executor", "ray", "--workers", "1", "--out", "out"],
                           cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        while not started.exists():  # the trial plays in a Ray worker: Ray is started, its handlers installed
            if run.poll() is not None:
                pytest.fail(f"the run ended before its trial began: {run.stderr.read()}")
            time.sleep(0.2)
        run.send_signal(signal.SIGTERM)
        _, err = run.communicate(timeout=240)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 130, err
    assert "wbc: interrupted" in err and "--resume" in err


def test_on_ray_episodes_are_saved_by_the_driver_under_a_relative_out(local_ray, scenario, tmp_path, monkeypatch):
    # the worker's working directory is not the command's: it once wrote (or failed to write) the file there
    monkeypatch.chdir(tmp_path)
    result = run_arena(ArenaConfig(controllers=("stand",), scenario=scenario, trials=2, out_dir=Path("out"),
                                   executor="ray", save_episodes=True, progress=False))
    assert len(result.records) == 2
    saved = sorted(p.name for p in (tmp_path / "out" / "episodes" / "stand").iterdir())
    assert saved == ["soft-s0-t0.npz", "soft-s0-t1.npz"]
