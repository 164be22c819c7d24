"""The browser viewer: server binding, recordings, replays from results directories, pacing, and a real browser."""

import base64
import json
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import umsgpack

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.sim_trial import run_trial
from wbc.cli.main import main
from wbc.errors import ConfigError, ScenarioError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.robots.registry import get_robot
from wbc.scenario.lock import check_published
from wbc.scenario.push import Push
from wbc.scenario.scenario import load_scenario
from wbc.scenario.terrain import TerrainConfig
from wbc.types import MotorCommand
from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import VizFrame
from wbc.viz.live import LiveObserver, LiveViewer
from wbc.viz.player import Controls, Player, PlayerConfig
from wbc.viz.recording import Recording
from wbc.viz.replay import load_stored_episode
from wbc.viz.server import MeshcatServer, ServerConfig
from wbc.viz.sim_frames import foot_forces_in_world
from wbc.viz.view import ViewConfig, replay_episode, view_trial

# One push at 1.0 s for 0.1 s; 2 s trials: short enough for a test, long enough to see the push and its aftermath.
SHORT = """
[scenario]
name = "viztest"
version = 1
description = "a short push for the viewer tests"
robot = "a1-wx200"
duration_s = 2.0

[terrain]
kind = "fractal"
amplitude_m = 0.03

[commands]
ramp_s = 0.5
[[commands.options]]
vx = 0.0

[pushes]
first_s = [1.0, 1.0]
interval_s = [5.0, 5.0]
duration_s = 0.1
offset_m = 0.1

[[bands]]
name = "soft"
push_force_n = [120.0, 150.0]
"""

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    path = tmp_path_factory.mktemp("scn") / "viztest.toml"
    path.write_text(SHORT)
    return path


@pytest.fixture(scope="module")
def recording(short, tmp_path_factory):
    """A recorded trial of the standing controller: (html path, view result, trial)."""
    trial = load_scenario(short).trial("soft", 0, 0)
    out = tmp_path_factory.mktemp("rec") / "trial.html"
    result = view_trial(trial, "stand", ViewConfig(live=False, record=out))
    return out, result, trial


def _commands(html: str) -> list[dict]:
    """The meshcat commands embedded in a recorded page, decoded."""
    block = re.search(r"var wbcCommands = \[(.*?)\];", html, re.S)
    assert block, "no embedded command list"
    return [umsgpack.unpackb(base64.b64decode(s)) for s in re.findall(r'"([A-Za-z0-9+/=]+)"', block.group(1))]


def _psutil():
    return pytest.importorskip("psutil")  # the dev extra installs it (CI runs these tests); a bare env skips them


def _listening(pid: int) -> list[tuple[str, int]]:
    psutil = _psutil()
    return [(c.laddr.ip, c.laddr.port) for c in psutil.Process(pid).net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN]


def _other_local_address() -> str | None:
    psutil = _psutil()
    for addrs in psutil.net_if_addrs().values():
        for a in addrs:
            if a.family == socket.AF_INET and not a.address.startswith("127."):
                return a.address
    return None


# -- server ----------------------------------------------------------------------------------------------------------
def test_server_listens_on_loopback_only():
    with MeshcatServer() as server:
        listening = _listening(server.pid)
        assert {port for _, port in listening} >= {server.web_port}
        assert listening and all(ip == "127.0.0.1" for ip, _ in listening), listening
        assert server.web_url.startswith("http://127.0.0.1:")
        page = urllib.request.urlopen(server.web_url, timeout=60).read().decode()
        assert "main.min.js" in page
        other = _other_local_address()
        if other is not None:  # the same port on this machine's other interface must refuse the connection
            with pytest.raises(OSError):
                socket.create_connection((other, server.web_port), timeout=2).close()
    assert server.pid is None


def test_server_host_option_moves_only_the_web_page():
    with MeshcatServer(ServerConfig(host="127.0.0.2")) as server:
        listening = dict((port, ip) for ip, port in _listening(server.pid))
        assert listening[server.web_port] == "127.0.0.2"
        zmq_port = int(server.zmq_url.rsplit(":", 1)[1])
        assert listening[zmq_port] == "127.0.0.1"  # scene commands never leave loopback


def test_server_exits_with_its_parent():
    code = ("import os; from wbc.viz.server import MeshcatServer; "
            "print(MeshcatServer().start().pid, flush=True); os._exit(0)")  # dies without stopping its server
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=Path(__file__).resolve().parent.parent)
    pid = int(out.stdout.strip().splitlines()[-1])
    psutil = _psutil()
    try:
        psutil.Process(pid).wait(timeout=10)
    except psutil.NoSuchProcess:
        pass
    assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE


def test_the_printed_address_opens_in_a_browser_and_says_who_can_reach_it():
    from wbc.viz.server import listening_on, web_address

    assert web_address("127.0.0.1", 7000) == "http://127.0.0.1:7000/static/"
    assert web_address("::1", 7000) == "http://[::1]:7000/static/"  # no brackets: not an address a browser takes
    assert web_address("0.0.0.0", 7001) == "http://127.0.0.1:7001/static/"
    assert web_address("::", 7001) == "http://[::1]:7001/static/"
    assert listening_on("127.0.0.1") == "127.0.0.1 only" and listening_on(None) == "127.0.0.1 only"
    assert listening_on("0.0.0.0").startswith("every interface (0.0.0.0)")  # "0.0.0.0 only" said the opposite
    assert listening_on("::").startswith("every interface (::)")


