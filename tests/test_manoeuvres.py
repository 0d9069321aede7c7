"""Standard manoeuvres and their metrics (shipid.manoeuvres): analytic truths, IMO limits,
the six MARIN KVLCC2 logs against the values in their README, batch consistency."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from shipid.manoeuvres import (
    detect_manoeuvre, imo_limits, metrics, steady_rps, turning_circle, turning_metrics, turning_sweep, zigzag,
    zigzag_metrics,
)
from shipid.models import get_model
from shipid.models.base import Model

MARIN = Path(__file__).parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"


class FirstOrderShip(Model):
    """Constant speed U, yaw rate lagging K delta with time constant tau (psi' = r, r' = (K delta - r)/tau).

    Its track has a closed form up to quadrature: psi(t) = r_s (t - tau (1 - exp(-t/tau))) after a rudder step,
    steady circle radius U / r_s.  Used as an independent truth for the whole turning-circle pipeline.
    """

    name = "first-order-test-ship"
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ("delta", "n")
    param_names = ("K", "tau")
    lpp = 100.0
    rudder_rate = 1e6  # a rudder step
    design_speed = 5.0

    def _rhs(self, t, x, u, p):
        psi, uu, v, r = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
        K, tau = p[..., 0], p[..., 1]
        out = [uu * np.cos(psi) - v * np.sin(psi), uu * np.sin(psi) + v * np.cos(psi), r,
               0.0 * uu, 0.0 * v, (K * u[..., 0] - r) / tau]
        shape = np.broadcast_shapes(*[np.shape(o) for o in out])
        return np.stack([np.broadcast_to(o, shape) for o in out], axis=-1)


def _first_order_truth(U, r_s, tau):
    psi = lambda t: r_s * (t - tau * (1 - math.exp(-t / tau)))  # noqa: E731
    t90 = brentq(lambda t: psi(t) - math.pi / 2, 0, 1e4)
    t180 = brentq(lambda t: psi(t) - math.pi, 0, 1e4)
    adv = quad(lambda t: U * math.cos(psi(t)), 0, t90, epsabs=1e-11, epsrel=1e-12)[0]
    tra = quad(lambda t: U * math.sin(psi(t)), 0, t90, epsabs=1e-11, epsrel=1e-12)[0]
    td = quad(lambda t: U * math.sin(psi(t)), 0, t180, epsabs=1e-11, epsrel=1e-12)[0]
    return adv, tra, td, 2 * U / r_s


def test_turning_circle_of_a_first_order_ship_matches_quadrature():
    model = FirstOrderShip([0.05, 8.0])
    res = turning_circle(model, 20.0, speed=5.0, n=10.0, side="both", dt=0.2)
    r_s = 0.05 * math.radians(20)
    adv, tra, td, diam = _first_order_truth(5.0, r_s, 8.0)
    for m in res.metrics:
        assert m.advance == pytest.approx(adv, rel=2e-4)
        assert m.transfer == pytest.approx(tra, rel=2e-4)
        assert m.tactical_diameter == pytest.approx(td, rel=2e-4)
        assert m.steady_diameter == pytest.approx(diam, rel=1e-6)
        assert m.speed_loss == pytest.approx(0.0, abs=1e-12)
        assert m.max_heading_change_deg >= 540.0
        assert m.reference.startswith("model origin")
    assert [m.side for m in res.metrics] == ["starboard", "port"]


def test_metrics_of_an_exact_circle_from_arrays():
    """Straight approach then an exact circle of radius R: advance = transfer = R, TD = steady diameter = 2R."""
    R, U, dt = 250.0, 6.0, 0.0125
    te = 2400 * dt  # execute on a sample (the track has a kink there)
    t = dt * np.arange(2400 + int(3 * 2 * math.pi * R / U / dt))
    s = np.clip(t - te, 0, None) * U / R
    x = np.where(t < te, U * (t - te), R * np.sin(s))
    y = np.where(t < te, 0.0, R * (1 - np.cos(s)))
    psi = s.copy()
    delta = np.where(t < te, 0.0, math.radians(35))
    m = turning_metrics(t, x, y, psi, np.full(t.size, U), delta, lpp=100.0, execute_time=te)
    assert m.advance == pytest.approx(R, rel=1e-8) and m.transfer == pytest.approx(R, rel=1e-8)
    assert m.tactical_diameter == pytest.approx(2 * R, rel=1e-8)
    assert m.steady_diameter == pytest.approx(2 * R, rel=1e-10)
    assert m.time_90 == pytest.approx(math.pi / 2 * R / U, rel=1e-8)
    assert m.track_reach_10deg == pytest.approx(math.radians(10) * R, rel=1e-6)
    d = m.to_dict()
    assert d["manoeuvre"] == "turning" and d["advance_L"] == pytest.approx(2.5, rel=1e-8)
    assert d["imo"]["advance_pass"] is True and d["imo"]["tactical_diameter_pass"] is True
    # the same track mirrored is a port turn with the same metrics
    mp = turning_metrics(t, x, -y, -psi, np.full(t.size, U), -delta, lpp=100.0, execute_time=te)
    assert mp.side == "port" and mp.transfer == pytest.approx(R, rel=1e-8)


def _sine_zigzag(T=120.0, amp=20.0, switch=10.0, te=10.0, dt=1e-3):
    """Heading amp sin(2 pi (t - te)/T) after te; rudder reversed exactly when |psi| reaches the switch angle."""
    k_e = int(round(te / dt))
    t = dt * np.arange(k_e + int(1.2 * T / dt))
    te = t[k_e]  # execute on a sample
    ph = 2 * math.pi * np.clip(t - te, 0, None) / T
    psi = np.radians(amp) * np.sin(ph)
    delta = np.zeros(t.size)
    sign = 1.0
    for k in range(t.size):
        if k < k_e:
            continue
        if sign * psi[k] >= math.radians(switch):
            sign = -sign
        delta[k] = sign * math.radians(switch)
    return t, psi, delta


def test_zigzag_metrics_of_a_sine_heading_are_exact():
    T, te = 120.0, 10.0
    t, psi, delta = _sine_zigzag(T=T, te=te)
    m = zigzag_metrics(t, psi, delta, lpp=100.0)
    assert m.first_side == "starboard" and m.rudder_deg == 10 and m.switch_deg == 10
    assert m.execute_time == pytest.approx(te, abs=1e-2)
    assert m.overshoot1_deg == pytest.approx(10.0, abs=1e-6)
    assert m.overshoot2_deg == pytest.approx(10.0, abs=1e-6)
    assert m.time_second_execute == pytest.approx(T / 12, abs=2e-3)   # asin(1/2) / (2 pi) T
    assert m.overshoot1_time == pytest.approx(T / 4, abs=2e-3)
    assert m.overshoot2_time == pytest.approx(3 * T / 4, abs=2e-3)
    assert detect_manoeuvre(delta) == "zigzag"
    mp = zigzag_metrics(t, -psi, -delta, lpp=100.0)
    assert mp.first_side == "port" and mp.overshoot1_deg == pytest.approx(10.0, abs=1e-6)


@pytest.mark.parametrize("lv, o1, o2", [(5.0, 10.0, 25.0), (20.0, 15.0, 32.5), (30.0, 20.0, 40.0), (45.0, 20.0, 40.0)])
def test_imo_overshoot_limits(lv, o1, o2):
    lim = imo_limits(100.0, 100.0 / lv)
    assert lim["zz10_overshoot1_deg"] == pytest.approx(o1) and lim["zz10_overshoot2_deg"] == pytest.approx(o2)
    assert lim["zz20_overshoot1_deg"] == 25.0 and lim["advance_L"] == 4.5 and lim["tactical_diameter_L"] == 5.0


def test_imo_pass_fail_flags():
    t, psi, delta = _sine_zigzag(amp=25.0)  # overshoots 15 deg
    slow = zigzag_metrics(t, psi, delta, lpp=100.0, u=np.full(t.size, 10.0))   # L/V = 10 s: limit 10 deg
    fast = zigzag_metrics(t, psi, delta, lpp=100.0, u=np.full(t.size, 4.0))    # L/V = 25 s: limit 17.5 deg
    assert slow.imo()["overshoot1_pass"] is False and slow.imo()["overshoot1_limit_deg"] == 10.0
    assert fast.imo()["overshoot1_pass"] is True and fast.imo()["overshoot1_limit_deg"] == 17.5
    assert fast.imo()["overshoot2_limit_deg"] == pytest.approx(17.5 + 0.75 * 25)


def test_steady_rps_of_the_response_model_is_the_quadratic_root():
    m = get_model("kcs-response")
    c = m.params_series()
    U = np.array([1.5, 1.7, 2.2])
    n = steady_rps(m, U)
    # a1 U + a8 U n + a9 n^2 = 0
    disc = (c.a8 * U) ** 2 - 4 * c.a9 * c.a1 * U
    truth = (-c.a8 * U + np.sqrt(disc)) / (2 * c.a9)
    np.testing.assert_allclose(n, truth, rtol=1e-9)


def test_steady_rps_with_one_parameter_set_per_speed():
    """Per-member parameters (B, np) give each speed its own model's rps, as B separate calls do."""
    m = get_model("mmg", "kvlcc2", lpp=320.0)
    P = m.params * (1 + 0.05 * np.random.default_rng(0).normal(size=(3, m.np)))
    batch = steady_rps(m, np.full(3, 7.0), params=P)
    one = np.array([steady_rps(m, 7.0, params=p)[0] for p in P])
    np.testing.assert_allclose(batch, one, rtol=1e-9)
    assert np.ptp(batch) > 0.05  # the members really differ


