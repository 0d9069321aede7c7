"""Optimal control: LEPF, exact gradients (RK4 sensitivities, costates, shooting Jacobians),
the analytic bang-bang answer of Ghorbani et al.'s scenario 1 against both numeric solvers and the
paper, scenarios 2-3 constraints, identified-model plans and the `shipid plan` CLI."""
import builtins
import json
from pathlib import Path

import numpy as np
import pytest

from shipid.cli import main
from shipid.control import (Problem, bang_bang_straight, kcs_turn_problem, lepf, paper_problem, problem_from_dict,
                            rk4_sensitivities, solve_direct, solve_indirect, switch_time)
from shipid.control.direct import _MS
from shipid.control.indirect import _Augmented
from shipid.models import get_model
from shipid.simulate import simulate

PAPER = {"switch_x": 258.0, "switch_u": 9.0, "switch_t": 37.0, "final_time": 53.0}


def _planing_mass(m):
    s = m.params_series()
    return s["m"] - s["X_udot"]


def test_lepf_linear_extension_is_c1():
    r = 0.04
    eps = -np.sqrt(r)
    v, d = lepf(np.array([eps - 1e-9, eps + 1e-9]), r)
    assert v[0] == pytest.approx(v[1], rel=1e-6) and d[0] == pytest.approx(d[1], rel=1e-6)
    v, _ = lepf(np.array([-1.0, 0.5]), r)
    assert v[0] == pytest.approx(1.0) and v[1] == pytest.approx((0.5 - 2 * eps) / eps**2)


def test_rk4_sensitivities_match_finite_differences():
    m = get_model("planing-boat")
    rng = np.random.default_rng(0)
    x, u = m.sample_point(rng, batch=(3,))
    h = 0.3
    xn, A, B, c = rk4_sensitivities(m, x, u, m.params, h)
    for j in range(m.nx):
        e = np.zeros(m.nx)
        e[j] = 1e-6
        fd = (rk4_sensitivities(m, x + e, u, m.params, h)[0] - rk4_sensitivities(m, x - e, u, m.params, h)[0]) / 2e-6
        np.testing.assert_allclose(A[..., j], fd, rtol=1e-5, atol=1e-7)
    e = np.array([1.0, 1e-6])
    fd = (rk4_sensitivities(m, x, u + e * [1, 0], m.params, h)[0] - rk4_sensitivities(m, x, u - e * [1, 0], m.params, h)[0]) / 2.0
    np.testing.assert_allclose(B[..., 0], fd, rtol=1e-5, atol=1e-9)
    fd = (rk4_sensitivities(m, x, u, m.params, h + 1e-6)[0] - rk4_sensitivities(m, x, u, m.params, h - 1e-6)[0]) / 2e-6
    np.testing.assert_allclose(c, fd, rtol=1e-5, atol=1e-6)


def _kcs_small(**kw):
    pr = kcs_turn_problem(n_intervals=6, substeps=2, **kw)
    pr.state_bounds = {"r": (-0.2, 0.2)}
    return Problem(model=pr.model, x0=pr.x0, input_bounds={"delta": (pr.u_lo[0], pr.u_hi[0]), "n": (5.0, 13.0)},
                   input_rate_bounds={"delta": pr.rate[0]}, u_initial=pr.u_initial, terminal={"psi": np.pi / 2, "r": 0.0},
                   state_bounds={"r": (-0.2, 0.2)}, terminal_bounds={"v": (-0.1, 0.1)}, tf_guess=20.0,
                   n_intervals=6, substeps=2, state_scale={"psi": 0.1, "r": 0.01},
                   running=lambda x, u: (0.01 * u[..., 0] ** 2, np.zeros_like(x), np.stack([0.02 * u[..., 0], 0 * u[..., 1]], -1)))


def test_costate_gradient_is_exact():
    pr = _kcs_small()
    aug = _Augmented(pr)
    rng = np.random.default_rng(1)
    z = np.r_[rng.uniform(0.2, 0.8, 12), 1.1]
    for r in (1.0, 1e-3):
        f, g = aug(z, r)
        for i in range(len(z)):
            e = np.zeros_like(z)
            e[i] = 1e-6
            fd = (aug(z + e, r)[0] - aug(z - e, r)[0]) / 2e-6
            assert g[i] == pytest.approx(fd, rel=1e-5, abs=1e-6), (r, i)


