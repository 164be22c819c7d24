"""`BatchedRollout`: a repeatable ``mujoco.rollout`` throughput measurement, for ``bench sim`` and ``bench train``.

Both benches time the same batched physics, on their own robot and on the bare-A1 reference, interleaved in the same
repeats so that the two figures see the same machine. A rollout keeps every step's state of every copy, so its buffers
grow with the batch times the steps: `check_rollout_memory` refuses a batch whose buffers would not fit before they
are allocated, with `check_memory`, which ``bench train`` refuses its environments with too.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout

from wbc.errors import ConfigError

__all__ = ["MEMORY_SHARE", "BatchedRollout", "available_memory_bytes", "check_memory", "check_rollout_memory",
           "rollout_bytes"]

MEMORY_SHARE = 0.5
"""The most of the available memory (`available_memory_bytes`) the rollouts' buffers may take."""


def available_memory_bytes(meminfo: str | Path = "/proc/meminfo") -> int | None:
    """The memory available to a new allocation without swapping (``MemAvailable``) [bytes].

    Args:
        meminfo: the file that tells it (Linux's).

    Returns:
        The figure, or None where the system does not tell (no such file, or no readable ``MemAvailable`` line).
    """
    try:
        with open(meminfo, encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024  # given in kB
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        return None
    return None


def rollout_bytes(model: mujoco.MjModel, batch: int, nstep: int) -> int:
    """The bytes of the buffers a `BatchedRollout` of `model` allocates: start states, controls, every step's state."""
    state = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    return 8 * batch * (state * (nstep + 1) + model.nu)


def check_rollout_memory(models: Sequence[mujoco.MjModel], batch: int, nstep: int, option: str = "--batch") -> None:
    """Refuse a batch whose rollouts' buffers, one rollout per model, would not fit in memory.

    They may take at most `MEMORY_SHARE` of the memory available (`available_memory_bytes`); where the system does not
    tell how much that is, nothing is refused.

    Args:
        models: the model of each rollout that will be allocated together.
        batch: copies of the state in each.
        nstep: physics steps of each copy.
        option: the command-line option that sets `batch`, named in the message.

    Raises:
        ConfigError: the buffers would take more than `MEMORY_SHARE` of the available memory; the message names
            `option`, the estimate, the memory available and the largest batch that fits.
    """
    need = sum(rollout_bytes(model, batch, nstep) for model in models)
    check_memory(option, batch, need, each=need / batch,
                 what=f"the batched rollouts' buffers ({batch} environments x {nstep} steps)",
                 none_fits="free some memory (no batch fits in what is left)")


def check_memory(option: str, count: int, need: float, *, each: float, what: str, none_fits: str) -> None:
    """Refuse `count`, the value of `option`, when the `need` bytes it takes exceed `MEMORY_SHARE` of available memory.

    Where the system does not tell how much memory is available (`available_memory_bytes`), nothing is refused.

    Args:
        option: the command-line option that sets `count`, named in the message.
        count: its value.
        need: the bytes `count` takes in all.
        each: the bytes each unit of `count` takes; the rest of `need` is taken whatever `count` is. The message
            gives the largest `count` that fits.
        what: what takes them, for the message (``the batched rollouts' buffers (N environments x S steps)``).
        none_fits: what the message advises when not even a `count` of 1 fits.

    Raises:
        ConfigError: `need` is more than `MEMORY_SHARE` of the available memory; the message names `option`, the
            estimate, the memory available and the largest `count` that fits.
    """
    available = available_memory_bytes()
    if available is None or need <= MEMORY_SHARE * available:
        return
    fits = int((MEMORY_SHARE * available - (need - each * count)) // each)
    advice = f"give {option} {fits} or less" if fits >= 1 else none_fits
    raise ConfigError(f"{option} {count}: {what} need about {need / 1e9:.1f} GB, more than {MEMORY_SHARE:.0%} of the "
                      f"memory available ({available / 1e9:.1f} GB); {advice}")


class BatchedRollout:
    """`mujoco.rollout` of `batch` copies of a model's current state over `nstep` steps, repeatable.

    Every `rate` call starts again from the state the model had at construction, with its controls held, so repeats
    time the same work. The caller shuts the persistent thread pool down (``rollout.shutdown_persistent_pool``).

    Args:
        model: the model.
        data: its data, in the state to start every rollout from.
        batch: copies of the state rolled out together.
        nthread: rollout threads.
        nstep: physics steps per rollout.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, batch: int, nthread: int, nstep: int) -> None:
        which = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(model, which))
        mujoco.mj_getState(model, data, state, which)
        self.model, self.nstep, self.batch = model, nstep, batch
        self.datas = [mujoco.MjData(model) for _ in range(nthread)]
        self.init = np.tile(state, (batch, 1))
        self.control = np.tile(data.ctrl.copy(), (batch, 1, 1))
        self.out = np.empty((batch, nstep, state.size))

    def rate(self) -> float:
        """Roll the batch out once; physics steps of all copies per second of wall time [steps/s]."""
        t0 = time.perf_counter()
        rollout.rollout(self.model, self.datas, self.init, self.control, nstep=self.nstep, state=self.out,
                        persistent_pool=True)
        return self.batch * self.nstep / (time.perf_counter() - t0)
