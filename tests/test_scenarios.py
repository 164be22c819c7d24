"""Scenario files: loading, validation messages, content hashing, the publication lock and seeded sampling."""

import dataclasses
import hashlib
import json
import math
import random
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from wbc.errors import ConfigError, UnknownNameError, WbcError
from wbc.scenario import (
    CommandChange,
    ScenarioError,
    check_published,
    load_scenario,
    trial_scenario_text,
    warn_if_unpublished,
    write_trial_scenario,
)
from wbc.types import VelocityCommand

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
PUSH = SCENARIOS / "push-v1.toml"  # push version 1: the tests below pin its values, hash and trials
PUSH_CURRENT = SCENARIOS / "push.toml"  # the current version of the push task
PUSH_V2_DURATION_S = 0.09  # [s] push version 2's calibrated push duration (its notes say how)
TURN = SCENARIOS / "turn.toml"
TURN_BOTH_WAYS = SCENARIOS / "turn-both-ways.toml"

# Line numbers matter: the broken-file cases below assert them.
BASE = """\
# Base scenario for the broken-file tests.
[scenario]
name = "base"
version = 1
description = "A valid scenario that the tests break one edit at a time."
robot = "a1-wx200"
duration_s = 10.0

[terrain]
kind = "fractal"
amplitude_m = 0.05

[domain]
friction = [0.8, 1.0]

[commands]
ramp_s = 0.5

[[commands.options]]
vx = 0.0

[[commands.options]]
vx = 0.3

[pushes]
first_s = [2.0, 3.0]
interval_s = [4.0, 6.0]
duration_s = 0.05
offset_m = 0.12

[[bands]]
name = "in"
push_force_n = [200.0, 300.0]

[[bands]]
name = "ood"
push_force_n = [300.0, 400.0]
"""

OPTIONS = "[[commands.options]]\nvx = 0.0\n\n[[commands.options]]\nvx = 0.3\n"
# Appended to BASE: its header on line 39, start_s 40, duration_s 41, force_n 42, offset_m 43.
FIXED = ("\n[[fixed_pushes]]\nstart_s = 3.0\nduration_s = 0.05\nforce_n = [100.0, 0.0, 0.0]\n"
         "offset_m = [0.0, 0.1, 0.0]\n")
# Inserted after the second option: its header on line 25, at_s 26, vx 27.
CHANGE = "vx = 0.3\n\n[[commands.changes]]\nat_s = 4.0\nvx = 0.5\n"
PUSHES = "[pushes]\nfirst_s = [2.0, 3.0]\ninterval_s = [4.0, 6.0]\nduration_s = 0.05\noffset_m = 0.12\n"
BANDS = BASE[BASE.index("[[bands]]") :]
SCENARIO_TABLE = BASE[BASE.index("[scenario]") : BASE.index("[terrain]")]


