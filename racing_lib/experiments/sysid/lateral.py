"""The lateral fits: tyres, steering lag and yaw inertia.

The lateral fits: each axle's Pacejka curve from steady circles, then the steering lag and the
yaw inertia from steering steps.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from racing_lib.experiments.sysid.samples import (
    _V_MIN,
    FitStats,
    _condition,
    _missing,
    _r2,
    _rms,
    _Samples,
    _subset,
)
from racing_lib.model import ModelOptions, ModelParams
from racing_lib.vehicle import (
    longitudinal_load_transfer,
    pacejka_lateral,
    static_axle_loads,
)

__all__ = ["rate_limited_steering"]

#: The braking-stability run is judged while the speed is above this share of its start (-).
_JUDGED_SPEED_SHARE = 0.8

#: The share of cornering samples whose lateral-acceleration error the grip margin covers (-):
#: the plan leaves unused the error that this share of the model's predictions stay within. A plan
#: rides the limit for seconds on end, tens of control periods, so the margin must cover nearly
#: every error the model makes, not a typical one: with 95 %, the van of CommonRoad's vehicle 3
#: (a 1.3 % margin) lost 2 of 10 laps of Sepang, pushing its front tyres past their peak out of a
#: corner; with 99 % (3.0 %) none. For the simulated car the 99 % error is 4.6-5.2 % of the peak,
#: the 5 % that chapter 04 had chosen by hand.
GRIP_QUANTILE = 0.99

#: The manoeuvres whose samples measure the grip's uncertainty. Not the steering-rate run: its
#: prediction needs the rate limit, which the steering lag alone does not model; nor the
#: braking-stability run, whose growing yaw the stability margin answers.
_GRIP_KINDS = ("circles", "steps", "laps")

#: The Pacejka coefficients of both axles, in the order :func:`_lateral_error` takes them.
_TYRE_COEFFS = ("B_f", "C_f", "D_f", "B_r", "C_r", "D_r")


def _axle_loads(kp: ModelParams, S: _Samples) -> tuple[np.ndarray, np.ndarray]:
    """Axle loads (N) with the longitudinal load transfer of the measured v_x_dot (Eq. 12)."""
    F_zf0, F_zr0 = static_axle_loads(kp.m, kp.l_f, kp.l_r, kp.g, S.theta)
    dW = longitudinal_load_transfer(kp.m, S.dvx, kp.h_c, kp.l_f, kp.l_r)
    return F_zf0 - dW, F_zr0 + dW


def _slip(kp: ModelParams, S: _Samples, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slip angles alpha_f, alpha_r (Eq. 11), rad."""
    vx = np.maximum(S.vx, 1.0)
    return delta - (S.vy + kp.l_f * S.r) / vx, -(S.vy - kp.l_r * S.r) / vx


def _jac_condition(jac: Any) -> float:
    J = np.asarray(jac.todense() if hasattr(jac, "todense") else jac)
    return _condition(J)


def _fit_axle(alpha: np.ndarray, phi: np.ndarray, mu: float) -> tuple[np.ndarray, Any]:
    """Pacejka B, C, D of one axle from force per unit load ``phi`` at slip ``alpha``.

    ``C`` is kept at or above 1.2 so that the fitted curve has a force peak (at
    ``tan(pi / (2 C)) / B``), which the planner and the MPC use as their slip bound. The simulated
    car's axles are broad (the inner wheel, nearly unloaded in a fast corner, peaks early, the
    outer one late), and with ``C`` free the fit drifts to ``C ~ 1``, a curve without a peak, for
    an RMS residual only about 1 % smaller.
    """
    best = None
    for C0 in (1.3, 1.9):
        res = least_squares(
            lambda p: pacejka_lateral(alpha, 1.0, mu, p[0], p[1], p[2]) - phi,
            x0=[10.0, C0, 1.0],
            bounds=([1.0, 1.2, 0.2], [60.0, 1.99, 3.0]),
            x_scale=[10.0, 1.0, 1.0],
        )
        if best is None or res.cost < best.cost:
            best = res
    return best.x, best


