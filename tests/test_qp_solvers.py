"""The MPC's QP backends: DAQP and ProxSuite solve the same QPs to the same plan, warm starts count, failures and
unknown names are refused with what to do; ``wbc bench mpc`` compares them on the walk's QPs; the MPC's settings
come from a file; PlaCo's whole-body QP is a registered variant that plays in the arena."""

import json
import re

import daqp
import numpy as np
import pytest
from conftest import SHORT_SCENARIO
from test_mpc import _standing_problem

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.trial_record import TrialRecord
from wbc.cli.main import main
from wbc.control.registry import CONTROLLERS, get_controller
from wbc.errors import ConfigError
from wbc.mpc import QP_SOLVERS, CentroidalMpc, DenseQp, MpcConfig, MpcSolveError, ProxsuiteSolver, make_qp_solver
from wbc.mpc.config_table import mpc_config_from_table
from wbc.mpc.controller import MpcController
from wbc.mpc.qp_solvers import DaqpSolver, constraint_violation
from wbc.robots.registry import get_robot

TROT = np.array([[1, 0, 0, 1]] * 5 + [[0, 1, 1, 0]] * 5, bool)


def _mpc_with(solver: str, like: CentroidalMpc) -> CentroidalMpc:
    """An MPC like `like` (same limits) solving with `solver`."""
    cfg = MpcConfig(qp_solver=solver)
    return CentroidalMpc(cfg, like._arm_lower - cfg.arm_margin, like._arm_upper + cfg.arm_margin, like._arm_vmax)


def _standing_qp(gait: str):
    """The MPC of the standing a1-wx200 and one update's problem: standing, trotting or kicked sideways."""
    mpc, x0, feet, params = _standing_problem()
    n = mpc.config.horizon
    contact = TROT if gait == "trot" else np.ones((n, 4), bool)
    x = x0.copy()
    if gait == "pushed":
        x[3:6] = (0.0, 0.8, 0.0)
        x[6] = 0.15
    args = (np.tile(x0, (n, 1)), contact, np.tile(feet, (n, 1, 1)), params)
    return mpc, x, args


def test_the_registry_names_daqp_first_and_proxsuite():
    assert list(QP_SOLVERS) == ["daqp", "proxsuite"]
    for name in QP_SOLVERS:
        solver = make_qp_solver(name)
        assert solver.name == name and solver.version()


@pytest.mark.parametrize("gait", ["stand", "trot", "pushed"])
def test_every_backend_solves_the_standing_robots_mpc_qp_to_the_same_plan(gait):
    mpc, x, args = _standing_qp(gait)
    problem = mpc.build(x, *args)
    plans = {name: _mpc_with(name, mpc).solve(problem) for name in QP_SOLVERS}
    daqp = plans["daqp"]
    for name, plan in plans.items():
        np.testing.assert_allclose(plan.forces, daqp.forces, atol=1e-2, err_msg=name)  # [N]
        np.testing.assert_allclose(plan.arm_velocity, daqp.arm_velocity, atol=1e-5, err_msg=name)
        assert problem.objective(plan.z) == pytest.approx(problem.objective(daqp.z), rel=1e-9, abs=1e-9)
        assert plan.iterations >= 1 and plan.solve_s > 0
    # the plans keep the constraints the friction rows stand for
    f = plans["proxsuite"].forces
    assert np.all(np.abs(f[..., :2]) <= mpc.config.mu * f[..., 2:3] + 1e-6)


def test_every_backend_finds_the_optimum_where_a_row_and_a_bound_are_active():
    # min |z - (1, 2)|^2 s.t. z1 + z2 <= 2, 0 <= z1, z2 <= 1.2: the row and z2's bound hold it at (0.8, 1.2),
    # with multipliers 0.4 (row) and 1.2 (bound)
    qp = DenseQp(H=2 * np.eye(2), g=np.array([-2.0, -4.0]), C=np.array([[1.0, 1.0]]), l=np.array([-np.inf]),
                 u=np.array([2.0]), l_box=np.array([0.0, -5.0]), u_box=np.array([5.0, 1.2]))
    for name in QP_SOLVERS:
        for start in (None, np.array([0.0, 0.0]), np.array([5.0, 1.2])):
            result = make_qp_solver(name).solve(qp, start)
            assert result.solved, (name, result.status)
            np.testing.assert_allclose(result.z, [0.8, 1.2], atol=1e-6, err_msg=name)
            assert result.warm == (start is not None)