def write(tmp_path: Path, text: str, name: str = "case.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def edit(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, f"the edit's target {old!r} must occur exactly once"
    return text.replace(old, new)


def assert_same(a, b, path="trial"):
    """Deep equality of dataclasses / tuples / numpy arrays / scalars."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert np.array_equal(a, b), path
    elif isinstance(a, tuple | list):
        assert len(a) == len(b), path
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{k}]")
    else:
        assert a == b, path


def trials_equal(a, b) -> bool:
    try:
        assert_same(a, b)
    except AssertionError:
        return False
    return True


# ------------------------------------------------------------------------------------------------------------------
# Shipped files, hashing, lock


def test_base_file_is_valid(tmp_path):
    s = load_scenario(write(tmp_path, BASE))
    assert s.name == "base" and s.bands == ("in", "ood") and s.duration_s == 10.0


def test_shipped_scenarios_load_and_are_published():
    push, current, turn = load_scenario(PUSH), load_scenario(PUSH_CURRENT), load_scenario(TURN)
    assert (push.name, push.version, push.robot, push.bands) == ("push", 1, "a1-wx200", ("in", "ood"))
    assert (current.name, current.version, current.robot, current.bands) == ("push", 2, "a1-wx200", ("in", "ood"))
    assert (turn.name, turn.version, turn.robot, turn.bands) == ("turn", 2, "go1-arm", ("1.0", "1.25", "1.5"))
    assert push.duration_s == current.duration_s == turn.duration_s == 20.0
    assert "calibrat" in push.notes and "stand" in push.notes
    assert "calibrat" in current.notes and "learned-locked" in current.notes and "mpc-locked" in current.notes
    for s in (push, current, turn):
        assert len(s.hash) == 64 and int(s.hash, 16) >= 0
        check_published(s)
        check_published(s, SCENARIOS / "published.toml")


def test_every_shipped_scenario_is_published_and_the_push_variants_differ_from_push_only_where_they_say():
    for path in sorted(SCENARIOS.glob("*.toml")):
        if path.name != "published.toml":
            check_published(load_scenario(path))
    push = load_scenario(PUSH)
    slippery = load_scenario(SCENARIOS / "push-low-friction.toml")
    strong = load_scenario(SCENARIOS / "push-strong.toml")
    for variant in (slippery, strong):
        assert variant.robot == push.robot and variant.bands == push.bands and variant.duration_s == push.duration_s
    a, b, c = push.trial("in", 0, 3), slippery.trial("in", 0, 3), strong.trial("in", 0, 3)
    assert 0.4 <= b.domain.friction <= 0.5 and b.terrain == a.terrain
    assert [p.duration for p in c.pushes] == [0.10] * len(c.pushes) and 0.0 <= c.domain.payload_mass <= 1.0


def test_push_version_2_differs_from_version_1_only_in_the_push_duration_and_both_are_published():
    v1, v2 = tomllib.loads(PUSH.read_text()), tomllib.loads(PUSH_CURRENT.read_text())
    assert (v1["scenario"]["name"], v1["scenario"]["version"]) == ("push", 1)
    assert (v2["scenario"]["name"], v2["scenario"]["version"]) == ("push", 2)
    assert v1["pushes"]["duration_s"] == 0.06
    assert v2["pushes"]["duration_s"] == PUSH_V2_DURATION_S
    # the notes keep version 1's reasoning word for word and add version 2's calibration
    assert v1["scenario"]["notes"] in v2["scenario"]["notes"]
    for data in (v1, v2):
        for key in ("version", "notes"):
            del data["scenario"][key]
        del data["pushes"]["duration_s"]
    assert v1 == v2  # robot, description, bands, offsets, commands, terrain, domain: all the same
    lock = tomllib.loads((SCENARIOS / "published.toml").read_text())
    first, second = load_scenario(PUSH), load_scenario(PUSH_CURRENT)
    assert lock["push"] == {"1": first.hash, "2": second.hash}
    check_published(first)
    check_published(second)
    # its trials are drawn from the same distribution (not the same draws: the content hash seeds the sampling)
    for trial in second.trials(None, [0, 1], 20):
        assert all(p.duration == PUSH_V2_DURATION_S for p in trial.pushes) and 3 <= len(trial.pushes) <= 5


def test_hash_ignores_comments_layout_and_key_order_but_not_values(tmp_path):
    text = PUSH.read_text()
    reference = load_scenario(PUSH).hash
    relaid = "# a new comment\n\n" + text.replace("vx = 0.3", "vx=0.3   # walking, re-commented").replace(
        'kind = "fractal"\namplitude_m = 0.05', 'amplitude_m = 0.05\n\n\nkind   =   "fractal"'
    )
    assert relaid != text
    assert load_scenario(write(tmp_path, relaid)).hash == reference
    for old, new in [("offset_m = 0.12", "offset_m = 0.13"), ("version = 1", "version = 2"),
                     ('name = "ood"', 'name = "out"'), ("Push timing", "Push  timing")]:
        assert load_scenario(write(tmp_path, edit(text, old, new))).hash != reference, old


def test_changed_published_file_is_refused(tmp_path):
    shutil.copy(SCENARIOS / "published.toml", tmp_path / "published.toml")
    changed = load_scenario(write(tmp_path, edit(PUSH.read_text(), "offset_m = 0.12", "offset_m = 0.1"), "push.toml"))
    with pytest.raises(ScenarioError) as err:
        check_published(changed)
    assert "without a version bump" in str(err.value) and "bump [scenario] version" in str(err.value)
    assert str(tmp_path / "push.toml") in str(err.value)


def test_a_lock_beside_a_copy_cannot_publish_other_content_under_the_toolkits_name_and_version(tmp_path, capsys):
    """A lock beside any file publishes what it lists: a copy of push.toml with one value changed, beside a lock that
    listed its hash as push version 2, played as the published push v2 (run.json: published, report: yes). The
    toolkit's names and versions are its own; a scenario of another name publishes in any lock."""
    changed = write(tmp_path, edit(PUSH.read_text(), "offset_m = 0.12", "offset_m = 0.1"), "push.toml")
    scenario = load_scenario(changed)
    write(tmp_path, f'[push]\n"{scenario.version}" = "{scenario.hash}"\n', "published.toml")
    with pytest.raises(ScenarioError) as err:
        check_published(scenario)
    text = str(err.value)
    assert "the toolkit's published scenario" in text and str(SCENARIOS / "published.toml") in text
    assert scenario.hash in text and err.value.field == "[scenario] name"
    assert not warn_if_unpublished(scenario) and "the toolkit's published scenario" in capsys.readouterr().err
    # renamed, the same content publishes in its own lock
    mine = load_scenario(write(tmp_path, edit(changed.read_text(), 'name = "push"', 'name = "my-push"'), "mine.toml"))
    write(tmp_path, f'[my-push]\n"{mine.version}" = "{mine.hash}"\n', "published.toml")
    check_published(mine)
    # the toolkit's own file, beside the toolkit's own lock, is published as ever
    check_published(load_scenario(PUSH))


def test_an_unpublished_copy_under_the_toolkits_name_is_told_to_take_a_name_of_its_own(tmp_path):
    """The unpublished message gave the lines that publish an edited copy of push.toml as push version 2 in a lock
    beside it, which the next run then refused as the toolkit's name and version; it now gives a name of its own and
    the lines that publish the file under it, which the next run accepts."""
    changed = write(tmp_path, edit(PUSH.read_text(), "offset_m = 0.12", "offset_m = 0.1"), "push.toml")
    scenario = load_scenario(changed)
    lock = tmp_path / "published.toml"
    for lock_text in (None, "[other]\n\"1\" = \"00\"\n"):  # no lock beside it, then a lock that does not list it
        if lock_text is not None:
            lock.write_text(lock_text)
        with pytest.raises(ScenarioError) as err:
            check_published(scenario)
        text = str(err.value)
        assert "unpublished" in text and "the toolkit's published scenario" in text
        assert err.value.field == "[scenario] name"
        assert 'name = "my-push"' in text and "[push]" not in text
        lines = text[text.index("[my-push]"):text.index(f"to {lock}")]
    renamed = load_scenario(write(tmp_path, edit(changed.read_text(), 'name = "push"', 'name = "my-push"'),
                                  "push.toml"))
    assert renamed.hash in lines
    lock.write_text(lines)
    check_published(renamed)


def test_unpublished_version_is_refused_with_the_fix(tmp_path):
    lock = write(tmp_path, (SCENARIOS / "published.toml").read_text(), "lock.toml")
    bumped = load_scenario(write(tmp_path, edit(PUSH.read_text(), "version = 1", "version = 3"), "push.toml"))
    with pytest.raises(ScenarioError) as err:
        check_published(bumped, lock)
    text = str(err.value)
    assert "unpublished" in text and bumped.hash in text and '"3"' in text and str(lock) in text
    with pytest.raises(ScenarioError, match="does not exist"):
        check_published(bumped)  # no published.toml next to this copy


def test_malformed_lock_is_a_scenario_error(tmp_path):
    s = load_scenario(PUSH)
    with pytest.raises(ScenarioError) as err:
        check_published(s, write(tmp_path, "[push]\n\"1\" = 5\n", "lock.toml"))
    assert err.value.line == 2
    with pytest.raises(ScenarioError, match="invalid TOML"):
        check_published(s, write(tmp_path, "[push\n", "lock.toml"))


# ------------------------------------------------------------------------------------------------------------------
# Sampling


def test_trials_are_reproducible_across_loads():
    a, b = load_scenario(PUSH), load_scenario(PUSH)
    for band, seed, index in [("in", 0, 0), ("ood", 3, 7), ("in", 12345, 99)]:
        assert_same(a.trial(band, seed, index), b.trial(band, seed, index))
    t = a.trial("in", 0, 0)
    assert (t.scenario, t.scenario_hash, t.robot, t.key, t.duration_s) == ("push", a.hash, "a1-wx200", ("in", 0, 0),
                                                                            20.0)
    assert t.terrain.kind == "fractal" and t.terrain.amplitude == 0.05
    assert 0.8 <= t.domain.friction <= 1.0 and t.domain.payload_mass == 0.0 and t.domain.motor_strength == 1.0


def test_different_index_or_seed_gives_a_different_trial():
    s = load_scenario(PUSH)
    t = s.trial("in", 0, 0)
    for other in (s.trial("in", 0, 1), s.trial("in", 1, 0)):
        assert other.terrain_seed != t.terrain_seed
        assert not trials_equal(other, t)


def test_bands_share_everything_but_their_own_values():
    s = load_scenario(PUSH)
    for seed, index in [(0, 0), (1, 5), (7, 31)]:
        a, b = s.trial("in", seed, index), s.trial("ood", seed, index)
        assert a.terrain_seed == b.terrain_seed
        assert_same(a.domain, b.domain)
        assert_same(a.command, b.command)
        assert len(a.pushes) == len(b.pushes) > 0
        for pa, pb in zip(a.pushes, b.pushes, strict=True):
            assert pa.start == pb.start and pa.duration == pb.duration
            assert np.array_equal(pa.offset_in_base, pb.offset_in_base)
            heading_a = np.arctan2(pa.force_in_world[1], pa.force_in_world[0])
            heading_b = np.arctan2(pb.force_in_world[1], pb.force_in_world[0])
            assert heading_a == pytest.approx(heading_b, abs=1e-12)
            assert 200.0 <= np.linalg.norm(pa.force_in_world) <= 300.0
            assert 300.0 <= np.linalg.norm(pb.force_in_world) <= 400.0
            # the same u maps into each band: F_ood - 300 == F_in - 200
            assert np.linalg.norm(pb.force_in_world) - 300 == pytest.approx(np.linalg.norm(pa.force_in_world) - 200)


def test_trials_order_count_and_independence_of_request_order():
    s = load_scenario(PUSH)
    batch = s.trials(None, [3, 1], 4)
    assert [t.key for t in batch] == [(b, sd, i) for b in ("in", "ood") for sd in (3, 1) for i in range(4)]
    assert len(s.trials(["ood"], [0, 1, 2], 5)) == 15
    assert [t.key for t in s.trials("ood", [0], 2)] == [("ood", 0, 0), ("ood", 0, 1)]
    assert s.trials(None, [0], 0) == []
    shuffled = list(batch)
    random.Random(0).shuffle(shuffled)
    fresh = load_scenario(PUSH)
    for t in shuffled:
        assert_same(fresh.trial(t.band, t.seed, t.index), t)


def test_push_statistics():
    s = load_scenario(PUSH)
    trials = s.trials(["in"], [0], 400)
    walking = sum(t.command.vx == 0.3 for t in trials)
    standing = sum(t.command.vx == 0.0 for t in trials)
    assert walking + standing == 400 and 150 <= walking <= 250
    assert all(t.command.ramp_s == 0.5 and t.command.vy == 0.0 and t.command.yaw_rate == 0.0 for t in trials)
    axes = [0, 0]
    for t in trials:
        assert 3 <= len(t.pushes) <= 5
        starts = [p.start for p in t.pushes]
        assert 2.0 <= starts[0] <= 3.0
        assert all(4.0 - 1e-9 <= b - a <= 6.0 + 1e-9 for a, b in zip(starts, starts[1:], strict=False))
        assert starts[-1] < t.duration_s
        for p in t.pushes:
            off = p.offset_in_base
            assert off[2] == 0.0 and np.count_nonzero(off[:2]) == 1 and np.all(np.abs(off) <= 0.12)
            axes[int(off[1] != 0.0)] += 1
            assert p.force_in_world[2] == 0.0 and 200.0 <= np.linalg.norm(p.force_in_world) <= 300.0
            assert p.duration == 0.06  # the calibrated push duration
    assert 0.4 < axes[0] / sum(axes) < 0.6
    frictions = np.array([t.domain.friction for t in trials])
    assert frictions.min() >= 0.8 and frictions.max() <= 1.0 and frictions.std() > 0.03


def test_turn_statistics():
    s = load_scenario(TURN)
    trials = s.trials(None, [0], 150)
    for t in trials:
        assert t.pushes == () and t.terrain.kind == "flat" and t.command.ramp_s == 1.0
        assert t.command.vx == float(t.band)
        assert t.command.yaw_rate in (0.5, 2.0)
    fast = sum(t.command.yaw_rate == 2.0 for t in trials)
    assert 0.4 * len(trials) < fast < 0.6 * len(trials)
    # version 2 randomises friction, so trials of one band and yaw rate are not all the same episode
    frictions = np.array([t.domain.friction for t in trials])
    assert frictions.min() >= 0.8 and frictions.max() <= 1.0
    assert len(np.unique(frictions)) == len(trials) // len(s.bands)  # bands share (seed, index) draws


def test_turn_both_ways_statistics():
    s = load_scenario(TURN_BOTH_WAYS)
    assert s.robot == "go1-arm" and s.bands == ("stand", "1.0", "1.5", "2.0")
    trials = s.trials(None, [0], 200)
    for t in trials:
        assert t.pushes == () and t.terrain.kind == "flat" and t.command.ramp_s == 1.0 and t.command.vy == 0.0
        if t.band == "stand":
            assert t.command.vx == 0.0 and t.command.yaw_rate == 0.0 and math.copysign(1.0, t.command.yaw_rate) > 0
        else:
            assert t.command.vx == float(t.band) and t.command.yaw_rate in (0.0, 0.5, -0.5, 2.0, -2.0)
    moving = [t.command.yaw_rate for t in trials if t.band == "2.0"]
    for yaw in (0.0, 0.5, -0.5, 2.0, -2.0):  # five options drawn uniformly
        assert 0.12 < moving.count(yaw) / len(moving) < 0.28


def test_band_yaw_rate_overrides_the_option_and_keeps_its_sign_flip(tmp_path):
    text = edit(BASE, "[[commands.options]]\nvx = 0.3\n", "[[commands.options]]\nyaw_rate = 1.0\nrandom_sign = true\n")
    text = edit(text, 'name = "ood"', 'name = "ood"\nyaw_rate = 2.5')
    s = load_scenario(write(tmp_path, text))
    for i in range(200):
        a, b = s.trial("in", 0, i), s.trial("ood", 0, i)
        if a.command.yaw_rate == 0.0:  # the first option: no yaw of its own, but band ood turns at 2.5
            assert b.command.yaw_rate == 2.5
        else:
            assert b.command.yaw_rate == 2.5 * a.command.yaw_rate  # the same option, the same sign flip
    assert {s.trial("ood", 0, i).command.yaw_rate for i in range(200)} == {2.5, -2.5}


def _canonical_trial(t) -> list:
    """Every value of a trial but its delays, exactly (floats as hex): what a published file's trials must keep."""
    f = lambda x: float(x).hex()  # noqa: E731
    d = t.domain
    return [t.band, t.seed, t.index, t.terrain_seed, f(d.friction), f(d.payload_mass),
            [f(x) for x in np.atleast_1d(d.motor_strength)], [f(x) for x in d.payload_com],
            [f(t.command.vx), f(t.command.vy), f(t.command.yaw_rate), f(t.command.ramp_s)],
            [[[f(x) for x in p.force_in_world], [f(x) for x in p.offset_in_base], f(p.start), f(p.duration)]
             for p in t.pushes]]


# sha256 of the canonical trials of seeds 0, 1, 7, indices 0..4, every band, recorded before the delay ranges existed
PUBLISHED_TRIALS = {
    "push": "e9d6c351abb779b90dad691a1fa4349620c4f98774479dcbbb13f719ba938f02",
    "turn": "802f3fa7594dc79e08262267c35acb8b50f903dff5b0bba8d2980f1de80adf21",
}


@pytest.mark.parametrize("path", [PUSH, TURN], ids=["push", "turn"])
def test_published_files_sample_the_trials_they_sampled_before_delay_ranges_existed(path):
    s = load_scenario(path)
    check_published(s)  # the hash is unchanged too (absent keys are not in the parsed content)
    trials = s.trials(None, [0, 1, 7], 5)
    digest = hashlib.sha256(json.dumps([_canonical_trial(t) for t in trials]).encode()).hexdigest()
    assert digest == PUBLISHED_TRIALS[s.name]
    assert all(t.domain.actuation_delay == 0.0 and t.domain.sensing_delay == 0.0 for t in trials)


def test_delay_ranges_are_drawn_per_trial_only_when_declared(tmp_path):
    both = load_scenario(write(tmp_path, edit(
        BASE, "friction = [0.8, 1.0]", "friction = [0.8, 1.0]\nactuation_delay_s = [0.002, 0.02]\n"
        "sensing_delay_s = [0.0, 0.004]"), "both.toml"))
    trials = both.trials(None, [0, 1], 20)
    act = np.array([t.domain.actuation_delay for t in trials])
    sense = np.array([t.domain.sensing_delay for t in trials])
    assert act.min() >= 0.002 and act.max() <= 0.02 and act.std() > 0.003
    assert sense.min() >= 0.0 and sense.max() <= 0.004 and sense.std() > 0.0005
    assert not np.array_equal(act / 0.018, sense / 0.004)  # two draws, not one mapped twice
    assert_same(both.trial("in", 1, 3), load_scenario(tmp_path / "both.toml").trial("in", 1, 3))
    only = load_scenario(write(tmp_path, edit(BASE, "friction = [0.8, 1.0]", "actuation_delay_s = [0.01, 0.01]"),
                               "only.toml"))
    for t in only.trials(None, [0], 5):
        assert t.domain.actuation_delay == 0.01 and t.domain.sensing_delay == 0.0 and t.domain.friction == 1.0
    # a declared range is content: it changes the hash, so such a file is a new scenario (or version)
    assert only.hash != load_scenario(write(tmp_path, edit(BASE, "friction = [0.8, 1.0]", ""), "none.toml")).hash


def test_fixed_pushes_command_changes_and_terrain_seed_reach_every_trial(tmp_path):
    text = edit(edit(BASE, "vx = 0.3\n", CHANGE), "amplitude_m = 0.05", "amplitude_m = 0.05\nseed = 12345")
    text += FIXED + FIXED.replace("start_s = 3.0", "start_s = 0.25").replace("[100.0, 0.0, 0.0]", "[0.0, -80.5, 10.0]")
    s = load_scenario(write(tmp_path, text))
    assert s.hash != load_scenario(write(tmp_path, BASE, "base.toml")).hash
    for t in s.trials(None, [0, 1], 4):
        assert t.terrain_seed == 12345
        starts = [p.start for p in t.pushes]
        assert starts == sorted(starts)
        first = [p for p in t.pushes if np.array_equal(p.force_in_world, [0.0, -80.5, 10.0])]
        second = [p for p in t.pushes if np.array_equal(p.force_in_world, [100.0, 0.0, 0.0])]
        assert len(first) == len(second) == 1
        assert (first[0].start, first[0].duration, list(first[0].offset_in_base)) == (0.25, 0.05, [0.0, 0.1, 0.0])
        assert (second[0].start, second[0].duration) == (3.0, 0.05)
        lo, hi = (200.0, 300.0) if t.band == "in" else (300.0, 400.0)
        drawn = [p for p in t.pushes if p is not first[0] and p is not second[0]]
        assert drawn and all(lo <= np.linalg.norm(p.force_in_world) <= hi for p in drawn)  # [pushes] still draws
        # the command: the drawn option up to the change, the change's command from then on, held
        assert t.command.at(3.999) == VelocityCommand(vx=t.command.vx)
        assert t.command.at(4.0) == t.command.at(9.9) == VelocityCommand(vx=0.5)
    # without a [pushes] table, the fixed pushes are a trial's only pushes
    only = load_scenario(write(tmp_path, edit(edit(BASE, PUSHES, ""), "push_force_n = [200.0, 300.0]\n", "")
                               .replace("push_force_n = [300.0, 400.0]\n", "") + FIXED, "only.toml"))
    assert [(p.start, list(p.force_in_world)) for p in only.trial("ood", 2, 1).pushes] == [(3.0, [100.0, 0.0, 0.0])]


def test_a_trial_written_as_a_scenario_file_is_every_trial_of_it(tmp_path):
    trial = load_scenario(PUSH_CURRENT).trial("ood", 1, 3)
    change = CommandChange(at_s=5.0, command=VelocityCommand(vx=0.2, yaw_rate=-0.5))
    played = dataclasses.replace(trial, command=dataclasses.replace(trial.command, changes=(change,)),
                                 domain=dataclasses.replace(trial.domain, actuation_delay=0.013))
    path = tmp_path / "frozen.toml"
    written = write_trial_scenario(path, played, name="frozen", description="one trial, frozen", header="kept")
    text = path.read_text()
    assert text.startswith("# kept\n") and written.hash in text and written.bands == ("ood",)
    for seed, index in ((0, 0), (4, 9)):
        assert_same(written.trial("ood", seed, index), dataclasses.replace(
            played, scenario="frozen", scenario_hash=written.hash, seed=seed, index=index))
    # what a scenario file cannot say is refused, not approximated
    off_centre = dataclasses.replace(trial, domain=dataclasses.replace(trial.domain, payload_com=np.ones(3) * 0.01))
    with pytest.raises(ConfigError, match="payload"):
        trial_scenario_text(off_centre, name="x", description="x")


def test_random_sign_flips_about_half(tmp_path):
    text = edit(BASE, "[[commands.options]]\nvx = 0.3\n", "[[commands.options]]\nyaw_rate = 1.0\nrandom_sign = true\n")
    s = load_scenario(write(tmp_path, text))
    yaw = [t.command.yaw_rate for t in s.trials(["in"], [0], 400) if t.command.yaw_rate != 0.0]
    assert set(yaw) == {1.0, -1.0} and 0.35 < yaw.count(-1.0) / len(yaw) < 0.65


def test_unknown_band_lists_the_bands():
    s = load_scenario(PUSH)
    for call in (lambda: s.trial("mid", 0, 0), lambda: s.trials(["in", "mid"], [0], 1)):
        with pytest.raises(UnknownNameError) as err:
            call()
        assert "'mid'" in str(err.value) and "in" in err.value.valid and "ood" in err.value.valid


def test_bad_seed_is_refused():
    s = load_scenario(PUSH)
    for seed in (-1, 1.5, True):
        with pytest.raises(WbcError, match="seed"):
            s.trial("in", seed, 0)


# ------------------------------------------------------------------------------------------------------------------
# Broken files: (id, edited text, field named in the message, exact line or None)

BROKEN = [
    ("toml-syntax", edit(BASE, "version = 1", "version = = 1"), None, 4),
    ("toml-duplicate-key", edit(BASE, "kind = \"fractal\"", "kind = \"fractal\"\nkind = \"flat\""),
     "[terrain] kind", 11),
    ("toml-duplicate-table", BASE + "\n[terrain]\nkind = \"flat\"\n", "[terrain]", 39),
    ("toml-duplicate-band-key", edit(BASE, 'name = "ood"', 'name = "ood"\nname = "far"'), "[[bands]] #2 name", 37),
    ("toml-duplicate-multiline", edit(BASE, "friction = [0.8, 1.0]", "friction = [0.8, 1.0]\nfriction = [\n  0.8,\n"
                                                                      "  1.0,\n]"), "[domain] friction", 15),
    ("missing-scenario", edit(BASE, SCENARIO_TABLE, ""), "[scenario]", None),
    ("missing-name", edit(BASE, 'name = "base"\n', ""), "[scenario] name", 2),
    ("bad-name", edit(BASE, 'name = "base"', 'name = "Base!"'), "[scenario] name", 3),
    ("version-string", edit(BASE, "version = 1", 'version = "1"'), "[scenario] version", 4),
    ("version-bool", edit(BASE, "version = 1", "version = true"), "[scenario] version", 4),
    ("version-zero", edit(BASE, "version = 1", "version = 0"), "[scenario] version", 4),
    ("version-too-big", edit(BASE, "version = 1", "version = 1000001"), "[scenario] version", 4),
    ("version-huge", edit(BASE, "version = 1", "version = 99999999999999999999999"), "[scenario] version", 4),
    ("empty-description", edit(BASE, '"A valid scenario that the tests break one edit at a time."', '"  "'),
     "[scenario] description", 5),
    ("unknown-robot", edit(BASE, '"a1-wx200"', '"spot"'), "[scenario] robot", 6),
    ("duration-zero", edit(BASE, "duration_s = 10.0", "duration_s = 0"), "[scenario] duration_s", 7),
    ("duration-too-long", edit(BASE, "duration_s = 10.0", "duration_s = 601"), "[scenario] duration_s", 7),
    ("duration-string", edit(BASE, "duration_s = 10.0", 'duration_s = "10"'), "[scenario] duration_s", 7),
    ("duration-nan", edit(BASE, "duration_s = 10.0", "duration_s = nan"), "[scenario] duration_s", 7),
    ("unknown-key-scenario", edit(BASE, "version = 1\n", "version = 1\ncolour = 'red'\n"), "[scenario] colour", 5),
    ("missing-terrain", edit(BASE, '[terrain]\nkind = "fractal"\namplitude_m = 0.05\n', ""), "[terrain]", None),
    ("bad-kind", edit(BASE, '"fractal"', '"hilly"'), "[terrain] kind", 10),
    ("amplitude-too-big", edit(BASE, "amplitude_m = 0.05", "amplitude_m = 0.5"), "[terrain] amplitude_m", 11),
    ("octaves-float", edit(BASE, "amplitude_m = 0.05", "amplitude_m = 0.05\noctaves = 2.5"), "[terrain] octaves",
     12),
    ("unknown-key-terrain", edit(BASE, "amplitude_m = 0.05", "amplitude_m = 0.05\nroughness = 1"),
     "[terrain] roughness", 12),
    ("terrain-not-table", edit(edit(BASE, '[terrain]\nkind = "fractal"\namplitude_m = 0.05\n', ""),
                               "# Base", 'terrain = "flat"\n# Base'), "[terrain]", 1),
    ("friction-zero", edit(BASE, "friction = [0.8, 1.0]", "friction = [0.0, 1.0]"), "[domain] friction", 14),
    ("friction-reversed", edit(BASE, "friction = [0.8, 1.0]", "friction = [1.0, 0.8]"), "[domain] friction", 14),
    ("friction-three", edit(BASE, "friction = [0.8, 1.0]", "friction = [0.8, 0.9, 1.0]"), "[domain] friction", 14),
    ("friction-string", edit(BASE, "friction = [0.8, 1.0]", 'friction = ["a", 1.0]'), "[domain] friction", 14),
    ("friction-scalar", edit(BASE, "friction = [0.8, 1.0]", "friction = 0.9"), "[domain] friction", 14),
    ("payload-too-big", edit(BASE, "friction = [0.8, 1.0]", "payload_kg = [0.0, 25.0]"), "[domain] payload_kg", 14),
    ("unknown-key-domain", edit(BASE, "friction = [0.8, 1.0]", "gravity = [9.8, 9.8]"), "[domain] gravity", 14),
    ("delay-too-long", edit(BASE, "friction = [0.8, 1.0]", "friction = [0.8, 1.0]\nactuation_delay_s = [0.0, 0.5]"),
     "[domain] actuation_delay_s", 15),
    ("delay-negative", edit(BASE, "friction = [0.8, 1.0]", "sensing_delay_s = [-0.001, 0.01]"),
     "[domain] sensing_delay_s", 14),
    ("delay-scalar", edit(BASE, "friction = [0.8, 1.0]", "sensing_delay_s = 0.01"), "[domain] sensing_delay_s", 14),
    ("delay-reversed", edit(BASE, "friction = [0.8, 1.0]", "actuation_delay_s = [0.02, 0.01]"),
     "[domain] actuation_delay_s", 14),
    ("delay-in-ms", edit(BASE, "friction = [0.8, 1.0]", "actuation_delay_ms = [2, 10]"),
     "[domain] actuation_delay_ms", 14),
    ("ramp-too-long", edit(BASE, "ramp_s = 0.5", "ramp_s = 11"), "[commands] ramp_s", 17),
    ("unknown-key-commands", edit(BASE, "ramp_s = 0.5", "ramp = 0.5"), "[commands] ramp", 17),
    ("missing-options", edit(BASE, OPTIONS, ""), "[commands] options", 16),
    ("empty-options", edit(edit(BASE, OPTIONS, ""), "ramp_s = 0.5", "ramp_s = 0.5\noptions = []"),
     "[commands] options", 18),
    ("option-vx-too-big", edit(BASE, "vx = 0.0", "vx = 5.0"), "[[commands.options]] #1 vx", 20),
    ("option-unknown-key", edit(BASE, "vx = 0.3", "vx = 0.3\nvz = 1.0"), "[[commands.options]] #2 vz", 24),
    ("option-sign-string", edit(BASE, "vx = 0.3", 'vx = 0.3\nrandom_sign = "yes"'),
     "[[commands.options]] #2 random_sign", 24),
    ("push-duration-negative", edit(BASE, "duration_s = 0.05", "duration_s = -0.05"), "[pushes] duration_s", 28),
    ("offset-too-big", edit(BASE, "offset_m = 0.12", "offset_m = 0.6"), "[pushes] offset_m", 29),
    ("interval-reversed", edit(BASE, "interval_s = [4.0, 6.0]", "interval_s = [6.0, 4.0]"), "[pushes] interval_s",
     27),
    ("interval-zero", edit(BASE, "interval_s = [4.0, 6.0]", "interval_s = [0.0, 6.0]"), "[pushes] interval_s", 27),
    ("first-negative", edit(BASE, "first_s = [2.0, 3.0]", "first_s = [-1.0, 3.0]"), "[pushes] first_s", 26),
    ("first-after-end", edit(BASE, "first_s = [2.0, 3.0]", "first_s = [2.0, 12.0]"), "[pushes] first_s", 26),
    ("missing-offset", edit(BASE, "offset_m = 0.12\n", ""), "[pushes] offset_m", 25),
    ("unknown-key-pushes", edit(BASE, "offset_m = 0.12", "offset_m = 0.12\nheading = 0.0"), "[pushes] heading", 30),
    ("unknown-table", BASE + "\n[extra]\nx = 1\n", "[extra]", 39),
    ("missing-bands", edit(BASE, BANDS, ""), "[[bands]]", None),
    ("empty-bands", "bands = []\n" + edit(BASE, BANDS, ""), "[[bands]]", 1),
    ("bands-as-tables", edit(BASE, BANDS, BANDS.replace('[[bands]]\nname = "in"', "[bands.in]").replace(
        '[[bands]]\nname = "ood"', "[bands.ood]")), "[[bands]]", 31),
    ("duplicate-band", edit(BASE, 'name = "ood"', 'name = "in"'), "[[bands]] #2 name", 36),
    ("bad-band-name", edit(BASE, 'name = "ood"', 'name = "o o d"'), "[[bands]] #2 name", 36),
    ("band-unknown-key", edit(BASE, 'name = "ood"', 'name = "ood"\ncolour = 1'), "[[bands]] #2 colour", 37),
    ("force-missing", edit(BASE, "push_force_n = [300.0, 400.0]\n", ""), "[[bands]] #2 push_force_n", 35),
    ("force-without-pushes", edit(BASE, PUSHES, ""), "[[bands]] #1 push_force_n", 28),
    ("force-too-big", edit(BASE, "[300.0, 400.0]", "[300.0, 6000.0]"), "[[bands]] #2 push_force_n", 37),
    ("force-three", edit(BASE, "[300.0, 400.0]", "[300.0, 350.0, 400.0]"), "[[bands]] #2 push_force_n", 37),
    ("band-vx-string", edit(BASE, 'name = "in"', 'name = "in"\nvx = "fast"'), "[[bands]] #1 vx", 33),
    ("band-yaw-too-big", edit(BASE, 'name = "in"', 'name = "in"\nyaw_rate = 9.0'), "[[bands]] #1 yaw_rate", 33),
    ("terrain-seed-negative", edit(BASE, "amplitude_m = 0.05", "amplitude_m = 0.05\nseed = -1"), "[terrain] seed", 12),
    ("terrain-seed-float", edit(BASE, "amplitude_m = 0.05", "amplitude_m = 0.05\nseed = 1.5"), "[terrain] seed", 12),
    ("terrain-seed-too-big", edit(BASE, "amplitude_m = 0.05", "amplitude_m = 0.05\nseed = 2147483648"),
     "[terrain] seed", 12),
    ("change-after-end", edit(edit(BASE, "vx = 0.3\n", CHANGE), "at_s = 4.0", "at_s = 10.0"),
     "[[commands.changes]] #1 at_s", 26),
    ("change-missing-at", edit(edit(BASE, "vx = 0.3\n", CHANGE), "at_s = 4.0\n", ""),
     "[[commands.changes]] #1 at_s", 25),
    ("change-vx-too-big", edit(edit(BASE, "vx = 0.3\n", CHANGE), "vx = 0.5", "vx = 5.0"),
     "[[commands.changes]] #1 vx", 27),
    ("change-unknown-key", edit(edit(BASE, "vx = 0.3\n", CHANGE), "vx = 0.5", "vx = 0.5\nvz = 1.0"),
     "[[commands.changes]] #1 vz", 28),
    ("changes-out-of-order", edit(BASE, "vx = 0.3\n", CHANGE + "\n[[commands.changes]]\nat_s = 4.0\n"),
     "[[commands.changes]] #2 at_s", 30),
    ("changes-not-tables", edit(BASE, "ramp_s = 0.5", "ramp_s = 0.5\nchanges = 4.0"), "[commands] changes", 18),
    ("fixed-start-after-end", edit(BASE + FIXED, "start_s = 3.0", "start_s = 10.0"), "[[fixed_pushes]] #1 start_s",
     40),
    ("fixed-start-missing", edit(BASE + FIXED, "start_s = 3.0\n", ""), "[[fixed_pushes]] #1 start_s", 39),
    ("fixed-too-short", edit(BASE + FIXED, "duration_s = 0.05\nforce", "duration_s = 0.001\nforce"),
     "[[fixed_pushes]] #1 duration_s", 41),
    ("fixed-force-two", edit(BASE + FIXED, "[100.0, 0.0, 0.0]", "[100.0, 0.0]"), "[[fixed_pushes]] #1 force_n", 42),
    ("fixed-force-string", edit(BASE + FIXED, "[100.0, 0.0, 0.0]", '["east", 0.0, 0.0]'),
     "[[fixed_pushes]] #1 force_n", 42),
    ("fixed-force-scalar", edit(BASE + FIXED, "[100.0, 0.0, 0.0]", "100.0"), "[[fixed_pushes]] #1 force_n", 42),
    ("fixed-force-nan", edit(BASE + FIXED, "[100.0, 0.0, 0.0]", "[nan, 0.0, 0.0]"), "[[fixed_pushes]] #1 force_n",
     42),
    ("fixed-force-zero", edit(BASE + FIXED, "[100.0, 0.0, 0.0]", "[0.0, 0.0, 0.0]"), "[[fixed_pushes]] #1 force_n",
     42),
    ("fixed-force-too-big", edit(BASE + FIXED, "[100.0, 0.0, 0.0]", "[1500.0, 1500.0, 0.0]"),
     "[[fixed_pushes]] #1 force_n", 42),
    ("fixed-impulse-too-big", edit(edit(BASE + FIXED, "[100.0, 0.0, 0.0]", "[1000.0, 0.0, 0.0]"),
                                   "duration_s = 0.05\nforce", "duration_s = 0.5\nforce"),
     "[[fixed_pushes]] #1 force_n", 42),
    ("fixed-offset-too-far", edit(BASE + FIXED, "[0.0, 0.1, 0.0]", "[0.6, 0.0, 0.0]"), "[[fixed_pushes]] #1 offset_m",
     43),
    ("fixed-unknown-key", BASE + FIXED + "heading = 1.0\n", "[[fixed_pushes]] #1 heading", 44),
    ("fixed-second-bad", BASE + FIXED + FIXED.replace("start_s = 3.0", "start_s = -1.0"),
     "[[fixed_pushes]] #2 start_s", 46),
    ("fixed-empty", "fixed_pushes = []\n" + BASE, "[[fixed_pushes]]", 1),
]


@pytest.mark.parametrize(("text", "field", "line"), [case[1:] for case in BROKEN], ids=[case[0] for case in BROKEN])
def test_broken_file_names_file_line_and_field(tmp_path, text, field, line):
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert isinstance(err.value, WbcError) and isinstance(err.value, ValueError)
    assert message.startswith(str(path)), message
    assert err.value.path == str(path)
    assert err.value.field == field, message
    if field is not None:
        assert f" {field}: " in message, message
    assert err.value.line == line, message
    if line is not None:
        assert message.startswith(f"{path}:{line}: "), message


def test_messages_say_what_and_how(tmp_path):
    cases = {
        "version-bool": "expected an integer, got boolean true",
        "version-string": "expected an integer, got string '1'",
        "version-too-big": "must be in [1, 1000000], got 1000001",
        "toml-duplicate-key": "invalid TOML: kind is set twice (first at line 10); keep one",
        "toml-duplicate-table": "invalid TOML: [terrain] names what is defined already (first at line 9)",
        "toml-duplicate-multiline": "invalid TOML: friction is set twice (first at line 14)",
        "terrain-seed-too-big": "must be in [0, 2147483647], got 2147483648",
        "unknown-robot": "valid robots: a1-wx200, go1-arm",
        "unknown-key-terrain": "valid keys of [terrain]: kind, amplitude_m",
        "push-duration-negative": "must be in [0.01, 1], got -0.05",
        "friction-reversed": "lo <= hi",
        "friction-three": "2 numbers",
        "duplicate-band": "duplicate band name 'in' (also [[bands]] #1)",
        "force-without-pushes": "add [pushes] or remove push_force_n",
        "bad-kind": "'flat', 'fractal'",
        "missing-scenario": "missing required table",
        "changes-out-of-order": "must be later than the change before it (4 s), got 4",
        "fixed-force-zero": "its magnitude must be in (0, 2000] N, got 0",
        "fixed-impulse-too-big": "delivers 500 N s, more than 200 N s",
        "fixed-force-two": "expected an array of 3 numbers, got an array of 2",
        "fixed-offset-too-far": "each number must be in [-0.5, 0.5], got 0.6 at position 1",
        "unknown-table": "[[fixed_pushes]]",
    }
    texts = {case[0]: case[1] for case in BROKEN}
    for case, expected in cases.items():
        with pytest.raises(ScenarioError) as err:
            load_scenario(write(tmp_path, texts[case]))
        assert expected in str(err.value), (case, str(err.value))


def test_spec_example_message(tmp_path):
    path = write(tmp_path, edit(BASE, "duration_s = 0.05", "duration_s = -0.05"))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}:28: [pushes] duration_s: must be in [0.01, 1], got -0.05"


