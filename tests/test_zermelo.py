"""Zermelo solvers against the example of Zwierzewicz, closed forms and each other."""
import numpy as np
import pytest
from scipy.optimize import brentq

from shipid.routing import (HOUR, KNOT, NM, FunctionField, GridField, UniformField, VortexField, ZermeloProblem,
                            extremal, linear_shear, math_from_course, paper_problem, solve_pmp,
                            solve_transcription)
from shipid.routing.zermelo import PAPER_TF_CLOSED_FORM_H

T_PRINTED_A = 10.9157305276  # h, extremal through the printed A (this solver; transcription agrees to 2e-9)


def test_paper_example_pmp_from_printed_start():
    r = solve_pmp(paper_problem())
    assert r.success and r.reached
    assert r.time == pytest.approx(T_PRINTED_A, rel=1e-9)
    assert r.time == pytest.approx(10.9157, abs=5e-5)
    # the paper's rounded angles: u(0) ~ 345 deg, u(tf) ~ 210 deg (nautical course)
    assert np.degrees(r.course[0]) == pytest.approx(345.0, abs=0.05)
    assert np.degrees(r.course[-1]) == pytest.approx(210.0, abs=0.05)
    np.testing.assert_allclose(r.xy[0], [3.66, -1.86], atol=1e-8)
    np.testing.assert_allclose(r.xy[-1], [0.0, 0.0], atol=1e-12)
    # the paper's 10.93 h is NOT the time from the printed A
    assert abs(r.time - 10.93) > 0.01


def test_paper_closed_form_extremal_u0_345_alpha_30():
    """The extremal with u(tf) = 210 deg and u(0) = 345 deg takes exactly 4 (1 + sqrt 3) h."""
    P = paper_problem()
    thf = float(math_from_course(np.radians(210.0)))
    e = extremal(P, thf, PAPER_TF_CLOSED_FORM_H)
    assert np.degrees(e.course[0]) == pytest.approx(345.0, abs=1e-7)
    # paper's heading law u*(t) = pi + atan(tan a / (k (tf - t) tan a + 1)), a = 30 deg, k = -0.5
    a, k, tf = np.radians(30.0), -0.5, PAPER_TF_CLOSED_FORM_H
    den = k * (tf - e.t) * np.tan(a) + 1
    u_paper = np.pi + np.arctan(np.tan(a) / den) + np.where(den > 0, 0.0, np.pi)
    np.testing.assert_allclose(np.cos(e.course), np.cos(u_paper), atol=1e-8)
    np.testing.assert_allclose(np.sin(e.course), np.sin(u_paper), atol=1e-8)
    # its start is ~0.004 nm from the printed A; PMP from there recovers 4 (1 + sqrt 3)
    start = e.xy[0]
    assert 0.003 < np.hypot(*(start - [3.66, -1.86])) < 0.005
    r = solve_pmp(ZermeloProblem(0.5, linear_shear(-0.5), start, (0, 0)))
    assert r.time == pytest.approx(4 * (1 + np.sqrt(3)), rel=1e-9)
    assert np.degrees(r.course[0]) == pytest.approx(345.0, abs=1e-6)


def test_straight_line_without_current_8_21_h():
    P = ZermeloProblem(0.5, UniformField(), (3.66, -1.86), (0.0, 0.0))
    expected = np.hypot(3.66, 1.86) / 0.5
    assert expected == pytest.approx(8.21, abs=0.005)
    for r in (solve_pmp(P), solve_transcription(P, n=10)):
        assert r.time == pytest.approx(expected, rel=1e-8)
        np.testing.assert_allclose(np.cos(r.heading - np.arctan2(1.86, -3.66)), 1.0, atol=1e-6)


def test_transcription_agrees_with_pmp_and_si_units():
    r = solve_pmp(paper_problem())
    q = solve_transcription(paper_problem(), n=20)
    assert q.success and q.reached
    assert q.time == pytest.approx(r.time, rel=1e-6)
    assert np.degrees(q.course[0]) == pytest.approx(np.degrees(r.course[0]), abs=0.05)
    si = solve_pmp(paper_problem("si"))
    assert si.time / HOUR == pytest.approx(r.time, rel=1e-9)
    assert si.xy[0] == pytest.approx(np.array([3.66, -1.86]) * NM)


