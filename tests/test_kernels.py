"""`wbc._kernels`: the numeric kernels every x86-64 machine with AVX2 runs, chosen when `wbc` is imported."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from wbc import _kernels

_REPORT = ("import json, os; {first}from wbc._kernels import kernels_pinned; import numpy; "
           "from threadpoolctl import threadpool_info; "
           "blas = [i.get('architecture') for i in threadpool_info() if i.get('internal_api') == 'openblas']; "
           "from numpy._core._multiarray_umath import __cpu_features__ as f; "
           "print(json.dumps(dict(pinned=kernels_pinned(), blas=blas, avx512=bool(f.get('AVX512F')))))")

avx2 = pytest.mark.skipif(not {"avx2", "fma"} <= _kernels._cpu_flags(), reason="an x86-64 CPU with AVX2 and FMA only")


def _report(first: str = "", **env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")}
    out = subprocess.run([sys.executable, "-c", _REPORT.format(first=first)], env={**clean, **env},
                         capture_output=True, text=True, check=True, timeout=120)
    return json.loads(out.stdout)


@avx2
def test_importing_wbc_first_pins_openblas_to_haswell_and_numpy_below_avx512():
    got = _report()
    assert got == {"pinned": True, "blas": ["Haswell"], "avx512": False}
    # this test process too: conftest imports wbc before numpy
    assert _kernels.kernels_pinned()


@avx2
def test_a_program_that_loaded_numpy_first_keeps_its_kernels_and_is_told_so():
    got = _report(first="import numpy; ")
    assert got["pinned"] is False


@avx2
def test_a_users_own_choice_is_kept():
    got = _report(OPENBLAS_CORETYPE="Sandybridge")
    assert got["pinned"] is True and got["blas"] == ["Sandybridge"]
