"""The robot's state from what it measures: kinematics, the base estimator, and a robot that reports its estimate.

One package, used alike by the MPC (which closes its loop on the estimate) and by the arena (whose hardware trials
are judged on it, a robot having no simulator truth):

- `wbc.estimation.kinematics`: `RobotKinematics` (feet, hips, leg Jacobians, gravity torques, CoM and centroidal
  momentum at a state) and `CentroidalParams`, over the compiled tree pass of `wbc.estimation.tree`;
- `wbc.estimation.filter`: `BaseEstimator`, the Kalman filter over the base's position and velocity and the feet
  (IMU and leg kinematics);
- `wbc.estimation.base_estimate`: `BaseEstimate`, the filter fed from a robot's `RobotState` once per control tick;
- `wbc.estimation.estimated_robot`: `EstimatedRobot`, a robot whose base truth is that estimate (a hardware trial's
  metrics).
"""

from wbc.estimation.filter import BaseEstimator, EstimatorConfig

__all__ = ["BaseEstimator", "EstimatorConfig"]
