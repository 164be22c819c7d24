"""The safety layer: `SafeRobot` wraps any `Robot` and decides what reaches its motors.

``waiting`` -> ``ramp`` -> ``run``, and ``damped`` (latched) on any trip: stale or bad state, joint range, over-power,
motor temperature or mode, tilt, remote L2 + B, software e-stop. Every transition is a `SafetyEvent`.
"""

from wbc.hardware.safety.config import SafetyConfig
from wbc.hardware.safety.events import REASONS, REMEDIES, TRIP_REASONS, SafetyEvent
from wbc.hardware.safety.limits import POSITION_TABLES, UNITREE_POSITION_LIMITS, position_range
from wbc.hardware.safety.ramp import CommandRamp
from wbc.hardware.safety.safe_robot import SafeRobot
from wbc.hardware.safety.state import SafetyState

__all__ = [
    "POSITION_TABLES",
    "REASONS",
    "TRIP_REASONS",
    "UNITREE_POSITION_LIMITS",
    "REMEDIES",
    "CommandRamp",
    "SafeRobot",
    "SafetyConfig",
    "SafetyEvent",
    "SafetyState",
    "position_range",
]