def _fit_lateral(
    kp: ModelParams, S: _Samples, fit_lag: bool
) -> tuple[dict[str, float], dict[str, FitStats]]:
    """Steps 1 and 2: tyres from the steady state, then the steering lag and I_zz from all data."""
    lat, ss = _lateral_samples(kp, S)
    coeffs, F_zf, F_zr, stats = _fit_steady_tyres(kp, S, ss)
    Bf, Cf, Df, Br, Cr, Dr = coeffs
    tau, I_zz, transient = _fit_lag_and_inertia(kp, S, lat, coeffs, F_zf, F_zr, fit_lag)
    stats |= transient
    full = np.array([Bf, Cf, Df, Br, Cr, Dr, I_zz / 1000.0, tau])
    p = full
    names = ("B_f", "C_f", "D_f", "B_r", "C_r", "D_r")
    out = {k: float(v) for k, v in zip(names, p[:6], strict=True)}
    out["I_zz"] = float(p[6] * 1000.0)
    out["steer_tau"] = float(p[7])
    return out, stats


def _lateral_samples(kp: ModelParams, S: _Samples) -> tuple[np.ndarray, np.ndarray]:
    """The samples the lateral fits use: all cornering ones, and the steady-state ones.

    Parameters
    ----------
    kp : ModelParams
        Known values (``mu``; ``g`` in m/s^2).
    S : _Samples
        All samples.

    Returns
    -------
    lat, ss : ndarray of bool
        Designed manoeuvres with little longitudinal acceleration; of those, the steady-state
        cornering samples (|a_y| > 0.3 m/s^2).

    Raises
    ------
    ModelError
        If the logs lack steering, or steady-state cornering up to 0.55 mu g.
    """
    g, mu = kp.g, kp.mu
    # Little longitudinal force: the car's tyres share friction between x and y, the model's don't.
    # Designed manoeuvres only: laps add wall contacts and kerb-to-kerb slides the logs cannot flag.
    designed = (S.kind == "circles") | (S.kind == "steps")
    lat = designed & S.valid & (S.vx > _V_MIN) & (np.abs(S.dvx) < 1.5)
    if not np.any(designed):
        raise _missing(
            "the Pacejka tyre parameters B, C, D and the yaw inertia I_zz",
            "the logs hold no steady-state circles and no steering steps (laps are not used for "
            "the tyres: wall contacts and slides would corrupt them)",
            "circles",
            S,
        )
    if not np.any(lat) or (
        np.max(np.abs(S.steer[lat])) < 0.01 and np.max(np.abs(S.a_y[lat])) < 1.0
    ):
        raise _missing(
            "the Pacejka tyre parameters B, C, D and the yaw inertia I_zz",
            "the logs contain no steering (|delta| < 0.01 rad and |a_y| < 1 m/s^2 throughout)",
            "circles",
            S,
        )
    ss = lat & S.settled & (np.abs(S.dr) < 0.03) & (np.abs(S.dvy) < 0.1) & (np.abs(S.dvx) < 0.5)
    ss &= np.abs(S.a_y) > 0.3
    a_y_max = float(np.max(np.abs(S.a_y[ss]))) if np.any(ss) else 0.0
    if np.count_nonzero(ss) < 30 or a_y_max < 0.55 * mu * g:
        circ = (S.kind == "circles") & S.valid
        seen = float(np.max(np.abs(S.a_y[circ]))) if np.any(circ) else 0.0
        raise _missing(
            "the Pacejka tyre parameters B, C, D",
            f"it gave {np.count_nonzero(ss)} steady-state cornering samples, reaching |a_y| = "
            f"{a_y_max:.1f} m/s^2 (the largest lateral acceleration in control: "
            f"{seen:.1f} m/s^2); the peak factor D needs >= 30 samples up to at least "
            f"{0.55 * mu * g:.1f} m/s^2 (0.55 mu g of the data sheet's mu = {mu:g})",
            "circles",
            S,
        )
    return lat, ss


