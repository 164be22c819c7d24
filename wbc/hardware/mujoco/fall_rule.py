"""The fall rule, shared by evaluation (`MujocoRobot.fallen`) and training (`BatchedEnv`'s termination).

A robot has fallen when one of its collision geoms touches the ground anywhere but at a foot (the paper's termination
rule: the trunk or a non-foot link on the ground). A contact is a foot's if it is the foot sphere's, or if it lies
within `FOOT_ZONE` of a foot centre: the URDFs' calf boxes run down to the foot centre, so a foot pressed a little into
the ground also brings the calf box's end into contact, which is still the foot, not a fall. A calf touching the
ground away from its foot (a kneeling robot) is a fall.

`MujocoRobot` applies the rule to MuJoCo's contact list (`touches_off_foot`, compiled: it runs after every control
tick); the batched env applies it to contact sensors (one per
`fall_geoms` geom, reporting contact positions) and foot-centre sensors inside MuJoCo's step, vectorised over robots.
"""

from __future__ import annotations

import mujoco
import numba
import numpy as np

from wbc.robots.description import FOOT_NAMES

__all__ = ["FOOT_ZONE", "fall_geoms", "foot_geoms", "near_feet", "touches_off_foot"]

FOOT_ZONE = 0.035  # [m] contacts this close to a foot centre are the foot's (foot sphere radius 0.02 + margin)


def foot_geoms(model: mujoco.MjModel) -> np.ndarray:
    """The foot spheres' geom ids, in `FOOT_NAMES` order (FR, FL, RR, RL).

    Feet are fused into the calves, so each is found by place and shape: the sphere of the foot site's body closest
    to the site.
    """
    out = []
    for foot in FOOT_NAMES:
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, foot)
        body = model.site_bodyid[site]
        spheres = [g for g in range(model.ngeom)
                   if model.geom_bodyid[g] == body and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
        out.append(min(spheres, key=lambda g: np.linalg.norm(model.geom_pos[g] - model.site_pos[site])))
    return np.array(out)


def fall_geoms(model: mujoco.MjModel) -> np.ndarray:
    """The robot's collision geoms other than the foot spheres (their ground contacts are falls unless `near_feet`)."""
    feet = set(foot_geoms(model).tolist())
    can_touch = set(model.pair_geom2.tolist())  # the scene pairs each robot collision geom with the ground
    return np.array([g for g in range(model.ngeom) if model.geom_bodyid[g] != 0 and g not in feet
                     and (g in can_touch or model.geom_contype[g] or model.geom_conaffinity[g])])


def near_feet(contact_pos: np.ndarray, foot_centres: np.ndarray) -> np.ndarray:
    """Whether each contact lies within `FOOT_ZONE` of a foot centre.

    Args:
        contact_pos: (..., 3) contact positions in the world [m].
        foot_centres: (..., F, 3) foot centres in the world [m], broadcast against `contact_pos`.

    Returns:
        (...) bool.
    """
    d2 = np.square(contact_pos[..., None, :] - foot_centres).sum(axis=-1)
    return (d2 < FOOT_ZONE * FOOT_ZONE).any(axis=-1)


@numba.njit(cache=True, nogil=True)
def touches_off_foot(pairs, contact_pos, terrain_geom, is_foot_geom, foot_geoms, geom_xpos):  # pragma: no cover
    """The fall rule on one robot's contact list: whether a ground contact is neither a foot's nor near one.

    True when a contact is neither a foot sphere's nor within `FOOT_ZONE` of a foot centre.

    Args:
        pairs: the contacts' geom pairs (ncon, 2), one of each the ground's (`terrain_geom`).
        contact_pos: the contacts' positions, world (ncon, 3) [m].
        terrain_geom: the ground's geom id.
        is_foot_geom: (ngeom,) bool, True at the foot spheres.
        foot_geoms: the foot spheres' geom ids (4,).
        geom_xpos: every geom's centre, world (ngeom, 3) [m].
    """
    zone2 = FOOT_ZONE * FOOT_ZONE
    for c in range(pairs.shape[0]):
        other = pairs[c, 1] if pairs[c, 0] == terrain_geom else pairs[c, 0]
        if is_foot_geom[other]:
            continue
        near = False
        for f in range(foot_geoms.shape[0]):
            g = foot_geoms[f]
            dx = contact_pos[c, 0] - geom_xpos[g, 0]
            dy = contact_pos[c, 1] - geom_xpos[g, 1]
            dz = contact_pos[c, 2] - geom_xpos[g, 2]
            if dx * dx + dy * dy + dz * dz < zone2:
                near = True
                break
        if not near:
            return True
    return False
