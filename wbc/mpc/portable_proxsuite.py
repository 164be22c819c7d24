"""`proxsuite`: ProxSuite's portable (SSE2) build, so an MPC solve does not depend on where memory was allocated.

ProxSuite ships three builds of its bindings (AVX-512, AVX2, portable) and picks the widest the CPU runs. The wide
builds' Eigen reductions start with a scalar head that depends on each buffer's address modulo the 32 or 64 byte
vector width, while the allocator guarantees only 16 bytes; the same QP then solves to answers that differ in the
last bits from one process to the next, depending on what was allocated before it. 16-byte vectors always start
aligned, so the portable build gives the same bits whatever the heap history, and on this project's problem sizes it
is as fast (the measurements: docs/mpc-notes.md).

ProxSuite picks its build at import, asking its ``proxsuite.instructionset`` helper what the CPU supports; this
module answers "nothing wide" for that one question before the import. If ProxSuite was already imported by
someone else, the build already loaded is kept (only one can live in a process) and `BUILD` names it (``wbc bench mpc
--json`` reports it as ``proxsuite_build``).
"""

from __future__ import annotations

import sys
import types

__all__ = ["BUILD", "PORTABLE_BUILD", "proxsuite"]

PORTABLE_BUILD = "proxsuite_pywrap"
"""Module name of ProxSuite's portable bindings."""


def _import_portable() -> types.ModuleType:
    if "proxsuite" in sys.modules:
        return sys.modules["proxsuite"]
    key = "proxsuite.instructionset"
    narrow = types.ModuleType(key)
    narrow.has_AVX512F = lambda: False  # type: ignore[attr-defined]
    narrow.has_AVX2 = lambda: False  # type: ignore[attr-defined]
    sys.modules[key] = narrow
    try:
        import proxsuite as module
    finally:
        if sys.modules.get(key) is narrow:
            del sys.modules[key]
    return module


proxsuite = _import_portable()
BUILD: str = getattr(getattr(proxsuite, "_submodule", None), "__name__", "unknown").rsplit(".", 1)[-1]
"""The ProxSuite build in use (``proxsuite_pywrap`` when this module chose it)."""