def _fit_steady_tyres(
    kp: ModelParams, S: _Samples, ss: np.ndarray
) -> tuple[tuple[float, ...], np.ndarray, np.ndarray, dict[str, FitStats]]:
    """Step 1: both axles' Pacejka factors from steady cornering (r_dot ~ 0).

    The yaw balance splits m a_y between the axles.

    Returns
    -------
    (B_f, C_f, D_f, B_r, C_r, D_r) : tuple of float
        Stiffness (1/rad), shape and peak factors (dimensionless).
    F_zf, F_zr : ndarray
        The axle loads of every sample, N.
    stats : dict
        The fit's quality, as ``"tyres (steady state)"``.
    """
    mu = kp.mu
    F_zf, F_zr = _axle_loads(kp, S)
    L = kp.wheelbase
    a_f, a_r = _slip(kp, S, S.steer)
    phi_f = kp.m * S.a_y * kp.l_r / L / np.cos(S.steer) / F_zf
    phi_r = kp.m * S.a_y * kp.l_f / L / F_zr
    (Bf, Cf, Df), res_f = _fit_axle(a_f[ss], phi_f[ss], mu)
    (Br, Cr, Dr), res_r = _fit_axle(a_r[ss], phi_r[ss], mu)
    stats = {
        "tyres (steady state)": FitStats(
            "tyres (steady state)",
            int(np.count_nonzero(ss)),
            _rms(np.concatenate([res_f.fun * F_zf[ss], res_r.fun * F_zr[ss]])) / kp.m,
            "m/s^2",
            _r2(np.concatenate([phi_f[ss], phi_r[ss]]), np.concatenate([res_f.fun, res_r.fun])),
            max(_jac_condition(res_f.jac), _jac_condition(res_r.jac)),
        )
    }
    return (Bf, Cf, Df, Br, Cr, Dr), F_zf, F_zr, stats


def _fit_lag_and_inertia(
    kp: ModelParams,
    S: _Samples,
    lat: np.ndarray,
    coeffs: tuple[float, ...],
    F_zf: np.ndarray,
    F_zr: np.ndarray,
    fit_lag: bool,
) -> tuple[float, float, dict[str, FitStats]]:
    """Step 2: the steering lag (s) and the yaw inertia I_zz (kg m^2) from all cornering samples.

    Parameters
    ----------
    kp : ModelParams
        Known values (mass in kg, geometry in m, ``mu``).
    S : _Samples
        All samples.
    lat : ndarray of bool
        The cornering samples (:func:`_lateral_samples`).
    coeffs : tuple of float
        The steady-state tyres (B_f, C_f, D_f, B_r, C_r, D_r).
    F_zf, F_zr : ndarray
        The axle loads of every sample, N.
    fit_lag : bool
        Fit the lag (otherwise 0 s).

    Returns
    -------
    tau : float
        Steering lag, s.
    I_zz : float
        Yaw inertia, kg m^2.
    stats : dict
        The lateral and yaw balances' fit quality.
    """
    mu = kp.mu
    Bf, Cf, Df, Br, Cr, Dr = coeffs
    # Step 2a: the steering lag from the lateral balance m a_y = F_yf(delta) cos(delta) + F_yr, with
    # the steady-state tyres (a one-parameter nonlinear least-squares fit). The tyre curves stay
    # those of the steady state, which sees them cleanly.
    tr = lat & (np.abs(S.dr) > 0.2)
    if np.count_nonzero(tr) < 20:
        raise _missing(
            "the yaw inertia I_zz",
            f"only {np.count_nonzero(tr)} samples with |r_dot| > 0.2 rad/s^2 (need >= 20): the "
            "logs have no yaw transients",
            "steps",
            S,
        )
    idx = np.flatnonzero(lat)
    Ssub = _subset(S, idx)
    F_zf_s, F_zr_s = F_zf[idx], F_zr[idx]

    def front_rear(tau: float) -> tuple[np.ndarray, np.ndarray]:
        delta = S.steer_effective(tau)[idx]
        af, ar = _slip(kp, Ssub, delta)
        fyf = pacejka_lateral(af, F_zf_s, mu, Bf, Cf, Df) * np.cos(delta)
        return fyf, pacejka_lateral(ar, F_zr_s, mu, Br, Cr, Dr)

    def lateral_residual(q: np.ndarray) -> np.ndarray:
        fyf, fyr = front_rear(float(q[0]))
        return (fyf + fyr) / kp.m - Ssub.a_y

    if fit_lag:
        res = least_squares(lateral_residual, [0.05], bounds=([0.0], [0.5]), x_scale=[0.05])
        tau = float(res.x[0])
    else:
        tau = 0.0
    fyf, fyr = front_rear(tau)
    I_zz = _fit_inertia(kp, Ssub, fyr)
    return tau, I_zz, _balance_stats(kp, Ssub, fyf, fyr, I_zz)