def test_server_bad_host_is_a_clear_error():
    with pytest.raises(ViewerError, match="192.0.2.123"):
        MeshcatServer(ServerConfig(host="192.0.2.123", start_timeout_s=10)).start()


# -- live scene ------------------------------------------------------------------------------------------------------
def test_live_viewer_registers_robot_arm_and_push_paths():
    desc = get_robot("a1-wx200", "actuated")
    with MeshcatServer() as server:
        viewer = LiveViewer(server)
        viewer.load(SceneContent(desc, TerrainConfig(), None))
        q = np.r_[0.0, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, desc.nominal_q]
        viewer.show(VizFrame(t=0.1, qpos=q, push_force_in_world=np.array([0.0, 200.0, 0.0]),
                             push_point_in_world=q[:3]))
        paths = viewer.paths
        assert any(p.endswith("root_joint/trunk_0") for p in paths["robot"])
        assert {p.split("/")[2] for p in paths["arm"]} >= {"arm_waist", "arm_shoulder", "arm_elbow"}
        assert paths["push"] == ["wbc/push"]
        # the server's own scene holds them: a static page asked from it lists the arm's forearm mesh
        html = viewer.vis.static_html()
        assert "MeshCat.Viewer" in html


# -- recording -------------------------------------------------------------------------------------------------------
def test_recording_is_self_contained_with_robot_arm_push_and_animation(recording):
    path, result, trial = recording
    html = path.read_text(encoding="utf-8")
    assert 200_000 < len(html) < 8_000_000
    # nothing fetched from elsewhere: no external scripts, styles, images or fetches
    assert not re.search(r"""(src|href)\s*=\s*["']https?:""", html)
    assert not re.search(r"""fetch\(\s*["']https?:""", html)
    assert "<link" not in html
    commands = _commands(html)
    objects = {c["path"] for c in commands if c["type"] == "set_object"}
    assert "/meshcat/wbc/robot/root_joint/trunk_0" in objects
    assert any(p.startswith("/meshcat/wbc/arm/arm_elbow/") for p in objects)
    assert {"/meshcat/wbc/push/shaft", "/meshcat/wbc/push/head"} <= objects
    anims = [c for c in commands if c["type"] == "set_animation"]
    assert len(anims) == 1
    clips = {a["path"]: a["clip"] for a in anims[0]["animations"]}
    # the push arrow shows exactly while the push acts (1.0 s to 1.1 s), at 50 frames per second
    visible = next(t for t in clips["/meshcat/wbc/push"]["tracks"] if t["name"] == ".visible")
    shown = [k["time"] / 50.0 for k in visible["keys"] if k["value"]]
    hidden = [k["time"] / 50.0 for k in visible["keys"] if not k["value"]]
    assert len(shown) == 1 and 1.0 <= shown[0] <= 1.04
    assert any(1.08 <= t <= 1.14 for t in hidden)
    # the trunk moves: its position track has many keys over the 2 s
    trunk = clips["/meshcat/wbc/robot/root_joint"]
    position = next(t for t in trunk["tracks"] if t["name"] == ".position")
    times = np.frombuffer(position["times"].data, dtype="<f4")  # float32 arrays (meshcat's Float32Array)
    values = np.frombuffer(position["values"].data, dtype="<f4").reshape(-1, 3)
    assert len(times) > 20 and len(values) == len(times)
    assert np.all(np.diff(times) > 0)
    assert result.frames_recorded == pytest.approx(trial.duration_s * 50, abs=2)
    assert set(result.paths) >= {"robot", "arm", "push", "contacts", "command", "plan", "terrain"}


@pytest.mark.parametrize(("robot", "arm_mode", "arm_parts"), [("a1-wx200", "locked", 4), ("a1-wx200", "none", 0)])
def test_scene_of_every_arm_mode(robot, arm_mode, arm_parts):
    desc = get_robot(robot, arm_mode)
    rec = Recording(SceneContent(desc, TerrainConfig(), None), fps=10.0)
    assert len(rec.paths["arm"]) == arm_parts and len(rec.paths["robot"]) >= 13  # trunk, 4 x (hip, thigh, calf)
    q = np.r_[0.0, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, desc.nominal_q]
    assert rec.add(VizFrame(t=0.0, qpos=q)) and rec.frames == 1
    assert rec.content.robot.arm_tip_path(q, np.zeros((3, 3))) is None  # no arm plan without an actuated arm


