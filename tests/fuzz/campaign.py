"""The fuzz campaign: every case in its own process, under a memory cap and a time limit; a table per surface.

    .venv/bin/python -m tests.fuzz.campaign --cases 420 --seed 29 --timeout 40 --memory-mb 4096 [--root PATH]

``--root PATH`` puts another checkout of the project first on ``PYTHONPATH`` (the code before a fix, say), so the
same cases run against it; the seed results directory (a 2-trial run of ``stand`` with its episodes) is written by
that code too. Cases run one at a time. The table counts, per surface, the cases and their verdicts (`execute`):
clean errors, valid runs, crashes (a traceback), hangs (past ``--timeout``) and silent failures (implausible results
or an invalid input accepted); the failures follow, one line each.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from .cases import REPO, SURFACES, Case, generate, prepare_materials
from .execute import VERDICTS, Verdict


def _env(root: Path | None) -> dict[str, str]:
    env = dict(os.environ)
    paths = ([str(root)] if root else []) + [str(REPO)]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    env.setdefault("OMP_NUM_THREADS", "1")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("MKL_NUM_THREADS", "1")
    return env


def _run(cmd: list[str], *, cwd: Path, env: dict[str, str], timeout: float) -> tuple[int | None, str, str]:
    """(exit status, or None past `timeout`; stdout; stderr) of `cmd` in a session of its own (killed whole)."""
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
        return proc.returncode, out.decode(errors="replace"), err.decode(errors="replace")
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return None, out.decode(errors="replace"), err.decode(errors="replace")


def seed_results(work: Path, tiny: Path, env: dict[str, str]) -> Path:
    """A results directory with its episodes, written by the code under test: ``wbc run stand --trials 2`` on the tiny
    scenario."""
    out = work / "seed-run"
    if out.exists():
        shutil.rmtree(out)
    rc, _, err = _run([sys.executable, "-m", "wbc.cli.main", "run", "stand", "--scenario", str(tiny), "--trials", "2",
                       "--workers", "1", "--save-episodes", "--out", str(out), "--quiet"], cwd=work, env=env,
                      timeout=300)
    if rc != 0:
        raise SystemExit(f"the seed run failed (exit {rc}):\n{err}")
    return out


def run_case(case: Case, d: Path, *, env: dict[str, str], timeout: float, memory_mb: int) -> Verdict:
    """One case in a child process (`fuzz.execute.main`), judged from its verdict line, exit status and stderr."""
    from .execute import materialize

    d.mkdir(parents=True)
    materialize(case, d)
    with (d / "case.pkl").open("wb") as f:
        pickle.dump(case, f)
    rc, out, err = _run([sys.executable, "-m", "tests.fuzz.execute", str(d / "case.pkl"), str(d),
                         "--memory-mb", str(memory_mb)], cwd=d, env=env, timeout=timeout)
    if rc is None:
        return Verdict("hang", f"past {timeout:g} s")
    line = next((ln for ln in reversed(out.splitlines()) if ln.startswith("FUZZ-VERDICT ")), None)
    if line is None:
        tail = [ln for ln in err.splitlines() if ln.strip()]
        return Verdict("crash", f"exit {rc} without a verdict: {tail[-1][:200] if tail else ''}")
    verdict = json.loads(line[len("FUZZ-VERDICT "):])
    if verdict["kind"] != "crash" and "Traceback (most recent call last)" in err:
        tail = [ln for ln in err.splitlines() if ln.strip()]
        return Verdict("crash", f"a traceback on stderr: {tail[-1][:200]}")
    return Verdict(verdict["kind"], verdict["detail"])


def table(results: list[tuple[Case, Verdict]]) -> str:
    """Cases and verdicts per surface, with a total row."""
    head = f"{'surface':<12} {'cases':>6} " + " ".join(f"{v:>7}" for v in VERDICTS)
    lines = [head, "-" * len(head)]
    total: Counter = Counter()
    for surface in SURFACES:
        counts = Counter(v.kind for c, v in results if c.surface == surface)
        n = sum(counts.values())
        total.update(counts)
        lines.append(f"{surface:<12} {n:>6} " + " ".join(f"{counts[v]:>7}" for v in VERDICTS))
    lines.append("-" * len(head))
    lines.append(f"{'total':<12} {sum(total.values()):>6} " + " ".join(f"{total[v]:>7}" for v in VERDICTS))
    return "\n".join(lines)


def failures(results: list[tuple[Case, Verdict]]) -> str:
    """One line per case that was neither clean nor valid."""
    return "\n".join(f"{v.kind:<6} {c.surface:<10} {c.name[:90]:<90} | {v.detail}"
                     for c, v in results if v.kind not in ("clean", "valid"))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.fuzz.campaign", description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=420, help="about this many cases, spread over the seven surfaces")
    p.add_argument("--seed", type=int, default=29)
    p.add_argument("--timeout", type=float, default=40.0, help="per case [s]; past it a case is a hang")
    p.add_argument("--memory-mb", type=int, default=4096, help="address-space cap of each case's process [MiB]")
    p.add_argument("--root", type=Path, default=None, help="a checkout of the project to test instead of this one")
    p.add_argument("--work", type=Path, default=None, help="scratch directory (default /tmp/wbc-fuzz-SEED)")
    p.add_argument("--surface", action="append", choices=SURFACES, help="only these surfaces (repeatable)")
    p.add_argument("--report", type=Path, default=None, help="also write the table and the failures here")
    args = p.parse_args(argv)
    work = (args.work or Path(f"/tmp/wbc-fuzz-{args.seed}")).resolve()
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    env = _env(args.root.resolve() if args.root else None)
    rc, where, _ = _run([sys.executable, "-c", "import wbc; print(wbc.__file__)"], cwd=work, env=env, timeout=120)
    started = time.monotonic()
    mat = prepare_materials(work / "materials")
    mat.results = seed_results(work / "materials", mat.tiny, env)
    cases = generate(args.seed, args.cases, mat, surfaces=tuple(args.surface or SURFACES))
    print(f"fuzz campaign: {len(cases)} cases, seed {args.seed}, timeout {args.timeout:g} s, memory cap "
          f"{args.memory_mb} MiB, wbc from {where.strip()}", flush=True)
    results: list[tuple[Case, Verdict]] = []
    for i, case in enumerate(cases):
        verdict = run_case(case, work / f"case-{i:04d}", env=env, timeout=args.timeout, memory_mb=args.memory_mb)
        results.append((case, verdict))
        print(f"[{i + 1}/{len(cases)}] {verdict.kind:<6} {case.surface:<10} {case.name[:80]}", flush=True)
        shutil.rmtree(work / f"case-{i:04d}", ignore_errors=True)
    report = (f"wbc from {where.strip()}; {len(cases)} cases, seed {args.seed}, timeout {args.timeout:g} s, memory cap "
              f"{args.memory_mb} MiB; {time.monotonic() - started:.0f} s\n\n{table(results)}\n\nfailures:\n"
              f"{failures(results)}\n")
    print("\n" + report)
    if args.report:
        args.report.write_text(report)
    return 0 if all(v.kind in ("clean", "valid") for _, v in results) else 1


if __name__ == "__main__":
    sys.exit(main())