def test_file_problems(tmp_path):
    with pytest.raises(ScenarioError, match="file not found") as err:
        load_scenario(tmp_path / "missing.toml")
    assert str(err.value).startswith(str(tmp_path / "missing.toml"))
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path)  # a directory
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(BASE.replace("A valid", "A v\xe9lid").encode("latin-1"))
    with pytest.raises(ScenarioError, match="UTF-8") as err:
        load_scenario(bad)
    assert err.value.line == 5
    # UTF-8 with a byte-order mark, as some Windows editors save it, reads as the same scenario, lines unmoved
    marked = tmp_path / "bom.toml"
    marked.write_bytes(b"\xef\xbb\xbf" + BASE.encode("utf-8"))
    assert load_scenario(marked).hash == load_scenario(write(tmp_path, BASE)).hash
    marked.write_bytes(b"\xef\xbb\xbf" + edit(BASE, "duration_s = 0.05", "duration_s = -0.05").encode("utf-8"))
    with pytest.raises(ScenarioError) as err:
        load_scenario(marked)
    assert err.value.line == 28


def test_a_stray_sub_table_or_key_is_named_at_its_own_line(tmp_path):
    n = BASE.count("\n")
    path = write(tmp_path, BASE + "\n[scenario.extra]\ncolour = 1\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert (err.value.line, err.value.field) == (n + 2, "[scenario] extra") and "unknown key" in str(err.value)
    path = write(tmp_path, "colour = 1\n" + BASE)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value).startswith(f"{path}:1: colour: a key outside every table; each key belongs to one of "
                                     "[scenario], [terrain]")


