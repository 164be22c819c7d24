"""First-principles analysis of the arm as a tail (the paper's Section VIII), from this toolkit's robot models.

Two quantities, each computed twice:

1. Static: the largest shift of the system CoM that rotating the arm can cause.
   - Paper's rod model: cCoM = M_a / (M_a + M_b) * l / 2 (arm = rod of mass M_a and length l pivoting at the body
     CoM).
   - Exact: the arm swept over a grid of its joint ranges on the Pinocchio model; the shift is half the largest
     width of the set of reachable horizontal CoM positions (the rod model's CoM swings over +-cCoM).
2. Dynamic: body angular acceleration per unit arm angular acceleration, arm swinging in the roll plane.
   - Paper's rod-and-cuboid model: alpha_b / alpha_a = -4 M_a l^2 / (M_b (h^2 + w^2)) (rod about its end, trunk a
     cuboid of height h and width w about its centre).
   - Exact: the whole robot floating free at rest, no gravity, arm pointing sideways and straight out; the shoulder
     joint (whose axis is then the body's x axis) is accelerated and the floating base's reaction is solved from the
     full mass matrix, M_bb a_b = -M_bj qdd_j. The ratio is taken against the arm's absolute angular acceleration
     (joint plus base), as in the rod model.

The inputs of the formulas come from the model: M_a = moving arm mass (shoulder, upper arm, forearm with wrist and
gripper), M_b = everything else, l = shoulder axis to the tip of the lumped forearm with the arm straight, h and w =
the trunk collision box's height and width.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass

import numpy as np
import pinocchio as pin

from wbc.errors import AnalysisError
from wbc.robots.description import RobotDescription
from wbc.robots.joint_table import joint_table
from wbc.robots.pinocchio_model import build_pinocchio
from wbc.robots.urdf import robot_urdf

__all__ = ["TailAnalysis", "PAPER_CCOM_SHIFT_M", "PAPER_ALPHA_RATIO", "analyze_tail"]

PAPER_CCOM_SHIFT_M = 0.022
"""The paper's rod-model CoM shift for its robot (Section VIII) [m], printed beside ours."""
PAPER_ALPHA_RATIO = -0.378
"""The paper's rod-and-cuboid body/arm angular acceleration ratio for its robot (Section VIII), printed beside ours."""


@dataclass(frozen=True)
class TailAnalysis:
    """Results of `analyze_tail` (lengths [m], masses [kg], ratios dimensionless)."""

    robot: str
    arm_mass_moving: float
    body_mass: float
    arm_length: float
    trunk_height: float
    trunk_width: float
    ccom_shift_m: float
    ccom_shift_m_exact: float
    alpha_ratio: float
    alpha_ratio_exact: float
    paper_ccom_shift_m: float = PAPER_CCOM_SHIFT_M
    paper_alpha_ratio: float = PAPER_ALPHA_RATIO

    def as_dict(self) -> dict[str, float | str]:
        """Plain dict (the JSON output of ``wbc analyze tail``)."""
        return asdict(self)


def _trunk_box(desc: RobotDescription) -> tuple[float, float]:
    """Height and width of the trunk's collision box [m]."""
    root = ET.fromstring(robot_urdf(desc))
    for link in root.findall("link"):
        if link.get("name") == "trunk":
            box = link.find("collision/geometry/box")
            if box is not None:
                sx, sy, sz = (float(v) for v in box.get("size").split())
                return sz, sy
    raise AnalysisError(f"{desc.name}: the tail analysis takes the trunk's height and width from the collision box of "
                        "its 'trunk' link, and the URDF has none; give that link a "
                        "<collision><geometry><box size=\"x y z\"/></geometry></collision>")


def _arm_length(desc: RobotDescription) -> float:
    elbow = np.asarray(desc.arm.joints[2].origin)
    forearm = desc.arm.links[2]
    return float(np.linalg.norm(elbow) + np.linalg.norm(np.subtract(forearm.shape_to, forearm.shape_from)))


def _exact_ccom_shift(desc: RobotDescription, samples: int) -> float:
    pr = build_pinocchio(desc)
    table = joint_table(desc)
    base = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0]
    qj = desc.nominal_q
    arm_idx = pr.joints.house_from_pin[12:]  # pin positions of the arm joints
    grids = [np.linspace(table.lower[i], table.upper[i], samples) for i in range(12, 15)]
    coms = []
    q = np.r_[base, qj[pr.joints.pin_from_house]]
    for a in grids[0]:
        for b in grids[1]:
            for c in grids[2]:
                q[7 + arm_idx] = (a, b, c)
                coms.append(pin.centerOfMass(pr.model, pr.data, q)[:2].copy())
    pts = np.array(coms)
    angles = np.linspace(0.0, math.pi, 180, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    proj = pts @ dirs.T
    return float(0.5 * (proj.max(axis=0) - proj.min(axis=0)).max())


def _exact_alpha_ratio(desc: RobotDescription) -> float:
    pr = build_pinocchio(desc)
    model, data = pr.model, pr.data
    # waist +90 deg (arm to the left), shoulder and elbow so the arm is straight and horizontal
    shoulder = math.atan2(desc.arm.joints[2].origin[2], desc.arm.joints[2].origin[0])
    shoulder = math.pi / 2 - shoulder
    arm_q = np.array([math.pi / 2, shoulder, -shoulder])
    qj = np.concatenate([desc.leg_nominal_q, arm_q])
    q = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, qj[pr.joints.pin_from_house]]
    mass = pin.crba(model, data, q)
    mass = np.triu(mass) + np.triu(mass, 1).T
    k = 6 + int(np.flatnonzero(pr.joints.pin_from_house == 13)[0])  # shoulder column in v
    a_base = -np.linalg.solve(mass[:6, :6], mass[:6, k])  # per unit shoulder acceleration
    # the shoulder axis in the world with the waist at +90 deg: body y rotated about z by +90 deg = -x
    axis = np.array([-1.0, 0.0, 0.0])
    alpha_b = float(a_base[3:] @ axis)
    return alpha_b / (1.0 + alpha_b)


def analyze_tail(desc: RobotDescription, *, samples: int = 13) -> TailAnalysis:
    """Compute the paper's static and dynamic arm quantities for `desc` (its arm must be actuated).

    Args:
        desc: robot with an actuated arm.
        samples: grid points per arm joint for the exact CoM sweep.

    Raises:
        AnalysisError: the robot's URDF gives its trunk no collision box.
    """
    if desc.arm_mode != "actuated":
        desc = desc.with_arm_mode("actuated")
    m_a = desc.arm.moving_mass
    total = float(pin.computeTotalMass(build_pinocchio(desc).model))
    m_b = total - m_a
    length = _arm_length(desc)
    h, w = _trunk_box(desc)
    return TailAnalysis(
        robot=desc.name,
        arm_mass_moving=m_a,
        body_mass=m_b,
        arm_length=length,
        trunk_height=h,
        trunk_width=w,
        ccom_shift_m=m_a / (m_a + m_b) * length / 2.0,
        ccom_shift_m_exact=_exact_ccom_shift(desc, samples),
        alpha_ratio=-4.0 * m_a * length**2 / (m_b * (h**2 + w**2)),
        alpha_ratio_exact=_exact_alpha_ratio(desc),
    )
