"""Fuzz cases over the seven input surfaces of `wbc`: what files a case writes, and what it runs on them.

A `Case` is a few files written into an empty directory (bytes, a symbolic link, a directory, a copy of a results
directory) and one action: the ``wbc`` command line (``cli``) or a direct call of the loader the command would use
(see `fuzz.execute.CALLS`), with ``{d}`` in its arguments standing for the case's directory. `generate` draws the
cases of every surface from one seed (``numpy.random.default_rng(seed)``): fixed cases the issue names first, then
random mutations (`fuzz.mutations`) of the project's own files (`Materials`).

The surfaces:

- ``files``: any TOML input, and any file input, replaced by a nesting bomb, a link to ``/dev/zero``, a directory,
  non-UTF-8 or damaged bytes;
- ``scenario``: scenario values accepted and then played (1-second trials of ``stand``);
- ``never-acts``: controllers whose rate means they never act (an ONNX I/O file's ``rate_hz``, a policy's
  ``policy_dt``, a plug-in's ``rate_hz``);
- ``policy``: ``policy:PATH`` files (JSON and ``.npz``) and ``onnx:PATH`` models and their I/O files;
- ``episode``: stored episodes (``wbc view --episode``);
- ``results``: results directories resumed (``--resume``): edited, duplicated, torn rows, corrupt ``run.json``,
  directories where files belong;
- ``flags``: command-line values out of range.
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import mutations as m

SURFACES = ("files", "scenario", "never-acts", "policy", "episode", "results", "flags")
"""The surfaces of issue 29, in its order."""

REPO = Path(__file__).resolve().parents[2]
"""The checkout these tests live in: its scenarios and shipped weights are the seeds of every mutation."""

TINY_SCENARIO = '''\
[scenario]
name = "fuzz-tiny"
version = 1
description = "one second of standing on flat ground, pushed once (the fuzz campaign's scenario)"
robot = "a1-wx200"
duration_s = 1.0

[terrain]
kind = "flat"

[commands]
ramp_s = 0.1

[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.3, 0.4]
interval_s = [2.0, 3.0]
duration_s = 0.05
offset_m = 0.05

[[bands]]
name = "in"
push_force_n = [50.0, 80.0]
'''
"""A 1-second scenario: a trial of ``stand`` on it takes about a second to play."""

ONNX_JOINTS = [f"{leg}_{part}_joint" for part in ("hip", "thigh", "calf") for leg in ("FL", "FR", "RL", "RR")]
"""Isaac Lab's joint order for a Unitree quadruped: by joint type, then FL, FR, RL, RR."""
ONNX_IO_TEMPLATE = '''\
[policy]
robot = "a1-wx200"
arm_mode = "none"
rate_hz = 50.0
joints = {joints}

[observation]
history = {history}

[[observation.terms]]
name = "base_ang_vel"
scale = 0.25

[[observation.terms]]
name = "velocity_commands"
scale = [2.0, 2.0, 0.25]

[[observation.terms]]
name = "joint_pos_rel"

[[observation.terms]]
name = "last_action"

[action]
kind = "joint_position"
scale = 0.5
clip = 100.0

[pd]
kp = [30.0, 30.0, 30.0, 30.0, 40.0, 40.0, 40.0, 40.0, 50.0, 50.0, 50.0, 50.0]
kd = 1.5
'''
"""The I/O file of a 12-joint ONNX policy, its joints (``{joints}``, a TOML list) and history (``{history}``) left
to fill (tests/test_onnx_policy.py fills them too)."""
ONNX_IO = ONNX_IO_TEMPLATE.format(joints=json.dumps(ONNX_JOINTS), history=1)
"""`ONNX_IO_TEMPLATE` in Isaac Lab's joint order, one frame of history."""
ONNX_FRAME = 3 + 3 + 12 + 12

PLUGIN_CONFIG = 'gain = 1.0\nname = "hold"\n\n[limits]\nmax_torque = [20.0, 20.0]\n'
"""A ``--controller-config`` table."""

PLUGIN = '''\
"""A plug-in that holds the nominal posture at a fuzzed rate."""
from wbc.types import MotorCommand


class Hold:
    rate_hz = {rate}

    def __init__(self, desc):
        self.command = MotorCommand(q=desc.nominal_q.copy(), dq=desc.nominal_q * 0.0, kp=desc.nominal_q * 0.0 + 40.0,
                                    kd=desc.nominal_q * 0.0 + 1.0, tau=desc.nominal_q * 0.0)

    def reset(self):
        pass

    def act(self, state, command):
        return self.command

    def counters(self):
        return {{}}


def make(desc, config=None):
    return Hold(desc)
'''
"""A plug-in module whose controller's rate the never-acts surface fuzzes."""

