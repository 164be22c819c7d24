"""`wbc`: whole-body control of quadrupeds that carry an arm.

Subpackages: `wbc.robots` (robot descriptions, MuJoCo and Pinocchio models), `wbc.hardware` (the robot interface
and its backends). See the README for the command line.
"""

from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["MotorCommand", "RobotState", "VelocityCommand", "__version__"]

__version__ = "0.1.0"
