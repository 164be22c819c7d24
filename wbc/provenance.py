"""`provenance()`: what produced a result (package versions, Python, platform, CPU, git revision), saved beside it.

The results store (``run.json``) and a training run (``config.json``) both write this one record, so every output of
the toolkit names the code that made it the same way; a revision with uncommitted changes to tracked files is marked
``-dirty``, since those changes are not in the revision it names, and the changes themselves are named by the sha256
of ``git diff-index -p HEAD`` (untracked files are not covered: a new file nothing tracks is not in the hash; the text
itself is `git_diff`, which a results directory keeps). Outside a git checkout (an installed wheel, a copied tree, a
Ray node) git knows nothing of the code, so the record also holds `package_sha256`: one hash over every file of the
``wbc`` package (its modules and shipped data and weights), which changes with any edit wherever it runs. Beside
the versions it records what else moves the last bits of a result: the CPU's model and the instruction-set flags its
numerical kernels pick by (AVX2 or AVX-512 ...), and the sha256 of ``requirements/wbc.lock`` when the package runs
from a checkout that has it.

`RESULT_PACKAGES` are the packages whose version changes a result's bits: a resumed run compares them with those it
began under (`wbc.arena.results`), and the test suite compares them with the lock's pins (``tests/test_lock.py``).
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import re
import subprocess
from importlib import metadata
from pathlib import Path

__all__ = ["CHECKOUT", "CPU_FLAGS", "LOCK_FILE", "PACKAGES", "RESULT_PACKAGES", "cpu", "git_diff_sha256",
           "git_diff", "git_revision", "lock_sha256", "package_sha256", "provenance"]

RESULT_PACKAGES = ("numpy", "scipy", "mujoco", "numba", "llvmlite", "proxsuite", "pin", "placo", "casadi", "daqp",
                   "example-robot-data", "torch", "rsl-rl-lib", "onnxruntime")
"""Packages whose version changes the bits of a result: the physics (MuJoCo), the linear algebra (NumPy), the MPC's
compiled tick (numba, llvmlite), its QP backends (ProxSuite, DAQP), the whole-body models and solvers (Pinocchio,
placo, CasADi), the robot models (example-robot-data), the policies' runtimes (torch, rsl-rl, ONNX Runtime), and the
statistics' p-values and intervals (SciPy)."""

PACKAGES = ("wbc", *RESULT_PACKAGES, "meshcat", "threadpoolctl", "ray")
"""Packages whose versions are recorded (those installed): `RESULT_PACKAGES`, the toolkit itself, and those that
change no result (the viewer, the thread-pool control, an executor)."""

CPU_FLAGS = re.compile(r"^(avx.*|fma4?|f16c|sse4_[12]|sse4a|amx.*|asimd.*|sve.*|neon)$")
"""The instruction-set flags recorded: those by which OpenBLAS, numpy's SIMD dispatch, LLVM and MuJoCo pick a kernel
(x86: SSE4, AVX, AVX2, FMA, AVX-512, AMX; Arm: NEON/ASIMD, SVE)."""

LOCK_FILE = Path(__file__).resolve().parent.parent / "requirements" / "wbc.lock"
"""The lock of a checkout (absent from an installed wheel)."""


CHECKOUT = Path(__file__).resolve().parent
"""Where git is asked for the revision: this package's directory (a checkout's, or an install's outside any)."""


def _git(*args: str) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(["git", *args], cwd=CHECKOUT, capture_output=True, timeout=10)


def git_revision() -> str:
    """The git revision of the checkout holding this package, ``-dirty`` if tracked files changed.

    Returns ``unknown`` outside a git checkout (an installed wheel) or without git.
    """
    try:
        rev = _git("rev-parse", "HEAD")
        if rev.returncode != 0:
            return "unknown"
        dirty = _git("status", "--porcelain", "--untracked-files=no")
        return rev.stdout.decode().strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def git_diff_sha256() -> str | None:
    """The sha256 of ``git diff-index -p --binary HEAD`` (`git_diff`): the uncommitted changes to tracked files.

    Untracked files are not covered. Returns None outside a git checkout or without git.
    """
    diff = git_diff()
    return None if diff is None else hashlib.sha256(diff).hexdigest()


def git_diff() -> bytes | None:
    """The uncommitted changes to tracked files, as `git_diff_sha256` hashes them (binary ones too).

    Returns None outside a git checkout or without git; empty bytes for a clean checkout.
    """
    try:
        # the plumbing command, whose output no user setting of `git diff` (prefixes, algorithm, context, textconv)
        # changes: the same tree hashes the same for every user; the index's file times refreshed first, as `git diff`
        # does, so that a file touched but not changed is not a change
        _git("update-index", "-q", "--refresh")
        diff = _git("diff-index", "-p", "--binary", "--no-textconv", "--no-ext-diff", "HEAD")
    except (OSError, subprocess.SubprocessError):
        return None
    return diff.stdout if diff.returncode == 0 else None