def test_proxsuite_takes_the_previous_solution_as_its_warm_start():
    # a sequence of nearby QPs (the standing robot's sideways velocity grows a little at each update), each started
    # from the previous one's solution and from rest (no force, the arm still): the previous solution saves iterations
    mpc, x, args = _standing_qp("stand")
    solver = ProxsuiteSolver()
    previous = None
    from_previous_total = from_rest_total = 0
    for vy in np.linspace(0.0, 0.1, 6):
        x[4] = vy
        problem = mpc.build(x, *args)
        rest = np.clip(np.zeros(problem.g.size), problem.l_box, problem.u_box)
        from_rest = solver.solve(problem, rest)
        assert from_rest.solved and from_rest.warm and from_rest.iterations >= 1
        if previous is None:  # started at its own solution, ProxQP finds it optimal before any iteration
            assert solver.solve(problem, from_rest.z).iterations == 0
        else:
            from_previous = solver.solve(problem, np.clip(previous, problem.l_box, problem.u_box))
            assert from_previous.solved and from_previous.warm
            assert from_previous.iterations <= from_rest.iterations
            np.testing.assert_allclose(from_previous.z * problem.scale, from_rest.z * problem.scale, atol=1e-2)
            from_previous_total += from_previous.iterations
            from_rest_total += from_rest.iterations
        previous = from_rest.z
    assert from_previous_total < from_rest_total


@pytest.mark.parametrize(("solver", "label"), [("daqp", "DAQP exit flag -1 (infeasible)"),
                                                ("proxsuite", "ProxSuite PROXQP_")])
def test_an_infeasible_qp_raises_mpc_solve_error_naming_the_solver(solver, label):
    mpc, x, args = _standing_qp("stand")
    problem = mpc.build(x, *args)
    problem.l = problem.l.copy()
    problem.l[0] = 1e3  # f_x - mu f_z >= 1000 (in units of 100 N): beyond every force the boxes allow
    with pytest.raises(MpcSolveError, match=re.escape(f"MPC QP not solved ({label}")) as caught:
        _mpc_with(solver, mpc).solve(problem, np.zeros(problem.horizon * 15))
    assert caught.value.problem is problem
    assert f"qp_solver='{solver}'" in str(caught.value)  # how to replay it under the same backend


def test_an_unknown_qp_solver_is_a_config_error_listing_the_valid_ones(capsys):
    with pytest.raises(ConfigError, match=r"MpcConfig.qp_solver 'osqp' is not a QP solver; valid QP solvers: "
                                          r"daqp, proxsuite"):
        MpcConfig(qp_solver="osqp")
    with pytest.raises(ConfigError, match="valid QP solvers: daqp, proxsuite"):
        make_qp_solver("qpoases")
    with pytest.raises(ConfigError, match="valid QP solvers: daqp, proxsuite"):
        mpc_config_from_table({"mpc": {"qp_solver": "osqp"}})
    with pytest.raises(SystemExit):
        main(["bench", "mpc", "--qp-solver", "osqp"])
    assert "invalid choice: 'osqp' (choose from 'daqp', 'proxsuite')" in capsys.readouterr().err