def test_batch_equals_separate_runs():
    m = get_model("mmg")
    both = turning_circle(m, 35.0, speed=[1.0, 1.179], side="starboard", heading_change_deg=200)
    for i, U in enumerate([1.0, 1.179]):
        one = turning_circle(m, 35.0, speed=U, side="starboard", heading_change_deg=200, dt=0.05 * m.lpp / 1.179)
        assert both.metrics[i].tactical_diameter == pytest.approx(one.metrics[0].tactical_diameter, rel=1e-12)


def test_zigzag_controller_reverses_at_the_switch_heading():
    m = get_model("mmg")
    z = zigzag(m, 20.0, first="port")
    met = z.metrics[0]
    assert z.success and met.first_side == "port" and met.rudder_deg == 20
    sim = z.member(0)
    t = sim.index.to_numpy()
    t2 = met.execute_time + met.time_second_execute
    k = np.searchsorted(t, t2)
    # rudder at -20 deg until the heading reached -20 deg, then moving towards +20 deg
    assert sim["delta"].iloc[k - 2] == pytest.approx(-math.radians(20))
    assert sim["delta"].iloc[k + 2] > -math.radians(20) + 1e-6
    assert math.degrees(sim["psi"].iloc[k] - sim["psi"].iloc[0]) == pytest.approx(-20.0, abs=0.3)
    assert 5 < met.overshoot1_deg < 25 and 5 < met.overshoot2_deg < 30