def test_grid_version_of_the_paper_current_gives_the_same_time():
    x = np.linspace(-6, 6, 13)
    y = np.linspace(-4, 4, 9)
    X, Y = np.meshgrid(x, y)
    g = GridField(x, y, -0.5 * Y, 0 * Y)
    r = solve_pmp(ZermeloProblem(0.5, g, (3.66, -1.86), (0, 0)))
    assert r.time == pytest.approx(T_PRINTED_A, rel=1e-8)


def test_current_twice_the_boat_speed_uniform_analytic():
    """|w| = 2 V: the target (1000, 500) m is reachable; analytic minimum time 500 s."""
    P = ZermeloProblem(1.0, UniformField(2.0, 0.0), (0.0, 0.0), (1000.0, 500.0))
    for r in (solve_pmp(P), solve_transcription(P, n=10)):
        assert r.reached
        assert r.time == pytest.approx(500.0, rel=1e-7)
        assert np.degrees(np.mod(r.heading[0], 2 * np.pi)) == pytest.approx(90.0, abs=1e-3)


def test_unreachable_target_reports_instead_of_raising():
    P = ZermeloProblem(1.0, UniformField(2.0, 0.0), (0.0, 0.0), (-1000.0, 0.0))
    r = solve_pmp(P)
    assert not r.reached and not r.success
    q = solve_transcription(P, n=10, max_iter=50)
    assert not q.success


def test_vortex_faster_than_the_boat_pmp_and_transcription_agree():
    f = VortexField(gamma=2 * np.pi * 300.0 * 1.5 / (1 - np.exp(-1)), rc=300.0)  # 1.5 m/s at r = rc
    assert f.max_speed((-1000, 1000, -1000, 1000)) > 1.5
    P = ZermeloProblem(1.0, f, (-600.0, -250.0), (650.0, 200.0))
    r = solve_pmp(P)
    q = solve_transcription(P, n=30, guess=r)
    assert r.reached and q.reached
    assert q.time == pytest.approx(r.time, rel=1e-5)


@pytest.mark.slow
def test_vortex_transcription_from_straight_line_finds_the_pmp_route():
    f = VortexField(gamma=2 * np.pi * 300.0 * 1.5 / (1 - np.exp(-1)), rc=300.0)
    P = ZermeloProblem(1.0, f, (-600.0, -250.0), (650.0, 200.0))
    r = solve_pmp(P)
    q0 = solve_transcription(P, n=30)
    assert q0.reached
    assert q0.time == pytest.approx(r.time, rel=1e-5)


def test_time_dependent_uniform_current_transcription_analytic():
    """w(t) = (0.5 + 1e-4 t, 0): heading constant; |B - A - int w dt| = V T."""
    f = FunctionField(lambda t, xy: np.stack(np.broadcast_arrays(0.5 + 1e-4 * np.asarray(t), 0.0 * xy[..., 0]), -1))
    P = ZermeloProblem(1.0, f, (0.0, 0.0), (300.0, 800.0))
    T = brentq(lambda T: np.hypot(300 - 0.5 * T - 5e-5 * T**2, 800) - T, 1.0, 900.0)
    q = solve_transcription(P, n=20)
    assert q.reached
    assert q.time == pytest.approx(T, rel=1e-7)
    with pytest.raises(ValueError, match="time dependent"):
        solve_pmp(P)


def test_result_table_and_validation():
    r = solve_pmp(paper_problem(), n_out=11)
    df = r.to_pandas()
    assert list(df.columns) == ["t", "x", "y", "heading_deg", "course_deg"]
    np.testing.assert_allclose(np.mod(90 - df.heading_deg, 360), df.course_deg, atol=1e-9)
    assert df.t.iloc[-1] == pytest.approx(r.time)
    with pytest.raises(ValueError, match="speed must be a positive"):
        ZermeloProblem(0.0, UniformField(), (0, 0), (1, 1))
    assert KNOT == pytest.approx(0.514444, rel=1e-5)
