"""The numbers of the paper's three results tables (Huang et al., "Manipulator as a Tail"), printed beside ours.

Copied from the paper's Tables I, II and III as published, as text with the paper's digits (`PaperValue`): success
in percent, as there (`PaperValue.mean` gives it as a fraction like the arena's success rates); TTF as the fraction of
the episode survived; tracking errors as printed (the paper gives no unit; its text defines them as L2 distances of
velocities, m/s and rad/s). Table I and II cells are mean and standard deviation over 5 seeds; Table III gives means
only. Columns are the paper's push-force bands (Tables I and
III: 200-300 and 300-400, the paper's force unit, which its footnote doubts) or forward speeds (Table II: 1, 1.25
and 1.5 m/s); a scenario's band stands beside the column that commands what it does
(`wbc.tools.paper.tables.paper_column`).
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal
from typing import Any

__all__ = ["PROTOCOL_I", "PROTOCOL_II", "PROTOCOL_III", "PaperProtocol", "PaperValue", "TABLE_I", "TABLE_II",
           "TABLE_III"]


@dataclass(frozen=True, kw_only=True)
class PaperValue:
    """One cell of a paper table as the paper prints it: the mean, and the std over seeds where the paper gives one.

    The paper's digits are kept as text, so that its precision travels with the number and the cell is printed as
    the paper printed it: ``0.975 ± 0.00``, never a ``0.975 ± 0.000`` whose third digit the paper did not give.

    Attributes:
        mean_text: the mean as the paper prints it (``"95.02"``, ``"0.975"``).
        std_text: the std over seeds as the paper prints it (``"0.62"``, ``"0.00"``); None where it gives none.
        percent: the texts are in percent (success), while `mean` and `std` are fractions like the arena's success
            rates.
    """

    mean_text: str
    std_text: str | None = None
    percent: bool = False

    def _value(self, text: str) -> float:
        return float(Decimal(text).scaleb(-2)) if self.percent else float(text)

    @property
    def mean(self) -> float:
        """The mean, in the arena's unit (success as a fraction)."""
        return self._value(self.mean_text)

    @property
    def std(self) -> float | None:
        """The std over seeds, in the arena's unit; None where the paper gives none."""
        return None if self.std_text is None else self._value(self.std_text)

    @property
    def text(self) -> str:
        """The cell as the paper prints it: ``95.02 ± 0.62``, or the mean alone (``95.73``)."""
        return self.mean_text if self.std_text is None else f"{self.mean_text} ± {self.std_text}"


@dataclass(frozen=True, kw_only=True)
class PaperProtocol:
    """How the paper evaluated a table: the n behind its numbers.

    Attributes:
        trials: trials per column (band) and contender, over all its seeds.
        seeds: the seeds they were spread over; None where the paper does not say (Table III).
        duration_s: each trial's length [s].
        note: what else the paper says of the trials ("" for nothing).
    """

    trials: int
    seeds: int | None
    duration_s: float
    note: str = ""

    @property
    def trials_per_seed(self) -> int | None:
        """Trials per column, contender and seed (``--trials`` for the paper's protocol); None without seeds."""
        return None if self.seeds is None else self.trials // self.seeds

    @property
    def text(self) -> str:
        """As the printed header says it: ``5 seeds, 2000 trials, 20 s each``, then the note."""
        seeds = f"{self.seeds} seeds, " if self.seeds is not None else ""
        return f"{seeds}{self.trials} trials, {self.duration_s:g} s each" + (f"; {self.note}" if self.note else "")

    def to_json(self) -> dict[str, Any]:
        """``paper.json``'s ``paper_protocol``: ``{"seeds", "trials", "trials_per_seed", "duration_s", "note"}``."""
        return {"seeds": self.seeds, "trials": self.trials, "trials_per_seed": self.trials_per_seed,
                "duration_s": self.duration_s, "note": self.note}


def _row(**cells: tuple[tuple[str, str | None], ...]) -> dict[str, tuple[PaperValue, ...]]:
    # success is printed in percent, as the paper prints it
    return {metric: tuple(PaperValue(mean_text=m, std_text=s, percent=metric == "success_rate") for m, s in values)
            for metric, values in cells.items()}


