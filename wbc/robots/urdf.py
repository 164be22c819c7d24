"""Build the robot's URDF: the quadruped from example-robot-data plus the arm from its `ArmSpec`.

This URDF is the single kinematic/inertial source read by both MuJoCo and Pinocchio. Nothing is downloaded: the
quadruped's URDF and meshes come from the installed example-robot-data package.
"""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

import numpy as np

from wbc.errors import WbcError
from wbc.robots.arm_spec import ArmLinkSpec
from wbc.robots.description import FOOT_NAMES, RobotDescription
from wbc.robots.inertial import Inertial

__all__ = ["example_robot_data_share", "foot_radii", "robot_urdf", "ARM_PREFIX"]

ARM_PREFIX = "arm_"


@functools.cache
def example_robot_data_share() -> Path:
    """The folder that holds ``example-robot-data/robots/...`` (the ``package://`` root of its URDFs).

    Raises:
        WbcError: the example-robot-data package is not installed.
    """
    try:
        files = metadata.distribution("example-robot-data").files or []
    except metadata.PackageNotFoundError:
        raise WbcError(
            "the example-robot-data package is not installed; it provides the A1 and Go1 URDFs "
            "(pip install example-robot-data)"
        ) from None
    for f in files:
        parts = Path(str(f)).parts
        if "example-robot-data" in parts and parts[-1].endswith(".urdf"):
            full = Path(str(f.locate())).resolve()
            idx = len(full.parts) - (len(parts) - parts.index("example-robot-data"))
            return Path(*full.parts[:idx])
    raise WbcError("the example-robot-data package is installed but ships no URDF files")


def _fmt(v: np.ndarray | tuple[float, ...] | list[float]) -> str:
    return " ".join(f"{float(x):.10g}" for x in v)


def _cylinder_origin(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[str, str, float]:
    """URDF origin (xyz, rpy) and length of a cylinder whose axis runs from a to b."""
    pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    d = pb - pa
    length = float(np.linalg.norm(d))
    yaw = math.atan2(d[1], d[0])
    pitch = math.atan2(math.hypot(d[0], d[1]), d[2])
    return _fmt(0.5 * (pa + pb)), _fmt((0.0, pitch, yaw)), length


def _inertial_element(parent: ET.Element, inertial: Inertial) -> None:
    el = ET.SubElement(parent, "inertial")
    ET.SubElement(el, "origin", xyz=_fmt(inertial.com), rpy="0 0 0")
    ET.SubElement(el, "mass", value=f"{inertial.mass:.10g}")
    i = inertial.inertia
    ET.SubElement(
        el, "inertia",
        ixx=f"{i[0, 0]:.10g}", iyy=f"{i[1, 1]:.10g}", izz=f"{i[2, 2]:.10g}",
        ixy=f"{i[0, 1]:.10g}", ixz=f"{i[0, 2]:.10g}", iyz=f"{i[1, 2]:.10g}",
    )


def _arm_link(robot: ET.Element, spec: ArmLinkSpec) -> None:
    link = ET.SubElement(robot, "link", name=ARM_PREFIX + spec.name)
    xyz, rpy, length = _cylinder_origin(spec.shape_from, spec.shape_to)
    for tag in ("visual", "collision"):
        el = ET.SubElement(link, tag)
        ET.SubElement(el, "origin", xyz=xyz, rpy=rpy)
        geom = ET.SubElement(el, "geometry")
        ET.SubElement(geom, "cylinder", radius=f"{spec.radius:.10g}", length=f"{length:.10g}")
        if tag == "visual":
            ET.SubElement(el, "material", name="arm_black")
    _inertial_element(link, spec.inertial)


def _add_arm(robot: ET.Element, desc: RobotDescription) -> None:
    arm = desc.arm
    mat = ET.SubElement(robot, "material", name="arm_black")
    ET.SubElement(mat, "color", rgba="0.1 0.1 0.1 1")
    _arm_link(robot, arm.base)
    mount = ET.SubElement(robot, "joint", name=ARM_PREFIX + "mount", type="fixed")
    ET.SubElement(mount, "origin", xyz=_fmt(arm.mount_xyz), rpy=_fmt(arm.mount_rpy))
    ET.SubElement(mount, "parent", link="trunk")
    ET.SubElement(mount, "child", link=ARM_PREFIX + arm.base.name)
    parent = arm.base.name
    for joint, link, q0 in zip(arm.joints, arm.links, arm.nominal_q, strict=True):
        _arm_link(robot, link)
        axis = np.asarray(joint.axis, dtype=np.float64)
        if desc.arm_mode == "actuated":
            el = ET.SubElement(robot, "joint", name=ARM_PREFIX + joint.name, type="revolute")
            ET.SubElement(el, "origin", xyz=_fmt(joint.origin), rpy="0 0 0")
            ET.SubElement(el, "axis", xyz=_fmt(axis))
            ET.SubElement(el, "limit", lower=f"{joint.lower:.10g}", upper=f"{joint.upper:.10g}",
                          effort=f"{joint.effort:.10g}", velocity=f"{joint.velocity:.10g}")
            ET.SubElement(el, "dynamics", damping=f"{joint.damping:.10g}", friction=f"{joint.frictionloss:.10g}")
        else:
            # A locked arm is rigid: the joint becomes fixed, rotated by its nominal angle about its axis.
            k = int(np.argmax(np.abs(axis)))
            if not np.isclose(abs(axis[k]), 1.0):
                raise WbcError(f"{desc.name}: locked arm joint {joint.name} needs a principal axis, got {axis}")
            rpy = np.zeros(3)
            rpy[k] = float(q0) * np.sign(axis[k])
            el = ET.SubElement(robot, "joint", name=ARM_PREFIX + joint.name, type="fixed")
            ET.SubElement(el, "origin", xyz=_fmt(joint.origin), rpy=_fmt(rpy))
        ET.SubElement(el, "parent", link=ARM_PREFIX + parent)
        ET.SubElement(el, "child", link=ARM_PREFIX + link.name)
        parent = link.name


_URDF_CACHE: dict[str, str] = {}


def _positive_definite(inertial: ET.Element) -> bool:
    el = inertial.find("inertia")
    if el is None:
        return True
    v = {k: float(el.get(k, "0")) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
    tensor = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])
    return bool(np.all(np.linalg.eigvalsh(tensor) > 0)) or not tensor.any()