def test_recording_of_mpc_shows_its_plan(tmp_path, short):
    trial = load_scenario(short).trial("soft", 0, 0)
    import dataclasses

    trial = dataclasses.replace(trial, duration_s=0.2)
    out = tmp_path / "mpc.html"
    view_trial(trial, "mpc", ViewConfig(live=False, record=out))
    anim = next(c for c in _commands(out.read_text()) if c["type"] == "set_animation")
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    plan_visible = next(t for t in clips["/meshcat/wbc/plan"]["tracks"] if t["name"] == ".visible")
    assert any(k["value"] for k in plan_visible["keys"]), "the MPC's plan never showed"
    assert "/meshcat/wbc/plan/com/0" in clips and "/meshcat/wbc/plan/footholds/FL" in clips
    assert "/meshcat/wbc/plan/arm/0" in clips  # the arm plan (tip path)


# -- runner hook and truth for the overlays ---------------------------------------------------------------------------
def test_observer_sees_every_tick_and_changes_nothing(short):
    trial = load_scenario(short).trial("soft", 0, 0)
    ticks = []
    _, with_obs = run_trial(trial, "stand", observer=lambda t, robot, ctrl, cmd: ticks.append(t))
    _, without = run_trial(trial, "stand")
    assert len(ticks) == len(without.t)
    np.testing.assert_allclose(ticks, without.t)
    np.testing.assert_array_equal(with_obs.qpos, without.qpos)


def test_foot_forces_carry_the_robot_standing():
    robot = MujocoRobot(MujocoRobotConfig())
    robot.connect()
    desc = robot.desc
    for _ in range(500):
        robot.write(MotorCommand.hold(desc.nominal_q, 60.0, 2.0))
        robot.advance(0.002)
    forces = foot_forces_in_world(robot)
    weight = robot.model.body_subtreemass[1] * 9.81
    assert forces[:, 2].sum() == pytest.approx(weight, rel=0.05)
    assert np.all(forces[:, 2] > 0.1 * weight)
    robot.apply_push(Push(force_in_world=np.array([0.0, 100.0, 0.0]), offset_in_base=np.zeros(3),
                          start=robot.time, duration=0.1))
    robot.advance(0.01)
    assert robot.sim_truth().external_force_in_world[1] == 100.0


# -- replay from a results directory ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def results_dir(short, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "r"
    run_arena(ArenaConfig(controllers=("stand",), scenario=short, trials=2, out_dir=out, workers=1,
                          progress=False, save_episodes=True))
    return out


def test_run_view_watches_every_trial_in_process(short, tmp_path):
    # what `wbc run --view` does, with a recorder in place of the browser: every trial reaches the observer
    observer = LiveObserver(None, None, recording_fps=10.0)
    run_arena(ArenaConfig(controllers=("stand",), scenario=short, trials=2, out_dir=tmp_path / "r", workers=2,
                          progress=False, observer=observer))
    assert len(observer.recordings) == 2
    assert all(r.frames == pytest.approx(20, abs=1) for r in observer.recordings)
    with pytest.raises(ConfigError, match="local executor"):
        ArenaConfig(controllers=("stand",), scenario=short, executor="ray", observer=observer)


def test_replay_from_results_dir(results_dir, tmp_path):
    stored = load_stored_episode(results_dir, 1)
    assert stored.path == results_dir / "episodes" / "stand" / "soft-s0-t1.npz"
    assert len(stored.episode.pushes) == 1 and stored.episode.pushes.start[0] == pytest.approx(1.0)
    frames = list(stored.frames())
    assert len(frames) == len(stored.episode.t) - 1  # the last row's joints of its instant were never read
    pushed = [f.t for f in frames if f.pushed]
    dt = stored.episode.control_dt
    assert pushed and 1.0 < pushed[0] <= 1.0 + dt + 1e-9 and 1.1 <= pushed[-1] < 1.1 + dt
    out = tmp_path / "replay.html"
    result = replay_episode(stored, ViewConfig(live=False, record=out))
    assert result.recording == out and result.frames_recorded > 90
    assert "/meshcat/wbc/push/shaft" in {c["path"] for c in _commands(out.read_text())}


def test_a_replay_draws_the_trunk_and_joints_of_one_instant_as_the_trial_played_afresh(short):
    # the viewer draws a trial it plays from the simulation after each tick; a stored row holds the trunk after
    # the tick but the joints read before it: paired as rows, the legs were drawn one control tick late
    from wbc.viz.replay import frames_of

    trial = load_scenario(short).trial("soft", 0, 0)
    fresh = {}

    def observe(t, robot, controller, command):
        fresh[round(t, 9)] = robot.data.qpos.copy()

    _, episode = run_trial(trial, "stand", observer=observe)
    frames = list(frames_of(episode))
    assert len(frames) == len(episode.t) - 1 > 50
    for frame in frames:
        assert np.array_equal(frame.qpos, fresh[round(frame.t, 9)]), frame.t