def _fit_inertia(kp: ModelParams, Ssub: _Samples, fyr: np.ndarray) -> float:
    """Step 2b: the yaw inertia I_zz (kg m^2) by linear least squares, given the rear forces (N).

    Raises
    ------
    ModelError
        If the fit gives a non-positive inertia.
    """
    # Step 2b: I_zz by linear least squares from the yaw balance with the front force eliminated
    # through the measured lateral balance: I_zz r_dot = l_f m a_y - L F_yr. The front axle carries
    # the steering, so its force is where the actuator noise and lag enter; in this form that noise
    # appears identically on both sides (l_f dF_yf) instead of only in r_dot, which would bias I_zz
    # low (errors in the regressor). Only the rear tyre model enters.
    L = kp.wheelbase
    rd = Ssub.dr
    y_rear = kp.l_f * kp.m * Ssub.a_y - L * fyr
    A = rd[:, None]
    I_zz = float(np.linalg.lstsq(A, y_rear, rcond=None)[0][0])
    if not I_zz > 0.0:
        raise _missing(
            "the yaw inertia I_zz",
            f"the yaw-balance fit gave a non-positive inertia ({I_zz:.3g} kg m^2)",
            "steps",
            Ssub,
        )
    return I_zz


def _balance_stats(
    kp: ModelParams, Ssub: _Samples, fyf: np.ndarray, fyr: np.ndarray, I_zz: float
) -> dict[str, FitStats]:
    """How well the fitted front and rear forces (N) and I_zz (kg m^2) explain a_y and r_dot."""
    rd = Ssub.dr
    n = rd.size
    e_lat = (fyf + fyr) / kp.m - Ssub.a_y
    e_yaw = (kp.l_f * fyf - kp.l_r * fyr) / I_zz - rd  # the full model's yaw-acceleration error
    stats = {}
    stats["lateral balance (all data)"] = FitStats(
        "lateral balance (all data)", n, _rms(e_lat), "m/s^2", _r2(Ssub.a_y, e_lat), 1.0
    )
    stats["yaw balance (all data)"] = FitStats(
        "yaw balance (all data)",
        n,
        _rms(e_yaw),
        "rad/s^2",
        _r2(rd, e_yaw),
        1.0,  # one regressor (r_dot); its excitation was checked above
    )
    return stats


def _lateral_error(
    kp: ModelParams, S: _Samples, delta: np.ndarray, coeffs: tuple[float, ...]
) -> np.ndarray:
    """The model's lateral acceleration less the measured one, m/s^2, on every sample of ``S``.

    Parameters
    ----------
    kp : ModelParams
        Mass (kg), geometry (m) and ``mu`` of the car.
    S : _Samples
        The samples (their loads include the measured longitudinal load transfer).
    delta : ndarray
        The steering angle the tyres saw at each sample, rad.
    coeffs : tuple of float
        ``B_f, C_f, D_f, B_r, C_r, D_r`` (:data:`_TYRE_COEFFS`).

    Returns
    -------
    ndarray
        ``(F_yf cos(delta) + F_yr) / m - a_y``.
    """
    Bf, Cf, Df, Br, Cr, Dr = coeffs
    F_zf, F_zr = _axle_loads(kp, S)
    a_f, a_r = _slip(kp, S, delta)
    fyf = pacejka_lateral(a_f, F_zf, kp.mu, Bf, Cf, Df) * np.cos(delta)
    fyr = pacejka_lateral(a_r, F_zr, kp.mu, Br, Cr, Dr)
    return (fyf + fyr) / kp.m - S.a_y