POLICY = "a1-wx200-none"
"""The shipped policy whose files the policy surface mutates (`wbc/learned/weights/`)."""


@dataclass(frozen=True)
class Link:
    """A symbolic link to `target`."""

    target: str


@dataclass(frozen=True)
class Dir:
    """An empty directory."""


@dataclass(frozen=True)
class Tree:
    """A copy of the directory `source` (a seed results directory)."""

    source: str


@dataclass(frozen=True)
class Case:
    """One fuzz case.

    Attributes:
        surface: one of `SURFACES`.
        name: what was mutated, for the table of failures.
        files: (path relative to the case directory, content), written in order: bytes, `Link`, `Dir` or `Tree`.
        call: ``cli`` (``args`` is the ``wbc`` command line) or a loader name of `fuzz.execute.CALLS`.
        args: the command line or the loader's arguments, ``{d}`` standing for the case directory.
        out: with ``cli``: the results directory a valid run leaves, relative to the case directory.
        rows: the rows a valid run's ``trials.csv`` must hold.
        must_reject: the input breaks a rule the issue states (a negative clip, a value no run can use): accepting it
            is a silent failure even when nothing else looks wrong.
        in_process: the case may run inside the test process (it cannot start a long run or hold the process).
    """

    surface: str
    name: str
    files: tuple[tuple[str, object], ...]
    call: str
    args: tuple[str, ...]
    out: str | None = None
    rows: int | None = None
    must_reject: bool = False
    in_process: bool = True


@dataclass
class Materials:
    """The valid inputs every mutation starts from.

    Attributes:
        dir: where the shared files live (the tiny scenario the seed run recorded, by absolute path).
        results: a results directory written by ``wbc run stand --trials 2 --save-episodes`` on the tiny scenario
            (by the code under test), or None where the caller skips the surfaces that need it.
    """

    dir: Path
    results: Path | None = None
    scenarios: dict[str, str] = field(default_factory=dict)
    policy_json: dict = field(default_factory=dict)
    policy_arrays: dict[str, np.ndarray] = field(default_factory=dict)
    onnx_model: bytes = b""

    @property
    def tiny(self) -> Path:
        return self.dir / "tiny.toml"