def test_multiple_shooting_jacobians_are_exact():
    pr = _kcs_small()
    ms = _MS(pr, 3)
    rng = np.random.default_rng(2)
    U = pr.initial_controls() + 0.05 * rng.normal(size=(6, 2))
    _, X, _ = pr.simulate(U, 20.0)
    w = ms.pack(U, X[4::4] + 0.01, 20.0)
    for fun, jac in ((ms.eq, ms.eq_jac), (ms.ineq, ms.ineq_jac), (lambda w: ms.cost(w)[0], lambda w: ms.cost(w)[1][None])):
        J = jac(w)
        for i in range(ms.n):
            e = np.zeros_like(w)
            e[i] = 1e-6
            np.testing.assert_allclose(J[:, i], (fun(w + e) - fun(w - e)) / 2e-6, rtol=1e-5, atol=1e-6)


def test_switch_time_detection():
    U = np.r_[np.full(5, 7500.0), 3750.0, np.zeros(4)]
    assert switch_time(U, 0.0, 7500.0, 50.0) == pytest.approx(27.5)
    assert switch_time(np.r_[np.full(5, 7500.0), np.zeros(5)], 0.0, 7500.0, 50.0) == pytest.approx(25.0)
    assert switch_time(np.r_[7500.0, 0.0, 7500.0, 0.0], 0.0, 7500.0, 4.0) is None


@pytest.fixture(scope="module")
def bang():
    m = get_model("planing-boat")
    return m, bang_bang_straight(m.resistance, _planing_mass(m), 7500.0, 300.0, 0.5)


def test_analytic_answer_replayed_by_the_4dof_model(bang):
    m, b = bang
    # the switching curve answer, replayed through the full 4-DOF model with a fine RK4 grid
    t = np.linspace(0.0, b.final_time, 4001)
    T = np.where(t < b.switch_t, 7500.0, 0.0)
    res = simulate(m, np.zeros(8), t, inputs=np.c_[T, np.zeros_like(t)])
    assert res.state("x")[-1] == pytest.approx(300.0, abs=0.05)
    assert res.state("u")[-1] == pytest.approx(0.5, abs=0.01)
    assert np.all(res.state("y") == 0.0)


def test_analytic_answer_against_the_paper(bang):
    m, b = bang
    rel = {k: getattr(b, k) / PAPER[k] - 1 for k in PAPER}
    # Savitsky's curve for Table 1 (VCG 0.5 m) has its hump 1 kN below full thrust, so the boat
    # clears it: total time within 15 % of the paper, but the switch comes earlier and faster.
    assert abs(rel["final_time"]) < 0.15 and abs(rel["switch_x"]) < 0.15
    assert rel["switch_u"] > 0.4 and rel["switch_t"] < -0.15
    # The paper's numbers imply R_T(9 m/s) close to full thrust (its boat is stuck behind the hump):
    # raising our curve by 10 % (k_R = 1.10) reproduces all four numbers within 15 %.
    b2 = bang_bang_straight(lambda u: 1.10 * m.resistance(u), _planing_mass(m), 7500.0, 300.0, 0.5)
    for k in PAPER:
        assert getattr(b2, k) == pytest.approx(PAPER[k], rel=0.15), k


def test_scenario1_direct_agrees_with_analytic(bang):
    _, b = bang
    res = solve_direct(paper_problem(1, n_intervals=12, substeps=8))
    assert res.success, res.message
    assert res.final_time == pytest.approx(b.final_time, rel=0.01)
    assert res.switch_time == pytest.approx(b.switch_t, rel=0.03)