def test_sweep_is_one_batch_with_monotone_diameters():
    m = get_model("mmg", "kcs")
    df = turning_sweep(m, rudder_deg=[10, 15, 25], speeds=[1.7, 2.0, 2.2])
    assert len(df) == 9 and df["success"].all()
    for _, g in df.groupby("speed"):
        assert np.all(np.diff(g.sort_values("rudder_deg")["tactical_diameter_L"].to_numpy()) < 0)
    assert np.all(np.diff(df[df.rudder_deg == 15].sort_values("speed")["n"].to_numpy()) > 0)


def test_metrics_errors_are_clear():
    df = pd.DataFrame({"time": [0, 1, 2], "psi": [0, 0, 0], "delta": [0, 0.1, 0.1]})
    with pytest.raises(ValueError, match="ship length unknown"):
        metrics(df)
    with pytest.raises(ValueError, match=r"need column\(s\) \['x', 'y', 'u'\]"):
        metrics(df, lpp=100.0, kind="turning")
    with pytest.raises(ValueError, match="no manoeuvre"):
        metrics(df.assign(delta=0.0), lpp=100.0)
    deg = pd.DataFrame({"time": np.arange(5.0), "psi": [0, 90, 180, 270, 360], "delta": [0, .5, .5, .5, .5]})
    with pytest.raises(ValueError, match="looks like degrees"):
        metrics(deg, lpp=100.0)
    class NoSway(FirstOrderShip):
        state_names = ("x", "y", "psi", "u", "r")

    with pytest.raises(ValueError, match=r"lacks \['v'\]"):
        turning_circle(NoSway([0.05, 8.0]), 35.0)