def test_a_settings_file_chooses_the_qp_solver_and_refuses_unknown_keys(tmp_path):
    path = tmp_path / "proxsuite.toml"
    path.write_text('whole_body = "legs"\n[mpc]\nqp_solver = "proxsuite"\nweight_com = [40, 40, 400]\n')
    spec = get_controller("wbc.mpc.config_table:make", config=path)
    ctrl = spec.make(get_robot("a1-wx200"))
    assert isinstance(ctrl, MpcController)
    assert ctrl.mpc.qp_solver.name == "proxsuite" and ctrl.config.mpc.weight_com == (40.0, 40.0, 400.0)
    assert ctrl.solves == 0  # built and reset, its compiled parts loaded
    with pytest.raises(ConfigError, match=r"^\[mpc\] qp: unknown key; valid keys in \[mpc\]: horizon, .*"
                                          r"qp_solver"):
        mpc_config_from_table({"mpc": {"qp": "daqp"}})
    with pytest.raises(ConfigError, match=r"^\[mpc\] horizon must be an integer, got 1.5"):
        mpc_config_from_table({"mpc": {"horizon": 1.5}})


def test_bench_mpc_walks_on_proxsuite_and_compares_every_backend_on_the_walks_qps(capsys):
    argv = ["bench", "mpc", "--qp-solver", "proxsuite", "--seconds", "0.3", "--threaded-blas", "--no-reference"]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].endswith("QP solver proxsuite 0.8.0, BLAS default threads")
    head = next(i for i, line in enumerate(lines) if "QP backends on the same" in line)
    assert "the loop ran proxsuite 0.8.0" in lines[head]
    assert lines[head + 1].split() == ["solver", "solve", "ms", "p50", "p99", "iters", "p50", "max", "unsolved", "max",
                                       "|dF|", "N", "max", "dJ"]
    rows = [line.split() for line in lines[head + 2:head + 4]]
    assert [r[:2] for r in rows] == [["daqp", rows[0][1]], ["proxsuite", "0.8.0"]]
    assert rows[0][-3:] == ["0", "0", "0"]  # DAQP against itself: all solved, no difference
    assert rows[1][-3] == "0" and float(rows[1][-2]) < 0.01  # ProxSuite: all solved, the same forces to 0.01 N
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["qp_solver"] == "proxsuite 0.8.0"
    assert out["qp_comparison_skipped"] is None
    # the walk's MPC updates (one per 32 ms), every one solved by both backends
    assert out["qp_daqp_qps"] == out["qp_proxsuite_qps"] >= 0.3 / 0.032
    assert out["qp_daqp_unsolved"] == out["qp_proxsuite_unsolved"] == 0
    assert out["qp_daqp_force_max_diff_n"] == 0.0 and out["qp_proxsuite_force_max_diff_n"] < 0.01
    assert out["qp_proxsuite_iterations_median"] >= 1 and out["qp_proxsuite_solve_ms_p99"] > 0


def test_placos_whole_body_qp_is_a_registered_variant_that_plays_in_the_arena(tmp_path):
    spec = CONTROLLERS["mpc-wbqp"]
    ctrl = spec.make(get_robot("a1-wx200"))
    assert isinstance(ctrl, MpcController) and ctrl.wbc is not None and ctrl.config.whole_body == "qp"
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO, encoding="utf-8")
    cfg = ArenaConfig(controllers=("mpc", "mpc-wbqp"), scenario=scenario, trials=1, out_dir=tmp_path / "out",
                      workers=1, progress=False)
    run_arena(cfg)
    rows = {r.controller: r for r in TrialRecord.read_csv(tmp_path / "out" / "trials.csv")}
    wbqp = rows["mpc-wbqp"]
    assert wbqp.outcome == "success" and wbqp.ticks == 500
    # PlaCo's QP ran every tick without failing over to the leg layer, and the MPC solved at every update
    assert wbqp.counter_values["wbc_failures"] == 0 and wbqp.counter_values["mpc_solves"] >= 31
    assert rows["mpc"].counter_values["wbc_failures"] == 0


