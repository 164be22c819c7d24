"""The numbers of the paper's three results tables (Huang et al., "Manipulator as a Tail"), printed beside ours.

Copied from the paper's Tables I, II and III as published: success in percent there, stored here as fractions like
the arena's success rates; TTF as the fraction of the episode survived; tracking errors as printed (the paper gives
no unit; its text defines them as L2 distances of velocities, m/s and rad/s). Table I and II cells are mean and
standard deviation over 5 seeds; Table III gives means only. Columns are the paper's push-force bands (Tables I and
III: 200-300 and 300-400, the paper's force unit, which its footnote doubts) or forward speeds (Table II: 1, 1.25
and 1.5 m/s); a scenario's band stands beside the column that commands what it does
(`wbc.tools.paper.tables.paper_column`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PaperValue", "TABLE_I", "TABLE_II", "TABLE_III"]


@dataclass(frozen=True)
class PaperValue:
    """One cell of a paper table: the mean, and the std over seeds where the paper gives one."""

    mean: float
    std: float | None = None


def _row(**cells: tuple[tuple[float, float | None], ...]) -> dict[str, tuple[PaperValue, ...]]:
    return {metric: tuple(PaperValue(m, s) for m, s in values) for metric, values in cells.items()}


TABLE_I: dict[str, dict[str, tuple[PaperValue, ...]]] = {
    "No arm": _row(success_rate=((0.9502, 0.0062), (0.6803, 0.0114)), ttf=((0.975, 0.00), (0.809, 0.01)),
                   vlin_err=((0.230, 0.02), (0.765, 0.03))),
    "Locked": _row(success_rate=((0.9061, 0.0077), (0.4583, 0.0171)), ttf=((0.950, 0.00), (0.627, 0.01)),
                   vlin_err=((0.067, 0.01), (0.224, 0.01))),
    "Actuated": _row(success_rate=((0.9611, 0.0037), (0.7820, 0.0177)), ttf=((0.982, 0.00), (0.875, 0.01)),
                     vlin_err=((0.027, 0.00), (0.120, 0.02))),
}
"""Table I, locomotion under pushes (A1 + WX200): arm setting -> metric -> (200-300, 300-400)."""

TABLE_II: dict[str, dict[str, tuple[PaperValue, ...]]] = {
    "No arm": _row(success_rate=((0.9029, 0.0046), (0.8914, 0.0070), (0.8648, 0.0085)),
                   vang_err=((0.332, 0.023), (0.300, 0.019), (0.291, 0.017)),
                   vlin_err=((0.014, 0.001), (0.022, 0.001), (0.031, 0.001))),
    "Locked": _row(success_rate=((0.8232, 0.0051), (0.7781, 0.0101), (0.6977, 0.0047)),
                   vang_err=((0.234, 0.012), (0.228, 0.010), (0.226, 0.008)),
                   vlin_err=((0.015, 0.001), (0.025, 0.001), (0.037, 0.001))),
    "Actuated": _row(success_rate=((0.8964, 0.0064), (0.8678, 0.0077), (0.8296, 0.0074)),
                     vang_err=((0.184, 0.012), (0.178, 0.010), (0.175, 0.009)),
                     vlin_err=((0.010, 0.001), (0.015, 0.001), (0.024, 0.001))),
}
"""Table II, high-speed turns (Go1 + arm): arm setting -> metric -> (1, 1.25, 1.5 m/s)."""

TABLE_III: dict[str, dict[str, tuple[PaperValue, ...]]] = {
    "PPO": _row(success_rate=((0.6443, None), (0.2310, None)), ttf=((0.770, None), (0.405, None)),
                vlin_err=((0.028, None), (0.029, None))),
    "PPO cur": _row(success_rate=((0.7685, None), (0.3440, None)), ttf=((0.843, None), (0.458, None)),
                    vlin_err=((0.032, None), (0.114, None))),
    "Fine-tuned pi2": _row(success_rate=((0.6975, None), (0.3703, None)), ttf=((0.807, None), (0.543, None)),
                           vlin_err=((0.023, None), (0.066, None))),
    "Decoupled": _row(success_rate=((0.9210, None), (0.6848, None)), ttf=((0.930, None), (0.734, None)),
                      vlin_err=((0.085, None), (0.222, None))),
    "One stage demonstration": _row(success_rate=((0.8793, None), (0.5503, None)), ttf=((0.934, None), (0.692, None)),
                                    vlin_err=((0.023, None), (0.077, None))),
    "Ours": _row(success_rate=((0.9573, None), (0.8473, None)), ttf=((0.975, None), (0.916, None)),
                 vlin_err=((0.021, None), (0.081, None))),
}
"""Table III, the staged method against its baselines under pushes: policy -> metric -> (200-300, 300-400)."""
