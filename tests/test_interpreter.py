"""`realtime_switch_interval`: motor-facing commands shorten the switch interval, never lengthen it."""

from __future__ import annotations

import sys
from collections.abc import Iterator

import pytest

from wbc.hardware.interpreter import REALTIME_SWITCH_INTERVAL_S, realtime_switch_interval


@pytest.fixture(autouse=True)
def _restore() -> Iterator[None]:
    previous = sys.getswitchinterval()
    yield
    sys.setswitchinterval(previous)


def test_shortens_to_the_realtime_interval_and_returns_the_previous() -> None:
    sys.setswitchinterval(0.005)
    assert realtime_switch_interval() == pytest.approx(0.005, rel=0.05)
    assert sys.getswitchinterval() == pytest.approx(REALTIME_SWITCH_INTERVAL_S, rel=0.05)


def test_never_lengthens_a_shorter_interval() -> None:
    sys.setswitchinterval(0.0001)
    realtime_switch_interval()
    assert sys.getswitchinterval() == pytest.approx(0.0001, rel=0.05)  # kept to the microsecond


def test_rejects_a_non_positive_interval() -> None:
    with pytest.raises(ValueError, match="must be > 0"):
        realtime_switch_interval(0.0)