_CACHES = ("__pycache__",)
"""Directories of the package that hold caches, not code (Python's bytecode; numba's cache lives there too)."""

_CACHE_SUFFIXES = (".pyc", ".pyo", ".nbi", ".nbc")
"""Files that are caches: bytecode, and numba's index and compiled functions."""

_STRAY_SUFFIXES = ("~", ".orig", ".rej", ".bak", ".swp", ".swo")
"""Files no install holds and no code reads: an editor's backups and swap files, a patch's leftovers."""


def package_files(root: Path = CHECKOUT) -> list[tuple[str, Path]]:
    """The files of the package at `root` that `package_sha256` covers, as (path relative to `root`, path), sorted.

    Every file but caches (`_CACHES` directories, `_CACHE_SUFFIXES` files) and strays (hidden files and folders such
    as ``.DS_Store``, `_STRAY_SUFFIXES` files such as an editor's backups): the modules and the shipped data and
    weights.
    """
    found = []
    for folder, dirs, names in os.walk(root):
        dirs[:] = [d for d in dirs if d not in _CACHES and not d.startswith(".")]
        for name in names:
            if not name.endswith(_CACHE_SUFFIXES + _STRAY_SUFFIXES) and not name.startswith("."):
                path = Path(folder) / name
                found.append((path.relative_to(root).as_posix(), path))
    return sorted(found)


def package_files_sha256(root: Path) -> str:
    """The sha256 over `package_files` of `root`: each file's relative path and the sha256 of its bytes, in order."""
    total = hashlib.sha256()
    for relative, path in package_files(root):
        total.update(relative.encode() + b"\0" + hashlib.sha256(path.read_bytes()).digest())
    return total.hexdigest()


@functools.cache
def package_sha256() -> str | None:
    """The sha256 of this ``wbc`` package's files (`package_files_sha256`), read once per process.

    It names the code that ran wherever it runs: from a checkout, an installed wheel, a copied tree, a Ray node.
    A few tens of milliseconds (the shipped weights are most of its bytes). None where a file cannot be read.
    """
    try:
        return package_files_sha256(CHECKOUT)
    except OSError:
        return None


def lock_sha256(path: Path = LOCK_FILE) -> str | None:
    """The sha256 of the checkout's ``requirements/wbc.lock``, None where there is none (an installed wheel)."""
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def cpu(cpuinfo: Path = Path("/proc/cpuinfo")) -> dict[str, object]:
    """The CPU's model and the instruction-set flags that pick numerical kernels (`CPU_FLAGS`), sorted.

    Read from `cpuinfo` (Linux; its first processor); elsewhere the model is `platform.processor` (or the machine)
    and the flags are None: not known, which is not the same as none.
    """
    model, flags = None, None
    try:
        text = cpuinfo.read_text(encoding="utf-8", errors="replace")
    except OSError:
        text = ""
    for line in text.splitlines():
        key, _, value = line.partition(":")
        key = key.strip().lower()
        if model is None and key in ("model name", "hardware", "cpu model"):
            model = value.strip()
        elif flags is None and key in ("flags", "features"):
            flags = sorted({f for f in value.split() if CPU_FLAGS.match(f)})
        elif not line.strip() and model is not None and flags is not None:
            break  # the first processor's block: the others are the same chip
    return {"model": model or platform.processor() or platform.machine() or "unknown", "flags": flags}


def provenance() -> dict[str, object]:
    """Package versions, Python, platform, CPU, git revision, and where known the lock's and the changes' hashes.

    Returns:
        ``python``, ``platform``, ``packages`` (name -> version, those of `PACKAGES` installed), ``git_revision``,
        ``cpu`` (`cpu`), ``lock_sha256`` (only from a checkout with the lock), ``git_diff_sha256`` (only for a
        ``-dirty`` revision: `git_diff_sha256`, untracked files not covered) and ``wbc_sha256`` (`package_sha256`,
        where its files could be read).
    """
    versions = {}
    for pkg in PACKAGES:
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            continue
    revision = git_revision()
    out: dict[str, object] = {"python": platform.python_version(), "platform": platform.platform(),
                              "packages": versions, "git_revision": revision, "cpu": cpu()}
    lock = lock_sha256()
    if lock is not None:
        out["lock_sha256"] = lock
    if revision.endswith("-dirty"):
        diff = git_diff_sha256()
        if diff is not None:
            out["git_diff_sha256"] = diff
    files = package_sha256()
    if files is not None:
        out["wbc_sha256"] = files
    return out