def _grip_uncertainty(fitted: ModelParams, S: _Samples, tau: float) -> tuple[float, int]:
    """Step 6: how much of its peak the identified model may get the lateral acceleration wrong.

    On the samples of the circles, the steering steps and the laps (:data:`_GRIP_KINDS`; in
    control and above ``_V_MIN``), the identified tyres and steering lag predict the lateral
    acceleration (:func:`_lateral_error`). The uncertainty is the :data:`GRIP_QUANTILE`
    quantile of the error's magnitude, divided by the model's peak acceleration
    (:meth:`~racing_lib.model.ModelParams.peak_acceleration`, the radius of the planner's
    friction circle): 99 % of the predictions lie within that share of the peak. The tyre and
    lag fits did not use the laps (their slides and kerbs would corrupt the tyres), so the laps
    also test the model where it was not fitted.

    A plan that keeps this share of the friction unused (the identified grip margin, see
    :meth:`IdentificationResult.car_model`) asks for no more than the car gave in 99 % of what
    was seen. A model that explains the car worse, or a car that varies more from corner to
    corner, gets a wider margin.

    Parameters
    ----------
    fitted : ModelParams
        The identified model (tyres, mass in kg, geometry in m).
    S : _Samples
        All samples.
    tau : float
        The identified steering lag, s.

    Returns
    -------
    share : float
        The error quantile over the peak acceleration (-), NaN without samples.
    n : int
        The samples it was measured on.
    """
    use = np.isin(S.kind, _GRIP_KINDS) & S.valid & (S.vx > _V_MIN) & np.isfinite(S.a_y)
    if not np.any(use):
        return math.nan, 0
    delta = S.steer_effective(tau)[use]
    coeffs = tuple(getattr(fitted, k) for k in _TYRE_COEFFS)
    error = np.abs(_lateral_error(fitted, _subset(S, np.flatnonzero(use)), delta, coeffs))
    return float(np.quantile(error, GRIP_QUANTILE) / fitted.peak_acceleration()), int(error.size)


def _front_force_sin(kp: ModelParams, S: _Samples, tyres: dict[str, float]) -> np.ndarray:
    """``F_yf sin(delta)`` (N) with the identified tyres and steering lag: the steering's drag."""
    delta = S.steer_effective(tyres["steer_tau"])
    F_zf, _ = _axle_loads(kp, S)
    a_f, _ = _slip(kp, S, delta)
    return pacejka_lateral(a_f, F_zf, kp.mu, tyres["B_f"], tyres["C_f"], tyres["D_f"]) * np.sin(
        delta
    )


def rate_limited_steering(
    steer_cmd: np.ndarray, tau: float, rate_max: float, dt: float = 0.1, n_sub: int = 20
) -> np.ndarray:
    """Mean angle over each period behind a first-order lag whose rate is limited, rad.

    ``delta_dot = clip((delta_cmd - delta) / tau, -rate_max, rate_max)`` with each command held
    for ``dt`` s, integrated with ``n_sub`` exact-enough Euler substeps per period (the rate
    limit makes the response piecewise linear); the actuator starts settled at the first command.

    Parameters
    ----------
    steer_cmd : ndarray, shape (N,)
        Steering commands, rad.
    tau : float
        Time constant of the lag, s.
    rate_max : float
        Largest steering rate, rad/s.
    dt : float
        Control period, s.
    n_sub : int
        Substeps per period.
    """
    c = np.asarray(steer_cmd, dtype=float).ravel()
    out = np.empty_like(c)
    if c.size == 0:
        return out
    h = dt / n_sub
    delta, tau = float(c[0]), max(float(tau), h)
    for k, cmd in enumerate(c):
        acc = 0.0
        for _ in range(n_sub):
            rate = min(max((cmd - delta) / tau, -rate_max), rate_max)
            nxt = delta + h * rate
            acc += 0.5 * (delta + nxt)
            delta = nxt
        out[k] = acc / n_sub
    return out


