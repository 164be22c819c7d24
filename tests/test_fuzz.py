"""The fuzz suite of issue 29: every input a user hands `wbc` ends in a clean error or a valid, plausible result.

The default suite runs a few hundred seeded cases over the seven surfaces (`fuzz.cases.SURFACES`) in this process:
the loaders of scenarios, I/O files, plug-in configurations, policies, episodes and results directories, and the
command line up to the call that would play trials (`fuzz.execute`), each case under a time limit and an
address-space cap. The ``slow`` test runs the subprocess campaign (`fuzz.campaign`), which also plays the trials.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from fuzz.cases import SURFACES, Case, generate, prepare_materials
from fuzz.execute import Implausible, check_results, check_row, execute, limits, materialize

SEED = 29
CASES = 280  # in-process cases, over the seven surfaces
CASE_SECONDS = 20.0  # per case: far above what a loader needs, so only a real hang reaches it
CASE_MEMORY_MB = 2048  # address space a case may add to this process


@pytest.fixture(scope="module")
def materials(tmp_path_factory):
    """The project's files, and a 2-trial results directory with its episodes (played once, here)."""
    from wbc.arena.compare import ArenaConfig, run_arena

    mat = prepare_materials(tmp_path_factory.mktemp("fuzz-materials"))
    out = mat.dir / "seed-run"
    run_arena(ArenaConfig(controllers=("stand",), scenario=mat.tiny, trials=2, out_dir=out, workers=1,
                          progress=False, save_episodes=True))
    mat.results = out
    return mat


@pytest.fixture(scope="module")
def cases(materials) -> list[Case]:
    return [c for c in generate(SEED, CASES, materials) if c.in_process]


@pytest.mark.parametrize("surface", SURFACES)
def test_every_input_ends_in_a_clean_error_or_a_valid_result(surface, cases, tmp_path):
    cases = [c for c in cases if c.surface == surface]
    assert len(cases) >= 20
    bad = []
    for i, case in enumerate(cases):
        d = tmp_path / f"case-{i}"
        d.mkdir()
        materialize(case, d)
        with limits(CASE_SECONDS, CASE_MEMORY_MB):
            verdict = execute(case, d, full=False)
        if verdict.kind not in ("clean", "valid"):
            bad.append(f"{verdict.kind}: {case.name[:80]} | {verdict.detail}")
    assert not bad, f"{len(bad)} of {len(cases)} {surface} cases failed:\n" + "\n".join(bad)


def test_the_plausibility_check_passes_a_real_run_and_refuses_edited_rows(materials):
    import csv

    check_results(materials.results, 2)
    with (materials.results / "trials.csv").open(newline="") as f:
        row = next(csv.DictReader(f))
    for edit in ({"ttf": "-5"}, {"success": "False"}, {"ticks": "0"}, {"vlin_err": "6.8e6"}, {"wall_s": "-1"},
                 {"vang_err": "inf"}, {"seed": "nan"}):
        with pytest.raises(Implausible):
            check_row({**row, **edit})


def test_a_case_that_is_not_refused_cleanly_is_a_crash_and_an_accepted_invalid_input_is_silent(materials, tmp_path):
    crash = Case("files", "a call the harness does not know", (("s.toml", b""),), "no such call", ("{d}/s.toml",))
    assert execute(crash, tmp_path, full=False).kind == "crash"
    bad = Case("flags", "stand on its own", (), "cli", ("check-controller", "stand", "--seconds", "0.1"),
               must_reject=True)
    assert execute(bad, tmp_path, full=False).kind == "silent"


def test_the_cases_are_seeded(materials):
    surfaces = ("scenario", "results", "flags")  # quick to draw
    first = [(c.surface, c.name, c.args) for c in generate(SEED, 90, materials, surfaces=surfaces)]
    again = [(c.surface, c.name, c.args) for c in generate(SEED, 90, materials, surfaces=surfaces)]
    other = [(c.surface, c.name, c.args) for c in generate(SEED + 1, 90, materials, surfaces=surfaces)]
    assert first == again
    assert first != other


@pytest.mark.slow
def test_the_campaign_finds_no_crash_hang_or_silent_failure(tmp_path):
    root = Path(__file__).resolve().parents[1]
    report = tmp_path / "report.txt"
    proc = subprocess.run([sys.executable, "-m", "tests.fuzz.campaign", "--cases", "420", "--seed", str(SEED),
                           "--timeout", "60", "--memory-mb", "4096", "--work", str(tmp_path / "work"), "--report",
                           str(report)], cwd=root, capture_output=True, text=True)
    assert proc.returncode == 0, report.read_text() if report.exists() else proc.stdout[-5000:] + proc.stderr[-5000:]