def _build_urdf(desc: RobotDescription) -> str:
    share = example_robot_data_share()
    path = share / "example-robot-data" / "robots" / desc.urdf_path
    try:
        robot = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise WbcError(f"{path}: cannot read the {desc.quadruped} URDF ({exc})") from None
    for tag in ("transmission", "gazebo"):
        for el in robot.findall(tag):
            robot.remove(el)
    legs = {name.rsplit("_", 1)[0] for name in desc.joint_names[:12]}
    for joint in robot.findall("joint"):
        name = joint.get("name", "")
        if name.rsplit("_", 1)[0] in legs and joint.get("type") == "revolute":
            part = ("hip", "thigh", "calf").index(name.split("_")[1])
            dyn = joint.find("dynamics")
            if dyn is None:
                dyn = ET.SubElement(joint, "dynamics")
            dyn.set("damping", f"{desc.leg_damping[part]:.10g}")
            dyn.set("friction", f"{desc.leg_frictionloss[part]:.10g}")
    for link in robot.findall("link"):
        inertial = link.find("inertial")
        if inertial is not None and not _positive_definite(inertial):
            # Placeholder inertias (Go1's 1e-6 kg 'base' has all-equal entries) are not physical; MuJoCo rejects
            # them. Dropping them changes the mass by at most such a placeholder's.
            link.remove(inertial)
        if link.get("name", "").startswith(desc.collision_free_links):
            for col in link.findall("collision"):
                link.remove(col)
    if desc.has_arm:
        _add_arm(robot, desc)
    ET.indent(robot)
    return ET.tostring(robot, encoding="unicode")


def robot_urdf(desc: RobotDescription) -> str:
    """The robot's URDF as a string (quadruped + arm in the description's arm mode).

    Mesh paths stay ``package://example-robot-data/...``; resolve them against `example_robot_data_share()`.
    """
    key = repr(desc)
    if key not in _URDF_CACHE:
        _URDF_CACHE[key] = _build_urdf(desc)
    return _URDF_CACHE[key]


def foot_radii(desc: RobotDescription) -> np.ndarray:
    """Each foot's collision-sphere radius in the robot's URDF, in `FOOT_NAMES` order (4,) [m].

    A loaded foot rolls on its sphere: the point in contact is still while the sphere's centre (the foot frame) moves
    at omega x r, so a velocity estimate that assumes the foot frame still reads the robot's speed low by that much
    (`wbc.estimation.tree.tree_pass`'s contact velocities correct it).

    Raises:
        WbcError: a foot link without exactly one collision sphere.
    """
    robot = ET.fromstring(robot_urdf(desc))
    links = {link.get("name"): link for link in robot.findall("link")}
    radii = []
    for foot in FOOT_NAMES:
        link = links.get(foot)
        spheres = [] if link is None else link.findall("collision/geometry/sphere")
        if len(spheres) != 1:
            raise WbcError(f"the URDF of robot {desc.name!r}: link {foot!r} has {len(spheres)} collision spheres, the "
                           "contact-velocity estimate needs exactly one")
        radii.append(float(spheres[0].get("radius", "nan")))
    out = np.array(radii)
    if not np.all(np.isfinite(out) & (out >= 0.0)):
        raise WbcError(f"the URDF of robot {desc.name!r}: foot sphere radii {out.tolist()} are not all finite and >= 0")
    return out
