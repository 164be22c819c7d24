"""The robot as a Pinocchio model (free-flyer root), with visual geometry from the URDF meshes for the viewer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wbc.robots.conventions import JointIndexMap
from wbc.robots.description import RobotDescription
from wbc.robots.joint_table import joint_table
from wbc.robots.urdf import example_robot_data_share, robot_urdf

__all__ = ["PinocchioRobot", "build_pinocchio"]

_MESH_LOADER = pin.CachedMeshLoader()
"""Loads each mesh file once per process: a robot's four calves share one file, and every viewer scene of a robot
after its first (an A / B page, each trial of a watched run) reads none again. Parsing a Collada mesh and building
its collision tree is most of the cost of a robot's visual model (~0.8 s for the A1 without the cache, ~0.3 s for
its first model with it)."""


@dataclass
class PinocchioRobot:
    """A Pinocchio model of one robot and the index map to the house joint order.

    Attributes:
        model: kinematic/dynamic model, root joint ``root_joint`` (free flyer); rotor inertia in ``model.armature``.
        data: a data buffer for `model`.
        joints: house-order <-> Pinocchio-order joint permutation.
        visual_model: visual geometry (URDF meshes), or None when not requested.
    """

    model: pin.Model
    data: pin.Data
    joints: JointIndexMap
    visual_model: pin.GeometryModel | None = None


def build_pinocchio(desc: RobotDescription, *, with_visuals: bool = False) -> PinocchioRobot:
    """Build the Pinocchio model of `desc` from the same URDF as the MuJoCo model."""
    urdf = robot_urdf(desc)
    model = pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())
    table = joint_table(desc)
    pin_names = tuple(model.names[2:])
    joints = JointIndexMap(table.names, pin_names)
    armature = np.zeros(model.nv)
    armature[6:] = table.armature[joints.pin_from_house]
    model.armature = armature
    visual = None
    if with_visuals:
        visual = pin.buildGeomFromUrdfString(
            model, urdf, pin.GeometryType.VISUAL, package_dirs=[str(example_robot_data_share())],
            mesh_loader=_MESH_LOADER,
        )
    return PinocchioRobot(model=model, data=model.createData(), joints=joints, visual_model=visual)