def onnx_linear_model(weight: np.ndarray, bias: np.ndarray | None = None, *, input_name: str = "obs",
                      extra_input: bool = False) -> bytes:
    """An ONNX network ``actions = obs @ weight + bias`` (float32, batch of 1), optionally with a second, unused
    input (tests/test_onnx_policy.py builds its networks with it too)."""
    from onnx import TensorProto, helper, numpy_helper

    d, n = weight.shape
    bias = np.zeros(n) if bias is None else bias
    inputs = [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, [1, d])]
    if extra_input:
        inputs.append(helper.make_tensor_value_info("hidden", TensorProto.FLOAT, [1, 8]))
    graph = helper.make_graph(
        [helper.make_node("MatMul", [input_name, "w"], ["y"]), helper.make_node("Add", ["y", "b"], ["actions"])],
        "linear", inputs, [helper.make_tensor_value_info("actions", TensorProto.FLOAT, [1, n])],
        [numpy_helper.from_array(weight.astype(np.float32), "w"),
         numpy_helper.from_array(bias.astype(np.float32), "b")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def prepare_materials(dir: Path, results: Path | None = None) -> Materials:
    """Write the shared files into `dir` and read the project's own (scenarios, a shipped policy, an ONNX model)."""
    dir.mkdir(parents=True, exist_ok=True)
    (dir / "tiny.toml").write_text(TINY_SCENARIO)
    mat = Materials(dir=dir, results=results)
    mat.scenarios = {p.name: p.read_text() for p in sorted((REPO / "scenarios").glob("*.toml"))
                     if p.name != "published.toml"}
    weights = REPO / "wbc" / "learned" / "weights"
    mat.policy_json = json.loads((weights / f"{POLICY}.json").read_text())
    with np.load(weights / f"{POLICY}.npz") as z:
        mat.policy_arrays = {k: z[k] for k in z.files}
    try:
        mat.onnx_model = onnx_linear_model(np.zeros((ONNX_FRAME, 12)))
    except ImportError:  # without the onnx extra the ONNX cases are skipped
        mat.onnx_model = b""
    return mat


# -------------------------------------------------------------------------------------------------- the actions --

def _run_argv(scenario: str, *extra: str, controller: str = "stand", trials: int = 1) -> tuple[str, ...]:
    return ("run", controller, "--scenario", scenario, "--trials", str(trials), "--workers", "1", "--out", "{d}/out",
            "--quiet", *extra)


def _policy_files(meta: dict, arrays: dict[str, np.ndarray], *, npz: bytes | None = None):
    return (("p.json", json.dumps(meta, allow_nan=True).encode()),
            ("p.npz", npz if npz is not None else m.npz_bytes(arrays)))


def _one_second(text: str) -> str:
    """A scenario shortened to one second (its pushes moved inside it), so that its trial plays in a few seconds."""
    data = tomllib.loads(text)
    data["scenario"]["duration_s"] = 1.0
    data.get("commands", {})["ramp_s"] = min(data.get("commands", {}).get("ramp_s", 0.0), 0.2)
    if "pushes" in data:
        data["pushes"]["first_s"] = [0.3, 0.4]
    return m.dump_toml(data)


# ------------------------------------------------------------------------------------------------- the surfaces --

def _files_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """Any TOML input a nesting bomb; any file input a link to /dev/zero, a directory, damaged bytes."""
    targets = {  # kind -> (file name in the case dir, loader call, its args, valid bytes)
        "scenario": ("s.toml", "scenario", ("{d}/s.toml",), TINY_SCENARIO.encode()),
        "io": ("m.toml", "onnx", ("{d}/m.onnx", "{d}/m.toml"), ONNX_IO.encode()),
        "plugin-config": ("c.toml", "plugin_config", ("{d}/c.toml",), PLUGIN_CONFIG.encode()),
        "policy-json": ("p.json", "policy", ("{d}/p",), json.dumps(mat.policy_json).encode()),
        "policy-npz": ("p.npz", "policy", ("{d}/p",), None),
        "run.json": ("r/run.json", "results", ("{d}/r", str(mat.tiny)), None),
        "trials.csv": ("r/trials.csv", "results", ("{d}/r", str(mat.tiny)), None),
        "episode": ("r/episodes/stand/in-s0-t0.npz", "episode", ("{d}/r",), None),
    }
    if not mat.onnx_model:
        del targets["io"]
    if mat.results is None:
        for k in ("run.json", "trials.csv", "episode"):
            del targets[k]

    def base(kind: str) -> tuple:
        fname, call, args, _ = targets[kind]
        files: list = []
        if kind == "io":
            files.append(("m.onnx", mat.onnx_model))
        if kind.startswith("policy"):
            files += [f for f in _policy_files(mat.policy_json, mat.policy_arrays) if f[0] != fname]
        if call in ("results", "episode"):
            files.append(("r", Tree(str(mat.results))))
        return tuple(files), call, args

    def valid_bytes(kind: str) -> bytes:
        fname, _, _, data = targets[kind]
        if data is not None:
            return data
        if kind == "policy-npz":
            return m.npz_bytes(mat.policy_arrays)
        return (mat.results / fname[2:]).read_bytes()

    cases = []
    kinds = list(targets)
    toml_kinds = [k for k in kinds if targets[k][0].endswith(".toml")]
    fixed = []
    for k in toml_kinds:
        fixed += [(k, "500 nested [", m.nesting_bomb(500).encode()),
                  (k, "100000 nested [", m.nesting_bomb(100_000).encode()),
                  (k, "500 nested inline tables", m.nesting_bomb(500, kind="table").encode())]
    for k in kinds:
        fixed += [(k, "link to /dev/zero", Link("/dev/zero")), (k, "a directory", Dir())]
    fixed += [(k, "500 nested [ in JSON", ("[" * 500 + "]" * 500).encode()) for k in ("policy-json", "run.json")
              if k in targets]
    for kind, label, content in fixed:
        files, call, args = base(kind)
        cases.append(Case("files", f"{kind}: {label}", (*files, (targets[kind][0], content)), call, args))
    while len(cases) < n:
        kind = kinds[int(rng.integers(len(kinds)))]
        files, call, args = base(kind)
        data, label = m.mutate_bytes(rng, valid_bytes(kind))
        cases.append(Case("files", f"{kind}: {label}", (*files, (targets[kind][0], data)), call, args))
    # a few through the command line, as a user meets them
    cli = [Case("files", "cli: scenario 500 nested [", (("s.toml", m.nesting_bomb(500).encode()),), "cli",
                _run_argv("{d}/s.toml")),
           Case("files", "cli: scenario link to /dev/zero", (("s.toml", Link("/dev/zero")),), "cli",
                _run_argv("{d}/s.toml")),
           Case("files", "cli: policy json link to /dev/zero",
                (*[f for f in _policy_files(mat.policy_json, mat.policy_arrays) if f[0] != "p.json"],
                 ("p.json", Link("/dev/zero"))), "cli", ("check-controller", "policy:{d}/p", "--seconds", "0.1"))]
    return cases[: max(0, n - len(cli))] + cli


SCENARIO_FIXED: tuple[tuple[tuple, object, bool], ...] = (
    (("terrain", "kind"), "fractal", False),
    (("terrain", "base_wavelength_m"), 0.001, False),
    (("domain", "friction"), [1e-10, 1e-10], False),
    (("domain", "motor_strength"), [1e-10, 1e-10], False),
    (("domain", "payload_kg"), [20.0, 20.0], False),
    (("scenario", "duration_s"), 1e-300, False),
    (("pushes", "duration_s"), 1e-300, False),
    (("pushes", "offset_m"), 0.5, False),
    (("bands", 0, "push_force_n"), [5000.0, 5000.0], False),
    (("pushes", "interval_s"), [1e-300, 1e-300], False),
    (("scenario", "duration_s"), math.nan, True),
    (("scenario", "duration_s"), math.inf, True),
    (("domain", "friction"), [math.nan, math.nan], True),
)
"""(field, value, must be refused) the issue names, each applied to the tiny scenario."""


def _scenario_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """Scenario values accepted, then played: a 1-second trial of ``stand`` must be a valid run or a clean error."""
    tiny = tomllib.loads(TINY_SCENARIO)
    cases = []
    for path, value, reject in SCENARIO_FIXED:
        data = copy.deepcopy(tiny)
        data.setdefault(path[0], {})
        data = m.set_path(data, path, value)
        if path == ("terrain", "base_wavelength_m"):
            data["terrain"]["kind"] = "fractal"
        cases.append(_scenario_case(data, f"{'.'.join(map(str, path))}={value!r}", reject))
    seeds = [tiny] + [tomllib.loads(_one_second(t)) for t in mat.scenarios.values()]
    while len(cases) < n:
        seed = seeds[int(rng.integers(len(seeds)))]
        data, label = m.mutate_data(rng, seed)
        if rng.random() < 0.3:
            data, label2 = m.mutate_data(rng, data)
            label = f"{label}; {label2}"
        cases.append(_scenario_case(data, label, False))
    return cases


def _scenario_case(data: dict, label: str, reject: bool) -> Case:
    text = m.dump_toml(data).encode()
    # the campaign plays it; the in-process suite loads it, samples its trials and builds its ground
    return Case("scenario", label, (("s.toml", text),), "scenario_run", ("{d}/s.toml",), out="out",
                must_reject=reject)  # one trial per band: as many rows as the scenario has bands


NEVER_ACTS_RATES = (0.02, 1e-6, 0.0, -1.0, math.nan, math.inf, 1e-300, 1e9, 0.5, 2.0, 50.0, 1000.0)


def _never_acts_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """Controllers whose rate is too low to act in a trial (or not a rate at all) must be refused, not score 100 %."""
    cases = []
    for i, rate in enumerate(NEVER_ACTS_RATES):
        reject = not (math.isfinite(rate) and rate >= 1.0)  # slower than 1 Hz: it never acts in a trial
        mod = f"fuzzplug{i}_{int(rng.integers(1 << 30))}"
        plugin = ((f"{mod}.py", PLUGIN.format(rate=rate).encode()),)
        cases.append(Case("never-acts", f"plug-in rate_hz={rate!r}", plugin, "controller_run",
                          (f"{mod}:make", str(mat.tiny), ""), out="out", rows=1, must_reject=reject,
                          in_process=False))  # a plug-in's rate may be refused trial by trial: only a played run shows
        meta = dict(mat.policy_json, policy_dt=(1.0 / rate if rate not in (0.0,) and math.isfinite(rate) else rate))
        cases.append(Case("never-acts", f"policy_dt={meta['policy_dt']!r}", _policy_files(meta, mat.policy_arrays),
                          "controller_run", ("policy:{d}/p", str(mat.tiny), ""), out="out", rows=1,
                          must_reject=not (0.0 < meta["policy_dt"] <= 1.0)))
        if mat.onnx_model:
            data = tomllib.loads(ONNX_IO)
            data["policy"]["rate_hz"] = rate
            cases.append(Case("never-acts", f"io rate_hz={rate!r}",
                              (("m.onnx", mat.onnx_model), ("m.toml", m.dump_toml(data).encode())),
                              "controller_run", ("onnx:{d}/m.onnx", str(mat.tiny), "{d}/m.toml"), out="out", rows=1,
                              must_reject=reject))
    cases.append(Case("never-acts", "check-controller io rate_hz=1e-6",
                      (("m.onnx", mat.onnx_model),
                       ("m.toml", ONNX_IO.replace("rate_hz = 50.0", "rate_hz = 1e-6").encode())),
                      "cli", ("check-controller", "onnx:{d}/m.onnx", "--io", "{d}/m.toml", "--seconds", "0.2"),
                      must_reject=True, in_process=False))
    rng.shuffle(cases)
    return cases[:n]


POLICY_FIXED: tuple[tuple[str, object, bool], ...] = (
    ("policy_dt", 0.0, True), ("policy_dt", -0.02, True), ("policy_dt", math.nan, True),
    ("clip_actions", -1.0, True), ("clip_actions", 0.0, True), ("clip_actions", math.nan, True),
    ("normalizer_eps", -0.01, True), ("normalizer_eps", math.nan, True),
    ("action_scale", math.inf, True), ("action_scale", math.nan, True),
    ("num_actions", 2**40, True), ("hidden_dims", {"x": [1, {"y": 2}]}, True), ("obs_layout", [["ang_vel", -3]], True),
    ("kp", [math.nan] * 12, True), ("kd", [-1.0] * 12, True), ("default_q", [1e300] * 12, True),
    ("obs_scales", {"ang_vel": {"nested": [1, 2]}}, True),
)
"""(policy JSON key, value, must be refused) the issue names."""


def _policy_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """``policy:PATH`` files and ``onnx:PATH`` models: loaded, built and acted with, or refused cleanly."""
    meta, arrays = mat.policy_json, mat.policy_arrays
    cases = []

    def policy_case(label: str, meta2: dict, arrays2: dict, reject: bool, npz: bytes | None = None) -> Case:
        return Case("policy", label, _policy_files(meta2, arrays2, npz=npz), "policy", ("{d}/p",), must_reject=reject)

    for key, value, reject in POLICY_FIXED:
        cases.append(policy_case(f"json {key}={value!r}", dict(meta, **{key: value}), arrays, reject))
    neg = dict(arrays, obs_std=-arrays["obs_std"])
    cases.append(policy_case("npz obs_std negated", meta, neg, True))
    cases.append(policy_case("npz obs_std zero", meta, dict(arrays, obs_std=0.0 * arrays["obs_std"]), True))
    cases.append(policy_case("npz member claims 2^40 floats", meta, arrays, True,
                             npz=m.npz_huge_member(arrays, "policy/0/weight")))
    cases.append(policy_case("npz deflate bomb (2 GiB of zeros)", meta, arrays, True,
                             npz=m.npz_deflate_bomb(arrays, "obs_mean")))
    nan_weight = np.full_like(arrays["policy/0/weight"], np.nan)
    cases.append(policy_case("npz policy/0/weight NaN", meta, dict(arrays, **{"policy/0/weight": nan_weight}), True))
    if mat.onnx_model:
        extra = onnx_linear_model(np.zeros((ONNX_FRAME, 12)), extra_input=True)
        cases.append(Case("policy", "onnx model with an extra input", (("m.onnx", extra), ("m.toml", ONNX_IO.encode())),
                          "onnx", ("{d}/m.onnx", "{d}/m.toml"), must_reject=True))
        wrong = onnx_linear_model(np.zeros((ONNX_FRAME + 1, 12)))
        cases.append(Case("policy", "onnx model of another input size",
                          (("m.onnx", wrong), ("m.toml", ONNX_IO.encode())), "onnx", ("{d}/m.onnx", "{d}/m.toml"),
                          must_reject=True))
        cases.append(Case("policy", "onnx model NaN weights",
                          (("m.onnx", onnx_linear_model(np.full((ONNX_FRAME, 12), np.nan))),
                           ("m.toml", ONNX_IO.encode())), "onnx", ("{d}/m.onnx", "{d}/m.toml"), must_reject=True))
    io_data = tomllib.loads(ONNX_IO)
    keys = sorted(arrays)
    while len(cases) < n:
        roll = rng.random()
        if roll < 0.35:
            meta2, label = m.mutate_data(rng, meta)
            cases.append(policy_case(f"json {label}", meta2, arrays, False))
        elif roll < 0.6:
            key = keys[int(rng.integers(len(keys)))]
            a, label = m.mutate_array(rng, arrays[key])
            cases.append(policy_case(f"npz {key}: {label}", meta, dict(arrays, **{key: a}), False))
        elif roll < 0.7:
            data, label = m.mutate_bytes(rng, m.npz_bytes(arrays))
            cases.append(policy_case(f"npz bytes: {label}", meta, arrays, False, npz=data))
        elif mat.onnx_model and roll < 0.85:
            data, label = m.mutate_data(rng, io_data)
            files = (("m.onnx", mat.onnx_model), ("m.toml", m.dump_toml(data).encode()))
            cases.append(Case("policy", f"io {label}", files, "onnx", ("{d}/m.onnx", "{d}/m.toml")))
        elif mat.onnx_model:
            data, label = m.mutate_bytes(rng, mat.onnx_model)
            cases.append(Case("policy", f"onnx model bytes: {label}", (("m.onnx", data), ("m.toml", ONNX_IO.encode())),
                              "onnx", ("{d}/m.onnx", "{d}/m.toml")))
    return cases[:n]


def _episode_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """Stored episodes replayed (``wbc view --episode``): frames finite, poses unit quaternions, or a clean error."""
    if mat.results is None:
        return []
    rel = "r/episodes/stand/in-s0-t0.npz"
    with np.load(mat.results / rel[2:]) as z:
        ep = {k: z[k] for k in z.files}
    t, qpos = ep["t"], ep["qpos"]

    def case(label: str, arrays: dict | None = None, raw: bytes | None = None, reject: bool = False) -> Case:
        data = raw if raw is not None else m.npz_bytes(arrays)
        return Case("episode", label, (("r", Tree(str(mat.results))), (rel, data)), "episode", ("{d}/r",),
                    must_reject=reject)

    q0 = qpos.copy()
    q0[:, 3:7] = 0.0
    qn = qpos.copy()
    qn[5, :3] = np.nan
    t_nan, t_inf = t.copy(), t.copy()
    t_nan[3] = np.nan
    t_inf[-1] = np.inf
    cases = [case("t has a NaN", dict(ep, t=t_nan), reject=True), case("t has an inf", dict(ep, t=t_inf), reject=True),
             case("t longer than qpos", dict(ep, t=np.concatenate([t, t[-1] + 0.02 * np.arange(1, 11)])), reject=True),
             case("empty npz", {}, reject=True), case("NaN pose", dict(ep, qpos=qn), reject=True),
             case("zero quaternions", dict(ep, qpos=q0), reject=True),
             case("t decreasing", dict(ep, t=t[::-1].copy()), reject=True),
             case("control_dt 0", dict(ep, control_dt=np.float64(0.0)), reject=True),
             case("qpos 1e300", dict(ep, qpos=qpos * 1e300), reject=True),
             case("link to /dev/zero", raw=b"")]
    cases[-1] = Case("episode", "link to /dev/zero", (("r", Tree(str(mat.results))), (rel, Link("/dev/zero"))),
                     "episode", ("{d}/r",))
    keys = sorted(ep)
    while len(cases) < n:
        roll = rng.random()
        if roll < 0.6:
            key = keys[int(rng.integers(len(keys)))]
            a, label = m.mutate_array(rng, ep[key])
            cases.append(case(f"{key}: {label}", dict(ep, **{key: a})))
        elif roll < 0.8:
            key = keys[int(rng.integers(len(keys)))]
            cases.append(case(f"no {key}", {k: v for k, v in ep.items() if k != key}))
        else:
            data, label = m.mutate_bytes(rng, m.npz_bytes(ep))
            cases.append(case(f"bytes: {label}", raw=data))
    zero_quaternions = m.npz_bytes(dict(ep, qpos=q0))
    cli = [Case("episode", "cli: zero quaternions", (("r", Tree(str(mat.results))), (rel, zero_quaternions)), "cli",
                ("view", "--episode", "{d}/r", "--trial", "0", "--record", "{d}/v.html"), must_reject=True,
                in_process=False),
           Case("episode", "cli: t has a NaN", (("r", Tree(str(mat.results))), (rel, m.npz_bytes(dict(ep, t=t_nan)))),
                "cli", ("view", "--episode", "{d}/r", "--trial", "0", "--record", "{d}/v.html"), must_reject=True,
                in_process=False)]
    return cases[: max(0, n - len(cli))] + cli


def _csv_text(rows: list[list[str]]) -> bytes:
    buf = io.StringIO()
    csv.writer(buf).writerows(rows)
    return buf.getvalue().encode()


def _results_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """Results directories resumed: the finished run is plausible (rows unique, one scenario, values sane), or the
    directory is refused."""
    if mat.results is None:
        return []
    rows = list(csv.reader(io.StringIO((mat.results / "trials.csv").read_text())))
    header, row = rows[0], next(r for r in rows[1:] if r[rows[0].index("trial")] == "0")
    col = {name: i for i, name in enumerate(header)}
    run_json = json.loads((mat.results / "run.json").read_text())
    trials = _csv_text([header, row])  # trial 1 not stored: as if the run was stopped, so --resume plays it

    def edited(**cells: str) -> list[str]:
        r = list(row)
        for k, v in cells.items():
            r[col[k]] = v
        return r

    def case(label: str, files: tuple, reject: bool = False) -> Case:
        files = (("r", Tree(str(mat.results))), ("r/trials.csv", trials), *files)
        return Case("results", label, files, "results", ("{d}/r", str(mat.tiny)), out="r", rows=2,
                    must_reject=reject)

    def with_rows(label: str, body: list[list[str]], reject: bool = False) -> Case:
        return case(label, (("r/trials.csv", _csv_text([header, *body])),), reject)

    other_hash = edited(scenario_hash="0" * 64)
    cases = [
        case("non-UTF-8 byte in trials.csv", (("r/trials.csv", trials[:-20] + b"\xff\n"),)),
        case("run.json corrupt", (("r/run.json", b'{"config": {"controllers": ['),)),
        case("run.json config a list", (("r/run.json", json.dumps(dict(run_json, config=[1])).encode()),)),
        with_rows("a row with a missing cell", [row[:-1]]),
        with_rows("a row with an extra cell", [[*row, "1"]]),
        with_rows("success flipped against outcome", [edited(success="False")], True),
        with_rows("outcome fall, success True", [edited(outcome="fall")], True),
        with_rows("ttf=-5", [edited(ttf="-5")], True),
        with_rows("ttf=nan", [edited(ttf="nan")], True),
        with_rows("vlin_err=1e300", [edited(vlin_err="1e300")], True),
        with_rows("ticks=0 with success", [edited(ticks="0")], True),
        with_rows("duplicated row", [row, row], True),
        with_rows("row of another scenario hash", [other_hash], True),
        with_rows("trial index -1", [edited(trial="-1")], True),
        with_rows("seed 2^63", [edited(seed=str(2**63))], True),
        case("trials.csv is a directory", (("r/trials.csv", Dir()),)),
        case("run.json is a directory", (("r/run.json", Dir()),)),
        case("summary.json is a directory", (("r/summary.json", Dir()),)),
        case("report.md is a directory", (("r/report.md", Dir()),)),
        case("trials.csv links to /dev/zero", (("r/trials.csv", Link("/dev/zero")),)),
    ]
    numeric = [k for k in header if k not in ("controller", "scenario", "scenario_hash", "band", "outcome", "error",
                                              "backend", "metrics_source", "clamped_rows", "counters")]
    while len(cases) < n:
        roll = rng.random()
        if roll < 0.5:
            k = numeric[int(rng.integers(len(numeric)))]
            v = str(m.EXTREMES[int(rng.integers(len(m.EXTREMES)))])
            cases.append(with_rows(f"{k}={v}", [edited(**{k: v})]))
        elif roll < 0.7:
            k = header[int(rng.integers(len(header)))]
            v = ["", "x", "True", "-0", "1e999", "\x00"][int(rng.integers(6))]
            cases.append(with_rows(f"{k}={v!r}", [edited(**{k: v})]))
        elif roll < 0.85:
            data, label = m.mutate_data(rng, run_json)
            cases.append(case(f"run.json {label}", (("r/run.json", json.dumps(data).encode()),)))
        else:
            data, label = m.mutate_bytes(rng, trials)
            cases.append(case(f"trials.csv bytes: {label}", (("r/trials.csv", data),)))
    return cases[:n]


FLAG_CASES: tuple[tuple[str, tuple[str, ...], bool], ...] = (
    ("--workers 99999999999999999999999", ("--workers", "99999999999999999999999"), True),
    ("--workers 0", ("--workers", "0"), True),
    ("--workers -4", ("--workers", "-4"), True),
    ("--workers 100000", ("--workers", "100000"), True),
    ("--seeds 9223372036854775808", ("--seeds", "9223372036854775808"), True),
    ("--seeds 0", ("--seeds", "0"), True),
    ("--seeds -1", ("--seeds", "-1"), True),
    ("--trials 1000000000", ("--trials", "1000000000"), True),
    ("--trials 0", ("--trials", "0"), True),
    ("--trials -3", ("--trials", "-3"), True),
    ("--trials 99999999999999999999999", ("--trials", "99999999999999999999999"), True),
    # played once, with a warning: the records' check refuses a trial stored twice
    ("--band in --band in", ("--band", "in", "--band", "in"), False),
    ("--band nope", ("--band", "nope"), True),
    ("--max-consecutive-errors -1", ("--max-consecutive-errors", "-1"), True),
    ("--seeds 2", ("--seeds", "2"), False),
    ("--workers 2", ("--workers", "2"), False),
)
"""(label, options added to a 1-trial ``wbc run stand`` on the tiny scenario, must be refused)."""


def _flag_cases(rng: np.random.Generator, mat: Materials, n: int) -> list[Case]:
    """Command-line values out of range: a clean message (short, however long the value) or a valid run."""
    tiny = str(mat.tiny)
    cases = []
    for label, extra, reject in FLAG_CASES:
        argv = list(_run_argv(tiny))
        for i in range(0, len(extra) - 1, 2):  # later options win in argparse: the fuzzed value is the one used
            argv += [extra[i], extra[i + 1]]
        cases.append(Case("flags", f"run {label}", (), "cli", tuple(argv), out="out", must_reject=reject,
                          rows=None))
    cases.append(Case("flags", "run --out an existing file", (("f", b"x"),), "cli",
                      ("run", "stand", "--scenario", tiny, "--trials", "1", "--workers", "1", "--out", "{d}/f",
                       "--quiet"), must_reject=True))
    for value, reject in (("inf", True), ("1e6", True), ("nan", True), ("-1", True), ("0", True), ("1e-300", False),
                          ("0.1", False)):
        cases.append(Case("flags", f"check-controller --seconds {value}", (), "cli",
                          ("check-controller", "stand", "--robot", "a1-wx200", "--seconds", value),
                          must_reject=reject))
    if mat.results is not None:
        for value, reject in (("inf", True), ("nan", True), ("0", True), ("-5", True), ("1e300", True),
                              ("10", False)):
            cases.append(Case("flags", f"view --fps {value}", (("r", Tree(str(mat.results))),), "cli",
                              ("view", "--episode", "{d}/r", "--trial", "0", "--record", "{d}/v.html", "--fps", value),
                              must_reject=reject))
        for value in ("-1", "99999999999999999999999", "2"):
            cases.append(Case("flags", f"view --trial {value}", (("r", Tree(str(mat.results))),), "cli",
                              ("view", "--episode", "{d}/r", "--trial", value, "--record", "{d}/v.html"),
                              must_reject=True))
    cases.append(Case("flags", "view --speed nan", (), "cli",
                      ("view", "stand", "--scenario", tiny, "--trial", "0", "--record", "{d}/v.html", "--speed",
                       "nan", "--duration", "0.2"), must_reject=True))
    huge = "9" * 5000
    cases.append(Case("flags", "run --band of 5000 characters", (), "cli", _run_argv(tiny, "--band", huge),
                      must_reject=True))
    cases.append(Case("flags", "check-controller --robot of 5000 characters", (), "cli",
                      ("check-controller", "stand", "--robot", huge, "--seconds", "0.1"), must_reject=True))
    cases.append(Case("flags", "run a controller name of 5000 characters", (), "cli",
                      _run_argv(tiny, controller="x" * 5000), must_reject=True))
    pool = [("--trials", v) for v in ("2", "-0", "1e3", "nan", str(2**63), "0x10")] + \
           [("--seeds", v) for v in ("1", "3", str(2**31), "-2")] + [("--workers", v) for v in ("1", "-1", str(2**62))]
    while len(cases) < n:
        opt, value = pool[int(rng.integers(len(pool)))]
        cases.append(Case("flags", f"run {opt} {value}", (), "cli", _run_argv(tiny, opt, value), out="out",
                          must_reject=_reject_flag(opt, value)))
    return cases[:n]


def _reject_flag(opt: str, value: str) -> bool:
    try:
        v = int(value)
    except ValueError:
        return True  # argparse refuses it: a clean usage error
    return not (1 <= v <= {"--trials": 100_000, "--seeds": 10_000, "--workers": 1024}[opt])


GENERATORS = {"files": _files_cases, "scenario": _scenario_cases, "never-acts": _never_acts_cases,
              "policy": _policy_cases, "episode": _episode_cases, "results": _results_cases, "flags": _flag_cases}


def generate(seed: int, total: int, mat: Materials, *, surfaces: tuple[str, ...] = SURFACES) -> list[Case]:
    """About `total` cases, spread evenly over `surfaces`, drawn from `seed`."""
    per = max(1, total // len(surfaces))
    cases: list[Case] = []
    for surface in surfaces:  # each surface its own stream: a surface's cases do not depend on which others run
        cases += GENERATORS[surface](np.random.default_rng([seed, SURFACES.index(surface)]), mat, per)
    return cases