def test_line_numbers_skip_multiline_strings(tmp_path):
    tricky = 'notes = """\n[pushes]\nduration_s = 1\n[[bands]]\nname = "x"\n"""\n'
    text = edit(BASE, "version = 1\n", "version = 1\n" + tricky)  # 6 lines added after line 4
    text = edit(text, "duration_s = 0.05", "duration_s = 2.0")
    with pytest.raises(ScenarioError) as err:
        load_scenario(write(tmp_path, text))
    assert err.value.field == "[pushes] duration_s" and err.value.line == 34


def test_dotted_and_inline_forms_are_accepted(tmp_path):
    text = edit(BASE, '[terrain]\nkind = "fractal"\namplitude_m = 0.05\n', "")
    text = 'terrain.kind = "flat"\n' + text
    assert load_scenario(write(tmp_path, text)).trial("in", 0, 0).terrain.kind == "flat"
    bad = 'terrain.kind = "hilly"\n' + edit(BASE, '[terrain]\nkind = "fractal"\namplitude_m = 0.05\n', "")
    with pytest.raises(ScenarioError) as err:
        load_scenario(write(tmp_path, bad))
    assert err.value.field == "[terrain] kind" and err.value.line == 1


def test_random_edits_raise_only_scenario_errors(tmp_path):
    """Whatever the edit, a file either loads and samples, or raises ScenarioError: never a traceback."""
    rng = random.Random(0)
    lines = BASE.splitlines()
    values = ["1", "-1", "0", "1e9", "nan", "inf", "true", '"x"', "[]", "[1]", "[2, 1]", "[0, 0]", "{}", "{a = 1}",
              "1979-05-27", "[[1, 2]]", '""', "0.001"]
    loaded = 0
    for k in range(300):
        edited = list(lines)
        i = rng.randrange(len(edited))
        action = rng.random()
        if action < 0.3:
            del edited[i]
        elif action < 0.4:
            edited.insert(i, edited[rng.randrange(len(edited))])
        elif "=" in edited[i]:
            edited[i] = edited[i].split("=")[0] + "= " + rng.choice(values)
        else:
            edited[i] = edited[i][: rng.randrange(len(edited[i]) + 1)]
        path = write(tmp_path, "\n".join(edited) + "\n", f"fuzz{k}.toml")
        try:
            s = load_scenario(path)
        except ScenarioError as err:
            assert str(err).startswith(str(path))
            continue
        loaded += 1
        for band in s.bands:
            s.trials([band], [0], 2)
    assert 0 < loaded < 300


def test_a_shipped_scenario_loads_by_its_relative_path_from_any_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scenario = load_scenario("scenarios/push.toml")
    assert scenario.name == "push"
    check_published(scenario)  # the lock beside the resolved file is found too
    with pytest.raises(ScenarioError, match="file not found.*working directory, then from") as err:
        load_scenario("scenarios/no-such-scenario.toml")
    assert err.value.path == "scenarios/no-such-scenario.toml"


def test_a_relative_path_that_exists_from_the_working_directory_wins(tmp_path, monkeypatch):
    (tmp_path / "scenarios").mkdir()
    shipped = Path(__file__).resolve().parent.parent / "scenarios" / "push.toml"
    text = shipped.read_text(encoding="utf-8").replace('name = "push"', 'name = "my-push"')
    (tmp_path / "scenarios" / "push.toml").write_text(text, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert load_scenario("scenarios/push.toml").name == "my-push"
