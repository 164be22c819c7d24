"""Errors of the browser viewer: a bad results directory, episode, trial index or recording target."""

from __future__ import annotations

from wbc.errors import WbcError

__all__ = ["ViewerError"]


class ViewerError(WbcError):
    """The viewer cannot show what was asked (missing file, index out of range, server that would not start).

    The message names the file and the field at fault and says how to fix it.
    """
