"""Emulated robots on 127.0.0.1 that speak a real robot's wire, backed by the MuJoCo simulator, with faults on demand.

A hardware backend's tests run against these instead of a robot: `UnitreeEmulator` (the A1 / Go1 low-level UDP
wire). This room sits above `wbc.hardware.mujoco` (it drives a `MujocoRobot`) and below every controller.
"""

from wbc.hardware.emulators.faults import FRAME_FAULTS, STATE_FAULTS, Fault, FaultSet, apply_state_faults, mangle_frame
from wbc.hardware.emulators.logged_command import LoggedCommand
from wbc.hardware.emulators.unitree import MODES, UnitreeEmulator, UnitreeEmulatorConfig

__all__ = [
    "FRAME_FAULTS",
    "MODES",
    "STATE_FAULTS",
    "Fault",
    "FaultSet",
    "LoggedCommand",
    "UnitreeEmulator",
    "UnitreeEmulatorConfig",
    "apply_state_faults",
    "mangle_frame",
]
