"""`provenance()`: what a run records of the environment it was played under (``run.json``'s ``environment``).

Everything that moves a result's last bits is named: the packages that change results (numba and llvmlite compile
the MPC's tick, SciPy computes the p-values, ProxSuite is a QP backend), the CPU's model and instruction-set flags,
the lock's hash, the git revision and, for a ``-dirty`` one, the hash of its uncommitted changes.
"""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

import pytest

from wbc import provenance as provenance_module
from wbc.provenance import LOCK_FILE, RESULT_PACKAGES, cpu, provenance


# -- what is recorded ------------------------------------------------------------------------------------------------
def test_the_packages_that_compile_the_tick_and_compute_the_statistics_are_recorded() -> None:
    recorded = provenance()["packages"]
    for name in ("numba", "llvmlite", "scipy", "proxsuite"):
        assert name in RESULT_PACKAGES
        assert name in recorded, f"{name} is installed in the locked environment but not recorded"


def test_the_cpu_model_and_its_kernel_flags_are_recorded(tmp_path: Path) -> None:
    x86 = tmp_path / "x86"
    x86.write_text("processor\t: 0\nmodel name\t: Intel(R) Xeon(R) Gold\nflags\t\t: fpu sse2 sse4_2 avx avx2 fma "
                   "avx512f avx512bw cx16\n\nprocessor\t: 1\nmodel name\t: Intel(R) Xeon(R) Gold\nflags\t\t: fpu\n")
    assert cpu(x86) == {"model": "Intel(R) Xeon(R) Gold", "flags": ["avx", "avx2", "avx512bw", "avx512f", "fma",
                                                                     "sse4_2"]}
    arm = tmp_path / "arm"
    arm.write_text("processor\t: 0\nFeatures\t: fp asimd evtstrm aes sve sve2\nCPU part\t: 0xd0c\n\n"
                   "Hardware\t: Ampere Altra\n")
    assert cpu(arm)["flags"] == ["asimd", "sve", "sve2"]
    unknown = cpu(tmp_path / "absent")  # not Linux: the model from the platform, the flags unknown (not none)
    assert unknown["flags"] is None and isinstance(unknown["model"], str) and unknown["model"]
    assert set(provenance()["cpu"]) == {"model", "flags"}


@pytest.mark.skipif(not LOCK_FILE.exists(), reason="run from an install, not a checkout: no lock beside the package")
def test_the_lock_is_recorded_by_its_hash() -> None:
    assert provenance()["lock_sha256"] == hashlib.sha256(LOCK_FILE.read_bytes()).hexdigest()


def _git(repo: Path, *args: str) -> bytes:
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=repo, check=True,
                          capture_output=True).stdout


def test_a_dirty_revision_names_its_uncommitted_changes_by_their_hash(tmp_path: Path, monkeypatch) -> None:
    repo = tmp_path / "checkout"
    repo.mkdir()
    _git(repo, "init", "-q")
    (repo / "gains.py").write_text("KP = 60.0\n")
    (repo / "blob.bin").write_bytes(bytes(range(256)))
    _git(repo, "add", ".")
    _git(repo, "commit", "-q", "-m", "first")
    monkeypatch.setattr(provenance_module, "CHECKOUT", repo)
    clean = provenance()
    assert not clean["git_revision"].endswith("-dirty") and "git_diff_sha256" not in clean
    (repo / "gains.py").write_text("KP = 61.0\n")
    first = provenance()
    assert first["git_revision"] == clean["git_revision"] + "-dirty"
    assert first["git_diff_sha256"] == hashlib.sha256(_git(repo, "diff", "HEAD", "--binary")).hexdigest()
    (repo / "blob.bin").write_bytes(bytes(range(255, -1, -1)))  # a binary change moves the hash too
    assert provenance()["git_diff_sha256"] != first["git_diff_sha256"]
    (repo / "blob.bin").write_bytes(bytes(range(256)))
    (repo / "gains.py").write_text("KP = 62.0\n")  # another edit of the same file: another hash, the same revision
    again = provenance()
    assert again["git_revision"] == first["git_revision"] and again["git_diff_sha256"] != first["git_diff_sha256"]
