"""Shared memory between a controller's process and the I/O process that holds its robot's devices.

`IoBlocks` maps one memory file (``memfd``) that both processes map: a state block (written by the I/O process, read
by the controller's) and a command block (the other way). Each block has a single writer and is published without a
lock, so neither side ever waits for the other's interpreter:

- every block holds two slots; publication ``k`` goes to slot ``k % 2`` while slot ``(k - 1) % 2`` holds the
  previous, complete one; the block's header counts publications (``count``, an aligned 8-byte word);
- each slot is a sequence lock: its sequence word is odd while the writer fills it and ``2 k`` once publication ``k``
  is complete, and a CRC-32 of its record is written before that; a reader copies the slot named by ``count``, and
  keeps the copy only if the sequence word read before and after is ``2 k`` and the CRC matches (a torn or
  reordered copy, whatever the processor's memory order, is retried).

The memory is a ``memfd`` handed to the child as an inherited descriptor, not a named `multiprocessing.shared_memory`
block: it has no name to leak in ``/dev/shm`` when either process is killed (the kernel frees it with the last
mapping), and Python 3.11's resource tracker, which would register the child's attachment and start a tracker
process for it, is never involved.
"""

from __future__ import annotations

import mmap
import os
import time
import zlib

import numpy as np

from wbc.errors import RobotLinkError
from wbc.hardware.unitree.layout import REMOTE_SIZE

__all__ = ["HELD_DAMP", "HELD_FIELDS", "HELD_HOLD", "HELD_RAMP", "MAX_STATUS", "IoBlocks", "SeqBlock", "command_dtype",
           "state_dtype"]

MAX_STATUS = 32
"""Most motors whose mode and temperature a state carries (legs 12 + the arm's servos)."""

_SLOT_HEADER = 16  # sequence word (u8), CRC-32 (u4), padding
_BLOCK_HEADER = 64  # publication count (u8), failure flag (u8), padding to a cache line
_TORN_RETRY_S = 0.01  # [s] how long a reader retries before it calls the block broken


def state_dtype(num_joints: int) -> np.dtype:
    """One state: a `RobotState`, the remote's block, the motors' status, the devices' deadline trips and e-stops."""
    n = num_joints
    return np.dtype([
        ("tick", "<i8"), ("time", "<f8"), ("q", "<f8", (n,)), ("dq", "<f8", (n,)), ("tau_est", "<f8", (n,)),
        ("imu_quat", "<f8", (4,)), ("gyro_in_body", "<f8", (3,)), ("accel_in_body", "<f8", (3,)),
        ("foot_force", "<f8", (4,)), ("status_n", "<i8"), ("motor_mode", "<i8", (MAX_STATUS,)),
        ("motor_temperature", "<f8", (MAX_STATUS,)), ("has_remote", "<i8"), ("remote", "u1", (REMOTE_SIZE,)),
        ("deadline_trips", "<i8"), ("remote_estops", "<i8"), ("remote_estop_latched", "<i8"),
        # `JoinedDevices`: the legs' and the arm's state ages [s] (NaN: no such device) and deadline trips (-1: none)
        ("legs_age", "<f8"), ("arm_age", "<f8"), ("legs_deadline_trips", "<i8"), ("arm_deadline_trips", "<i8"),
    ])


HELD_FIELDS = ("generation", "mode", "kd", "duration_s", "slew", "kp", "ramp_kd", "hold_s")
"""The ``held`` field of a command record: what the joints no controller drives get (`HeldJoints`), as of this
command. ``generation`` counts the safety layer's calls (a new one starts a new ramp); ``mode`` is `HELD_HOLD`,
`HELD_DAMP` (``kd``) or `HELD_RAMP` (a `CommandRamp` of the other fields)."""
HELD_HOLD, HELD_DAMP, HELD_RAMP = 0.0, 1.0, 2.0


def command_dtype(num_joints: int) -> np.dtype:
    """One command: its rows q, dq, kp, kd, tau (5, n), the held joints' mode, the link's e-stop releases so far.

    ``held`` is `HELD_FIELDS`; ``estop_releases`` counts the safety layer's releases of the link's L2 + B latch
    (`RemoteEstopLatch`): a new count releases it, before the command it comes with.
    """
    return np.dtype([("rows", "<f8", (5, num_joints)), ("held", "<f8", (len(HELD_FIELDS),)),
                     ("estop_releases", "<i8")])


def _round_up(n: int, to: int = 64) -> int:
    return (n + to - 1) // to * to