def _fit_steer_rate(
    kp: ModelParams, S: _Samples, tyres: dict[str, float]
) -> tuple[float, FitStats | None, str]:
    """The steering actuator's rate limit (rad/s) from the steering-rate manoeuvre.

    With the identified tyres and lag fixed, a one-parameter search for the rate limit that
    best explains the lateral balance ``m a_y = F_yf cos(delta) + F_yr`` of the steering-rate
    logs (``delta`` from :func:`rate_limited_steering`). A rate the data cannot bound from above
    (the best fit at the search's top, 20 rad/s) is reported as ``inf``.

    Returns
    -------
    rate : float
        rad/s (``inf``: none seen; ``nan``: no steering-rate logs).
    stats : FitStats or None
        The lateral balance on those logs with the fitted rate.
    note : str
        What was found, for the result's notes.
    """
    logs = [(a, b) for a, b in S.bounds if S.kind[a] == "steering-rate"]
    if not logs:
        return (
            math.nan,
            None,
            (
                "no steering-rate limit identified: the logs hold no 'steering-rate' manoeuvre "
                "(racing_lib.experiments.sysid.steering_rate_log)"
            ),
        )
    idx = np.concatenate([np.arange(a, b) for a, b in logs])
    use = idx[S.valid[idx] & (S.vx[idx] > _V_MIN)]
    sub = _subset(S, use)
    tau = tyres["steer_tau"]
    coeffs = tuple(tyres[k] for k in _TYRE_COEFFS)

    def residual(log_rate: float) -> np.ndarray:
        delta = np.empty(S.vx.size)
        for a, b in logs:
            delta[a:b] = rate_limited_steering(S.steer[a:b], tau, math.exp(log_rate))
        return _lateral_error(kp, sub, delta[use], coeffs)

    grid = np.log(np.geomspace(0.05, 20.0, 25))
    costs = [float(np.sum(residual(g) ** 2)) for g in grid]
    k = int(np.argmin(costs))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    best = minimize_scalar(lambda g: float(np.sum(residual(g) ** 2)), bounds=(lo, hi),
                           method="bounded").x  # fmt: skip
    e = residual(best)
    stats = FitStats("steering rate", int(use.size), _rms(e), "m/s^2", _r2(sub.a_y, e), 1.0)
    step = float(np.max(np.abs(np.diff(S.steer[idx]))))
    if k == grid.size - 1:
        return (
            math.inf,
            stats,
            (
                f"no steering-rate limit seen: steps of {step:.3f} rad are followed as the "
                f"{tau:.3f} s lag alone predicts (a limit, if any, is above 20 rad/s)"
            ),
        )
    rate = float(math.exp(best))
    return (
        rate,
        stats,
        (
            f"steering-rate limit {rate:.3g} rad/s from {len(logs)} steering-rate log(s) with "
            f"steps of {step:.3f} rad (lateral balance RMS {stats.rms:.3g} m/s^2)"
        ),
    )


