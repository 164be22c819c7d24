"""`wbc`: whole-body control of quadrupeds that carry an arm.

Packages by role, from the bottom up: `wbc.scenario` (world data), `wbc.robots`, `wbc.hardware` (the robot interface
and its backends), `wbc.mpc` and `wbc.learned` (the two contenders), `wbc.control` (the controller protocol and
registry), `wbc.arena` (the runner loop and comparisons), `wbc.viz`, `wbc.tools`, `wbc.cli`. The documentation's
architecture page (docs/architecture.md) says what each holds.
"""

from wbc._kernels import pin_kernels

pin_kernels()  # before numpy loads: the same bits on every x86-64 machine (wbc/_kernels.py)

from wbc.types import MotorCommand, RobotState, VelocityCommand  # noqa: E402

__all__ = ["MotorCommand", "RobotState", "VelocityCommand", "__version__"]

__version__ = "0.1.0"
