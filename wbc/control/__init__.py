"""Controllers: the protocol every controller implements and its capabilities, the explicit registry, the stand."""

from wbc.control.protocol import Controller, HasDebugPlan, HasTickTimings, TruthSwitch
from wbc.control.registry import CONTROLLERS, POLICY_PREFIX, ControllerSpec, get_controller

__all__ = ["CONTROLLERS", "POLICY_PREFIX", "Controller", "ControllerSpec", "HasDebugPlan", "HasTickTimings",
           "TruthSwitch", "get_controller"]