@pytest.mark.slow
def test_scenario1_indirect_agrees_with_analytic(bang):
    _, b = bang
    # 11 LEPF stages: with 10, the exterior-penalty residual on u(tf) sits at the 0.01 tolerance and
    # depends on round-off (0.0085 before, 0.0137 after a 1e-11 change of the R_T evaluation); 11 give
    # 0.0082. The later stages stall after one L-BFGS-B iteration (docs/control.md), so it shrinks little.
    # A stage stopped at its iteration limit is not success; with the default max_iter=300
    # every stage converges.  Stages run to gtol (ftol=0, the default): with L-BFGS-B's relative-
    # reduction stop at 1e-13 an AMD EPYC stopped the late stages with the thrust sagging to 0.965 of
    # full and no switch; to gtol both CPUs give the bang-bang (switch 28.66 s, violation 0.0079).
    res = solve_indirect(paper_problem(1, n_intervals=20, substeps=4), method="bfgs", n_penalty=11)
    assert res.success, res.message
    assert res.final_time == pytest.approx(b.final_time, rel=0.01)
    assert res.switch_time == pytest.approx(b.switch_t, rel=0.03)


@pytest.mark.slow
@pytest.mark.parametrize("k", [2, 3])
def test_scenarios_2_3_satisfy_constraints(k):
    pr = paper_problem(k)
    res = solve_direct(pr)
    # The constraints are what we require.  SLSQP needs 339 iterations on scenario 3 on an AMD EPYC
    # (violation 0.0026); 300, the old default limit, stopped it at 0.0148 there.
    assert res.max_constraint_violation <= 1e-2, res.message
    df = res.to_pandas()
    # the paper's limits on the fine grid (1 % of each bound's range as tolerance)
    assert df["u"].max() <= 20.0 + 0.1
    assert np.degrees(df["p"].abs().max()) <= 10.0 * 1.01
    assert np.degrees(df["r"].abs().max()) <= 15.0 * 1.01
    assert np.degrees(df["phi"].abs().max()) <= 20.0 * 1.01
    assert df["T"].between(0, 7500).all() and np.degrees(df["phi_p"].abs().max()) <= 45.0 + 1e-9
    assert df["x"].iloc[-1] == pytest.approx(300.0, abs=0.1) and df["y"].iloc[-1] == pytest.approx(0.0, abs=0.1)
    assert abs(df["u"].iloc[-1]) <= 0.5 + 0.01
    # turning costs time against the straight run of scenario 1
    assert res.final_time > 45.0