def test_replay_errors_name_the_file_and_field(results_dir, tmp_path):
    with pytest.raises(ViewerError, match=r"run\.json: field trials: --trial 5 is out of range"):
        load_stored_episode(results_dir, 5)
    with pytest.raises(ViewerError, match="field bands"):
        load_stored_episode(results_dir, 0, band="hard")
    with pytest.raises(ViewerError, match="no such results directory"):
        load_stored_episode(tmp_path / "nowhere", 0)
    broken = tmp_path / "broken"
    shutil.copytree(results_dir, broken)
    (broken / "episodes" / "stand" / "soft-s0-t0.npz").write_bytes(b"not a zip")
    with pytest.raises(ViewerError, match=r"soft-s0-t0\.npz: not a readable \.npz archive"):
        load_stored_episode(broken, 0)
    (broken / "episodes" / "stand" / "soft-s0-t1.npz").unlink()
    with pytest.raises(ViewerError, match="--save-episodes"):
        load_stored_episode(broken, 1)
    changed = tmp_path / "changed"
    shutil.copytree(results_dir, changed)
    config = json.loads((changed / "run.json").read_text())
    config["config"]["scenario"]["hash"] = "0" * 64
    (changed / "run.json").write_text(json.dumps(config))
    with pytest.raises(ViewerError, match="field scenario.hash"):
        load_stored_episode(changed, 0)


def test_replay_of_a_trial_an_interrupted_run_never_played_says_to_resume(results_dir, tmp_path):
    with pytest.raises(ViewerError, match=r"the run's trials are 0\.\.1 per band and seed$"):  # a finished run
        load_stored_episode(results_dir, 5)
    # the run saved its episodes: the remedy for a trial it has not played yet is --resume, not --save-episodes
    cut = tmp_path / "cut"
    shutil.copytree(results_dir, cut)
    rows = (cut / "trials.csv").read_text().splitlines(keepends=True)
    kept = [r for r in rows if not r.startswith("stand,viztest,") or ",soft,0,1," not in r]
    assert len(kept) == len(rows) - 1
    (cut / "trials.csv").write_text("".join(kept))
    (cut / "episodes" / "stand" / "soft-s0-t1.npz").unlink()
    with pytest.raises(ViewerError, match=r"trial 1 of controller stand, band soft, seed 0 was not played: the run "
                                          r"was interrupted .* with --resume, plays the rest") as caught:
        load_stored_episode(cut, 1)
    assert "--save-episodes" not in str(caught.value)
    with pytest.raises(ViewerError, match=r"--trial 5 is out of range; the run's trials are 0\.\.1 per band and "
                                          r"seed; stand has played 1 \(0\.\.0\) of them so far"):
        load_stored_episode(cut, 5)
    (cut / "episodes" / "stand" / "soft-s0-t0.npz").unlink()  # played, its episode not stored
    with pytest.raises(ViewerError, match="no episode stored .* with --save-episodes"):
        load_stored_episode(cut, 0)


def test_cli_view_refuses_a_controller_named_twice_for_a_replay(results_dir, tmp_path, capsys):
    # CTRL and --controller naming two controllers replayed --controller's silently; an A / B view ignored it
    out = str(tmp_path / "x.html")
    common = ["--episode", str(results_dir), "--trial", "0", "--record", out]
    assert main(["view", "mpc", "--controller", "stand", *common]) != 0
    assert "--controller stand and mpc: two controllers named for one replay" in capsys.readouterr().err
    assert main(["view", "stand", "mpc", "--controller", "stand", *common]) != 0
    assert "an A / B view replays the two controllers it names" in capsys.readouterr().err
    assert main(["view", "stand", "--controller", "stand", *common]) == 0  # the same one twice: no doubt


def test_an_episode_file_given_to_episode_says_what_replays_it(tmp_path):
    saved = tmp_path / "live.npz"
    saved.write_bytes(b"")
    with pytest.raises(ViewerError, match=r"live\.npz: an episode file alone .* --export-scenario FILE\.toml"):
        load_stored_episode(saved, 0)


def test_cli_view_errors_and_record(results_dir, short, tmp_path, capsys, monkeypatch):
    assert main(["view", "--episode", str(results_dir), "--trial", "9", "--record", str(tmp_path / "x.html")]) == 2
    assert "field trials" in capsys.readouterr().err
    assert main(["view", "stand", "--scenario", str(short), "--trial", "0", "--record", str(tmp_path / "x.txt")]) == 2
    assert "--record" in capsys.readouterr().err
    assert main(["view", "nope", "--scenario", str(short), "--trial", "0", "--record", str(tmp_path / "x.html")]) == 2
    assert "unknown controller 'nope'" in capsys.readouterr().err
    out = tmp_path / "cli.html"
    opened = []
    monkeypatch.setattr("wbc.viz.view.webbrowser.open", lambda url, new=0: opened.append(url))
    assert main(["view", "stand", "--scenario", str(short), "--trial", "0", "--duration", "0.5",
                 "--record", str(out), "--open"]) == 0
    assert "recorded 25 frames" in capsys.readouterr().out
    assert out.stat().st_size > 100_000
    # nothing served: --open opens the page written, as it does a stored run's replay
    assert opened == [out.resolve().as_uri()]
    assert main(["view", "--episode", str(results_dir), "--trial", "1", "--record", str(tmp_path / "r.html"),
                 "--open"]) == 0
    assert opened[1] == (tmp_path / "r.html").resolve().as_uri()


