"""The command line, the tail analysis and optional-dependency messages."""

import json

import numpy as np
import pytest

from wbc.cli.main import main
from wbc.errors import MissingExtraError
from wbc.optional import require
from wbc.robots import get_robot
from wbc.tools.tail import analyze_tail


def test_analyze_tail_json_has_the_documented_keys(capsys):
    assert main(["analyze", "tail", "--robot", "a1-wx200", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("ccom_shift_m", "alpha_ratio", "alpha_ratio_exact"):
        assert isinstance(out[key], float)
    assert out["paper_ccom_shift_m"] == 0.022 and out["paper_alpha_ratio"] == -0.378


def test_tail_rod_model_uses_the_models_numbers():
    desc = get_robot("a1-wx200")
    res = analyze_tail(desc)
    m_a = desc.arm.moving_mass
    assert res.arm_mass_moving == pytest.approx(m_a)
    assert res.ccom_shift_m == pytest.approx(m_a / (m_a + res.body_mass) * res.arm_length / 2)
    # the arm swings the body the other way, and a light arm moves the CoM by centimetres only
    assert -1.0 < res.alpha_ratio_exact < 0.0
    assert 0.0 < res.ccom_shift_m_exact < 0.05
    # a heavier arm turns the body more
    heavy = analyze_tail(get_robot("a1-wx200", arm_mass_scale=2.0))
    assert heavy.alpha_ratio_exact < res.alpha_ratio_exact


def test_exact_alpha_ratio_agrees_with_mujocos_mass_matrix():
    """The floating-base solve on the Pinocchio model gives the same ratio from MuJoCo's mass matrix."""
    import mujoco

    from wbc.hardware.mujoco.scene import build_scene
    from wbc.scenario.terrain import TerrainConfig

    desc = get_robot("a1-wx200")
    res = analyze_tail(desc)
    model = build_scene(desc, TerrainConfig())
    model.opt.gravity[:] = 0
    model.dof_damping[:] = 0
    model.dof_frictionloss[:] = 0
    data = mujoco.MjData(model)
    s = np.pi / 2 - np.arctan2(0.2, 0.05)
    data.qpos[:7] = [0, 0, 3.0, 1, 0, 0, 0]
    data.qpos[7:] = np.r_[desc.leg_nominal_q, np.pi / 2, s, -s]
    mujoco.mj_forward(model, data)
    data.qacc[:] = 0
    data.qacc[6 + 13] = 1.0  # shoulder; solve for the base acceleration with zero base force
    m = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, m)
    a_base = -np.linalg.solve(m[:6, :6], m[:6, 6 + 13])
    alpha_b = a_base[3:] @ np.array([-1.0, 0.0, 0.0])
    assert alpha_b / (1 + alpha_b) == pytest.approx(res.alpha_ratio_exact, rel=1e-6)


def test_unknown_names_list_the_valid_ones(capsys):
    assert main(["analyze", "tail", "--robot", "spot"]) == 2
    assert "a1-wx200, go1-arm" in capsys.readouterr().err
    assert main(["bench", "sim", "--arm", "floppy"]) == 2
    assert "actuated, locked, none" in capsys.readouterr().err


def test_missing_extra_names_the_extra_to_install():
    with pytest.raises(MissingExtraError, match=r"wbc\[train\]"):
        require("torch_module_that_does_not_exist", "train")
    with pytest.raises(MissingExtraError, match=r"wbc\[hardware\]"):
        require("dynamixel_sdk_missing_for_test", "hardware")
    assert require("json") is json


def test_arm_momentum_study_measures_the_arm_against_the_push():
    from wbc.tools.arm_momentum import arm_momentum_study

    actuated = arm_momentum_study("scenarios/push.toml", "mpc", band="ood", trials=1, duration_s=3.5)
    locked = arm_momentum_study("scenarios/push.toml", "mpc-locked", band="ood", trials=1, duration_s=3.5)
    a, b = actuated[0], locked[0]
    # the same push (same trial) on both; 300-400 N for 0.06 s at up to 0.12 m off the trunk's centre
    assert a.push_angular_impulse == pytest.approx(b.push_angular_impulse, rel=0.05)
    assert 0.0 < a.push_angular_impulse < 400 * 0.06 * 0.4
    assert b.arm_momentum_peak == 0.0 and b.arm_travel_rad == 0.0
    assert a.arm_momentum_peak > 0.0 and a.arm_travel_rad > 0.0