@pytest.mark.slow
def test_identified_model_turn_direct_and_indirect_agree():
    fit = {"model": "kcs-response", "coef": get_model("kcs-response").params_series().to_dict()}
    # 12 intervals keep the test short (20 give the same pattern, 11.55 s vs 11.42 s here)
    pr = kcs_turn_problem(get_model(fit["model"], fit["coef"]), n_intervals=12)
    d = solve_direct(pr)
    i = solve_indirect(pr)
    assert d.success and i.success, (d.message, i.message)
    assert i.final_time == pytest.approx(d.final_time, rel=0.02)
    delta = d.controls[:, 0]
    # rudder limited by angle and rate: ramps at 16.8 deg/s, reaches hard over, counter-rudders
    steps = np.degrees(np.abs(np.diff(np.r_[0.0, delta]))) / (d.final_time / pr.n_intervals)
    assert steps.max() <= 16.8 * 1.001 and np.degrees(np.abs(delta)).max() == pytest.approx(35.0, abs=0.01)
    assert delta[-1] < 0 < delta[len(delta) // 2]


def test_indirect_my_turn_converges_and_agrees_with_direct():
    """The bundled PROBLEM.json example: the indirect method's last penalty stage ends at a minimum to rounding
    (L-BFGS-B's line search finds no decrease, even restarted) -- converged, and within 0.1 % of the direct
    method's final time, every constraint within the tolerance."""
    from shipid.control import load_problem

    pr = load_problem(Path(__file__).resolve().parents[1] / "data" / "my_turn.json")
    d = solve_direct(pr)
    i = solve_indirect(pr)
    assert d.success and i.success, (d.message, i.message)
    assert i.final_time == pytest.approx(d.final_time, rel=1e-3)
    assert i.max_constraint_violation <= i.tol
    assert all(h["message"][:1].islower() for h in i.history)  # the stages' status in words, not L-BFGS-B's codes


# ----------------------------------------------------------------------------------- CLI
def test_cli_plan_problem_json(tmp_path):
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": "kcs-response", "coef": {"c3": 0.2}}))
    prob = {"fit_result": "fit.json", "x0": {"u": 1.7}, "u_initial": {"delta": 0.0, "n": 10.0},
            "input_bounds": {"delta": [-0.6109, 0.6109], "n": [5, 13]}, "input_rate_bounds": {"delta": 0.2932},
            "terminal": {"psi": 0.5, "r": 0.0}, "tf_guess": 10, "n_intervals": 6, "substeps": 2,
            "state_scale": {"psi": 0.1, "r": 0.01}, "name": "kcs-small-turn"}
    pf = tmp_path / "problem.json"
    pf.write_text(json.dumps(prob))
    before = pf.read_text()
    out = tmp_path / "plan.json"
    assert main(["plan", str(pf), "--method", "direct", "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["method"] == "direct-slsqp" and doc["switch_time_s"] is None
    assert doc["max_constraint_violation"] <= 1e-2 and 3.0 < doc["final_time_s"] < 30.0
    csv = (tmp_path / "plan.csv").read_text().splitlines()
    assert csv[0] == "time [s],x [m],y [m],psi [rad],u [m/s],v [m/s],r [rad/s],delta [rad],n [rps]" and len(csv) > 20
    assert pf.read_text() == before
    # existing output is not overwritten without --force
    assert main(["plan", str(pf), "-o", str(out)]) == 2


def test_cli_bad_inputs(tmp_path, capsys):
    bad = tmp_path / "p.json"
    bad.write_text(json.dumps({"model": "kcs-response", "input_bounds": {"delta": [-0.5, 0.5]}, "colour": 1}))
    assert main(["plan", str(bad), "-o", str(tmp_path / "o.json")]) == 2
    assert "unknown key(s) 'colour'" in capsys.readouterr().err
    bad.write_text(json.dumps({"model": "kcs-response", "input_bounds": {"delta": [-0.5, 0.5]}}))
    assert main(["plan", str(bad), "-o", str(tmp_path / "o.json")]) == 2
    assert "every input needs finite bounds; missing for ['n']" in capsys.readouterr().err
    assert main(["plan", str(tmp_path / "nope.json"), "-o", str(tmp_path / "o.json")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["plan", "paper-1", "-o", str(tmp_path / "o.txt")]) == 2
    assert main(["plan", "paper-1", "--method", "indirect", "--optimizer", "slsqp", "-o", str(tmp_path / "o.json")]) == 2
    assert "not available with --method indirect" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown scenario"):
        paper_problem(7)
    with pytest.raises(ValueError, match="give 'model'"):
        problem_from_dict({"input_bounds": {}})


def test_missing_casadi_gives_a_clear_error(monkeypatch, capsys, tmp_path):
    real_import = builtins.__import__

    def no_casadi(name, *args, **kwargs):
        if name == "casadi" or name.startswith("casadi."):
            raise ImportError("No module named 'casadi'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_casadi)
    from shipid.control.ipopt import MissingExtraError, have_casadi  # importable without CasADi

    assert not have_casadi()
    with pytest.raises(MissingExtraError, match=r"pip install shipid\[casadi\]"):
        solve_direct(paper_problem(1, n_intervals=4, substeps=2), method="ipopt")
    # the CLI reports it as one line and exit code 2
    assert main(["plan", "paper-1", "--optimizer", "ipopt", "-o", str(tmp_path / "p.json")]) == 2
    assert "pip install shipid[casadi]" in capsys.readouterr().err
    # the rest of the control layer does not need CasADi
    assert solve_direct(paper_problem(1, n_intervals=4, substeps=2), max_iter=2).method == "direct-slsqp"


def test_plan_progress_on_request_and_quiet_off_a_terminal(tmp_path, capsys):
    args = ["plan", "paper-1", "--intervals", "6", "--substeps", "2"]
    assert main([*args, "-o", str(tmp_path / "a.json")]) in (0, 1)
    assert capsys.readouterr().err == ""  # stderr is not a terminal here: no progress by default
    assert main([*args, "--progress", "-o", str(tmp_path / "b.json")]) in (0, 1)
    assert "paper-1 (slsqp)" in capsys.readouterr().err
    solve_indirect(paper_problem(1, n_intervals=6, substeps=2), n_penalty=2, max_iter=5, progress=True)
    assert "LEPF stages" in capsys.readouterr().err
    assert main([*args, "--tol", "nan", "-o", str(tmp_path / "d.json")]) == 2
    assert "--tol nan" in capsys.readouterr().err
