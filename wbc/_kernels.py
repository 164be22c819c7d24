"""The same floating point on every x86-64 machine: numeric kernels chosen before numpy loads.

Two libraries under `wbc` pick their code by the CPU they find at run time. OpenBLAS, numpy's BLAS, picks a kernel per
CPU family (SkylakeX on an AVX-512 Intel, Zen on an AMD EPYC), and numpy picks its own SIMD loops (AVX-512 versions of
`arctan2`, `sin` and the reductions on a CPU that has it). Each gives results that differ in the last bits from
another's. One last bit is enough: a closed loop of contacts and a QP turns it into another trajectory, and a trial
that fell on one machine survives on another. So the published tables, the golden trials and a user's rerun would
agree only on the same CPU family.

`pin_kernels` asks both for the code every AVX2 machine runs: OpenBLAS's Haswell kernel (``OPENBLAS_CORETYPE``) and
numpy's loops without AVX-512 (``NPY_DISABLE_CPU_FEATURES``). With them, an Intel and an AMD machine give the same
bits under the locked versions (tests/test_golden.py and tests/test_mpc_ticks.py were recorded on one and pass on
the other). It runs when `wbc` is imported, so it works for the ``wbc`` command and for any program that imports
`wbc` before numpy; spawned worker processes inherit the settings. A value the user set is kept. A program that
loaded numpy first keeps its kernels (`kernels_pinned` says so); a CPU without AVX2 and FMA keeps its own BLAS
kernel, and other architectures are left as they are.
"""

from __future__ import annotations

import os
import platform
import sys

__all__ = ["BLAS_KERNEL", "NUMPY_FEATURES_OFF", "kernels_pinned", "pin_kernels"]

BLAS_KERNEL = "Haswell"
"""OpenBLAS's kernel for every x86-64 CPU with AVX2 and FMA (Intel since 2013, AMD since 2015)."""

NUMPY_FEATURES_OFF = ("AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL "
                      "AVX512_SPR")
"""numpy's AVX-512 dispatch targets, switched off (a target the CPU lacks is ignored)."""

_pinned = False


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def pin_kernels() -> bool:
    """Ask OpenBLAS and numpy for the kernels every AVX2 machine runs, if numpy is not loaded yet.

    Returns:
        True if the settings are in place for this process (set here, or by the user before), False if numpy was
        already loaded with its own, or the machine is not an x86-64 with AVX2 and FMA.
    """
    global _pinned
    if platform.machine().lower() not in ("x86_64", "amd64") or "numpy" in sys.modules:
        return _pinned
    flags = _cpu_flags()
    if not {"avx2", "fma"} <= flags:
        return _pinned
    os.environ.setdefault("OPENBLAS_CORETYPE", BLAS_KERNEL)
    os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_FEATURES_OFF)
    _pinned = True
    return _pinned


def kernels_pinned() -> bool:
    """True if this process's numeric kernels were pinned by `pin_kernels` before numpy loaded."""
    return _pinned