TABLE_I: dict[str, dict[str, tuple[PaperValue, ...]]] = {
    "No arm": _row(success_rate=(("95.02", "0.62"), ("68.03", "1.14")), ttf=(("0.975", "0.00"), ("0.809", "0.01")),
                   vlin_err=(("0.230", "0.02"), ("0.765", "0.03"))),
    "Locked": _row(success_rate=(("90.61", "0.77"), ("45.83", "1.71")), ttf=(("0.950", "0.00"), ("0.627", "0.01")),
                   vlin_err=(("0.067", "0.01"), ("0.224", "0.01"))),
    "Actuated": _row(success_rate=(("96.11", "0.37"), ("78.20", "1.77")), ttf=(("0.982", "0.00"), ("0.875", "0.01")),
                     vlin_err=(("0.027", "0.00"), ("0.120", "0.02"))),
}
"""Table I, locomotion under pushes (A1 + WX200): arm setting -> metric -> (200-300, 300-400)."""

PROTOCOL_I = PaperProtocol(seeds=5, trials=2000, duration_s=20.0)
"""Table I's protocol."""

TABLE_II: dict[str, dict[str, tuple[PaperValue, ...]]] = {
    "No arm": _row(success_rate=(("90.29", "0.46"), ("89.14", "0.70"), ("86.48", "0.85")),
                   vang_err=(("0.332", "0.023"), ("0.300", "0.019"), ("0.291", "0.017")),
                   vlin_err=(("0.014", "0.001"), ("0.022", "0.001"), ("0.031", "0.001"))),
    "Locked": _row(success_rate=(("82.32", "0.51"), ("77.81", "1.01"), ("69.77", "0.47")),
                   vang_err=(("0.234", "0.012"), ("0.228", "0.010"), ("0.226", "0.008")),
                   vlin_err=(("0.015", "0.001"), ("0.025", "0.001"), ("0.037", "0.001"))),
    "Actuated": _row(success_rate=(("89.64", "0.64"), ("86.78", "0.77"), ("82.96", "0.74")),
                     vang_err=(("0.184", "0.012"), ("0.178", "0.010"), ("0.175", "0.009")),
                     vlin_err=(("0.010", "0.001"), ("0.015", "0.001"), ("0.024", "0.001"))),
}
"""Table II, high-speed turns (Go1 + arm): arm setting -> metric -> (1, 1.25, 1.5 m/s)."""

PROTOCOL_II = PaperProtocol(seeds=5, trials=2000, duration_s=20.0,
                            note="yaw rate 0.5 rad/s in half the trials, 2 rad/s in the rest")
"""Table II's protocol."""

TABLE_III: dict[str, dict[str, tuple[PaperValue, ...]]] = {
    "PPO": _row(success_rate=(("64.43", None), ("23.10", None)), ttf=(("0.770", None), ("0.405", None)),
                vlin_err=(("0.028", None), ("0.029", None))),
    "PPO cur": _row(success_rate=(("76.85", None), ("34.40", None)), ttf=(("0.843", None), ("0.458", None)),
                    vlin_err=(("0.032", None), ("0.114", None))),
    "Fine-tuned pi2": _row(success_rate=(("69.75", None), ("37.03", None)), ttf=(("0.807", None), ("0.543", None)),
                           vlin_err=(("0.023", None), ("0.066", None))),
    "Decoupled": _row(success_rate=(("92.10", None), ("68.48", None)), ttf=(("0.930", None), ("0.734", None)),
                      vlin_err=(("0.085", None), ("0.222", None))),
    "One stage demonstration": _row(success_rate=(("87.93", None), ("55.03", None)),
                                    ttf=(("0.934", None), ("0.692", None)),
                                    vlin_err=(("0.023", None), ("0.077", None))),
    "Ours": _row(success_rate=(("95.73", None), ("84.73", None)), ttf=(("0.975", None), ("0.916", None)),
                 vlin_err=(("0.021", None), ("0.081", None))),
}
"""Table III, the staged method against its baselines under pushes: policy -> metric -> (200-300, 300-400)."""

PROTOCOL_III = PaperProtocol(seeds=None, trials=2000, duration_s=20.0, note="half standing, half at 0.3 m/s")
"""Table III's protocol: the paper gives no seeds for it, and means only."""