class SeqBlock:
    """One single-writer record in shared memory, double-buffered behind sequence words (see the module docstring).

    Args:
        buf: the shared mapping.
        offset: where the block starts (64-byte aligned).
        dtype: the record's layout.
    """

    def __init__(self, buf: mmap.mmap, offset: int, dtype: np.dtype) -> None:
        self.dtype = dtype
        self._size = dtype.itemsize
        self._stride = _round_up(_SLOT_HEADER + self._size)
        self._header = np.ndarray((2,), np.uint64, buffer=buf, offset=offset)
        base = offset + _BLOCK_HEADER
        self._seqs = [np.ndarray((1,), np.uint64, buffer=buf, offset=base + k * self._stride) for k in range(2)]
        self._crcs = [np.ndarray((1,), np.uint32, buffer=buf, offset=base + k * self._stride + 8) for k in range(2)]
        self._records = [np.ndarray((), dtype, buffer=buf, offset=base + k * self._stride + _SLOT_HEADER)
                         for k in range(2)]
        self._raws = [memoryview(buf)[base + k * self._stride + _SLOT_HEADER:
                                      base + k * self._stride + _SLOT_HEADER + self._size] for k in range(2)]

    @staticmethod
    def nbytes(dtype: np.dtype) -> int:
        """Bytes a block of `dtype` records takes (header and both slots)."""
        return _BLOCK_HEADER + 2 * _round_up(_SLOT_HEADER + dtype.itemsize)

    @property
    def count(self) -> int:
        """Publications so far (0: none yet); one aligned word, read without the lock."""
        return int(self._header[0])

    @property
    def failed(self) -> bool:
        """The writer's failure flag (the I/O process sets it when its devices failed)."""
        return bool(self._header[1])

    def set_failed(self) -> None:
        """Raise the failure flag."""
        self._header[1] = 1

    def record(self) -> np.ndarray:
        """The slot the next `publish` fills (a 0-d structured array): set its fields, then call `publish`.

        Only the block's one writer may call this; the slot's sequence word is made odd first.
        """
        k = self.count + 1
        self._seqs[k % 2][0] = 2 * k - 1
        return self._records[k % 2]

    def publish(self) -> int:
        """Complete the publication `record` began: CRC, sequence word, then the count. Returns its number."""
        k = self.count + 1
        slot = k % 2
        self._crcs[slot][0] = zlib.crc32(self._raws[slot])
        self._seqs[slot][0] = 2 * k
        self._header[0] = k
        return k

    def release(self) -> None:
        """Drop every view of the shared mapping (before it is unmapped)."""
        for raw in self._raws:
            raw.release()
        self._header = self._seqs = self._crcs = self._records = self._raws = None  # type: ignore[assignment]

    def read(self) -> tuple[int, np.ndarray | None]:
        """The newest complete publication: (its number, a private copy of its record), or (0, None) before any.

        Raises:
            RobotLinkError: no consistent copy within 10 ms (the writer lapped the reader every time, or the memory
                is corrupt).
        """
        deadline = None
        while True:
            k = self.count
            if k == 0:
                return 0, None
            slot = k % 2
            before = int(self._seqs[slot][0])
            data = bytes(self._raws[slot])
            crc = int(self._crcs[slot][0])
            after = int(self._seqs[slot][0])
            if before == after == 2 * k and zlib.crc32(data) == crc:
                return k, np.frombuffer(data, self.dtype)[0]
            now = time.monotonic()
            if deadline is None:
                deadline = now + _TORN_RETRY_S
            elif now > deadline:
                raise RobotLinkError(f"shared {self.dtype.names[0]} block: no consistent copy of publication {k} "
                                     f"within {_TORN_RETRY_S * 1e3:.0f} ms")


class IoBlocks:
    """The memory file and its two blocks (state, command) for a robot of `num_joints` joints.

    Args:
        num_joints: the robot's joints.
        fd: an existing memory file to map (the I/O process's inherited descriptor); None creates one.
    """

    def __init__(self, num_joints: int, fd: int | None = None) -> None:
        self.num_joints = num_joints
        state, command = state_dtype(num_joints), command_dtype(num_joints)
        state_bytes = SeqBlock.nbytes(state)
        size = state_bytes + SeqBlock.nbytes(command)
        self.fd = fd if fd is not None else os.memfd_create("wbc-io", 0)
        try:
            if fd is None:
                os.ftruncate(self.fd, size)
            self._map = mmap.mmap(self.fd, size)
        except BaseException:
            os.close(self.fd)
            raise
        self.state = SeqBlock(self._map, 0, state)
        self.command = SeqBlock(self._map, state_bytes, command)

    def close(self) -> None:
        """Unmap the memory and close the file (the kernel frees it once the other process has too)."""
        for block in (self.state, self.command):
            if block is not None:
                block.release()
        self.state = self.command = None  # type: ignore[assignment]
        try:
            self._map.close()
        except BufferError:
            pass  # a caller still holds a view; the mapping goes with the process
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
