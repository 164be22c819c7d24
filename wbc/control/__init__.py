"""Controllers: the protocol every controller implements and its capabilities; the registry; the stand controller.

The package re-exports the protocols only; the registry (`wbc.control.registry`), which builds every controller the
toolkit ships, is imported by name, so code that only speaks the protocol does not load the MPC and the policies.
"""

from wbc.control.protocol import Controller, HasDebugPlan, HasTickTimings, TruthSwitch

__all__ = ["Controller", "HasDebugPlan", "HasTickTimings", "TruthSwitch"]