def test_a_stored_run_of_an_unpublished_scenario_is_warned_about_as_every_command_that_plays_one_warns(
        results_dir, short, tmp_path, capsys, monkeypatch):
    import wbc.viz.server as server
    import wbc.viz.view as view

    monkeypatch.setattr(server.subprocess, "Popen", lambda *a, **k: pytest.fail("a server was started"))
    # the run played `short`, which no lock lists: the warning `wbc run` gave, said before the replay
    warning = "wbc: warning: " + str(pytest.raises(ScenarioError, check_published, load_scenario(short)).value)
    assert "unpublished" in warning
    assert main(["view", "--episode", str(results_dir), "--trial", "1", "--record", str(tmp_path / "r.html")]) == 0
    assert capsys.readouterr().err == warning + "\n"

    def stop(*args, **kwargs):
        raise ViewerError("stopped by the test before the replay")

    monkeypatch.setattr(view, "replay_ab", stop)  # an A / B of two stored runs of the same run: said once
    assert main(["view", "stand", "stand", "--episode", str(results_dir), "--trial", "1", "--record",
                 str(tmp_path / "ab.html")]) == 2
    assert capsys.readouterr().err == warning + "\nwbc: error: stopped by the test before the replay\n"
    # the same run of the scenario published (the lock beside it lists its hash): replayed without a warning
    published = tmp_path / "published" / short.name
    published.parent.mkdir()
    shutil.copy(short, published)
    scenario = load_scenario(published)
    (published.parent / "published.toml").write_text(f'[{scenario.name}]\n"{scenario.version}" = "{scenario.hash}"\n')
    run = tmp_path / "run"
    shutil.copytree(results_dir, run)
    config = json.loads((run / "run.json").read_text())
    config["config"]["scenario"]["path"] = str(published)
    (run / "run.json").write_text(json.dumps(config))
    assert main(["view", "--episode", str(run), "--trial", "1", "--record", str(tmp_path / "p.html")]) == 0
    assert capsys.readouterr().err == ""


# -- pacing ----------------------------------------------------------------------------------------------------------
class _FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def sleep(self, s):
        self.now += s


def _play(player, clock, ticks, dt=0.002, drawn=None):
    drawn = [] if drawn is None else drawn
    for k in range(1, ticks + 1):
        t = k * dt
        if player.due(t):
            player.wait(t)
            drawn.append((t, clock.now))  # "show"
            player.drew(t)
    return drawn


@pytest.mark.parametrize("speed", [1.0, 0.25])
def test_player_paces_real_time_and_slow_motion(speed):
    clock = _FakeClock()
    player = Player(PlayerConfig(speed=speed, fps=25.0), clock=clock, sleep=clock.sleep)
    drawn = _play(player, clock, 1000)  # 2 s of trial
    t0, w0 = drawn[0]
    t1, w1 = drawn[-1]
    assert (w1 - w0) == pytest.approx((t1 - t0) / speed, abs=1e-6)
    assert len(drawn) == pytest.approx(2.0 / speed * 25.0, rel=0.1)  # about fps frames per wall second


def test_player_pauses_at_a_time_and_steps():
    clock = _FakeClock()
    controls = Controls()
    player = Player(PlayerConfig(speed=0.0, pause_at=(0.5,), step_s=0.1), controls, clock=clock,
                    sleep=clock.sleep)
    drawn = []

    def run():
        _play(player, clock, 500, drawn=drawn)

    def reached():
        return max(t for t, _ in drawn)

    def settles(held) -> None:
        """Wait (bounded: 60 s) until the player thread has paused at `held` s or ended, however late a busy machine
        runs it; then 0.3 s more, in which a player that does not hold its pause would play on."""
        end = time.monotonic() + 60.0
        while time.monotonic() < end and thread.is_alive() and not (controls.paused and drawn and
                                                                      reached() >= held - 0.003):
            time.sleep(0.005)
        thread.join(0.3)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    settles(0.5)
    assert thread.is_alive() and controls.paused  # held at 0.5 s
    assert reached() == pytest.approx(0.5)
    controls.step()  # 0.1 s more, then paused again
    settles(0.6)
    assert thread.is_alive() and reached() == pytest.approx(0.6, abs=0.003)
    controls.toggle_pause()  # play on to the end
    thread.join(5)
    assert not thread.is_alive() and reached() > 1.0 - 1.0 / 30  # frames drawn to the end


def test_player_rejects_negative_speed():
    with pytest.raises(Exception, match="--speed"):
        PlayerConfig(speed=-1.0)


# -- a real browser --------------------------------------------------------------------------------------------------
def _chromium(jobs: list[tuple[str, Path, int]]) -> list[tuple[np.ndarray, str]]:
    """Screenshot (``PATH.png``, as an RGB array) and DOM after the scripts ran (text) of several pages, taken by
    headless Chromium in parallel (each start costs ~5 s), each after a budget of virtual time [ms]."""
    import matplotlib.image

    procs = []
    for url, png, budget_ms in jobs:
        cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
               "--enable-unsafe-swiftshader", "--hide-scrollbars", "--window-size=640,480",
               f"--user-data-dir={png.with_suffix('.profile')}", f"--virtual-time-budget={budget_ms}",
               f"--screenshot={png}", "--dump-dom", url]
        procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL))
    doms = [p.communicate(timeout=120)[0].decode("utf-8", errors="replace") for p in procs]
    results = []
    for (url, png, _), dom in zip(jobs, doms, strict=True):
        assert png.exists() and dom, f"chromium rendered nothing for {url}"
        results.append((matplotlib.image.imread(str(png))[:, :, :3], dom))
    return results


