"""Controllers: the protocol every controller implements, the explicit registry, and the stand controller."""

from wbc.control.registry import CONTROLLERS, POLICY_PREFIX, Controller, ControllerSpec, get_controller

__all__ = ["CONTROLLERS", "POLICY_PREFIX", "Controller", "ControllerSpec", "get_controller"]
