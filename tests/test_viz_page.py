"""The trial page: time plots and event marks beside the scene, A / B on one trial, and (with Chromium) the page."""

import base64
import dataclasses
import json
import re
import shutil
import subprocess

import numpy as np
import pytest
import umsgpack

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.episode import Episode
from wbc.arena.sim_trial import run_trial
from wbc.cli.main import main
from wbc.errors import ConfigError
from wbc.scenario import ScenarioError, check_published
from wbc.scenario.scenario import load_scenario
from wbc.types import VelocityCommand
from wbc.viz.errors import ViewerError
from wbc.viz.page import read_page_data
from wbc.viz.recording import GHOST_COLOR
from wbc.viz.replay import load_stored_episode
from wbc.viz.signals import PLOTS, TrialSignals
from wbc.viz.view import ViewConfig, replay_ab, replay_episode, view_ab, view_trial

# One push at 0.5 s for 0.1 s in a 1.5 s trial; the "hard" band's push topples a robot that only stands.
PAGE = """
[scenario]
name = "pagetest"
version = 1
description = "a short push for the trial page tests"
robot = "a1-wx200"
duration_s = 1.5

[terrain]
kind = "flat"

[commands]
ramp_s = 0.3
[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.5, 0.5]
interval_s = [5.0, 5.0]
duration_s = 0.1
offset_m = 0.1

[[bands]]
name = "soft"
push_force_n = [150.0, 150.0]

[[bands]]
name = "hard"
push_force_n = [400.0, 400.0]
"""

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    path = tmp_path_factory.mktemp("scn") / "pagetest.toml"
    path.write_text(PAGE)
    return path


@pytest.fixture(scope="module")
def page(scenario, tmp_path_factory):
    """A recorded trial page of the standing controller: (html path, page data, trial)."""
    trial = load_scenario(scenario).trial("soft", 0, 0)
    out = tmp_path_factory.mktemp("page") / "trial.html"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(out.parent)  # MuJoCo may write its log here
        view_trial(trial, "stand", ViewConfig(live=False, record=out))
    return out, read_page_data(out.read_text()), trial


@pytest.fixture(scope="module")
def ab_page(scenario, tmp_path_factory):
    """An A / B page of mpc against stand on the hard band (stand falls): (html path, result)."""
    trial = load_scenario(scenario).trial("hard", 0, 0)
    out = tmp_path_factory.mktemp("ab") / "ab.html"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(out.parent)  # MuJoCo may write its log here
        return out, view_ab(trial, ("mpc", "stand"), ViewConfig(live=False), out)


def _commands(html: str) -> list[dict]:
    block = re.search(r"var wbcCommands = \[(.*?)\];", html, re.S)
    assert block, "no embedded command list"
    return [umsgpack.unpackb(base64.b64decode(s)) for s in re.findall(r'"([A-Za-z0-9+/=]+)"', block.group(1))]


def _values(plot: dict, line: str) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in plot["lines"][line]], dtype=float)


def test_trial_page_holds_plots_with_data_and_event_marks(page):
    path, data, trial = page
    html = path.read_text()
    assert not re.search(r"""(src|href)\s*=\s*["']https?:""", html)  # one file, nothing fetched
    assert "window.wbcPage" in html and "wbc-plots" in html
    assert data["order"] == list(PLOTS) and data["duration"] == pytest.approx(trial.duration_s)
    (run,) = data["runs"]
    assert run["name"] == "stand"
    t = np.array(run["t"])
    assert len(t) > 50 and np.all(np.diff(t) > 0)
    plots = run["plots"]
    for key in ("attitude", "height", "velocity", "yaw_rate", "foot_forces", "torques", "arm_momentum"):
        assert key in plots, f"no {key} plot"
        for name, values in plots[key]["lines"].items():
            assert len(values) == len(t), f"{key}/{name}: {len(values)} values for {len(t)} samples"
        assert any(v is not None for vs in plots[key]["lines"].values() for v in vs), f"{key} holds no data"
    assert "mpc_com" not in plots  # a standing controller has no plan
    # the robot stands: height about its nominal, the feet carry its weight, the torques stay under their limits
    height = _values(plots["height"], "height")
    assert 0.2 < np.nanmedian(height) < 0.45
    weight = sum(_values(plots["foot_forces"], leg) for leg in ("FR", "FL", "RR", "RL"))
    assert 80.0 < np.nanmedian(weight) < 250.0
    torques = np.array([_values(plots["torques"], n) for n in plots["torques"]["lines"]])
    assert np.nanmax(np.abs(torques)) <= 1.0 + 1e-3 and torques.shape[0] == 15
    # the push: marked at its start for its duration, its angular impulse about the CoM grows only while it acts
    (push,) = [m for m in run["marks"] if m["kind"] == "push"]
    assert push["t"] == pytest.approx(trial.pushes[0].start, abs=1e-3)
    assert push["d"] == pytest.approx(trial.pushes[0].duration)
    impulse = np.linalg.norm([_values(plots["arm_momentum"], f"push H{a}") for a in "xyz"], axis=0)
    before, after = impulse[t < push["t"]], impulse[t > push["t"] + push["d"] + 0.05]
    assert np.all(before == 0.0) and np.all(after > 0.0)


def test_the_height_plot_says_it_is_the_world_z(page):
    # it was titled and documented as the height above the ground under the trunk, which it is not on rough ground
    _, data, _ = page
    title = data["runs"][0]["plots"]["height"]["title"]
    assert title == "trunk height (world z)"


