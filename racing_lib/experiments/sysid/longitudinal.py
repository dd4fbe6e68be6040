"""The longitudinal fits: drag, rolling resistance, pedal map and braking limit.

The longitudinal fits: drag and rolling resistance from the coast-down, the pedal map from laps
and pedal steps, the braking limit from full stops.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from racing_lib.experiments.sysid.lateral import _front_force_sin
from racing_lib.experiments.sysid.samples import (
    _MIN_SAMPLES,
    _V_MIN,
    FitStats,
    _check_regressor,
    _condition,
    _missing,
    _r2,
    _rms,
    _Samples,
    _samples,
    _subset,
)
from racing_lib.model import ModelParams, PedalMap, X
from racing_lib.model.drive import Drive
from racing_lib.vehicle import (
    drag_force,
    rolling_resistance,
)

__all__ = ["pedal_map_r2"]


def _fit_coast_down(
    kp: ModelParams, S: _Samples, fyf_sin: np.ndarray
) -> tuple[dict[str, float], dict[str, FitStats]]:
    """Step 3: C_xw and c_rr from the pedal-0 samples of coast-downs (linear least squares)."""
    cd = S.valid & (S.kind == "coast-down") & (S.pedal == 0.0) & (S.vx > _V_MIN)
    n = int(np.count_nonzero(cd))
    v = S.vx[cd]
    if n < _MIN_SAMPLES:
        raise _missing(
            "the drag C_xw and rolling resistance c_rr",
            f"only {n} pedal-0 coast-down samples above {_V_MIN:.0f} m/s (need >= {_MIN_SAMPLES})",
            "coast-down",
            S,
        )
    # Measured resistance: what is left of v_x_dot after the kinematic, steering and grade terms.
    y = S.dvx[cd] - S.r[cd] * S.vy[cd] + fyf_sin[cd] / kp.m + kp.g * np.sin(S.theta[cd])
    spread = (np.max(v**2) - np.min(v**2)) / np.max(v**2)
    if spread < 0.5 and -float(np.mean(y)) < _NO_RESISTANCE:
        return _no_resistance(n, v, y)
    if spread < 0.5:
        raise _missing(
            "the drag C_xw and rolling resistance c_rr",
            f"the coast-down speed only spans {np.min(v):.1f}-{np.max(v):.1f} m/s: at "
            "near-constant speed drag (v^2) and rolling resistance (constant) cannot be told apart",
            "coast-down",
            S,
        )
    A = np.column_stack(
        [
            -drag_force(v, 1.0) / kp.m,  # per unit C_xw
            -rolling_resistance(kp.m * kp.g * np.cos(S.theta[cd]), 1.0) / kp.m,  # per unit c_rr
        ]
    )
    cond = _check_regressor(A, ["v_x^2 (drag)", "1 (rolling)"], "C_xw and c_rr", "coast-down", S)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    e = y - A @ coef
    # Engine braking check: a powertrain that drags at pedal 0 adds a deceleration growing with
    # engine speed, i.e. roughly linear in v_x within a gear. Fit that term too; if it matters, keep
    # drag and rolling resistance from the extended fit and leave the engine braking to the pedal
    # map's state term m_0 + m_vx v_x (the measured a_x the map is fitted to includes it). Its
    # constant part cannot be told apart from rolling resistance with pedal-0 data alone.
    A3 = np.column_stack([A, v])
    coef3, *_ = np.linalg.lstsq(A3, y, rcond=None)
    e3 = y - A3 @ coef3
    linear = float(coef3[2] * np.mean(v))  # m/s^2 at the mean coast-down speed
    engine_braking = abs(linear) > 0.01 and _rms(e3) < 0.8 * _rms(e)
    if engine_braking:
        coef, e = coef3[:2], e3
        cond = _condition(A3)
        note = (
            f"engine braking at pedal 0 detected (speed-linear deceleration {linear:+.3f} m/s^2 at "
            f"{np.mean(v):.0f} m/s): drag and rolling resistance from the extended coast-down fit; "
            "the engine braking is left to the pedal map's state term"
        )
    else:
        note = (
            f"no engine braking at pedal 0 (speed-linear term {linear:+.4f} m/s^2 at "
            f"{np.mean(v):.0f} m/s, below 0.01): the coast-down is drag + rolling resistance only"
        )
    stats = {"coast-down": FitStats("coast-down", n, _rms(e), "m/s^2", _r2(y, e), cond)}
    return {"C_xw": float(coef[0]), "c_rr": float(coef[1]), "note": note}, stats


#: Mean deceleration at pedal 0 below which a car is taken to have no drag nor rolling
#: resistance, m/s^2 (a car that loses less than 1 m/s per minute of coasting).
_NO_RESISTANCE = 0.02


def _no_resistance(
    n: int, v: np.ndarray, y: np.ndarray
) -> tuple[dict[str, float | str], dict[str, FitStats]]:
    """C_xw = c_rr = 0 for a car that does not slow down at pedal 0 (speeds ``v`` in m/s).

    Both are non-negative, and their sum, the measured deceleration ``-y`` (m/s^2), is below
    :data:`_NO_RESISTANCE`: each one is that small too. (Told apart they cannot be: the speed
    hardly changes.)
    """
    decel = -float(np.mean(y))
    note = (
        f"no resistance at pedal 0: the coast-down kept {np.min(v):.1f}-{np.max(v):.1f} m/s "
        f"(mean deceleration {decel:+.4f} m/s^2 < {_NO_RESISTANCE} m/s^2), so drag and rolling "
        "resistance are taken as 0"
    )
    stats = {"coast-down": FitStats("coast-down", n, _rms(y), "m/s^2", float("nan"), 1.0)}
    return {"C_xw": 0.0, "c_rr": 0.0, "note": note}, stats


#: Manoeuvres whose samples only their own fits use, not the pedal map.
_OWN_FITS = ("braking", "steering-rate", "full-throttle", "braking-stability")


def _pedal_regressor(S: _Samples, v_corner: float | None, throttle: str = "share") -> np.ndarray:
    """Columns ``1, v_x, <throttle>, min(u_p, 0)`` of the pedal map's regression.

    The throttle column is ``max(u_p, 0) min(1, v_corner / v_x)`` in the ``"share"`` form (the
    pedal is a share of what the engine gives at that speed) and ``min(max(u_p, 0), v_corner /
    v_x)`` in the ``"demand"`` form (the pedal asks for an acceleration, which the power caps);
    see :class:`racing_lib.model.PedalMap`. For a fixed corner speed ``v_corner`` (m/s, where
    the power hyperbola meets the torque-limited gain ``m_thr``) either map is linear in its
    coefficients; None: no power limit (both forms are then the same).
    """
    u = np.maximum(S.pedal, 0.0)
    if v_corner is not None:
        cap = v_corner / np.maximum(S.vx, 1.0)
        u = u * np.minimum(1.0, cap) if throttle == "share" else np.minimum(u, cap)
    return np.column_stack([np.ones_like(S.vx), S.vx, u, np.minimum(S.pedal, 0.0)])


def _best_corner_speed(S: _Samples, y: np.ndarray, throttle: str = "share") -> float | None:
    """The corner speed ``p_thr / m_thr`` (m/s) that fits ``y`` best, or None for no power limit.

    A one-dimensional search (the rest is linear least squares): a grid, then a bounded refinement.
    None when the best corner lies above the data's speeds, i.e. the engine never ran out of power.
    """
    from scipy.optimize import minimize_scalar

    def sse(v_corner: float) -> float:
        A = _pedal_regressor(S, v_corner, throttle)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        return float(np.sum((y - A @ coef) ** 2))

    v_top = float(np.percentile(S.vx[S.pedal > 0.2], 95))
    grid = np.geomspace(3.0, max(v_top, 4.0), 40)
    costs = [sse(v) for v in grid]
    k = int(np.argmin(costs))
    if k == grid.size - 1:
        return None
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    return float(minimize_scalar(sse, bounds=(lo, hi), method="bounded").x)


def _best_throttle_form(S: _Samples, y: np.ndarray) -> tuple[str, float | None]:
    """The throttle form (``"share"`` or ``"demand"``) and corner speed (m/s) that fit best.

    Each form gets its own best corner speed; the one with the smaller squared residual wins,
    the share form on a tie (the simulated car's powertrain is of that form, CommonRoad's cars
    of the other: there a share map, fitted, made partial throttle at 13 m/s 40 % weaker than it
    is, and the controller spun the car out of a hairpin asking for less than it got).
    """
    best: tuple[float, str, float | None] | None = None
    for form in ("share", "demand"):
        v_corner = _best_corner_speed(S, y, form)
        A = _pedal_regressor(S, v_corner, form)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        sse = float(np.sum((y - A @ coef) ** 2))
        if best is None or sse < best[0]:
            best = (sse, form, v_corner)
    assert best is not None
    return best[1], best[2]


def _tyre_ax(kp: ModelParams, S: _Samples, fyf_sin: np.ndarray) -> np.ndarray:
    """Measured tyre acceleration a_x (m/s^2): Eq. 5 solved for a_x."""
    resist = drag_force(S.vx, kp.C_xw) + rolling_resistance(kp.m * kp.g * np.cos(S.theta), kp.c_rr)
    return S.dvx - S.r * S.vy + (resist + fyf_sin) / kp.m + kp.g * np.sin(S.theta)


def _fit_pedal(
    kp: ModelParams, S: _Samples, fyf_sin: np.ndarray
) -> tuple[PedalMap, dict[str, FitStats]]:
    """Step 4: the pedal map by linear least squares, with a held-out R^2."""
    # Stops at full brake are saturated by the tyres, not by the brakes: they are for the
    # braking limit (_fit_brake_limit), not for the slope. The actuator-limit runs have fits of
    # their own (_fit_full_throttle; the steering rate in lateral.py).
    use = S.valid & (S.vx > 3.0) & ~np.isin(S.kind, _OWN_FITS)
    thr = np.count_nonzero(use & (S.pedal > 0.2))
    brk = np.count_nonzero(use & (S.pedal < -0.2))
    if thr < 20 or brk < 20:
        raise _missing(
            "the pedal map (throttle and brake slopes)",
            f"{thr} throttle samples (u_p > 0.2) and {brk} brake samples (u_p < -0.2); each "
            "needs >= 20",
            "steps",
            S,
        )
    idx = np.flatnonzero(use)
    Su = _subset(S, idx)
    y = _tyre_ax(kp, Su, fyf_sin[idx])
    throttle, v_corner = _best_throttle_form(Su, y)
    A = _pedal_regressor(Su, v_corner, throttle)
    names = ["1", "v_x", "max(u_p, 0) (power-limited)", "min(u_p, 0)"]
    cond = _check_regressor(A, names, "the pedal map", "steps", S)
    # Hold out every fifth block of 50 periods (5 s) to judge the map on data it was not fit to.
    test = (np.arange(idx.size) // 50) % 5 == 4
    coef_train, *_ = np.linalg.lstsq(A[~test], y[~test], rcond=None)
    e_test = y[test] - A[test] @ coef_train
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    e = y - A @ coef
    if coef[2] <= 0.0 or coef[3] <= 0.0:
        raise _missing(
            "the pedal map",
            f"the fitted throttle/brake slopes ({coef[2]:.3g}, {coef[3]:.3g} m/s^2) are not both "
            "positive",
            "steps",
            S,
        )
    m_xi = np.zeros(len(X))
    m_xi[X.VX] = coef[1]  # only the speed drives the powertrain; other states would fit noise
    p_thr = None if v_corner is None else float(coef[2] * v_corner)
    pedal = PedalMap(
        m_0=coef[0], m_xi=tuple(m_xi), m_thr=coef[2], m_brk=coef[3], p_thr=p_thr, throttle=throttle
    )
    stats = {
        "pedal map": FitStats("pedal map", idx.size, _rms(e), "m/s^2", _r2(y, e), cond),
        "pedal map (held out)": FitStats(
            "pedal map (held out)",
            int(np.count_nonzero(test)),
            _rms(e_test),
            "m/s^2",
            _r2(y[test], e_test),
            cond,
        ),
    }
    return pedal, stats


def _fit_brake_limit(
    kp: ModelParams, S: _Samples, fyf_sin: np.ndarray
) -> tuple[float | None, float, str]:
    """Step 4b: the braking limit from the full stops: ``(a_brk_max, brake_max, note)``.

    ``a_brk_max`` is the median tyre deceleration (m/s^2) over the full-brake samples above
    10 m/s (below, the brakes fade out towards standstill), None without them. A stop whose
    wheels locked was backed off by the manoeuvre's watchdog to a lighter brake
    (:class:`~racing_lib.experiments.sysid.ManoeuvreSettings`): "full" is then the strongest brake
    each stop held, ``brake_max`` (in (0, 1]) that pedal's depth, and the limit the deceleration
    the car gives short of lock-up. ``brake_max`` is 1 when the full pedal held.
    """
    idx = np.flatnonzero(_full_brake(S) & S.valid & (S.vx > 10.0))
    if idx.size < _MIN_SAMPLES:
        ran = np.any(S.kind == "braking")
        todo = (
            "higher start speeds (braking_logs(speeds=...)) give more samples"
            if ran
            else "add the 'braking' manoeuvre to bound a_min by the tyres"
        )
        return (
            None,
            1.0,
            (
                f"no braking limit: {idx.size} full-brake samples above 10 m/s (need >= "
                f"{_MIN_SAMPLES}); {todo}"
            ),
        )
    decel = -_tyre_ax(kp, _subset(S, idx), fyf_sin[idx])
    limit = float(np.median(decel))
    spread = float(np.percentile(decel, 90) - np.percentile(decel, 10))
    pedal = float(np.max(S.pedal[idx]))
    locked = pedal > -0.999
    held = f" at pedal {pedal:.2f} or harder (backed off from lock-up)" if locked else ""
    return (
        limit,
        (-pedal if locked else 1.0),
        (
            f"braking limit {limit:.2f} m/s^2 from {idx.size} full-brake samples{held} "
            f"(10-90 % spread {spread:.2f} m/s^2)"
        ),
    )


def _full_brake(S: _Samples) -> np.ndarray:
    """The braking samples at the strongest brake their stop held for 1 s or more, bool."""
    out = np.zeros(S.vx.size, dtype=bool)
    for start, stop in S.bounds:
        if S.kind[start] != "braking":
            continue
        pedal = S.pedal[start:stop]
        levels, counts = np.unique(pedal[pedal < -0.2], return_counts=True)
        held = levels[counts >= 10]
        if held.size:
            out[start:stop] = pedal <= float(np.min(held)) + 1e-3
    return out


def pedal_map_r2(params: ModelParams, logs: Sequence[Drive], steer_tau: float = 0.0) -> float:
    """R^2 of ``params.pedal`` predicting the measured tyre acceleration a_x of ``logs``.

    Uses the same measured a_x as the fit (Eq. 5 solved for a_x with ``params``' drag, rolling
    resistance and tyres); pass logs the map was not fitted to for an honest score.
    """
    S = _samples(logs, "interval")
    tyres = {k: getattr(params, k) for k in ("B_f", "C_f", "D_f")}
    tyres["steer_tau"] = steer_tau
    fyf_sin = _front_force_sin(params, S, tyres)
    idx = np.flatnonzero(S.valid & (S.vx > 3.0))
    S = _subset(S, idx)
    y = _tyre_ax(params, S, fyf_sin[idx])
    xi = np.zeros((S.vx.size, len(X)))
    xi[:, X.VX], xi[:, X.VY], xi[:, X.R] = S.vx, S.vy, S.r
    return _r2(y, y - params.pedal.ax(xi, S.pedal))


def _fit_full_throttle(
    kp: ModelParams, S: _Samples, fyf_sin: np.ndarray
) -> tuple[dict[str, float], FitStats | None, str]:
    """Step 4c: power per mass (W/kg) and top speed (m/s) from the full-throttle run.

    The tyre acceleration ``a_x`` (Eq. 5 solved for it, with the identified resistances) times
    the speed is the power at the wheels per kg; where the engine is power limited it is a
    plateau, below it torque (or traction) limits it and at a governed top speed it drops to
    zero. The plateau is the median of the samples within 15 % of the 95th percentile. The top
    speed is the largest speed reached; it is a governed one when the run ended with the car no
    longer accelerating although the power would still have given ``0.3 P / v_x`` or more.

    Returns
    -------
    values : dict
        ``p_thr`` (W/kg), ``v_top`` (m/s), ``governed`` (1.0 or 0.0); NaN without the run.
    stats : FitStats or None
        ``a_x = P / v_x`` on the power-limited samples.
    note : str
        What was found, for the result's notes.
    """
    nan = {"p_thr": math.nan, "v_top": math.nan, "governed": 0.0}
    logs = [(a, b) for a, b in S.bounds if S.kind[a] == "full-throttle"]
    if not logs:
        note = (
            "no power limit from a full-throttle run: the logs hold no 'full-throttle' "
            "manoeuvre (racing_lib.experiments.sysid.full_throttle_log)"
        )
        return nan, None, note
    idx = np.concatenate([np.arange(a, b) for a, b in logs])
    use = idx[S.valid[idx] & (S.pedal[idx] >= 0.999) & (S.vx[idx] > _V_MIN)]
    v_top = float(np.max(S.vx[idx]))
    if use.size < 20:
        note = (
            f"no power limit: the 'full-throttle' manoeuvre ran, but held full throttle for "
            f"only {use.size} valid periods (need >= 20; reached {v_top:.1f} m/s): its watchdog "
            "backed the throttle off (wheel spin). Try a higher start speed "
            "(full_throttle_log(v_start=...)) or a longer ramp (ramp=...)"
        )
        return nan | {"v_top": v_top}, None, note
    sub = _subset(S, use)
    a_x = _tyre_ax(kp, sub, fyf_sin[use])
    power = a_x * sub.vx
    plateau = power >= 0.85 * float(np.percentile(power, 95))
    p = float(np.median(power[plateau]))
    e = a_x[plateau] - p / sub.vx[plateau]
    n = int(np.count_nonzero(plateau))
    stats = FitStats("full throttle (power)", n, _rms(e), "m/s^2", _r2(a_x[plateau], e), 1.0)
    last = slice(max(sub.vx.size - 10, 0), None)
    governed = bool(np.mean(a_x[last]) < 0.3 * p / v_top)
    what = "a governed top speed" if governed else "the speed reached when the run ended"
    note = (
        f"full throttle: {p:.4g} W/kg at the wheels from {n} power-limited samples; "
        f"{v_top:.1f} m/s is {what}"
    )
    return {"p_thr": p, "v_top": v_top, "governed": float(governed)}, stats, note