# ------------------------------------------------------------------ MARIN KVLCC2 measured logs
README_VALUES = {
    "tc_35": {"advance_L": 3.02, "transfer_L": 1.20, "tactical_diameter_L": 3.07},
    "tc_-35": {"advance_L": 3.09, "transfer_L": 1.35, "tactical_diameter_L": 3.33},
    "zz_10": {"overshoot1_deg": 9.4}, "zz_-10": {"overshoot1_deg": 8.1},
    "zz_20": {"overshoot1_deg": 15.6}, "zz_-20": {"overshoot1_deg": 12.7},
}


@pytest.fixture(scope="module")
def marin_logs():
    if not MARIN.is_dir():
        pytest.skip(f"MARIN KVLCC2 data not found at {MARIN.resolve()} (../shared/data/kvlcc2_marin beside the repo)")
    from shipid.logs import read_log

    return {k: read_log(MARIN / f"MARIN_FREE_KVLCC2_{k}_m.dat", fmt="marin") for k in README_VALUES}


@pytest.mark.parametrize("name", list(README_VALUES))
def test_marin_metrics_agree_with_readme(marin_logs, name):
    """Lengths within 0.01 L (the README's rounding is 0.005 L), overshoots within 0.15 deg
    (README: execute at |delta - delta0| > 0.5 deg, logged reference point, as here)."""
    m = metrics(marin_logs[name], lpp=320.0)
    d = m.to_dict()
    assert d["manoeuvre"] == ("turning" if name.startswith("tc") else "zigzag")
    assert d["reference"] == "logged point"
    for key, val in README_VALUES[name].items():
        tol = 0.15 if key.endswith("deg") else 0.01
        assert d[key] == pytest.approx(val, abs=tol), f"{name} {key}: {d[key]:.3f} vs README {val}"
    if name.startswith("tc"):
        # +35 deg in the MARIN files turns the ship to port (their rudder sign is opposite to MMG's)
        assert d["side"] == ("port" if name == "tc_35" else "starboard")
        assert 0.0 < d["steady_diameter_L"] < d["tactical_diameter_L"] and 0.5 < d["speed_loss"] < 0.75


_TURN_FIELDS = ("advance", "transfer", "tactical_diameter", "steady_diameter", "steady_speed", "speed_loss", "time_90",
                "time_180", "max_heading_change_deg", "track_reach_10deg", "approach_speed", "execute_time")


def _assert_same_turning(a, b, skip=()):
    for k in set(_TURN_FIELDS) - set(skip):
        va, vb = getattr(a, k), getattr(b, k)
        assert (math.isnan(va) and math.isnan(vb)) or va == pytest.approx(vb, rel=1e-12, abs=1e-12), k
    assert (a.side, a.success, a.message) == (b.side, b.success, b.message)


def test_batched_turning_metrics_equal_the_single_run_function():
    """The batch path of the turning metrics (all members of a simulation at once) gives what the public
    single-series function gives for each member -- also for a member whose simulation ended early, for a
    member that never reached 180 deg, and for headings wrapped to (-pi, pi]."""
    from shipid.manoeuvres import _turning_rows

    m = get_model("mmg")
    res = turning_circle(m, [10.0, 35.0], speed=1.179, side="both", heading_change_deg=400, method="dopri5", rtol=1e-6)
    sim, L = res.simulation, m.lpp
    X, delta = sim.x, sim.u[..., 0]
    U = np.hypot(X[..., 3], X[..., 4])
    te = res.metrics[0].execute_time
    ie = int(np.searchsorted(sim.t, te))
    k150 = int(np.argmax(np.abs(X[1, :, 2] - X[1, ie, 2]) > math.radians(150)))  # member 1 ends before 180 deg
    n_valid = np.array([sim.t.size, k150, sim.t.size, sim.t.size])
    psi = X[..., 2].copy()
    psi[3] = np.angle(np.exp(1j * psi[3]))  # wrapped heading
    rows = _turning_rows(sim.t, X[..., 0], X[..., 1], psi, U, delta, L, np.full(4, ie), np.full(4, te), "midship",
                         n_valid)
    for b in range(4):
        n = n_valid[b]
        one = turning_metrics(sim.t[:n], X[b, :n, 0], X[b, :n, 1], psi[b, :n], X[b, :n, 3], delta[b, :n], lpp=L,
                              v=X[b, :n, 4], execute_time=te, reference="midship")
        _assert_same_turning(rows[b], one)
    assert rows[1].success is False and "never reached 180 deg" in rows[1].message
    plain = _turning_rows(sim.t, X[..., 0], X[..., 1], X[..., 2], U, delta, L, np.full(4, ie), np.full(4, te),
                          "midship", np.full(4, sim.t.size))
    _assert_same_turning(rows[3], plain[3])  # the wrapped heading is unwrapped
    for b in range(4):  # the manoeuvre's own metrics are the rows of its simulation (nominal approach speed)
        _assert_same_turning(res.metrics[b], plain[b], skip=("approach_speed",))