_EXPECTED_TREE = {"wbc", "robot", "trunk_0", "arm", "arm_elbow", "arm_forearm_link_0", "push", "shaft", "head"}

_TREE_JS = "JSON.stringify(Array.from(document.querySelectorAll('li.title'), e => e.textContent))"
"""The scene tree's entry names in meshcat's control panel, as the page holds them now (as `_scene_tree` reads them
from a dumped DOM)."""


def _live_page(url: str, png: Path, deadline_s: float = 180.0) -> tuple[np.ndarray, set[str]]:
    """Screenshot (saved to `png`, returned as RGB) and scene tree of the live page, taken by headless Chromium once
    the scene is there.

    The live page receives its scene over a websocket, which a virtual-time budget does not wait for, so the page is
    driven over Chromium's DevTools protocol on 127.0.0.1 instead: its scene tree is read every 0.25 s until the
    whole of `_EXPECTED_TREE` has arrived and the push arrow is drawn, however slowly a loaded machine delivers them;
    `deadline_s` only bounds a page that never gets there (the assertions then say what is missing).
    """
    import asyncio
    import itertools
    import time

    import matplotlib.image
    from tornado.websocket import websocket_connect  # meshcat's web server is tornado: installed with it

    profile = png.with_suffix(".profile")
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--hide-scrollbars", "--window-size=640,480", f"--user-data-dir={profile}",
           "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0", url]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    end = time.monotonic() + deadline_s
    try:
        port_file = profile / "DevToolsActivePort"  # Chromium writes the port it chose here
        while not (port_file.exists() and port_file.read_text().strip()):
            assert time.monotonic() < end and proc.poll() is None, "chromium did not start its DevTools server"
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        pages: list[str] = []
        while not pages:
            targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=30).read())
            pages = [t["webSocketDebuggerUrl"] for t in targets if t.get("type") == "page"]
            assert pages or time.monotonic() < end, "chromium opened no page"
            time.sleep(0.1)

        async def drive() -> tuple[np.ndarray, set[str]]:
            conn = await websocket_connect(pages[0], max_message_size=1 << 26)
            ids = itertools.count(1)

            async def call(method: str, **params) -> dict:
                key = next(ids)
                await conn.write_message(json.dumps({"id": key, "method": method, "params": params}))
                while True:  # events of the page come in between; the answer carries our id
                    message = await conn.read_message()
                    assert message is not None, f"chromium closed the DevTools connection during {method}"
                    answer = json.loads(message)
                    if answer.get("id") == key:
                        return answer.get("result", {})

            try:
                while True:
                    value = await call("Runtime.evaluate", expression=_TREE_JS, returnByValue=True)
                    tree = set(json.loads(value["result"]["value"]))
                    late = time.monotonic() > end
                    if _EXPECTED_TREE <= tree or late:
                        shot = await call("Page.captureScreenshot", format="png")
                        png.write_bytes(base64.b64decode(shot["data"]))
                        image = matplotlib.image.imread(str(png))[:, :, :3]
                        if _red_pixels(image) > 200 or late:
                            return image, tree
                    await asyncio.sleep(0.25)
            finally:
                conn.close()

        return asyncio.run(drive())
    finally:
        proc.kill()
        proc.wait()


def _scene_tree(dom: str) -> set[str]:
    """Names of the scene-tree entries in meshcat's control panel, as the browser built it."""
    return set(re.findall(r'<li class="title">([^<]*)</li>', dom))


