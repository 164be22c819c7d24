"""How each controller is drawn in the arena's plots: a colour-blind-safe colour plus cues that need no colour.

`controller_styles` gives every controller of a run, by its position in the run's controller order, one
`ControllerStyle`: a colour of the Okabe-Ito palette (distinct under deuteranopia, protanopia and tritanopia), a
marker, a line style and a bar hatch. Marker, line style and hatch each differ between any two of the first eight
controllers, so that a reader who cannot tell the colours apart (or a grey print) still can; a controller keeps its
style in every plot of the run (`wbc.arena.plots`). Pure data: no matplotlib import.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["OKABE_ITO", "ControllerStyle", "controller_styles"]

OKABE_ITO = ("#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#000000", "#F0E442")
"""Okabe & Ito's colour-blind-safe palette (blue, orange, bluish green, vermillion, reddish purple, sky blue, black,
yellow), in the order controllers take it: yellow, the faintest on white, last."""

_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">")
_LINESTYLES: tuple[str | tuple[int, tuple[int, ...]], ...] = (
    "-", "--", ":", "-.", (0, (5, 1, 1, 1, 1, 1)), (0, (8, 2)), (0, (1, 1)), (0, (3, 1, 1, 1, 3, 3)))
_HATCHES = ("", "//", "..", "xx", "\\\\", "oo", "++", "--", "**", "||")


@dataclass(frozen=True)
class ControllerStyle:
    """How one controller is drawn.

    Attributes:
        color: its colour, ``#rrggbb``.
        marker: its matplotlib marker.
        linestyle: its matplotlib line style (a name or an ``(offset, dashes)`` pattern).
        hatch: its bar hatch ("" for a plain bar).
    """

    color: str
    marker: str
    linestyle: str | tuple[int, tuple[int, ...]]
    hatch: str


def controller_styles(controllers: Sequence[str]) -> dict[str, ControllerStyle]:
    """The style of each controller, by its position in `controllers` (the run's order), the same in every plot.

    Past eight controllers the colours repeat; marker, line style and hatch still tell them apart (markers repeat
    after ten, line styles after eight: no two of the first forty share both).

    Args:
        controllers: the run's controllers, in order.

    Returns:
        controller -> its `ControllerStyle`, in the order given.
    """
    return {c: ControllerStyle(color=OKABE_ITO[i % len(OKABE_ITO)], marker=_MARKERS[i % len(_MARKERS)],
                               linestyle=_LINESTYLES[i % len(_LINESTYLES)], hatch=_HATCHES[i % len(_HATCHES)])
            for i, c in enumerate(controllers)}