def test_missing_samples_are_skipped():
    """NaN (missing) position samples of a log do not break the turning metrics."""
    R, U, dt = 250.0, 6.0, 0.05
    te = 600 * dt
    t = dt * np.arange(600 + int(2.2 * math.pi * R / U / dt))
    s = np.clip(t - te, 0, None) * U / R
    df = pd.DataFrame({"time": t, "x": np.where(t < te, U * (t - te), R * np.sin(s)),
                       "y": np.where(t < te, 0.0, R * (1 - np.cos(s))), "psi": s, "u": U,
                       "delta": np.where(t < te, 0.0, math.radians(35))})
    full = metrics(df, lpp=100.0).to_dict()
    holes = df.copy()
    holes.loc[holes.index[1000:1003], "x"] = np.nan
    m = metrics(holes, lpp=100.0).to_dict()
    assert m["manoeuvre"] == "turning"
    assert m["advance_L"] == pytest.approx(full["advance_L"], rel=1e-6)
    assert m["tactical_diameter_L"] == pytest.approx(2.5 * 2, rel=1e-6)


# ------------------------------------------------------------------ input laws and integrators
from shipid.manoeuvres import RampSchedule, SampledHold, TurningRudder, ZigzagRudder  # noqa: E402
from shipid.simulate import simulate  # noqa: E402


def test_zigzag_overshoots_converge_with_the_step_when_the_reversal_is_located():
    """The reversal is located within the RK4 step: the overshoot errors fall with the step and are
    hundredths of a degree at the default step; reversing at the next step start instead (SampledHold,
    the old behaviour) lags the crossing by up to a step and is far less accurate at the same step."""
    m = get_model("mmg")
    L, U = m.lpp, 1.179
    ref = zigzag(m, 10, speed=U, first="starboard", method="dopri5", rtol=1e-9, dt=0.05 * L / U).metrics[0]
    err = {}
    for f in (0.1, 0.05):
        z = zigzag(m, 10, speed=U, first="starboard", dt=f * L / U).metrics[0]
        err[f] = max(abs(z.overshoot1_deg - ref.overshoot1_deg), abs(z.overshoot2_deg - ref.overshoot2_deg))
    print("overshoot errors [deg] by step [L/U]:", err)
    assert err[0.05] < 0.01 and err[0.05] < 0.75 * err[0.1]

    # the same law sampled at step starts (decision and hold per step) at the same step
    h = 0.05 * L / U
    n = steady_rps(m, U)
    te = h * round(2 * L / U / h)
    t = np.arange(0.0, te + 60 * L / U, h)
    law = ZigzagRudder(math.radians(10), math.radians(10), np.array([1.0]), np.zeros(1), n, m.rudder_rate, te)
    sim = simulate(m, np.array([[0, 0, 0, U, 0, 0]]), t, controller=SampledHold(law, h))
    zs = zigzag_metrics(sim.t, sim.x[0, :, 2], sim.u[0, :, 0], lpp=L, execute_time=te, switch_deg=10, rudder_deg=10)
    err_sampled = abs(zs.overshoot1_deg - ref.overshoot1_deg)
    print("reversal at step starts:", err_sampled)
    assert err_sampled > 5 * err[0.05]


