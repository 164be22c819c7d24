"""`LinkStats`: a snapshot of a Unitree low-level link's counters, for a log or a fault-injection test.

The link thread keeps the counts; `UnitreeRobot.link_stats()` copies them into this frozen record, so a reader
never sees a half-updated set. The period figures and the overruns are the link thread's own statistics
(`wbc.hardware.device_thread.DeviceThreadStats`, from `UnitreeRobot.thread_stats()`, which has the period's
percentiles too). Keys for a log come from `as_dict`, namespaced with ``link/``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ["LinkStats"]


@dataclass(frozen=True, kw_only=True)
class LinkStats:
    """Counters of one link since `connect`.

    Attributes:
        frames_sent: LowCmd datagrams put on the wire.
        damping_sent: of which damping frames (before the first state, after the write deadline, while closing).
        deadline_trips: times the write deadline expired and the link switched to damping.
        valid_states: LowState frames accepted (the freshness tick of `read`).
        rejected_states: LowState frames rejected by the decoder (`decode_stats` says why).
        foreign: datagrams dropped because they came from another address than the target.
        unsent: frames the network refused to send (down or unreachable for a while); the link went on.
        state_age: time since the newest valid state arrived [s] (inf before the first).
        period_mean: mean interval between two periods of the link thread [s] (0 before two).
        period_std: standard deviation of that interval (the link's jitter) [s].
        period_min: shortest such interval [s].
        period_max: longest such interval [s].
        overruns: periods that started more than a period after they were due (the link thread's late cycles,
            `DeviceThreadStats.late`; the thread then starts its schedule afresh).
        late_advances: `advance` calls that found their deadline already past.
        worst_lateness: the latest such call, by how much [s].
    """

    frames_sent: int = 0
    damping_sent: int = 0
    deadline_trips: int = 0
    valid_states: int = 0
    rejected_states: int = 0
    foreign: int = 0
    unsent: int = 0
    state_age: float = float("inf")
    period_mean: float = 0.0
    period_std: float = 0.0
    period_min: float = 0.0
    period_max: float = 0.0
    overruns: int = 0
    late_advances: int = 0
    worst_lateness: float = 0.0

    def as_dict(self, prefix: str = "link/") -> dict[str, float]:
        """The counters as a flat dict, keys namespaced with `prefix`."""
        return {f"{prefix}{k}": v for k, v in asdict(self).items()}