def _fit_braking_stability(
    fitted: ModelParams, options: ModelOptions, S: _Samples
) -> tuple[dict[str, Any], str]:
    """Step 5d: does a small yaw grow under braking, and does the model know? The stability run.

    The run (:func:`racing_lib.experiments.sysid.braking_stability_log`) brakes with the
    steering held after a kick. The yaw rate's deviation from the circle's steady state,
    ``dev = r - v_x kappa`` (``kappa`` the ``r / v_x`` of the second before the brake), either
    dies out or grows. It is judged from the fifth period of braking (the kick and the first
    half second of its response are over) until the brake lets go
    or the speed falls below ``_JUDGED_SPEED_SHARE`` of the braking's start (slower, the held
    steering's own steady state drifts from the circle's): the growth rate ``lambda`` (1/s) is
    the least-squares fit of ``d(dev)/dt = lambda dev``. The car *diverged* when ``lambda > 0``
    and the deviation reached 0.05 rad/s (far above the noise).

    The model's growth rate over the same samples, weighted alike (``dev^2``), is the largest
    real part of the identified model's lateral eigenvalues at each sample's speed and
    deceleration (:func:`racing_lib.model.lateral.lateral_linearization`). Where the car
    diverged faster than the model says, the difference is the model's error in exactly the
    quantity the planner must respect: the plans' stability margin
    (:attr:`racing_lib.model.CarModel.lateral_stability`, 1/s). The model here is the one
    identified, around straight driving; the planner applies the margin to its own parameters
    (the grip margin lowers the friction, by a few per cent with the full manoeuvre set) at the
    planned state, a small difference next to the margin.

    Returns
    -------
    result : dict
        ``stable`` (True, False, or None without the run), ``growth`` and ``model_growth``
        (1/s), ``v`` (m/s) and ``a_x`` (m/s^2, negative) where the deviation was largest, and
        ``margin``: the stability margin for the plans (1/s; None for a stable car).
    note : str
        What was found, for the result's notes.
    """
    nan = math.nan
    logs = [(a, b) for a, b in S.bounds if S.kind[a] == "braking-stability"]
    found: dict[str, Any] = {"stable": None, "growth": nan, "model_growth": nan}
    found |= {"v": nan, "a_x": nan, "margin": None}
    if not logs:
        return found, (
            "no braking stability judged: the logs hold no 'braking-stability' manoeuvre "
            "(racing_lib.experiments.sysid.braking_stability_log)"
        )
    a, b = logs[0]
    braking = np.flatnonzero(S.pedal[a:b] < 0.0) + a
    k0 = int(braking[0]) if braking.size else b
    judged = (np.arange(a, b) >= k0 + 5) & (S.pedal[a:b] < 0.0)
    judged &= S.vx[a:b] >= _JUDGED_SPEED_SHARE * S.vx[min(k0, b - 1)]
    run = np.arange(a, b)[judged]
    # The judged stretch ends at the first gap (the brake let go, or the car slowed down).
    gaps = np.flatnonzero(np.diff(run) > 1)
    run = run[: gaps[0] + 1] if gaps.size else run
    if run.size < 7:
        return found, (
            f"no braking stability judged: the braking-stability run gave {run.size} periods of "
            "braking at speed (need >= 7); a higher speed or a slower brake ramp gives more "
            "(braking_stability_log(v_test=..., ramp=...))"
        )
    before = np.arange(max(k0 - 10, a), k0)
    kappa = float(np.median(S.r[before] / np.maximum(S.vx[before], 1.0)))
    dev = S.r[run] - S.vx[run] * kappa
    dev_dot = S.dr[run] - S.dvx[run] * kappa
    weight = dev**2 / max(float(np.sum(dev**2)), 1e-12)
    found["growth"] = float(np.dot(dev, dev_dot) / max(float(np.dot(dev, dev)), 1e-12))
    found["stable"] = not (found["growth"] > 0.0 and float(np.max(np.abs(dev))) > 0.05)
    from racing_lib.model.lateral import lateral_linearization  # python-control: load it late

    model = [
        float(np.max(np.linalg.eigvals(lateral_linearization(fitted, v, options, accel=ax).A).real))
        for v, ax in zip(np.maximum(S.vx[run], 2.0), S.dvx[run], strict=True)
    ]
    found["model_growth"] = float(np.dot(weight, model))
    peak = int(run[np.argmax(np.abs(dev))])
    found["v"], found["a_x"] = float(S.vx[peak]), float(S.dvx[peak])
    verdict = "stayed stable" if found["stable"] else "diverged in yaw"
    note = (
        f"braking with the steering held ({found['v']:.1f} m/s, {found['a_x']:+.2f} m/s^2 at "
        f"the largest yaw deviation, {np.max(np.abs(dev)):.3f} rad/s), the car {verdict}: "
        f"growth {found['growth']:+.2f} 1/s, the model's {found['model_growth']:+.2f} 1/s"
    )
    if not found["stable"]:
        found["margin"] = max(found["growth"] - found["model_growth"], 0.0)
        note += (
            f"; plans keep the model's lateral dynamics stable with a margin of "
            f"{found['margin']:.2f} 1/s (CarModel.lateral_stability)"
        )
    return found, note