def test_dopri5_manoeuvres_agree_with_fine_rk4():
    m = get_model("mmg")
    L, U = m.lpp, 1.179
    fine = turning_circle(m, [20, 35], speed=U, dt=0.025 * L / U, steady_step_factor=1)
    fast = turning_circle(m, [20, 35], speed=U, method="dopri5", rtol=1e-6)
    assert fast.simulation.meta["method"] == "dopri5" and fast.success
    for a, b in zip(fine.metrics, fast.metrics):
        assert b.tactical_diameter_L == pytest.approx(a.tactical_diameter_L, abs=2e-4)
        assert b.advance_L == pytest.approx(a.advance_L, abs=2e-4)
    zf = zigzag(m, 20, speed=U, dt=0.025 * L / U)
    zd = zigzag(m, 20, speed=U, method="dopri5", rtol=1e-6, dt=0.025 * L / U)
    for a, b in zip(zf.metrics, zd.metrics):
        assert b.overshoot1_deg == pytest.approx(a.overshoot1_deg, abs=0.01)
        assert b.overshoot2_deg == pytest.approx(a.overshoot2_deg, abs=0.01)
    with pytest.raises(ValueError, match="method"):
        turning_circle(m, 35, speed=U, method="euler")


def test_ramp_schedule_follows_set_points_at_the_rate():
    s = RampSchedule(10.0, ((0.0, 10.0), (40.0, 8.0), (41.0, 12.0)), rate=1.0)
    assert s(np.array([0.0, 39.0, 40.0, 40.5, 41.0, 42.0, 44.0, 45.0, 100.0])) == pytest.approx(
        [10, 10, 10, 9.5, 9.0, 10.0, 12.0, 12.0, 12.0])  # 8 interrupted at 9 by the 12 set point
    assert s.stops == (40.0, 41.0, 44.0)
    with pytest.raises(ValueError, match="rate"):
        RampSchedule(1.0, (), rate=0.0)


def test_laws_record_the_inputs_that_acted():
    m = get_model("mmg")
    law = TurningRudder(np.radians([10.0, -35.0]), np.array([10.0, 11.0]), math.radians(2.0), 5.0)
    assert law.stops == (5.0, 10.0, 22.5)
    t = np.linspace(0, 30, 61)
    hist = law.input_history(t, None)
    for k in (0, 11, 20, 60):
        assert hist[:, k] == pytest.approx(law.inputs(t[k], None))
    assert hist[1, -1, 0] == pytest.approx(-math.radians(35)) and hist[0, 18, 0] == pytest.approx(math.radians(8))
    # zigzag: after an event the history is piecewise and inputs() agrees with it
    z = zigzag(m, 10, speed=1.179)
    u = z.simulation.u[0, :, 0]
    assert np.max(np.abs(np.diff(u))) <= m.rudder_rate * np.diff(z.simulation.t).max() + 1e-12


def test_zigzag_heading_reference_is_the_heading_at_the_execute():
    """An asymmetric ship (MMG with a 1 deg rudder neutral angle) drifts off course during the
    approach at zero rudder; the first reversal must still come 20 deg from the heading at the
    execute (ITTC), for both the fixed-step and the adaptive integrator."""
    m = get_model("mmg").with_params({"delta0": math.radians(1.0)})
    for kw in ({}, {"method": "dopri5", "rtol": 1e-8}):
        res = zigzag(m, 20.0, 20.0, first="starboard", execute_time=40.0, **kw)
        sim = res.simulation
        t, psi, delta = sim.t, sim.x[0, :, 2], sim.u[0, :, 0]
        i_e = int(np.searchsorted(t, 40.0))
        drift = math.degrees(psi[i_e] - psi[0])
        assert abs(drift) > 0.2, drift  # the approach really drifts (so the reference matters)
        i_rev = int(np.argmax(np.diff(delta) < -1e-9))  # first sample where the rudder swings back
        psi_rev = np.interp(t[i_rev], t, psi)
        assert math.degrees(psi_rev - psi[i_e]) == pytest.approx(20.0, abs=0.3), kw


