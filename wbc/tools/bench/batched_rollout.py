"""`BatchedRollout`: a repeatable ``mujoco.rollout`` throughput measurement, for ``bench sim`` and ``bench train``.

Both benches time the same batched physics, on their own robot and on the bare-A1 reference, interleaved in the same
repeats so that the two figures see the same machine.
"""

from __future__ import annotations

import time

import mujoco
import numpy as np
from mujoco import rollout

__all__ = ["BatchedRollout"]


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