def test_mpc_page_plots_its_prediction_against_what_happened(scenario, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log here
    trial = dataclasses.replace(load_scenario(scenario).trial("soft", 0, 0), duration_s=0.3)
    out = tmp_path / "mpc.html"
    view_trial(trial, "mpc", ViewConfig(live=False, record=out))
    plot = read_page_data(out.read_text())["runs"][0]["plots"]["mpc_com"]
    plan, com = _values(plot, "plan z"), _values(plot, "CoM z")
    assert np.count_nonzero(np.isfinite(plan)) > 5
    both = np.isfinite(plan) & np.isfinite(com)
    assert np.all(np.abs(plan[both] - com[both]) < 0.1)  # a prediction of the same CoM, not another quantity


def test_fall_and_safety_events_are_marked(scenario, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log here
    # a stored-episode run: its fall (and any safety transition) becomes a mark on the timeline
    trial = load_scenario(scenario).trial("hard", 0, 0)
    record, episode = run_trial(trial, "stand")
    assert not record.success, "the hard band's push no longer topples a standing robot: pick a stronger one"
    signals = TrialSignals.of_episode("stand", episode)
    kinds = [m.kind for m in signals.marks]
    assert kinds.count("fall") == 1 and kinds.count("push") == 1
    fall = next(m for m in signals.marks if m.kind == "fall")
    assert fall.t == pytest.approx(episode.fall_time_s)
    data = signals.thinned(25.0).to_json()
    assert len(data["t"]) <= 25.0 * trial.duration_s + 2
    assert {m["kind"] for m in data["marks"]} == {"push", "fall"}


def test_ab_page_holds_two_robots_and_marks_falls_and_divergence(ab_page):
    out, result = ab_page
    html = out.read_text()
    assert result.names == ("mpc", "stand")
    assert result.fall_s[0] is None and result.fall_s[1] is not None, "expected mpc to stand and stand to fall"
    assert result.divergence_s is not None and result.divergence_s <= result.fall_s[1]
    commands = _commands(html)
    (anim,) = [c for c in commands if c["type"] == "set_animation"]
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    for root in ("/meshcat/wbc/robot/root_joint", "/meshcat/ghost0/wbc/robot/root_joint"):
        pos = next(t for t in clips[root]["tracks"] if t["name"] == ".position")
        assert len(np.frombuffer(pos["times"].data, dtype="<f4")) > 20, f"{root} does not move"
    # the ghost is translucent, and its ground is not drawn twice
    colors = [c for c in commands if c["type"] == "set_property" and c["property"] == "color"]
    assert colors and all(c["path"].startswith("/meshcat/ghost0/wbc/") for c in colors)
    assert all(c["value"][3] == pytest.approx(GHOST_COLOR[3]) for c in colors)
    data = read_page_data(html)
    assert [r["name"] for r in data["runs"]] == ["mpc", "stand"]
    assert any(m["kind"] == "fall" for m in data["runs"][1]["marks"])
    assert not any(m["kind"] == "fall" for m in data["runs"][0]["marks"])
    assert [m["kind"] for m in data["marks"]] == ["divergence"]
    for run in data["runs"]:
        assert run["plots"]["attitude"]["lines"]["roll"], f"{run['name']} has no attitude"


def test_cli_view_ab_and_stored_episodes(scenario, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log here
    out = tmp_path / "ab.html"
    assert main(["view", "stand", "stand-locked", "--scenario", str(scenario), "--trial", "0", "--duration", "0.6",
                 "--record", str(out), "--at", "0.4"]) == 0
    said = capsys.readouterr().out
    assert "stand: survived" in said and f"{out.resolve().as_uri()}#t=0.4" in said
    assert [r["name"] for r in read_page_data(out.read_text())["runs"]] == ["stand", "stand-locked"]
    # the same from stored episodes (`wbc run --save-episodes`)
    results = tmp_path / "r"
    run_arena(ArenaConfig(controllers=("stand", "stand-locked"), scenario=scenario, trials=1, out_dir=results,
                          workers=1, progress=False, save_episodes=True))
    first, second = (load_stored_episode(results, 0, controller=c) for c in ("stand", "stand-locked"))
    ab = replay_ab(first, second, ViewConfig(live=False), tmp_path / "replay-ab.html")
    data = read_page_data(ab.recording.read_text())
    assert [r["name"] for r in data["runs"]] == ["stand", "stand-locked"]
    assert all(len(r["t"]) > 20 and any(m["kind"] == "push" for m in r["marks"]) for r in data["runs"])
    # a stored single run gets the trial page too, with what an episode holds
    single = replay_episode(first, ViewConfig(live=False, record=tmp_path / "one.html"))
    plots = read_page_data(single.recording.read_text())["runs"][0]["plots"]
    assert {"attitude", "height", "velocity", "yaw_rate"} <= set(plots)


def test_cli_view_ab_names_its_page_from_names_that_hold_path_separators(scenario, tmp_path, capsys, monkeypatch):
    """Without --record the page is ab-A-B-SCENARIO-BAND-sSEED-tI.html here, a path's separators made ``_``."""
    from wbc.learned.policy.shipped import shipped_weights
    from wbc.robots.registry import get_robot

    monkeypatch.chdir(tmp_path)
    policy = f"policy:{shipped_weights(get_robot('a1-wx200', 'locked'))}"
    assert main(["view", "stand", policy, "--scenario", str(scenario), "--trial", "0", "--duration", "0.2"]) == 0
    (page,) = tmp_path.glob("ab-*.html")
    assert page.name == f"ab-stand-{re.sub(r'[^A-Za-z0-9._-]+', '_', policy)}-pagetest-soft-s0-t0.html"
    assert page.resolve().as_uri() in capsys.readouterr().out
    # another band or seed of the same trial index is another page: neither overwrites the other
    for more in (["--band", "hard"], ["--seed", "1"]):
        assert main(["view", "stand", policy, "--scenario", str(scenario), "--trial", "0", "--duration", "0.2",
                     *more]) == 0
    assert {p.name.split("-pagetest-")[1] for p in tmp_path.glob("ab-*.html")} == {
        "soft-s0-t0.html", "hard-s0-t0.html", "soft-s1-t0.html"}


def test_cli_view_exports_the_trial_and_says_where_the_recording_time_went(scenario, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log here
    out, toml = tmp_path / "t.html", tmp_path / "t.toml"
    assert main(["view", "stand", "--scenario", str(scenario), "--band", "hard", "--trial", "0", "--duration", "0.8",
                 "--record", str(out), "--export-scenario", str(toml)]) == 0
    said = capsys.readouterr().out
    exported = load_scenario(toml)
    assert f"exported scenario {exported.name!r} (unpublished, hash {exported.hash[:12]})" in said
    assert f"wbc run stand --scenario {toml} --trials 1" in said
    timing = re.search(r"recording took ([0-9.]+) s: the trial's simulation ([0-9.]+) s \+ the viewer ([0-9.]+) s "
                       r"\(([0-9.]+)x the simulation alone\)", said)
    assert timing, said
    total, sim, viewer, ratio = map(float, timing.groups())
    assert total == pytest.approx(sim + viewer, abs=0.016) and ratio >= 1.0  # the parts add up; no speed asserted
    # the trial as played: its one push (at 0.5 s, before the 0.8 s end), the rest of it fixed
    trial = load_scenario(scenario).trial("hard", 0, 0)
    (push,) = exported.trial("hard", 9, 9).pushes
    assert push.start == trial.pushes[0].start and np.array_equal(push.force_in_world, trial.pushes[0].force_in_world)
    # an export needs one controller's trial; a bad file name is refused before anything plays
    assert main(["view", "stand", "stand-locked", "--scenario", str(scenario), "--trial", "0", "--duration", "0.3",
                 "--export-scenario", str(toml)]) != 0
    assert "not an A / B view" in capsys.readouterr().err
    assert main(["view", "stand", "--scenario", str(scenario), "--trial", "0", "--record", str(out),
                 "--export-scenario", str(tmp_path / "t.json")]) != 0
    assert "give a .toml file" in capsys.readouterr().err


def test_cli_view_says_where_it_saved_the_episode(scenario, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log here
    saved = tmp_path / "e.npz"
    assert main(["view", "stand", "--scenario", str(scenario), "--trial", "0", "--duration", "0.3", "--record",
                 str(tmp_path / "e.html"), "--save-episode", str(saved)]) == 0
    assert f"saved the episode played to {saved}" in capsys.readouterr().out.splitlines()
    assert Episode.load(str(saved)).survived_s == pytest.approx(0.3)


def test_a_stored_run_replays_with_the_arm_mode_its_run_json_records_without_building_the_controller(
        scenario, tmp_path, monkeypatch):
    # a policy file moved since, or an onnx: policy's I/O file given by --io, cannot be found again: the replay
    # must not need the controller, whose arm mode run.json records
    import wbc.viz.replay as replay

    out = tmp_path / "r"
    run_arena(ArenaConfig(controllers=("stand",), scenario=scenario, trials=1, out_dir=out, workers=1,
                          progress=False, save_episodes=True))
    run = json.loads((out / "run.json").read_text())
    assert run["controllers"]["stand"]["arm_mode"] == "actuated"

    def unbuildable(name, **kw):
        raise ConfigError(f"{name}: file not found")

    monkeypatch.setattr(replay, "get_controller", unbuildable)
    stored = load_stored_episode(out, 0)
    assert stored.arm_mode == "actuated" and stored.content().robot is not None
    replay_episode(stored, ViewConfig(live=False, record=tmp_path / "replay.html"))
    del run["controllers"]  # a run.json that records no controllers: asked of the controller, named when it fails
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(ViewerError, match=r"run\.json: field controllers\.stand\.arm_mode: missing, and stand "):
        load_stored_episode(out, 0)


def test_cli_view_ab_gives_io_to_the_onnx_policy_only(scenario, tmp_path, capsys, monkeypatch):
    pytest.importorskip("onnxruntime")
    from fuzz.cases import ONNX_FRAME, ONNX_IO_TEMPLATE, ONNX_JOINTS, onnx_linear_model

    import wbc.viz.view as view

    model, io = tmp_path / "nets" / "p.onnx", tmp_path / "p-io.toml"
    model.parent.mkdir()
    model.write_bytes(onnx_linear_model(np.zeros((ONNX_FRAME, 12)), None))
    io.write_text(ONNX_IO_TEMPLATE.format(joints=json.dumps(ONNX_JOINTS), history=1))
    built = []

    def fake_view_ab(trial, specs, cfg, path):
        built.extend(specs)
        raise ConfigError("stop here")

    monkeypatch.setattr(view, "view_ab", fake_view_ab)
    common = ["--scenario", str(scenario), "--trial", "0", "--record", str(tmp_path / "ab.html")]
    assert main(["view", f"onnx:{model}", "stand", "--io", str(io), *common]) != 0
    assert [s.name for s in built] == [f"onnx:{model}", "stand"], capsys.readouterr().err
    assert main(["view", f"onnx:{model}", f"onnx:{model}x", "--io", str(io), *common]) != 0
    assert "several controllers are an onnx:PATH policy" in capsys.readouterr().err  # write NAME=FILE
    assert main(["view", "mpc", "stand", "--io", str(io), *common]) != 0
    assert "no controller here is an onnx:PATH policy" in capsys.readouterr().err


def _carried(desc, xs):
    """Frames of `desc` standing at trunk x = each of `xs` [m], at times 0.002 s apart from 0.002 s (a 500 Hz run)."""
    from wbc.viz.frame import VizFrame

    out = []
    for i, x in enumerate(xs):
        qpos = np.zeros(7 + desc.num_joints)
        qpos[:4] = [x, 0.0, 0.3, 1.0]
        out.append(VizFrame(t=round(0.002 * (i + 1), 9), qpos=qpos))
    return out


def test_a_fast_controller_is_keyed_at_its_tick_nearest_each_frame():
    # rounding t * fps keyed a 500 Hz run's tick at 0.012 s as the frame at 0.02 s: drawn 8 ms before it happened
    from wbc.robots.registry import get_robot
    from wbc.viz.content import FOLLOW, SceneContent
    from wbc.viz.recording import Recording, frame_key

    assert [frame_key(t, 50.0, 0.002) for t in (0.010, 0.012, 0.018, 0.02, 0.022)] == [0, 0, 0, 1, 1]
    assert [frame_key(t, 50.0, 0.02) for t in (0.02, 0.04, 0.06)] == [1, 2, 3]
    # a 30 Hz run: each tick keys the last frame it is the nearest tick to (0.0667 s is nearest to 0.06 and 0.08 s)
    assert [frame_key(t, 50.0, 1 / 30) for t in (1 / 30, 2 / 30, 3 / 30)] == [2, 4, 5]
    desc = get_robot("a1-wx200", "actuated")
    rec = Recording(SceneContent.for_description(desc), fps=50.0, tick_s=0.002)
    frames = _carried(desc, [0.002 * (i + 1) for i in range(100)])  # the trunk's x is the frame's time
    keyed = [f.t for f in frames if rec.add(f)]
    assert keyed[:3] == [0.002, 0.02, 0.04] and keyed[-1] == pytest.approx(0.2)
    html = rec.html()
    for c in _commands(html):
        if c["type"] == "set_animation":
            track = next(t for a in c["animations"] if a["path"] == FOLLOW for t in a["clip"]["tracks"]
                         if t["name"] == ".position")
            times = np.frombuffer(track["times"].data, dtype="<f4")
            xs = np.frombuffer(track["values"].data, dtype="<f4").reshape(-1, 3)[:, 0]
            assert xs[0] == pytest.approx(0.002)  # no tick at 0 s: the first frame is the first tick's
            assert xs[1:] == pytest.approx(times[1:] / 50.0, abs=1e-6)  # the state drawn at each frame is its own


def test_the_first_divergence_of_two_runs_does_not_depend_on_their_order():
    from wbc.robots.registry import get_robot
    from wbc.viz.ab import first_divergence

    desc = get_robot("a1-wx200", "actuated")
    fast = _carried(desc, [0.0 if 0.002 * (i + 1) < 2.487 else 0.1 for i in range(1500)])  # parts at 2.488 s
    slow = _carried(desc, [0.0] * 1500)[9::10]  # 50 Hz: one frame each 0.02 s
    fast_kept, last = [], -1
    for f in fast:  # as a capture keeps them: the tick nearest each frame
        k = int(np.floor((f.t + 0.001) * 50 + 1e-6))
        if k > last:
            fast_kept.append(f)
            last = k
    ab = first_divergence(fast_kept, slow, 50.0, tick_a=0.002, tick_b=0.02)
    ba = first_divergence(slow, fast_kept, 50.0, tick_a=0.02, tick_b=0.002)
    assert ab == ba == pytest.approx(2.5)


def test_the_push_angular_impulse_is_integrated_over_the_push_alone_whatever_the_frame_rate(scenario, tmp_path,
                                                                                             monkeypatch):
    # a 90 ms push starting between frames: summed over whole frame intervals, it read 0.1 s of push at 50 frames a
    # second (five frames saw it) and another figure at another rate
    monkeypatch.chdir(tmp_path)
    text = scenario.read_text().replace("first_s = [0.5, 0.5]", "first_s = [0.505, 0.505]").replace(
        "duration_s = 0.1\n", "duration_s = 0.09\n")
    odd = tmp_path / "odd.toml"
    odd.write_text(text)
    trial = load_scenario(odd).trial("soft", 0, 0)
    assert trial.pushes[0].duration == pytest.approx(0.09)
    final = {}
    for fps in (50.0, 100.0, 30.0):
        out = tmp_path / f"p{fps:g}.html"
        view_trial(trial, "stand", ViewConfig(live=False, record=out, record_fps=fps))
        run = read_page_data(out.read_text())["runs"][0]
        lines = run["plots"]["arm_momentum"]["lines"]
        t = np.array(run["t"])
        at = int(np.searchsorted(t, 0.75))
        final[fps] = np.array([lines[f"push H{a}"][at] for a in "xyz"], dtype=float)
    assert np.linalg.norm(final[50.0]) > 0.5
    for fps in (100.0, 30.0):
        assert final[fps] == pytest.approx(final[50.0], rel=0.02), final


def test_cli_view_refuses_three_controllers(scenario, capsys):
    assert main(["view", "stand", "mpc", "stand", "--scenario", str(scenario), "--trial", "0"]) != 0
    assert "two for an A / B view" in capsys.readouterr().err


# -- a real browser --------------------------------------------------------------------------------------------------
def _dump(url: str, tmp_path, budget_ms: int = 6000) -> dict:
    """The page's state (``<pre id="wbc-state">``) after headless Chromium ran its scripts for `budget_ms`."""
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--hide-scrollbars", "--window-size=1000,700",
           "--disable-background-networking", "--disable-component-update", "--no-first-run",
           f"--user-data-dir={tmp_path / 'profile'}", f"--virtual-time-budget={budget_ms}", "--dump-dom", url]
    dom = subprocess.run(cmd, capture_output=True, timeout=120).stdout.decode("utf-8", errors="replace")
    m = re.search(r'<pre id="wbc-state"[^>]*>(.*?)</pre>', dom, re.S)
    assert m, "the page wrote no state"
    import html as html_lib

    return json.loads(html_lib.unescape(m.group(1))) | {"_dom": dom}


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_trial_page_plots_and_a_scrub_moves_scene_and_cursor_together(page, tmp_path):
    path, data, _ = page
    state = _dump(f"{path.resolve().as_uri()}#t=0.55", tmp_path)
    assert state["ready"] and not state["playing"]
    for key in ("attitude", "height", "velocity", "foot_forces", "torques", "arm_momentum"):
        assert state["plots"][key]["n"] > 50, f"the {key} plot drew no data"
    # the scrub to 0.55 s moved both: the cursor on every plot and meshcat's animation
    assert state["t"] == pytest.approx(0.55) and state["cursorT"] == pytest.approx(0.55)
    assert state["sceneT"] == pytest.approx(0.55, abs=1e-3)
    assert any(m["kind"] == "push" for m in state["marks"])
    assert "push 150 N" in state["_dom"]  # the push acting at 0.55 s is named in the bar


def _walking_page(path, follow_at=(4.0, 2.0)):
    """A page of the A1 carried in a straight line from the origin to `follow_at` over 2 s (frames made up)."""
    from wbc.robots.registry import get_robot
    from wbc.viz.content import SceneContent
    from wbc.viz.frame import VizFrame
    from wbc.viz.page import save_trial_page
    from wbc.viz.recording import Recording

    desc = get_robot("a1-wx200", "actuated")
    rec = Recording(SceneContent.for_description(desc), fps=50.0)
    signals = TrialSignals("walk")
    for k in range(1, 101):
        qpos = np.zeros(7 + desc.num_joints)
        qpos[:3] = [follow_at[0] * k / 100, follow_at[1] * k / 100, 0.3]
        qpos[3] = 1.0
        frame = VizFrame(t=k * 0.02, qpos=qpos)
        rec.add(frame)
        signals.add_frame(frame, None, None)
    return save_trial_page(path, rec, [signals], title="walk", duration=2.0)


def test_follow_trunk_poses_a_point_under_the_trunk_and_leaves_the_camera_to_the_page(tmp_path):
    # meshcat's orbit controls look at their target in the world: the recording moved /Cameras/default alone, so
    # the camera went with the robot while looking back at the origin, and the robot left the screen
    html = _walking_page(tmp_path / "walk.html").read_text()
    animated = {}
    for c in _commands(html):
        if c["type"] == "set_animation":
            for a in c["animations"]:
                animated[a["path"]] = a["clip"]["tracks"]
    assert "/Cameras/default" not in animated
    track = next(t for t in animated["/Cameras/follow"] if t["name"] == ".position")
    values = np.frombuffer(track["values"].data, dtype="<f4").reshape(-1, 3)
    assert values[-1] == pytest.approx([4.0, 2.0, 0.0], abs=1e-5)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_follow_trunk_moves_the_camera_target_with_the_robot(tmp_path):
    path = _walking_page(tmp_path / "walk.html")
    # meshcat's scene turns z-up into three.js's y-up: the world's (x, y, z) is three.js's (x, z, -y)
    state = _dump(f"{path.resolve().as_uri()}#t=2", tmp_path)
    assert state["cameraTarget"] == pytest.approx([4.0, 0.0, -2.0], abs=1e-3)
    fixed = _dump(f"{path.resolve().as_uri()}#t=2&follow=0", tmp_path)
    assert fixed["cameraTarget"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-3)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_ab_page_draws_two_robots(ab_page, tmp_path):
    out, result = ab_page
    state = _dump(f"{out.resolve().as_uri()}#t=0.8", tmp_path)
    assert state["robots"] == 2 and state["runs"] == ["mpc", "stand"]
    assert state["sceneT"] == pytest.approx(0.8, abs=1e-3)
    tree = set(re.findall(r'<li class="title">([^<]*)</li>', state["_dom"]))
    assert {"ghost0", "wbc", "robot", "trunk_0"} <= tree
    assert {m["kind"] for m in state["marks"]} >= {"fall", "divergence", "push"}


# -- the live page: pushes and commands from the browser ------------------------------------------------------------
def _http(url: str, body: dict | None = None, kind: str = "application/json") -> tuple[int, bytes]:
    import urllib.error
    import urllib.request

    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, headers={"Content-Type": kind} if data is not None else {})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def test_live_page_push_and_command_land_in_the_episode(scenario, tmp_path, monkeypatch):
    import threading
    import time

    from wbc.arena.episode import Episode
    from wbc.viz.live_page import LivePage
    from wbc.viz.player import PlayerConfig
    from wbc.viz.replay import frames_of

    monkeypatch.chdir(tmp_path)
    trial = load_scenario(scenario).trial("soft", 0, 0)
    saved = tmp_path / "episode.npz"
    exported = tmp_path / "live.toml"
    with LivePage() as page:
        assert page.url.startswith("http://127.0.0.1:")
        # refused: a bad push, a push that is not JSON (another site's form), a command before any trial plays
        assert _http(page.url + "push", {"force_n": -5})[0] == 400
        assert _http(page.url + "push", {"force_n": 100}, kind="text/plain")[0] == 415
        assert _http(page.url + "command", {"vx": 0.2})[0] == 400
        # a push for 0.9 s into the trial, posted before it starts: 120 N towards +y for 0.1 s at the trunk's front
        push = {"force_n": 120.0, "heading_deg": 90.0, "duration_s": 0.1, "point_in_base": [0.1, 0.0, 0.0], "t": 0.9}
        assert _http(page.url + "push", push) == (200, b'{"queued": true}')
        result: list = []
        cfg = ViewConfig(live=True, player=PlayerConfig(speed=0.5), save_episode=saved, keep_open=False,
                         export_scenario=exported)
        thread = threading.Thread(target=lambda: result.append(view_trial(trial, "stand", cfg, page=page)))
        thread.start()
        state: dict = {}
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # wait until the trial plays, then steer it from the "page"
            state = json.loads(_http(page.url + "state")[1])
            if state["t"] > 0.3:
                break
            time.sleep(0.02)
        # pause it from the page (a loaded machine must not finish the trial under the test's feet)
        assert json.loads(_http(page.url + "control", {"pause": True})[1])["paused"]
        state = json.loads(_http(page.url + "state")[1])
        assert state["t"] > 0.3 and not state["done"]
        assert any(m is not None for m in state["poses"].values()), "the live page receives no poses"
        assert "/meshcat/wbc/robot/root_joint" in state["poses"]
        assert state["data"]["runs"][0]["t"], "the live page receives no plots"
        live_html = _http(page.url)[1].decode()
        assert '"live":true' in live_html and "wbc-plots" in live_html
        assert _http(page.url + "command", {"vx": 0.25, "vy": 0.0, "yaw_rate": 0.1})[0] == 200
        assert not json.loads(_http(page.url + "control", {"pause": False, "speed": 4.0})[1])["paused"]
        thread.join(timeout=120)
        assert result, "the trial did not finish"
        # the finished trial: the page becomes the recorded page, its timeline marks the browser's push and command
        assert json.loads(_http(page.url + "state")[1])["done"]
        data = read_page_data(_http(page.url)[1].decode())
    marks = data["runs"][0]["marks"]
    kinds = [m["kind"] for m in marks]
    assert kinds.count("push") == 1 and kinds.count("browser_push") == 1 and kinds.count("command") == 1
    episode = result[0].episode
    for ep in (episode, Episode.load(str(saved))):
        assert len(ep.pushes) == 2  # the scenario's at 0.5 s and the browser's at 0.9 s
        j = int(np.argmax(ep.pushes.start))
        assert ep.pushes.start[j] == pytest.approx(0.9, abs=0.01)
        assert ep.pushes.force_in_world[j] == pytest.approx([0.0, 120.0, 0.0], abs=1e-9)
        assert ep.pushes.offset_in_base[j] == pytest.approx([0.1, 0.0, 0.0])
        actions = [a for _, k, a in ep.operator_events.rows() if k == "browser"]
        assert len(actions) == 2 and actions[0].startswith("browser ")
        assert ep.command[-1] == pytest.approx([0.25, 0.0, 0.1])  # the page's command held to the end
    # a replay draws the browser's push while it acts
    pushed = [f for f in frames_of(Episode.load(str(saved))) if f.pushed and f.t > 0.8]
    assert pushed and pushed[0].push_force_in_world == pytest.approx([0.0, 120.0, 0.0])
    # the exported scenario: unpublished, its hash in its comments, and its trial is this one as played, the
    # browser's push and command included; any of its trials replays the live episode to the bit
    assert result[0].exported.path == exported and result[0].exported.browser_pushes == 1
    replayed = load_scenario(exported)
    assert replayed.hash in exported.read_text() and replayed.bands == ("soft",)
    with pytest.raises(ScenarioError, match="unpublished"):
        check_published(replayed)
    again = replayed.trial("soft", 3, 5)
    (change,) = again.command.changes
    assert change.command == VelocityCommand(vx=0.25, vy=0.0, yaw_rate=0.1)
    assert change.at_s == next(t for t, k, a in episode.operator_events.rows() if "command" in a)
    _, replay = run_trial(again, "stand")
    assert np.array_equal(replay.pushes.start, episode.pushes.start)
    assert np.array_equal(replay.pushes.force_in_world, episode.pushes.force_in_world)
    assert np.array_equal(replay.command, episode.command) and np.array_equal(replay.qpos, episode.qpos)


def _raw_post(url: str, body: bytes, length: str) -> tuple[int, bytes]:
    import http.client
    import urllib.parse

    u = urllib.parse.urlsplit(url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=30)
    conn.putrequest("POST", u.path)
    conn.putheader("Content-Type", "application/json")
    conn.putheader("Content-Length", length)
    conn.endheaders()
    conn.send(body)
    reply = conn.getresponse()
    out = reply.status, reply.read()
    conn.close()
    return out


def test_live_page_endpoints_answer_a_bad_request_with_400_and_what_is_wrong():
    from wbc.viz.live_page import LivePage
    from wbc.viz.player import Controls

    with LivePage() as page:
        page.controls = Controls()
        for body, says in (({"speed": "abc"}, "speed must be a number"), ({"speed": None}, "speed must be a number"),
                           ({"speed": True}, "speed must be a number"), ({"pause": "false"}, "pause must be true or")):
            code, reply = _http(page.url + "control", body)
            assert code == 400 and says in json.loads(reply)["error"], (body, reply)
        assert not page.controls.paused  # "false" as a string paused the trial
        assert _raw_post(page.url + "control", b'{"pause": true}', "abc")[0] == 400
        assert _raw_post(page.url + "control", b"\xff\xfe", "2")[0] == 400
        assert _http(page.url + "control", {"pause": True}) == (200, b'{"paused": true, "speed": 1.0}')
        page.trial_s = 1.5  # known before the first tick (view_trial sets it): an early push is checked too
        assert _http(page.url + "push", {"force_n": 100.0, "t": 1e9})[0] == 400
        content, scene, signals = _scene_for_live_page()
        page.begin(scene, content, signals, title="t", duration=1.5, fps=50.0)
        push = {"force_n": 100.0, "duration_s": 0.1}
        for t in (1e9, 1.5, -1.0, float("inf")):
            code, reply = _http(page.url + "push", push | {"t": t})
            assert code == 400 and "t must be a trial time in [0, 1.5) s" in json.loads(reply)["error"], reply
        assert _http(page.url + "push", push | {"t": 1.4})[0] == 200
        page.finish("<html></html>")
        assert json.loads(_http(page.url + "push", push)[1])["error"] == "push: the trial has ended"


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_live_page_shows_the_push(scenario, tmp_path, monkeypatch):
    import threading
    import time

    from wbc.viz.live_page import LivePage
    from wbc.viz.player import PlayerConfig

    monkeypatch.chdir(tmp_path)
    trial = load_scenario(scenario).trial("soft", 0, 0)
    with LivePage() as page:
        push = {"force_n": 120.0, "heading_deg": 90.0, "duration_s": 0.1, "point_in_base": [0.0, 0.0, 0.0], "t": 0.6}
        assert _http(page.url + "push", push)[0] == 200
        cfg = ViewConfig(live=True, player=PlayerConfig(speed=0.1), keep_open=False)
        thread = threading.Thread(target=lambda: view_trial(trial, "stand", cfg, page=page), daemon=True)
        thread.start()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and json.loads(_http(page.url + "state")[1])["t"] < 0.75:
            time.sleep(0.05)
        _http(page.url + "control", {"pause": True})  # held mid-trial while the browser looks
        state = _dump(page.url, tmp_path, budget_ms=3000)
        _http(page.url + "control", {"pause": False, "speed": 10.0})
        thread.join(timeout=120)
    assert state["live"] and state["ready"]
    assert any(m["kind"] == "browser_push" for m in state["marks"]), state["marks"]
    assert state["plots"]["attitude"]["n"] > 10 and state["t"] >= 0.6
    assert 'id="wbc-push"' in state["_dom"]  # the page's own push control


def test_a_live_page_served_before_the_trial_began_is_told_to_load_its_scene():
    from wbc.viz.live_page import LivePage

    with LivePage() as page:
        early = read_page_data(_http(page.url)[1].decode())
        state = json.loads(_http(page.url + "state")[1])
        assert early["duration"] == 0 and state["scene"] == early["scene"] == 0
        content, scene, signals = _scene_for_live_page()
        page.begin(scene, content, signals, title="t", duration=1.5, fps=50.0)
        state = json.loads(_http(page.url + "state")[1])
        assert state["scene"] != early["scene"] and state["data"]["duration"] == 1.5
        assert read_page_data(_http(page.url)[1].decode())["scene"] == state["scene"]


def _scene_for_live_page():
    import base64 as b64

    from wbc.robots.registry import get_robot
    from wbc.viz.content import SceneContent
    from wbc.viz.recording import Recording

    rec = Recording(SceneContent.for_description(get_robot("a1-wx200", "actuated")), fps=50.0)
    return rec.content, [b64.b64encode(c).decode() for c in rec.window.commands()], TrialSignals("stand")


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_live_page_opened_before_the_first_tick_picks_up_the_scene_and_duration(tmp_path, monkeypatch):
    from wbc.viz.frame import VizFrame
    from wbc.viz.live_page import LivePage

    with LivePage() as page:
        served = page._page
        content, scene, signals = _scene_for_live_page()

        def first_then_begin():  # the trial begins right after the browser got the empty page
            html = served()
            if page._content is None:
                page.begin(scene, content, signals, title="t", duration=1.5, fps=50.0)
                qpos = np.zeros(22)
                qpos[2], qpos[3] = 0.3, 1.0
                page.show(VizFrame(t=0.2, qpos=qpos))
            return html

        monkeypatch.setattr(page, "_page", first_then_begin)
        state = _dump(page.url, tmp_path, budget_ms=4000)
    assert state["live"] and state["duration"] == 1.5 and state["t"] == pytest.approx(0.2)
    assert "trunk_0" in set(re.findall(r'<li class="title">([^<]*)</li>', state["_dom"]))


_CLICK_PUSH = """<script>
// what a person does: fill in the page's push control and press its button, once the live panel is built
var wbcClick = setInterval(function () {
  var button = document.getElementById("wbc-push");
  if (!button) { return; }
  clearInterval(wbcClick);
  document.getElementById("wbc-push-force").value = "140";
  document.getElementById("wbc-push-heading").value = "0";
  document.getElementById("wbc-push-duration").value = "0.1";
  document.getElementById("wbc-push-point").value = "0.05 0 0";
  button.click();
  var wait = setInterval(function () {
    if (window.wbcPage && window.wbcPage.lastReply) {
      clearInterval(wait);
      var out = document.createElement("pre");
      out.id = "wbc-test-reply";
      out.textContent = JSON.stringify(window.wbcPage.lastReply);
      document.body.appendChild(out);
    }
  }, 20);
}, 50);
</script>
</body>"""


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_push_from_the_page_is_stored_exported_and_replayed(scenario, tmp_path, monkeypatch):
    import threading
    import time

    import wbc.viz.live_page as live_page
    from wbc.arena.episode import Episode
    from wbc.viz.live_page import LivePage
    from wbc.viz.player import PlayerConfig

    monkeypatch.chdir(tmp_path)
    page_html = live_page.live_page_html
    # the live page as served, with a script that uses its push control as a person would
    monkeypatch.setattr(live_page, "live_page_html",
                        lambda *a, **k: page_html(*a, **k).replace("</body>", _CLICK_PUSH, 1))
    trial = load_scenario(scenario).trial("soft", 0, 0)
    saved, exported = tmp_path / "live.npz", tmp_path / "live.toml"
    result: list = []
    with LivePage() as page:
        cfg = ViewConfig(live=True, player=PlayerConfig(speed=0.2), keep_open=False, save_episode=saved,
                         export_scenario=exported)
        thread = threading.Thread(target=lambda: result.append(view_trial(trial, "stand", cfg, page=page)),
                                  daemon=True)
        thread.start()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and json.loads(_http(page.url + "state")[1])["t"] < 0.7:
            time.sleep(0.05)
        _http(page.url + "control", {"pause": True})  # held after the scenario's own push while the browser acts
        paused_at = json.loads(_http(page.url + "state")[1])["t"]
        state = _dump(page.url, tmp_path, budget_ms=4000)
        _http(page.url + "control", {"pause": False, "speed": 10.0})
        thread.join(timeout=120)
    assert state["live"] and '<pre id="wbc-test-reply">{"queued":true}</pre>' in state["_dom"], "no push was sent"
    assert result, "the trial did not finish"
    # in the stored episode: the scenario's push at 0.5 s, and the page's, applied at the tick after the pause
    stored = Episode.load(str(saved))
    assert len(stored.pushes) == 2 and stored.pushes.start[0] == pytest.approx(0.5)
    start, force = float(stored.pushes.start[1]), stored.pushes.force_in_world[1]
    assert paused_at <= start <= paused_at + 0.1
    assert force == pytest.approx([140.0, 0.0, 0.0]) and stored.pushes.offset_in_base[1] == pytest.approx([0.05, 0, 0])
    assert stored.pushes.duration[1] == pytest.approx(0.1)
    # in the exported scenario, exactly: the same start, force, point and duration, to the bit
    scenario_file = load_scenario(exported)
    fixed = scenario_file.trial("soft", 0, 0).pushes
    assert [p.start for p in fixed] == stored.pushes.start.tolist()
    assert np.array_equal([p.force_in_world for p in fixed], stored.pushes.force_in_world)
    assert np.array_equal([p.offset_in_base for p in fixed], stored.pushes.offset_in_base)
    # and the arena replays it: a run of the exported scenario meets the push at the same time with the same force,
    # and its episode is the live one
    results = tmp_path / "replay"
    run_arena(ArenaConfig(controllers=("stand",), scenario=exported, trials=1, out_dir=results, workers=1,
                          progress=False, save_episodes=True))
    replay = load_stored_episode(results, 0).episode
    assert np.array_equal(replay.pushes.start, stored.pushes.start)
    assert np.array_equal(replay.pushes.force_in_world, stored.pushes.force_in_world)
    assert np.array_equal(replay.qpos, stored.qpos)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_screenshot_of_a_trial_page_is_a_small_picture_of_the_page(page, tmp_path):
    # the docs' screenshots are taken this way (`python -m wbc.tools.screenshots`); here, of the test's own page
    from PIL import Image

    from wbc.tools.screenshots import COLORS, SIZE, screenshot

    path, _, _ = page
    png = screenshot(f"{path.resolve().as_uri()}#t=0.55", tmp_path / "page.png", budget_ms=6000)
    assert png.stat().st_size < 300_000
    with Image.open(png) as image:
        assert image.size == SIZE and image.mode == "P"
        used = image.getcolors(maxcolors=COLORS)
        assert used is not None and len(used) > 16  # not blank: sky, ground, robot, plots and bar
        rgb = image.convert("RGB")
        scene = rgb.crop((0, 0, SIZE[0] // 2, SIZE[1] - 100))  # the 3D view: drawn, not left white
        assert len(scene.getcolors(maxcolors=COLORS) or ()) > 8


def test_screenshots_refuse_a_missing_folder_before_anything_plays(tmp_path, capsys, monkeypatch):
    """A missing --out is refused up front (not created: a misspelt folder would be filled), not after rendering."""
    import wbc.tools.screenshots as screenshots
    from wbc.errors import WbcError

    for name in ("_trial_page", "_ab_page", "_live_page"):
        monkeypatch.setattr(screenshots, name, lambda *a, **k: pytest.fail("a page was played"))
    missing, afile = tmp_path / "nodir", tmp_path / "f.png"
    afile.write_bytes(b"")
    with pytest.raises(SystemExit) as stop:
        screenshots.main(["--out", str(missing)])
    assert stop.value.code == 2
    assert f"--out {missing}: no such folder; create it first (mkdir -p {missing})" in capsys.readouterr().err
    with pytest.raises(WbcError, match=f"{afile} is a file, not a folder"):
        screenshots.shoot(afile)
    assert not missing.exists()


# -- colour, marks and accessibility ---------------------------------------------------------------------------------
def _contrast(a: str, b: str) -> float:
    def lum(h: str) -> float:
        c = [int(h.lstrip("#")[i:i + 2], 16) / 255 for i in (0, 2, 4)]
        c = [x / 12.92 if x <= 0.03928 else ((x + 0.055) / 1.055) ** 2.4 for x in c]
        return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]

    lo, hi = sorted((lum(a), lum(b)))
    return (hi + 0.05) / (lo + 0.05)


def test_the_page_plots_in_the_arenas_palette_and_tells_its_marks_apart_without_colour():
    from wbc.arena.plot_style import OKABE_ITO
    from wbc.viz.page_script import PAGE_SCRIPT

    palette = json.loads(re.search(r"var COLORS = (\[[^\]]*\]);", PAGE_SCRIPT).group(1))
    assert palette == list(OKABE_ITO)  # the arena's colour-blind-safe palette, taken from plot_style
    colors = dict(re.findall(r'(\w+): "(#[0-9a-fA-F]{6})"', re.search(r"MARK_COLORS = \{(.*?)\};", PAGE_SCRIPT,
                                                                        re.S).group(1)))
    for kind in ("fall", "end", "safety", "operator", "command", "divergence"):
        assert _contrast(colors[kind], "#f4f4f4") >= 3.0, kind  # the timeline's background
    styles = re.search(r"MARK_STYLES = \{(.*?)\};", PAGE_SCRIPT, re.S).group(1)
    letters = re.findall(r'(\w+): \{dash: (\[[^\]]*\]),\s*letter: "(\w)"\}', styles)
    by_kind = {k: (d, letter) for k, d, letter in letters}
    assert by_kind["fall"] != by_kind["safety"] and by_kind["fall"][1] != by_kind["safety"][1]
    assert len({letter for _, _, letter in letters}) == len(letters)
    legend = re.search(r'var MARKS_LEGEND = (".*?");', PAGE_SCRIPT, re.S).group(1)
    for word in ("push", "browser push", "fall", "safety", "operator", "command", "divergence"):
        assert word in legend, word


def test_the_page_says_its_language_and_names_its_controls(tmp_path):
    html = _walking_page(tmp_path / "walk.html").read_text()
    assert '<html lang="en">' in html
    from wbc.viz.page_script import PAGE_SCRIPT

    assert re.search(r'id: "wbc-speed", "aria-label": "[^"]+"', PAGE_SCRIPT)
    assert re.search(r'id: "wbc-slider",[^}]*"aria-label": "[^"]+"', PAGE_SCRIPT, re.S)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_speed_menu_shows_the_speed_a_url_set_and_stays_within_its_range(tmp_path):
    path = _walking_page(tmp_path / "walk.html")
    state = _dump(f"{path.resolve().as_uri()}#t=1&speed=0.3", tmp_path)
    assert state["speed"] == pytest.approx(0.3)
    assert re.search(r'<option value="0\.3">x0\.3</option>', state["_dom"])  # the menu has the speed playing
    fast = _dump(f"{path.resolve().as_uri()}#t=1&speed=8", tmp_path)
    assert fast["speed"] == 2  # the menu's fastest