# ----------------------------------------------------------------------------- check angle
@pytest.mark.parametrize("rudder, check", [(10.0, 5.0), (20.0, 10.0)])
def test_zigzag_check_angle_is_read_from_the_log(rudder, check):
    """A 10/5 and a 20/10 zigzag (simulated with the known check angle) read as a log: the check angle is
    the heading deviation at the rudder reversals, so the overshoots are those of the simulation (to the
    0.01 deg of the step); read as rudder/rudder (the old default) they are wrong by degrees."""
    run = zigzag(get_model("kcs-response"), rudder, check, first="starboard")
    truth = run.metrics[0]
    log = run.member(0).reset_index()
    m = metrics(log, lpp=4.36)
    assert (m.rudder_deg, m.switch_deg, m.check_deg, m.check_source) == (rudder, check, check, "log")
    assert m.overshoot1_deg == pytest.approx(truth.overshoot1_deg, abs=0.01)
    assert m.overshoot2_deg == pytest.approx(truth.overshoot2_deg, abs=0.01)
    assert truth.overshoot1_deg > 1.0
    given = metrics(log, lpp=4.36, check_deg=check)
    assert given.check_source == "given" and given.overshoot1_deg == m.overshoot1_deg
    wrong = metrics(log, lpp=4.36, check_deg=rudder)
    assert not (abs(wrong.overshoot1_deg - truth.overshoot1_deg) < 3.0)  # NaN (never reached) or off by > 3 deg
    with pytest.raises(ValueError, match="check_deg=5.0 and switch_deg=6.0 differ"):
        zigzag_metrics(log["time"], log["psi"], log["delta"], lpp=4.36, check_deg=5.0, switch_deg=6.0)


def test_validation_runs_the_closed_loop_zigzag_with_the_logs_check_angle():
    """validate() of a 10/5 zigzag log with the model that made it: the closed-loop zigzag is a 10/5 one
    (settings from the log), and its overshoots equal the log's; an explicit (rudder, check) is used as given."""
    from shipid.logs import TrialLog
    from shipid.validation import validate_one

    model = get_model("kcs-response")
    df = zigzag(model, 10.0, 5.0, first="port").member(0).reset_index()
    log = TrialLog.from_arrays(df["time"].to_numpy(), name="zz_10_5",
                               **{c: df[c].to_numpy() for c in ("x", "y", "psi", "u", "v", "r", "delta", "n")})
    v = validate_one(model, log, lpp=4.36)
    assert v.standard_settings["switch_deg"] == 5.0 and v.standard_settings["rudder_deg"] == 10.0
    assert v.standard.overshoot1_deg == pytest.approx(v.measured.overshoot1_deg, abs=0.02)
    assert v.standard.overshoot2_deg == pytest.approx(v.measured.overshoot2_deg, abs=0.02)
    v2 = validate_one(model, log, lpp=4.36, zigzag_angles=(10.0, 6.0), closed_loop=False)
    assert v2.measured.switch_deg == 6.0 and v2.measured.check_source == "given"


def test_marin_zigzags_read_as_x_over_x(marin_logs):
    """The measured KVLCC2 zigzags reverse at 19.2 .. 21.5 deg of heading deviation (steering reaction):
    within 1.5 deg of the rudder angle they read as 10/10 and 20/20, as their README states."""
    for name in ("zz_10", "zz_-10", "zz_20", "zz_-20"):
        m = metrics(marin_logs[name], lpp=320.0)
        assert m.check_source == "log" and m.switch_deg == m.rudder_deg == abs(float(name.split("_")[1])), name


def test_cli_metrics_and_simulate_take_rudder_over_check(tmp_path, capsys):
    from shipid.cli import main
    from shipid.logs import TrialLog

    df = zigzag(get_model("kcs-response"), 20.0, 10.0, first="starboard").member(0).reset_index()
    log = TrialLog.from_arrays(df["time"].to_numpy(), name="zz_20_10",
                               **{c: df[c].to_numpy() for c in ("x", "y", "psi", "u", "v", "r", "delta", "n")})
    path = log.to_csv(tmp_path / "zz.csv")
    assert main(["metrics", str(path), "--lpp", "4.36"]) == 0
    auto = __import__("json").loads(capsys.readouterr().out)[0]
    assert auto["switch_deg"] == 10.0 and auto["check_source"] == "log"
    assert main(["metrics", str(path), "--lpp", "4.36", "--zigzag", "20/20"]) == 0
    forced = __import__("json").loads(capsys.readouterr().out)[0]
    assert forced["switch_deg"] == 20.0 and forced["check_source"] == "given"
    assert main(["metrics", str(path), "--lpp", "4.36", "--zigzag", "20/x"]) == 2
    assert "--zigzag '20/x': give rudder/heading angles in degrees (rudder/check)" in capsys.readouterr().err
