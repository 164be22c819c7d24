"""`provenance()`: what produced a result (package versions, Python, platform, git revision), saved beside it.

The results store (``run.json``) and a training run (``config.json``) both write this one record, so every output of
the toolkit names the code that made it the same way; a revision with uncommitted changes to tracked files is marked
``-dirty``, since those changes are not in the revision it names.
"""

from __future__ import annotations

import platform
import subprocess
from importlib import metadata
from pathlib import Path

__all__ = ["PACKAGES", "git_revision", "provenance"]

PACKAGES = ("wbc", "numpy", "mujoco", "pin", "placo", "casadi", "daqp", "meshcat", "example-robot-data",
            "threadpoolctl", "ray", "torch", "rsl-rl-lib", "onnxruntime")
"""Packages whose versions are recorded (those installed)."""


def git_revision() -> str:
    """The git revision of the checkout holding this package, ``-dirty`` if tracked files changed.

    Returns ``unknown`` outside a git checkout (an installed wheel) or without git.
    """
    cwd = Path(__file__).resolve().parent
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, timeout=5)
        if rev.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=5)
        return rev.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def provenance() -> dict[str, object]:
    """Package versions, Python, platform and git revision."""
    versions = {}
    for pkg in PACKAGES:
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            continue
    return {"python": platform.python_version(), "platform": platform.platform(), "packages": versions,
            "git_revision": git_revision()}
