"""Re-recording the goldens (``WBC_RECORD_GOLDEN=1``): in one process only, each golden file written once.

`tests/test_golden.py` and `tests/test_mpc_ticks.py` compare results with committed files, and re-record them when
``WBC_RECORD_GOLDEN=1``. Under pytest-xdist (``make test`` runs ``-n auto``) a worker could load a file another worker
is rewriting, and two workers write ``tests/golden/versions.json``: the suite refuses to record there
(`recording_refusal`, from ``conftest.pytest_configure``) and names the serial command, `RECORD_COMMAND`.
"""

from __future__ import annotations

import os

import pytest

RECORD_COMMAND = "make golden"
"""Re-records every golden in one process: ``WBC_RECORD_GOLDEN=1 .venv/bin/python -m pytest -q -p no:xdist
tests/test_golden.py tests/test_mpc_ticks.py``."""


def recording_refusal(numprocesses: object, worker: str | None) -> str | None:
    """Why the goldens cannot be re-recorded in this session (None when they can: one process).

    Args:
        numprocesses: pytest-xdist's ``-n`` (None without xdist; 0 runs in one process).
        worker: ``PYTEST_XDIST_WORKER``, set in an xdist worker.
    """
    if numprocesses in (None, 0, "0") and not worker:
        return None
    return ("WBC_RECORD_GOLDEN=1 re-records the goldens, which parallel workers (pytest-xdist, as `make test` runs) "
            "would race for: one loading tests/golden/mpc_ticks.npz while another rewrites it, two writing "
            f"tests/golden/versions.json. Re-record in one process: `{RECORD_COMMAND}` (WBC_RECORD_GOLDEN=1 "
            ".venv/bin/python -m pytest -q -p no:xdist tests/test_golden.py tests/test_mpc_ticks.py)")


def recording() -> bool:
    """Whether this session re-records the goldens; fails the test in an xdist worker (`recording_refusal`)."""
    if os.environ.get("WBC_RECORD_GOLDEN") != "1":
        return False
    problem = recording_refusal(None, os.environ.get("PYTEST_XDIST_WORKER"))
    if problem is not None:
        pytest.fail(problem)
    return True