def test_the_octagonal_pyramid_keeps_every_planned_force_inside_the_friction_cone():
    # kicked along a diagonal of the world's axes, where the square around the cone lets a force reach sqrt(2) mu
    import dataclasses

    from wbc.errors import ConfigError
    from wbc.mpc.centroidal_mpc import MpcConfig

    ratios = {}
    for pyramid in ("octagon", "outer"):
        mpc, x, args = _standing_qp("pushed")
        mpc.config = dataclasses.replace(mpc.config, pyramid=pyramid)
        x[3:6] = (1.5, 1.5, 0.0)
        f = mpc.solve(mpc.build(x, *args)).forces
        stance = f[..., 2] > 1e-6
        ratios[pyramid] = (np.linalg.norm(f[..., :2], axis=-1)[stance] / f[..., 2][stance]).max()
    assert ratios["octagon"] <= mpc.config.mu + 1e-6
    assert ratios["outer"] > 1.2 * mpc.config.mu  # the square around the cone, past it along the diagonal
    with pytest.raises(ConfigError, match="pyramid"):
        MpcConfig(pyramid="cone")


@pytest.mark.parametrize("solver", ["daqp", "proxsuite"])
def test_a_solution_that_breaks_the_rows_is_not_solved_though_the_backend_calls_it_optimal(solver):
    # weights of 1e20 on the orientation make the kicked robot's QP so ill-conditioned that DAQP reports an optimum
    # breaking friction rows by ~89 (8,900 N); a sane weight's solution keeps every constraint to round-off
    mpc, x, args = _standing_qp("pushed")
    sane = mpc.build(x, *args)
    result = make_qp_solver(solver).solve(sane)
    assert result.solved and constraint_violation(sane, result.z) < 1e-9
    cfg = MpcConfig(qp_solver=solver)
    # the settings refuse such weights (MAX_WEIGHT); set behind their back, the solve's own check is what is left
    object.__setattr__(cfg, "weight_rpy", (1e20, 1e20, 1e20))
    absurd = CentroidalMpc(cfg, mpc._arm_lower - cfg.arm_margin, mpc._arm_upper + cfg.arm_margin, mpc._arm_vmax)
    problem = absurd.build(x, *args)
    result = absurd.qp_solver.solve(problem)
    assert not result.solved
    if solver == "daqp":
        assert "exit flag 1 (optimal), its solution breaking a constraint by" in result.status
    with pytest.raises(MpcSolveError) as caught:
        absurd.solve(problem, np.zeros(problem.horizon * 15))
    assert caught.value.problem is problem


def test_daqps_optimum_outside_the_rows_is_refused_after_its_cold_start_too(monkeypatch):
    qp = DenseQp(H=np.eye(2), g=np.zeros(2), C=np.array([[1.0, 1.0]]), l=np.array([1.0]), u=np.array([np.inf]),
                 l_box=-np.ones(2), u_box=np.ones(2))
    calls = []

    def broken(*args, **kwargs):  # "optimal", at a point 1 short of the row
        calls.append(kwargs)
        return np.zeros(2), 0.0, 1, {"iterations": 1}

    monkeypatch.setattr(daqp, "solve", broken)
    result = DaqpSolver().solve(qp, np.zeros(2))
    assert not result.solved and not result.warm
    assert len(calls) == 2  # the warm attempt's broken optimum was followed by a cold start
    assert constraint_violation(qp, np.zeros(2)) == 1.0
    assert constraint_violation(qp, np.array([0.5, 0.5])) == 0.0
    assert constraint_violation(qp, np.array([np.nan, 0.5])) == np.inf


def test_an_absurd_weight_is_refused_naming_the_field():
    with pytest.raises(ConfigError, match=re.escape("MpcConfig.weight_rpy must be")):
        MpcConfig(weight_rpy=(1e20, 1e20, 1e20))
    with pytest.raises(ConfigError, match=re.escape("MpcConfig.weight_force must be")):
        MpcConfig(weight_force=1e13)
    MpcConfig(weight_rpy=(1e12, 1e12, 1e12))  # the bound itself is allowed
    with pytest.raises(ConfigError, match=re.escape("weight_rpy")):
        mpc_config_from_table({"mpc": {"weight_rpy": [1e30, 1e30, 1e30]}})
