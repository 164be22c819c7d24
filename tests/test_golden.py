"""Golden comparison: a fixed small `wbc compare` whose per-trial metrics were recorded and committed.

The committed CSVs (tests/golden/) hold every column of ``trials.csv`` but those timed on the machine (the wall time,
the controller's act times and deadline misses), one row per trial in
canonical order (controller as named, band, seed, trial). The same command must reproduce them exactly, to the last
digit: a refactor that changes a result, however slightly, fails here. Set ``WBC_RECORD_GOLDEN=1`` to re-record
(only for a deliberate change of behaviour, said in the commit message).
"""

import csv
import io
import os
from pathlib import Path

import pytest

from wbc.arena.record import MACHINE_TIMED
from wbc.cli.main import main

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).resolve().parent / "golden"
CONTROLLERS = ("stand", "mpc", "learned")
CASES = {
    "push": ["--scenario", str(ROOT / "scenarios/push-v1.toml"), "--trials", "3", "--seeds", "2"],
    "turn": ["--scenario", str(ROOT / "scenarios/turn.toml"), "--band", "1.5", "--trials", "2", "--seeds", "1"],
}
UNSTABLE = MACHINE_TIMED  # the columns timed on the machine's clock (wall time, act times, deadline misses)


def _canonical(trials_csv: Path) -> str:
    rows = list(csv.DictReader(trials_csv.open(encoding="utf-8")))
    fields = [f for f in rows[0] if f not in UNSTABLE]
    rows.sort(key=lambda r: (CONTROLLERS.index(r["controller"]), r["band"], int(r["seed"]), int(r["trial"])))
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return out.getvalue()


@pytest.mark.parametrize("case", sorted(CASES))
def test_golden_comparison_reproduces_exactly(case, tmp_path):
    out = tmp_path / case
    assert main(["compare", *CONTROLLERS, *CASES[case], "--out", str(out), "--quiet", "--workers", "2"]) == 0
    got = _canonical(out / "trials.csv")
    path = GOLDEN / f"{case}.csv"
    if os.environ.get("WBC_RECORD_GOLDEN") == "1":
        path.write_text(got, encoding="utf-8")
    want = path.read_text(encoding="utf-8")
    assert got.splitlines()[0] == want.splitlines()[0], "the trials.csv columns changed"
    for line_got, line_want in zip(got.splitlines()[1:], want.splitlines()[1:], strict=True):
        assert line_got == line_want