def _red_pixels(img: np.ndarray) -> int:
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(np.count_nonzero((r > 0.6) & (g < 0.3) & (b < 0.3)))


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (CI installs Debian's `chromium` package)")
def test_browser_renders_live_page_and_recorded_replay(recording, tmp_path):
    html, _, trial = recording
    push = trial.pushes[0]
    page = html.resolve().as_uri()
    desc = get_robot("a1-wx200", "actuated")
    with MeshcatServer() as server:  # the live page, served by our server on 127.0.0.1
        viewer = LiveViewer(server)
        viewer.load(SceneContent(desc, TerrainConfig(), None))
        q = np.r_[0.0, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, desc.nominal_q]
        viewer.show(VizFrame(t=0.1, qpos=q, push_force_in_world=np.array([0.0, 250.0, 0.0]),
                             push_point_in_world=q[:3], foot_force_in_world=np.tile([0.0, 0.0, 40.0], (4, 1))))
        # the recorded page holds its whole scene: virtual time renders it; the live page waits for its websocket
        (during, replay_dom), (before, _) = _chromium([
            (f"{page}#t={push.start + 0.5 * push.duration:.3f}", tmp_path / "during.png", 4000),  # mid-push
            (f"{page}#t=0.5", tmp_path / "before.png", 4000),  # replay, before the push
        ])
        live, live_tree = _live_page(server.web_url, tmp_path / "live.png")
    # the scene tree the browser built holds the robot, the arm and the push arrow
    for name, tree in (("live", live_tree), ("replay", _scene_tree(replay_dom))):
        missing = _EXPECTED_TREE - tree
        assert not missing, f"the {name} page's scene tree lacks {sorted(missing)} ({len(tree)} entries)"
    assert live.std() > 0.05, "blank live screenshot"
    assert _red_pixels(live) > 200, "the live page shows no push arrow"
    # the recorded page is the trial page: its 3D view is the left part above the timeline bar (the plots beside
    # it draw red lines of their own)
    during, before = during[:-80, :300], before[:-80, :300]
    assert during.std() > 0.05, "blank replay screenshot"
    assert _red_pixels(during) > 200, "the replay shows no push arrow during the push"
    assert _red_pixels(before) < 20, "the replay shows a push arrow before the push"


def test_cli_view_live_pauses_until_a_key(short, tmp_path):
    # a real terminal on stdin: start paused, step once, then play on with "p"; the trial waits for the keys
    import os
    import pty
    import time

    master, slave = pty.openpty()
    cmd = [sys.executable, "-m", "wbc.cli", "view", "stand", "--scenario", str(short), "--trial", "0",
           "--duration", "0.4", "--speed", "0", "--paused"]
    proc = subprocess.Popen(cmd, stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parent.parent)
    err: list[str] = []
    reader = threading.Thread(target=lambda: err.extend(iter(proc.stderr.readline, "")), daemon=True)
    reader.start()

    def said(text: str, wait: float) -> bool:
        end = time.monotonic() + wait
        while time.monotonic() < end:
            if any(text in line for line in err):
                return True
            time.sleep(0.1)
        return False

    try:
        assert said("viewer: http://127.0.0.1:", 30), err
        assert not said("finished", 4), "the trial ran although it was paused"
        os.write(master, b"s\n")  # one step of 0.02 s, paused again
        assert not said("finished", 2)
        os.write(master, b"p\n")  # play on
        assert said("finished", 30), err  # the page is still served until q
        assert proc.poll() is None
        os.write(master, b"q\n")
        out = proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
        os.close(slave)
    assert proc.returncode == 0, err
    assert "survived" in out


# -- frames posed and keyed in batches --------------------------------------------------------------------------------
def _frames(desc, n: int, seed: int = 0) -> list[VizFrame]:
    """n frames of a moving robot with pushes, foot forces, commands and an MPC-like plan on some of them."""
    rng = np.random.default_rng(seed)
    frames = []
    for i in range(n):
        t = 0.02 * i
        quat = np.r_[1.0, 0.1 * rng.standard_normal(3)]
        joints = desc.nominal_q + 0.2 * rng.standard_normal(desc.num_joints)
        q = np.r_[0.01 * i, 0.0, 0.3, quat / np.linalg.norm(quat), joints]
        pushed = 40 <= i % 97 < 50
        forces = None if i % 11 == 0 else rng.uniform(-5.0, 60.0, (4, 3))
        plan = None
        if i % 7 < 4:
            steps = 10
            plan = {"com_path_in_world": q[:3] + 0.01 * rng.standard_normal((steps, 3)),
                    "footholds_in_world": rng.uniform(-0.3, 0.3, (4, 3)),
                    "contact_schedule": rng.random((steps, 4)) < 0.5,
                    "forces_in_world": rng.uniform(-10.0, 80.0, (steps, 4, 3)),
                    "arm_q_plan": 0.3 * rng.standard_normal((steps, 3))}
        frames.append(VizFrame(t=t, qpos=q, command=np.array([0.5 * (i % 3 != 0), 0.1, 0.3]),
                               push_force_in_world=np.array([0.0, 150.0, 10.0]) if pushed else np.zeros(3),
                               push_point_in_world=q[:3] + 0.05, foot_force_in_world=forces, plan=plan))
    return frames


@pytest.mark.parametrize("by_pinocchio", [False, True])
def test_batched_poses_are_each_frame_posed_alone(by_pinocchio, monkeypatch):
    if by_pinocchio:  # joints the batch does not pose itself: the kinematics falls back on Pinocchio
        monkeypatch.setattr("wbc.viz.scene._REVOLUTE", {})
    desc = get_robot("a1-wx200", "actuated")
    content = SceneContent(desc, TerrainConfig(), None)
    frames = _frames(desc, 60)
    batch = content.poses_many(frames)
    alone = [content.poses(f) for f in frames]
    paths = {p for poses in alone for p in poses}
    assert paths == set(batch)
    for path in paths:
        posed = [i for i, poses in enumerate(alone) if path in poses]
        track = batch[path]
        np.testing.assert_array_equal(track.frames, posed, err_msg=path)
        np.testing.assert_array_equal(track.visible, [alone[i][path].visible for i in posed], err_msg=path)
        np.testing.assert_allclose(track.matrices, [alone[i][path].matrix for i in posed], atol=1e-12, err_msg=path)
    # what the batch covers: pushes on and off, foot forces missing on some frames, plans on some
    assert 0 < batch["wbc/push/shaft"].frames.size < len(frames)
    assert batch["wbc/contacts/FR"].visible.sum() < len(frames)
    assert 0 < batch["wbc/plan/com/0"].frames.size < len(frames)


def test_recording_keys_alike_in_chunks_and_frame_by_frame():
    desc = get_robot("a1-wx200", "actuated")
    frames = _frames(desc, 600, seed=1)  # past two chunks of 256
    chunked = Recording(SceneContent(desc, TerrainConfig(), None), fps=50.0)
    single = Recording(SceneContent(desc, TerrainConfig(), None), fps=50.0)
    for f in frames:
        assert chunked.add(f)
        assert single.add(f)
        single._tracks()  # keys what is pending: one frame at a time
    a = {(path, prop): (frames, values) for path, prop, _, frames, values in chunked._tracks()}
    b = {(path, prop): (frames, values) for path, prop, _, frames, values in single._tracks()}
    assert set(a) == set(b)  # the same tracks (in another order: a track comes where its node was first keyed)
    for (path, prop), (fa, va) in a.items():
        fb, vb = b[(path, prop)]
        np.testing.assert_array_equal(fa, fb, err_msg=f"{path} {prop}")
        if prop == "visible":
            assert va == vb, path
        else:
            np.testing.assert_allclose(va, vb, atol=1e-12, err_msg=f"{path} {prop}")
    assert chunked.frames == single.frames == len(frames)


def test_plot_values_round_alike_sampled_at_once_and_one_by_one():
    from wbc.viz.signals import _r, _round4

    rng = np.random.default_rng(3)
    x = np.concatenate([rng.standard_normal(20000) * 10.0 ** rng.uniform(-7, 6, 20000),
                        np.round(rng.standard_normal(2000), 5),  # many exact ties at the fifth digit
                        [0.12345, -0.00012345, 12345.0, 99995.0, 0.0, -0.0, np.nan, np.inf, -np.inf, 2.5e-5]])
    at_once = _round4(x)
    alone = np.array([np.nan if _r(v) is None else _r(v) for v in x.tolist()])
    np.testing.assert_array_equal(at_once, alone)


def _same_parts(a, b):
    assert [(p.name, p.joint, p.joint_id, p.color, p.is_arm, type(p.geometry)) for p in a] == \
        [(p.name, p.joint, p.joint_id, p.color, p.is_arm, type(p.geometry)) for p in b]
    for p, q in zip(a, b, strict=True):
        np.testing.assert_array_equal(p.placement, q.placement)
        if hasattr(p.geometry, "vertices"):
            np.testing.assert_array_equal(p.geometry.vertices, q.geometry.vertices)
            np.testing.assert_array_equal(p.geometry.faces, q.geometry.faces)
        else:
            keep = {k: v for k, v in vars(p.geometry).items() if k != "uuid"}
            assert keep == {k: v for k, v in vars(q.geometry).items() if k != "uuid"}


def test_robot_parts_come_back_the_same_from_the_cache(tmp_path, monkeypatch):
    from wbc.robots.pinocchio_model import build_pinocchio
    from wbc.viz import meshes

    desc = get_robot("a1-wx200", "actuated")
    robot = build_pinocchio(desc, with_visuals=True)
    built = meshes.visual_parts(robot.model, robot.visual_model)
    monkeypatch.setenv(meshes.CACHE_ENV, str(tmp_path / "cache"))
    first = meshes.robot_parts(desc, robot.model)  # builds them and writes the cache
    files = list((tmp_path / "cache").glob("parts-*.npz"))
    assert len(files) == 1
    monkeypatch.setattr(meshes, "build_pinocchio", lambda *a, **k: pytest.fail("the cache was not read"))
    cached = meshes.robot_parts(desc, robot.model)
    _same_parts(built, first)
    _same_parts(built, cached)
    assert any(hasattr(p.geometry, "vertices") for p in cached)  # the meshes, not only the primitives
    # another robot or arm mode is another file
    monkeypatch.undo()
    monkeypatch.setenv(meshes.CACHE_ENV, str(tmp_path / "cache"))
    meshes.robot_parts(get_robot("a1-wx200", "none"), build_pinocchio(get_robot("a1-wx200", "none")).model)
    assert len(list((tmp_path / "cache").glob("parts-*.npz"))) == 2


def test_a_broken_or_unwritable_cache_only_costs_the_rebuild(tmp_path, monkeypatch):
    from wbc.robots.pinocchio_model import build_pinocchio
    from wbc.viz import meshes

    desc = get_robot("a1-wx200", "locked")
    model = build_pinocchio(desc).model
    monkeypatch.setenv(meshes.CACHE_ENV, str(tmp_path))
    good = meshes.robot_parts(desc, model)
    (file,) = tmp_path.glob("parts-*.npz")
    file.write_bytes(b"not a cache file")
    again = meshes.robot_parts(desc, model)  # rebuilt, and the file rewritten
    _same_parts(good, again)
    assert file.read_bytes() != b"not a cache file"
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    monkeypatch.setenv(meshes.CACHE_ENV, str(blocked / "cache"))  # a directory that cannot be made
    _same_parts(good, meshes.robot_parts(desc, model))
