"""Launch a glider from the surface and follow it until it returns to the surface.

The glider starts on the free surface (``x = z = 0``) moving along its hull
axis at the launch speed, nose down at the launch angle **measured from the
vertical** (Divsalar et al., figure 10: 15 deg is a steep dive, 60 deg a shallow
one), so the initial pitch is ``theta0 = -(90 deg - angle)``.  The fin
incidence is held constant; the CG offset ``x_g`` (positive towards the nose,
Divsalar et al. figure 12) is set per launch as a model parameter, so any number of
launches run as one batch through :func:`shipid.simulate.simulate`.

Surface return is an event detected on the RK4 grid: the first step where the
depth ``z`` goes from positive to ``<= 0`` is refined by cubic Hermite
interpolation of every state between the two grid points (derivatives from
``model.rhs``), which is fourth-order accurate like the RK4 step itself.
Integration runs in chunks and stops as soon as every launch has surfaced.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from .._io import check_memory
from ..models import get_model
from ..models.base import Model
from ..results import ResultMixin
from ..simulate import simulate

__all__ = ["launch", "launch_state", "LaunchResult", "SUMMARY_COLUMNS"]

#: Columns of :attr:`LaunchResult.launches` (and :meth:`LaunchResult.summary`).
SUMMARY_COLUMNS = (
    "speed_m_s", "angle_deg", "fin_deg", "cg_m",
    "max_depth_m", "x_at_max_depth_m", "t_at_max_depth_s",
    "horizontal_m", "duration_s", "exit_angle_deg", "exit_pitch_deg", "exit_speed_m_s",
    "surfaced", "status",
)

_SCALAR_FIELDS = (
    "max_depth_m", "x_at_max_depth_m", "t_at_max_depth_s", "horizontal_m", "duration_s",
    "exit_angle_deg", "exit_pitch_deg", "exit_speed_m_s",
)


def launch_state(speed, angle_deg) -> np.ndarray:
    """Initial state ``[x, z, theta, u, w, q]`` of a surface launch.

    Parameters
    ----------
    speed : float or array
        Launch speed along the hull axis [m/s].
    angle_deg : float or array
        Launch angle from the vertical [deg].

    Returns
    -------
    ndarray, shape ``broadcast(speed, angle).shape + (6,)``
    """
    speed, ang = np.broadcast_arrays(np.asarray(speed, float), np.asarray(angle_deg, float))
    x0 = np.zeros(speed.shape + (6,))
    x0[..., 2] = -(np.pi / 2 - np.deg2rad(ang))
    x0[..., 3] = speed
    return x0


@dataclass
class LaunchResult(ResultMixin):
    """Result of :func:`launch` (one launch or a batch).

    Attributes
    ----------
    launches : pandas.DataFrame
        One row per launch (also :meth:`summary`) with :data:`SUMMARY_COLUMNS`: the launch settings,
        maximum depth [m], horizontal travel at surfacing [m], duration [s],
        exit flight-path angle above the horizontal [deg], exit pitch [deg],
        exit speed [m/s], whether it surfaced and a status word (``"surfaced"``,
        ``"t_max"`` if still submerged at ``t_max``, ``"non-finite"``).
    t : ndarray, shape (n_t,)
        Integration grid [s] (common to the batch).
    x : ndarray, shape (B, n_t, 6) or None
        States on the grid, NaN after each launch has surfaced (None when
        ``keep_trajectories=False``).
    exit_state : ndarray, shape (B, 6)
        Interpolated state at the surfacing instant (NaN if it did not surface).
    model : Model
    params : ndarray, shape (B, np)
        Parameters of each launch (``x_g`` set per launch).
    fin : ndarray, shape (B,)
        Fin incidence of each launch [rad].
    dt : float
        Step used [s].
    success : bool
        True when every launch surfaced with a finite state.
    status : int
        0 all surfaced, 1 some still submerged at ``t_max``, 2 some non-finite.
    message : str
    """

    launches: pd.DataFrame
    t: np.ndarray
    x: np.ndarray | None
    exit_state: np.ndarray
    model: Model
    params: np.ndarray
    fin: np.ndarray
    dt: float
    scalar: bool = False
    success: bool = True
    status: int = 0
    message: str = ""
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.launches)

    def summary(self) -> pd.DataFrame:
        """One row per launch: settings, maximum depth, horizontal travel, duration, exit angles and speed,
        whether it surfaced and its status (the table :attr:`launches`)."""
        return self.launches

    def _html_title(self) -> str:
        return "Glider launch" + (f"es ({len(self)})" if len(self) > 1 else "")

    def __getattr__(self, name):
        # max_depth_m, horizontal_m, ... as float (single launch) or array (batch)
        if name in _SCALAR_FIELDS:
            vals = self.launches[name].to_numpy()
            return float(vals[0]) if self.scalar else vals
        raise AttributeError(name)

    def as_dict(self, member: int = 0) -> dict:
        """Summary of one launch as a JSON-ready dict (SI units, degrees for angles)."""
        row = self.launches.iloc[member]
        out = {}
        for k in SUMMARY_COLUMNS:
            v = row[k]
            if isinstance(v, (np.bool_, bool)):
                out[k] = bool(v)
            elif isinstance(v, str):
                out[k] = v
            else:
                out[k] = None if not np.isfinite(v) else float(v)
        return out

    def to_pandas(self, member: int | None = None) -> pd.DataFrame:
        """Trajectory of one launch: states indexed by time, ending at the exit point.

        Columns ``x, z, theta, u, w, q`` plus ``depth`` (= z) [m]; for a batch without ``member``, every
        launch's rows with a ``launch`` column (its row in :attr:`launches`).
        """
        if self.x is None:
            raise ValueError("trajectories were not kept; call launch(..., keep_trajectories=True)")
        if member is None:
            if not self.scalar:
                return pd.concat([self.to_pandas(i).assign(launch=i) for i in range(len(self))])
            member = 0
        X = self.x[member]
        ok = np.isfinite(X[:, 0])
        t = self.t[ok]
        X = X[ok]
        if np.isfinite(self.exit_state[member, 0]):
            t = np.append(t, self.launches["duration_s"].iloc[member])
            X = np.vstack([X, self.exit_state[member]])
        df = pd.DataFrame(X, columns=list(self.model.state_names), index=pd.Index(t, name="time"))
        df["depth"] = df["z"]
        return df

    def plot(self, ax=None, members=None):
        """Trajectories in the vertical plane (horizontal travel vs depth, depth down).

        Parameters
        ----------
        ax : matplotlib Axes, optional
        members : sequence of int, optional
            Launches to draw (default: all, at most 40).
        """
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 3.5))
        if self.x is None:  # no trajectories kept: where each launch surfaced against how deep it went
            ax.plot(self.launches["horizontal_m"], self.launches["max_depth_m"], "o")
            if not ax.yaxis_inverted():
                ax.invert_yaxis()
            ax.set_xlabel("horizontal travel at surfacing [m]")
            ax.set_ylabel("maximum depth [m]")
            return ax
        if members is None:
            members = range(min(len(self), 40))
        for i in members:
            df = self.to_pandas(i)
            row = self.launches.iloc[i]
            ax.plot(df["x"], df["z"], label=f"{row.speed_m_s:g} m/s, {row.angle_deg:g} deg, fin {row.fin_deg:g}, cg {row.cg_m:g} m")
        ax.axhline(0.0, color="0.5", lw=0.8)
        if not ax.yaxis_inverted():
            ax.invert_yaxis()
        ax.set_xlabel("horizontal travel x [m]")
        ax.set_ylabel("depth z [m]")
        ax.set_aspect("equal", adjustable="datalim")
        return ax


def _validate(name, arr, lo=-np.inf, hi=np.inf, lo_open=False):
    arr = np.asarray(arr, dtype=float)
    bad = ~np.isfinite(arr) | (arr > hi) | ((arr <= lo) if lo_open else (arr < lo))
    if np.any(bad):
        v = float(arr[bad].ravel()[0])
        rel = ">" if lo_open else ">="
        raise ValueError(f"{name} = {v!r} is outside the valid range ({rel} {lo:g} and <= {hi:g}); pass a value inside it")
    return arr


def _hermite(y0, y1, f0, f1, h, s):
    s = s[..., None]
    s2, s3 = s * s, s * s * s
    h00 = 2 * s3 - 3 * s2 + 1
    h10 = s3 - 2 * s2 + s
    h01 = -2 * s3 + 3 * s2
    h11 = s3 - s2
    return h00 * y0 + h10 * h * f0 + h01 * y1 + h11 * h * f1


def _stable_dt(model, x0, fin, params, dt_max):
    """Step so that ``|lambda| dt <= 2`` for the stiffest launch (RK4 limit ~2.8)."""
    J = model.jac_x(0.0, x0, fin[:, None], params)
    lam = np.max(np.abs(np.linalg.eigvals(J)))
    return float(min(dt_max, 2.0 / lam)) if np.isfinite(lam) and lam > 0 else dt_max


def launch(
    speed,
    angle_deg,
    fin_deg=0.0,
    cg_m=0.0,
    *,
    model: Model | None = None,
    dt: float | None = None,
    t_max: float = 60.0,
    keep_trajectories: bool = True,
    progress: bool = False,
) -> LaunchResult:
    """Simulate surface launches until each glider returns to the surface.

    All arguments broadcast against each other; every element is one launch
    and all launches run as one vectorised batch.

    Parameters
    ----------
    speed : float or array
        Launch speed [m/s], > 0.
    angle_deg : float or array
        Launch angle from the vertical [deg], in [0, 89].
    fin_deg : float or array
        Fin incidence [deg] (positive = leading edge up), in [-45, 45].
    cg_m : float or array
        CG offset ``x_g`` from the centre of buoyancy [m], positive towards
        the nose; overrides the model's ``x_g``.
    model : Model, optional
        A ``glider`` model (default: ``get_model("glider")``, the paper set).
    dt : float, optional
        RK4 step [s].  Default: 0.01 s, reduced if the stiffest launch needs
        it (``|lambda_max| dt <= 2`` at launch; RK4 is stable to ~2.8).
    t_max : float
        Give up on launches still submerged after this time [s].
    keep_trajectories : bool
        Keep the states on the grid (memory ``B x n_t x 6`` floats).
    progress : bool
        Show a tqdm bar over the integration chunks.

    Returns
    -------
    LaunchResult
    """
    model = get_model("glider") if model is None else model
    if getattr(model, "name", None) != "glider":
        raise ValueError(f"launch needs a 'glider' model, got '{getattr(model, 'name', model)}'")
    speed = _validate("speed", speed, 0.0, 100.0, lo_open=True)
    angle_deg = _validate("angle_deg", angle_deg, 0.0, 89.0)
    fin_deg = _validate("fin_deg", fin_deg, -45.0, 45.0)
    half = float(model.params_series()["length"]) / 2
    cg_m = _validate("cg_m", cg_m, -half, half)
    if not (np.isfinite(t_max) and t_max > 0):
        raise ValueError(f"t_max = {t_max!r} must be a positive number of seconds")
    if dt is not None and not (np.isfinite(dt) and 0 < dt <= 1.0):
        raise ValueError(f"dt = {dt!r} must be in (0, 1] s")
    scalar = all(np.ndim(a) == 0 for a in (speed, angle_deg, fin_deg, cg_m))
    sp, an, fi, cg = (a.ravel() for a in np.broadcast_arrays(speed, angle_deg, fin_deg, cg_m))
    B = sp.size
    fin = np.deg2rad(fi)
    params = np.tile(model.params, (B, 1))
    params[:, model.param_index("x_g")] = cg
    x0 = launch_state(sp, an)
    if dt is None:
        dt = _stable_dt(model, x0, fin, params, 0.01)
    dt = float(dt)
    n_total = int(np.ceil(t_max / dt))
    # the trajectory of every launch is kept (6 doubles per step), plus one chunk of the simulation
    check_memory(8.0 * B * (n_total + 1) * 6 * 2, f"glider launch: dt {dt:g} s over t_max {t_max:g} s "
                 f"({n_total} steps x {B} launch(es))", "use a larger --dt (default: automatic, <= 0.01 s)")
    chunk = max(1, int(round(1.0 / dt)))      # 1 s of flight per chunk

    status = np.array(["t_max"] * B, dtype=object)
    exit_state = np.full((B, 6), np.nan)
    t_exit = np.full(B, np.nan)
    maxz = np.zeros(B)
    x_at_max = np.zeros(B)
    t_at_max = np.zeros(B)
    pieces: list[np.ndarray] = []
    x = x0.copy()
    active = np.arange(B)
    step0 = 0
    bar = None
    if progress:
        bar = tqdm(total=n_total, desc="glider launches", unit="step")
    while active.size and step0 < n_total:
        n = min(chunk, n_total - step0)
        t = (step0 + np.arange(n + 1)) * dt
        U = np.broadcast_to(fin[active, None, None], (active.size, n + 1, 1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = simulate(model, x[active], t, inputs=U, params=params[active])
        X = res.x                                    # (Ba, n+1, 6)
        if not res.success:
            # the simulator stops the whole batch at the first non-finite member:
            # mark the members that blew up and redo the chunk without them
            rowfinite = np.isfinite(X).all(axis=2)               # (Ba, n+1)
            r = int(np.where(rowfinite.any(axis=0))[0].max())
            rowbad = ~rowfinite[:, r]
            if not rowbad.any():                                  # all failed on the next row
                rowbad[:] = True
            status[active[rowbad]] = "non-finite"
            active = active[~rowbad]
            continue
        z = X[:, :, 1]
        cross = (z[:, :-1] > 0) & (z[:, 1:] <= 0)
        has = cross.any(axis=1)
        k = np.where(has, np.argmax(cross, axis=1) + 1, n + 1)   # first point at/above the surface
        # running maximum depth up to the crossing
        idx = np.arange(n + 1)
        zm = np.where(idx[None, :] < k[:, None], z, -np.inf)
        j = np.argmax(zm, axis=1)
        zj = zm[np.arange(active.size), j]
        better = zj > maxz[active]
        ab = active[better]
        maxz[ab] = zj[better]
        x_at_max[ab] = X[better, j[better], 0]
        t_at_max[ab] = t[j[better]]
        if has.any():
            rows = np.where(has)[0]
            kk = k[rows]
            y0, y1 = X[rows, kk - 1], X[rows, kk]
            pp = params[active[rows]]
            uu = fin[active[rows], None]
            f0 = model.rhs(0.0, y0, uu, pp)
            f1 = model.rhs(0.0, y1, uu, pp)
            lo, hi = np.zeros(rows.size), np.ones(rows.size)
            for _ in range(50):                       # bisection on the Hermite depth
                mid = 0.5 * (lo + hi)
                zmid = _hermite(y0, y1, f0, f1, dt, mid)[:, 1]
                below = zmid > 0
                lo = np.where(below, mid, lo)
                hi = np.where(below, hi, mid)
            s = 0.5 * (lo + hi)
            ex = _hermite(y0, y1, f0, f1, dt, s)
            ex[:, 1] = 0.0
            members = active[rows]
            exit_state[members] = ex
            t_exit[members] = t[kk - 1] + s * dt
            status[members] = "surfaced"
        if keep_trajectories:
            piece = np.full((B, n, 6), np.nan)
            keep = X[:, :-1].copy()
            keep[idx[None, :-1] >= k[:, None]] = np.nan
            piece[active] = keep
            pieces.append(piece)
        x = np.full((B, 6), np.nan)
        x[active] = X[:, -1]
        active = active[~has]
        step0 += n
        if bar is not None:
            bar.update(n)
    if bar is not None:
        bar.close()

    surfaced = status == "surfaced"
    fl = np.full((B, 6), np.nan)
    if surfaced.any():
        fl[surfaced] = model.rhs(0.0, exit_state[surfaced], fin[surfaced, None], params[surfaced])
    exit_angle = np.rad2deg(np.arctan2(-fl[:, 1], fl[:, 0]))
    summary = pd.DataFrame({
        "speed_m_s": sp, "angle_deg": an, "fin_deg": fi, "cg_m": cg,
        "max_depth_m": np.where(status != "non-finite", maxz, np.nan),
        "x_at_max_depth_m": np.where(status != "non-finite", x_at_max, np.nan),
        "t_at_max_depth_s": np.where(status != "non-finite", t_at_max, np.nan),
        "horizontal_m": exit_state[:, 0],
        "duration_s": t_exit,
        "exit_angle_deg": exit_angle,
        "exit_pitch_deg": (np.rad2deg(exit_state[:, 2]) + 180.0) % 360.0 - 180.0,
        "exit_speed_m_s": np.hypot(exit_state[:, 3], exit_state[:, 4]),
        "surfaced": surfaced,
        "status": status.astype(str),
    })
    n_bad = int((status == "non-finite").sum())
    n_sub = int((status == "t_max").sum())
    if n_bad:
        code, msg = 2, f"{n_bad} of {B} launch(es) became non-finite (reduce dt); {n_sub} still submerged at t_max = {t_max:g} s"
    elif n_sub:
        code, msg = 1, f"{n_sub} of {B} launch(es) still submerged at t_max = {t_max:g} s"
    else:
        code, msg = 0, f"all {B} launch(es) returned to the surface"
    if code:
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    xs = None
    tt = np.arange(step0 + 1) * dt
    if keep_trajectories:
        xs = np.concatenate(pieces + [np.full((B, 1, 6), np.nan)], axis=1) if pieces else np.full((B, 1, 6), np.nan)
        xs[:, 0] = x0
    return LaunchResult(launches=summary, t=tt, x=xs, exit_state=exit_state, model=model, params=params,
                        fin=fin, dt=dt, scalar=scalar, success=code == 0, status=code, message=msg)
