"""Controllers: the protocol every controller implements and its capabilities; plug-ins; the contract checker.

The package re-exports the protocols, the plug-in declaration and the contract checker, none of which loads a
controller or the simulator; the registry (`wbc.control.registry`), which builds every controller the toolkit ships
and resolves every controller name, is imported by name, so code that only speaks the protocol does not load the MPC
and the policies.
"""

from wbc.control.controller_contract import CheckConfig, ControllerCheck, check_controller
from wbc.control.plugin import ControllerPlugin
from wbc.control.protocol import Controller, HasDebugPlan, HasTickTimings, TruthSwitch
from wbc.control.spec import ControllerSpec

__all__ = ["CheckConfig", "Controller", "ControllerCheck", "ControllerPlugin", "ControllerSpec", "HasDebugPlan",
           "HasSettings", "HasTickTimings", "TruthSwitch", "check_controller"]
