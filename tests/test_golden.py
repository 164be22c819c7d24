"""Golden comparison: a fixed small `wbc compare` whose per-trial metrics were recorded and committed.

The committed CSVs (tests/golden/) hold every column of ``trials.csv`` but those timed on the machine (the wall time,
the controller's act times and deadline misses) and the row's checksum, which covers them, one row per trial in
canonical order (controller as named, band, seed, trial). The same command must reproduce them exactly, to the last
digit: a refactor that changes a result, however slightly, fails here. ``make golden`` re-records them
(``WBC_RECORD_GOLDEN=1`` in one process, `golden_recording`; only for a deliberate change of behaviour, said in the
commit message).

Results reproduce to the bit only under the same versions of the numerical packages (MuJoCo, numba, NumPy ...), so
the goldens are recorded in the environment `make test` installs from the lock (requirements/wbc.lock), and
tests/golden/versions.json records every installed distribution's version beside them. When a row differs, the
failure names the installed versions that are not the recording's: a changed dependency, not a changed controller.
"""

import csv
import io
import json
import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
from golden_recording import RECORD_COMMAND, recording, recording_refusal

from wbc.arena.trial_record import MACHINE_TIMED
from wbc.cli.main import main

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).resolve().parent / "golden"
CONTROLLERS = ("stand", "mpc", "learned")
CASES = {
    "push": ["--scenario", str(ROOT / "scenarios/push-v1.toml"), "--trials", "3", "--seeds", "2"],
    "turn": ["--scenario", str(ROOT / "scenarios/turn.toml"), "--band", "1.5", "--trials", "2", "--seeds", "1"],
}
UNSTABLE = MACHINE_TIMED  # the columns timed on the machine's clock (wall time, act times, deadline misses) and the
# checksum of the row's cells, which covers them
VERSIONS = GOLDEN / "versions.json"


def _environment() -> dict[str, object]:
    """The interpreter, the machine and every installed distribution's version (the project itself excluded)."""
    packages = {}
    for dist in metadata.distributions():
        name = (dist.metadata["Name"] or "").lower().replace("_", "-")
        if name and name != "wbc":
            packages[name] = dist.version
    return {"python": platform.python_version(), "machine": platform.machine(),
            "implementation": sys.implementation.name, "packages": dict(sorted(packages.items()))}


def _version_differences() -> list[str]:
    """What differs between the running environment and the one the goldens were recorded in, in words."""
    if not VERSIONS.exists():
        return [f"{VERSIONS.relative_to(ROOT)} is missing: the recording's versions are unknown"]
    recorded, now = json.loads(VERSIONS.read_text(encoding="utf-8")), _environment()
    out = [f"{key} {now[key]} (recorded {recorded.get(key)})" for key in ("python", "machine", "implementation")
           if now[key] != recorded.get(key)]
    old, new = recorded.get("packages", {}), now["packages"]
    for name in sorted(set(old) | set(new)):
        if old.get(name) != new.get(name):
            out.append(f"{name} {new.get(name, 'not installed')} (recorded {old.get(name, 'not installed')})")
    return out


def _explain_difference(case: str, index: int, got: str, want: str) -> str:
    differences = _version_differences()
    if differences:
        why = ("installed versions that differ from those the goldens were recorded with (tests/golden/"
               "versions.json): " + "; ".join(differences) + ". Install the locked versions (make test does) or, for "
               "a deliberate change of the lock, re-record with WBC_RECORD_GOLDEN=1 (`make golden`).")
    else:
        why = ("every installed version is the recording's, so the code changed a result: if that is deliberate, "
               "re-record with WBC_RECORD_GOLDEN=1 (`make golden`) and say why in the commit message.")
    return f"golden {case}: trial row {index} differs\n  got  {got}\n  want {want}\n{why}"


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
    if recording():  # in one process only: each case its own CSV, the same versions.json
        path.write_text(got, encoding="utf-8")
        VERSIONS.write_text(json.dumps(_environment(), indent=1) + "\n", encoding="utf-8")
    want = path.read_text(encoding="utf-8")
    assert got.splitlines()[0] == want.splitlines()[0], "the trials.csv columns changed"
    assert len(got.splitlines()) == len(want.splitlines()), "the number of trials changed"
    for index, (line_got, line_want) in enumerate(zip(got.splitlines()[1:], want.splitlines()[1:], strict=True)):
        assert line_got == line_want, _explain_difference(case, index, line_got, line_want)


def test_a_version_difference_is_named_in_the_golden_failure(monkeypatch, tmp_path):
    """The failure message names a changed dependency: here the recording claims another MuJoCo and lacks a package."""
    recorded = _environment()
    recorded["packages"] = dict(recorded["packages"], mujoco="0.0.1")
    dropped = next(name for name in recorded["packages"] if name != "mujoco")
    del recorded["packages"][dropped]
    fake = tmp_path / "versions.json"
    fake.write_text(json.dumps(recorded), encoding="utf-8")
    monkeypatch.setattr(sys.modules[__name__], "VERSIONS", fake)
    message = _explain_difference("push", 0, "a", "b")
    installed = metadata.version("mujoco")
    assert f"mujoco {installed} (recorded 0.0.1)" in message
    assert f"{dropped} " in message and "(recorded not installed)" in message
    assert "re-record with WBC_RECORD_GOLDEN=1" in message


def test_re_recording_under_parallel_workers_is_refused_with_the_serial_command():
    """WBC_RECORD_GOLDEN=1 make test recorded under xdist: test_mpc_ticks' first case rewrote the .npz while other
    workers loaded it, and both cases here wrote versions.json. Collecting only, so nothing is recorded either way."""
    env = dict(os.environ, WBC_RECORD_GOLDEN="1")
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2", "--collect-only",
                          str(Path(__file__))], capture_output=True, text=True, env=env, cwd=ROOT)
    assert out.returncode == pytest.ExitCode.USAGE_ERROR, out.stdout + out.stderr
    assert "parallel workers" in out.stderr and RECORD_COMMAND in out.stderr
    assert recording_refusal(None, None) is None and recording_refusal(0, None) is None
    assert recording_refusal("auto", None) is not None and recording_refusal(None, "gw1") is not None
