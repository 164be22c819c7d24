"""Where each contender fails (`wbc.arena.breakdown`), on a synthetic record set whose every count is known.

Two controllers, six trials with hand-placed pushes: which push a fall is charged to, the heading sectors and offset
axes, success standing against walking, falls before any push, the push-recovery curve's bins, and the report's
section and plot.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from wbc.arena.breakdown import (
    breakdown,
    breakdown_tables,
    command_label,
    heading_sector,
    push_outcomes,
    recovery_curve,
)
from wbc.arena.report import summarize, write_report
from wbc.arena.trial_record import TrialRecord
from wbc.errors import RecordError
from wbc.scenario.domain import DomainParams
from wbc.scenario.push import Push
from wbc.scenario.terrain import TerrainConfig
from wbc.scenario.trial import CommandChange, CommandSchedule, Trial
from wbc.types import VelocityCommand

HASH = "feed"
DURATION = 0.1  # [s] every push lasts this long


def _push(start: float, force: float, heading_deg: float, offset: tuple[float, float, float]) -> Push:
    return Push.horizontal(force, math.radians(heading_deg), offset, start, DURATION)


# (band, seed, index) -> (vx command, pushes)
TRIALS = {
    ("in", 0, 0): (0.0, (_push(2.0, 200.0, 0.0, (0.1, 0, 0)), _push(6.0, 250.0, 90.0, (0, 0.05, 0)),
                         _push(11.0, 300.0, 180.0, (0, -0.1, 0)))),
    ("in", 0, 1): (0.0, (_push(2.5, 220.0, -90.0, (-0.1, 0, 0)), _push(7.0, 280.0, 44.0, (0, 0.1, 0)))),
    ("in", 0, 2): (0.3, (_push(2.0, 210.0, 46.0, (0.02, 0, 0)), _push(8.0, 290.0, 135.0, (0, 0.12, 0)))),
    ("in", 0, 3): (0.3, (_push(3.0, 260.0, -150.0, (0, 0.03, 0)),)),
}

# controller -> index -> fall time (None: survived)
FALLS = {
    "steady": {0: None, 1: None, 2: None, 3: 1.0},          # falls once, before any push, walking
    "shaky": {0: 6.4, 1: 4.0, 2: 12.0, 3: None},            # charged to push 1, push 0, push 1
}


def _trial(band: str, seed: int, index: int) -> Trial:
    vx, pushes = TRIALS[(band, seed, index)]
    return Trial(scenario="synthetic", scenario_hash=HASH, robot="a1-wx200", band=band, seed=seed, index=index,
                 duration_s=20.0, terrain=TerrainConfig(), terrain_seed=0, domain=DomainParams(friction=1.0),
                 pushes=pushes, command=CommandSchedule(vx=vx))


def _record(controller: str, index: int, **overrides) -> TrialRecord:
    trial = _trial("in", 0, index)
    fall = FALLS[controller][index]
    fields = {"controller": controller, "scenario": "synthetic", "scenario_hash": HASH, "band": "in", "seed": 0,
              "trial": index, "success": fall is None, "ttf": 1.0 if fall is None else fall / 20.0,
              "fall_time_s": math.nan if fall is None else fall, "vlin_err": 0.1, "vang_err": 0.1,
              "max_roll_deg": 5.0, "max_pitch_deg": 3.0, "energy_j": 100.0, "arm_travel_rad": 0.0,
              "push_force_n": trial.push_force_n, "n_pushes": len(trial.pushes), "vx_cmd": trial.command.vx,
              "vy_cmd": 0.0, "yaw_rate_cmd": 0.0, "friction": 1.0, "payload_kg": 0.0, "fallbacks": 0,
              "wbc_failures": 0, "debug_truth": False, "wall_s": 1.0}
    fields |= overrides
    fields.setdefault("outcome", "success" if fields["success"] else "fall")
    return TrialRecord(**fields)


RECORDS = [_record(c, i) for c in FALLS for i in range(4)]
CONTROLLERS = tuple(FALLS)


def test_heading_sectors_and_command_labels():
    assert [heading_sector(math.radians(d)) for d in (0, 44, 46, 90, 134, 136, 180, -180, -136, -134, -90, -46,
                                                      -44, 360)] == [
        "forward", "forward", "left", "left", "left", "backward", "backward", "backward", "backward", "right",
        "right", "right", "forward", "forward"]
    assert command_label(RECORDS[0]) == "standing" and command_label(RECORDS[2]) == "vx 0.3"
    assert command_label(_record("steady", 0, vx_cmd=1.25, yaw_rate_cmd=2.0)) == "vx 1.25 yaw 2"


def test_each_push_gets_its_outcome_and_each_fall_its_push():
    outcomes = push_outcomes(RECORDS, _trial)
    steady = [o for o in outcomes if o.controller == "steady"]
    # trials 0-2 survived: all 7 pushes met and survived; trial 3 fell at 1 s, before its only push: none met
    assert len(steady) == 7 and all(o.survived for o in steady)
    shaky = {(o.trial, o.push): o for o in outcomes if o.controller == "shaky"}
    # trial 0 fell at 6.4 s: push 0 survived, push 1 (at 6 s) charged, 0.4 s later; push 2 never came
    assert shaky[(0, 0)].survived and not shaky[(0, 1)].survived and (0, 2) not in shaky
    assert shaky[(0, 1)].fall_after_s == pytest.approx(0.4)
    # trial 1 fell at 4 s, between its pushes at 2.5 and 7 s: charged to the first, 1.5 s after it
    assert not shaky[(1, 0)].survived and shaky[(1, 0)].fall_after_s == pytest.approx(1.5) and (1, 1) not in shaky
    # trial 2 fell at 12 s, 4 s after its last push: still that push's (nothing else came)
    assert not shaky[(2, 1)].survived and shaky[(2, 1)].fall_after_s == pytest.approx(4.0)
    o = shaky[(0, 1)]
    assert (o.sector, o.offset_axis, o.force_n) == ("left", "y", pytest.approx(250.0))
    assert o.impulse_ns == pytest.approx(250.0 * DURATION) and o.heading_deg == pytest.approx(90.0)
    assert shaky[(1, 0)].sector == "right" and shaky[(1, 0)].offset_axis == "x"


def test_breakdown_counts_by_command_sector_axis_and_falls():
    outcomes = push_outcomes(RECORDS, _trial)
    result = breakdown(RECORDS, outcomes, controllers=CONTROLLERS, bands=["in"])
    assert result["commands"] == ["standing", "vx 0.3"]
    steady, shaky = result["controllers"]["steady"]["in"], result["controllers"]["shaky"]["in"]
    # steady: both standing trials survived, one of two walking ones fell
    assert {k: (c["k"], c["n"]) for k, c in steady["by_command"].items()} == {"standing": (2, 2), "vx 0.3": (1, 2)}
    assert steady["falls"] == {"trials": 4, "falls": 1, "controller_errors": 0, "before_first_push": 1,
                               "after_push": 0, "median_s_after_push": None}
    # shaky: both standing trials fell, one walking trial of two
    assert {k: (c["k"], c["n"]) for k, c in shaky["by_command"].items()} == {"standing": (0, 2), "vx 0.3": (1, 2)}
    assert shaky["falls"] == {"trials": 4, "falls": 3, "controller_errors": 0, "before_first_push": 0,
                              "after_push": 3, "median_s_after_push": pytest.approx(1.5)}
    # shaky's pushes met: trial 0 pushes 0 (forward, x) and 1 (left, y; fell), trial 1 push 0 (right, x; fell),
    # trial 2 pushes 0 (left at 46 deg, x) and 1 (left at 135 deg, y; fell), trial 3 push 0 (backward, y)
    sectors = {s: (c["k"], c["n"]) for s, c in shaky["by_sector"].items()}
    assert sectors == {"forward": (1, 1), "left": (1, 3), "backward": (1, 1), "right": (0, 1)}
    axes = {a: (c["k"], c["n"]) for a, c in shaky["by_offset_axis"].items()}
    assert axes == {"x": (2, 3), "y": (1, 3)}
    cell = shaky["by_sector"]["left"]
    assert cell["rate"] == pytest.approx(1 / 3) and cell["ci95"][0] < 1 / 3 < cell["ci95"][1]
    assert steady["by_sector"]["right"]["n"] == 1 and steady["by_sector"]["backward"]["n"] == 1
    (header, rows), (push_header, push_rows) = breakdown_tables(result, "in", pushes=True)
    assert header == ["controller", "standing", "vx 0.3", "falls: no push / after one", "median fall delay [s]"]
    assert rows[1] == ["shaky", "0% 0/2", "50% 1/2", "0 / 3", "1.50"]
    assert push_header[1:] == ["pushed forward", "pushed left", "pushed backward", "pushed right", "offset x",
                               "offset y"]
    assert push_rows[1] == ["shaky", "100% 1/1", "33% 1/3", "100% 1/1", "0% 0/1", "67% 2/3", "33% 1/3"]
    assert len(breakdown_tables(result, "in", pushes=False)) == 1


def test_a_controller_error_is_neither_a_fall_nor_a_push_failed():
    # steady's trial 0 ended by its controller's error at 3 s, after its first push: no push is charged with it
    errored = _record("steady", 0, success=False, outcome="controller_error", ttf=0.15, error="act raised")
    records = [errored, *RECORDS[1:4]]
    outcomes = push_outcomes(records, _trial)
    assert not [o for o in outcomes if o.trial == 0] and len(outcomes) == len(push_outcomes(RECORDS[1:4], _trial))
    cell = breakdown(records, outcomes, controllers=("steady",), bands=["in"])["controllers"]["steady"]["in"]
    assert cell["falls"] == {"trials": 4, "falls": 1, "controller_errors": 1, "before_first_push": 1,
                             "after_push": 0, "median_s_after_push": None}
    assert cell["by_command"]["standing"]["k"] == 1  # it counts against success


@pytest.mark.parametrize("outcome", ["safety_trip", "operator_stop"])
def test_a_trip_or_a_stop_is_neither_a_fall_nor_a_push_failed(outcome: str):
    # steady's trial 0 ended by a hardware trial's trip or stop at 3 s, no fall time: no push is charged with it, and
    # it is not counted as a fall (its NaN fall time charged every push of the trial, and the falls counted it)
    stopped = _record("steady", 0, success=False, outcome=outcome, ttf=0.15)
    records = [stopped, *RECORDS[1:4]]
    outcomes = push_outcomes(records, _trial)
    assert not [o for o in outcomes if o.trial == 0]
    cell = breakdown(records, outcomes, controllers=("steady",), bands=["in"])["controllers"]["steady"]["in"]
    assert cell["falls"]["falls"] == 1 and cell["falls"]["before_first_push"] == 1


def test_recovery_curve_bins_every_push_met():
    outcomes = push_outcomes(RECORDS, _trial)
    curve = recovery_curve(outcomes, controllers=CONTROLLERS, n_bins=2)
    assert curve["edges"] == pytest.approx([20.0, 25.0, 30.0])  # impulses 20 .. 30 N s
    # shaky's pushes: 20, 25 (fell), 22 (fell), 21, 29 (fell), 26 N s -> [20, 25): 20, 22, 21; [25, 30]: 25, 29, 26
    assert [(c["k"], c["n"]) for c in curve["controllers"]["shaky"]] == [(2, 3), (1, 3)]
    assert sum(c["n"] for c in curve["controllers"]["steady"]) == 7
    assert recovery_curve([], controllers=CONTROLLERS)["edges"] == []


def test_records_that_do_not_match_their_trial_are_refused():
    with pytest.raises(RecordError, match="re-drawn"):
        push_outcomes([_record("steady", 0, n_pushes=2)], _trial)
    with pytest.raises(RecordError, match="scenario hash"):
        push_outcomes([_record("steady", 0, scenario_hash="other")], _trial)
    # played without its pushes (--no-push): no push outcome, the fall counts as one before any push
    no_push = [_record("shaky", 0, n_pushes=0, push_force_n=0.0)]
    assert push_outcomes(no_push, _trial) == []
    assert breakdown(no_push, [], controllers=["shaky"], bands=["in"])["controllers"]["shaky"]["in"]["falls"][
        "before_first_push"] == 1


def test_the_report_says_where_each_controller_fails_and_draws_the_recovery_curve(tmp_path):
    outcomes = push_outcomes(RECORDS, _trial)
    failures = breakdown(RECORDS, outcomes, controllers=CONTROLLERS, bands=["in"])
    curve = recovery_curve(outcomes, controllers=CONTROLLERS)
    summary = summarize(RECORDS, scenario_name="synthetic", scenario_hash=HASH, controllers=CONTROLLERS, bands=["in"])
    paths = write_report(tmp_path, summary, RECORDS, {}, failures=failures, curve=curve)
    assert "push_recovery.png" in {p.name for p in paths}
    png = (tmp_path / "push_recovery.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 1024
    report = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "## Where each controller fails" in report and "| shaky | 0% 0/2 | 50% 1/2 | 0 / 3 | 1.50 |" in report
    assert "(push_recovery.png)" in report
    assert np.isclose(curve["edges"][0], 20.0)


def test_a_band_shows_only_the_commands_played_in_it():
    # the turn task's bands fix the forward speed: each band has its own commands, and its table only those
    records = [_record("steady", 0), _record("steady", 2, band="fast", vx_cmd=1.5, yaw_rate_cmd=2.0, n_pushes=0,
                                             push_force_n=0.0)]
    result = breakdown(records, [], controllers=["steady"], bands=["in", "fast"])
    assert result["commands"] == ["standing", "vx 1.5 yaw 2"]
    assert breakdown_tables(result, "in", pushes=False)[0][0] == ["controller", "standing"]
    assert breakdown_tables(result, "fast", pushes=False) == [
        (["controller", "vx 1.5 yaw 2"], [["steady", "100% 1/1"]])]


def test_a_vertical_push_has_its_own_sector_and_equal_offsets_their_own_axis():
    up = Push(force_in_world=np.array([0.0, 0.0, 1000.0]), offset_in_base=np.array([0.05, 0.05, 0.0]), start=2.0,
              duration=DURATION)
    steep = Push(force_in_world=np.array([-100.0, 0.0, -300.0]), offset_in_base=np.array([0.05, -0.02, 0.0]),
                 start=6.0, duration=DURATION)
    TRIALS[("up", 0, 0)] = (0.0, (up, steep))
    try:
        record = _record("steady", 0, band="up", push_force_n=1000.0, n_pushes=2)
        first, second = push_outcomes([record], _trial)
        assert (first.sector, first.offset_axis, math.isnan(first.heading_deg)) == ("vertical", "x=y", True)
        assert (second.sector, second.offset_axis, second.heading_deg) == ("vertical", "x", 180.0)
        result = breakdown([record], [first, second], controllers=["steady"], bands=["up"])
        _, (header, rows) = breakdown_tables(result, "up", pushes=True)
        assert header[1:] == ["pushed forward", "pushed left", "pushed backward", "pushed right", "pushed vertical",
                              "offset x", "offset y", "offset x=y"]
        assert rows == [["steady", "-", "-", "-", "-", "100% 2/2", "100% 1/1", "-", "100% 1/1"]]
    finally:
        del TRIALS[("up", 0, 0)]


def test_a_trial_whose_command_changes_is_labelled_so():
    stop = CommandChange(at_s=3.0, command=VelocityCommand())

    def changing(band: str, seed: int, index: int) -> Trial:
        trial = _trial(band, seed, index)
        changes = (stop,) * (index % 3)  # trials 0 and 3: none, 1: one, 2: two
        return dataclasses.replace(trial, command=CommandSchedule(vx=trial.command.vx, changes=changes))

    assert command_label(_record("steady", 0, vx_cmd=0.5, yaw_rate_cmd=1.0), 1) == "vx 0.5 yaw 1, then 1 change"
    result = breakdown(RECORDS, push_outcomes(RECORDS, changing), controllers=CONTROLLERS, bands=["in"],
                       trial_of=changing)
    assert result["commands"] == ["standing", "standing, then 1 change", "vx 0.3", "vx 0.3, then 2 changes"]
