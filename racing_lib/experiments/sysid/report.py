"""The identification's report table: each fitted value beside the true one, and its fit.

Used by :func:`racing_lib.experiments.sysid.identify` to fill
:attr:`~racing_lib.experiments.sysid.IdentificationResult.rows`.
"""

from __future__ import annotations

from typing import Any

from racing_lib.model import ModelParams, X
from racing_lib.vehicle import VehicleParams, axle_cornering_stiffness

__all__: list[str] = []


def _truth_params(
    truth: VehicleParams | ModelParams | None,
) -> tuple[ModelParams | None, float | None]:
    if truth is None:
        return None, None
    tp = truth if isinstance(truth, ModelParams) else ModelParams.from_vehicle(truth)
    tau = getattr(truth, "steer_tau", None)
    return tp, (float(tau) if tau is not None else None)


def _derived(p: ModelParams) -> dict[str, float]:
    """Quantities that decide the car's behaviour more directly than B, C, D alone."""
    F_zf, F_zr = p.static_loads()
    return {
        "mu*D_f": p.mu * p.D_f,
        "mu*D_r": p.mu * p.D_r,
        "C_alpha_f": axle_cornering_stiffness(F_zf, p.mu, p.B_f, p.C_f, p.D_f),
        "C_alpha_r": axle_cornering_stiffness(F_zr, p.mu, p.B_r, p.C_r, p.D_r),
    }


#: The report's rows: (parameter, unit, the manoeuvres it is fitted from).
_REPORT_SPEC = (
    ("C_xw", "kg/m", "coast-down"),
    ("c_rr", "-", "coast-down"),
    ("B_f", "1/rad", "circles+steps"),
    ("C_f", "-", "circles+steps"),
    ("D_f", "-", "circles+steps"),
    ("B_r", "1/rad", "circles+steps"),
    ("C_r", "-", "circles+steps"),
    ("D_r", "-", "circles+steps"),
    ("mu*D_f", "-", "circles+steps"),
    ("mu*D_r", "-", "circles+steps"),
    ("C_alpha_f", "N/rad", "circles+steps"),
    ("C_alpha_r", "N/rad", "circles+steps"),
    ("I_zz", "kg m^2", "steps"),
    ("steer_tau", "s", "steps"),
    ("pedal m_0", "m/s^2", "laps+steps"),
    ("pedal m_vx", "1/s", "laps+steps"),
    ("pedal m_thr", "m/s^2", "laps+steps"),
    ("pedal m_brk", "m/s^2", "laps+steps"),
    ("pedal p_thr", "W/kg", "laps+steps"),
    ("pedal a_brk_max", "m/s^2", "braking"),
    ("pedal brake_max", "-", "braking"),
    ("steer_rate_max", "rad/s", "steering-rate"),
    ("p_thr (full throttle)", "W/kg", "full-throttle"),
    ("top speed", "m/s", "full-throttle"),
)


def _report_rows(
    fitted: ModelParams,
    tyres: dict[str, float],
    fits: dict[str, Any],
    truth: VehicleParams | ModelParams | None,
    limits: dict[str, float],
) -> list[dict[str, Any]]:
    """One row per identified parameter: fitted and true value, error (%), fit quality.

    Parameters
    ----------
    fitted : ModelParams
        The identified set.
    tyres : dict
        The lateral fit's values (``steer_tau`` in s).
    fits : dict
        The quality of each fit, by name.
    truth : VehicleParams, ModelParams or None
        The true car (None: no "true" column).
    limits : dict
        The actuators' limits (:func:`_fit_limits`).
    """
    tp, tau_true = _truth_params(truth)
    lat, yaw = fits["lateral balance (all data)"], fits["yaw balance (all data)"]
    pedal = fitted.pedal
    fd = _derived(fitted)
    td = _derived(tp) if tp is not None else {}
    pedal_vals = {
        "pedal m_0": pedal.m_0,
        "pedal m_vx": pedal.m_xi[X.VX],
        "pedal m_thr": pedal.m_thr,
        "pedal m_brk": pedal.m_brk,
        "pedal p_thr": pedal.p_thr if pedal.p_thr is not None else float("nan"),
        "pedal a_brk_max": pedal.a_brk_max if pedal.a_brk_max is not None else float("nan"),
        "pedal brake_max": pedal.brake_max,
    }
    fit_of = {
        "coast-down": f"RMS {fits['coast-down'].rms:.3g} m/s^2",
        "circles+steps": f"RMS lat {lat.rms:.3g} m/s^2",
        "steps": f"RMS yaw {yaw.rms:.3g} rad/s^2",
        "laps+steps": f"held-out R^2 {fits['pedal map (held out)'].r2:.3f}",
        "braking": "median of the full stops",
        "steering-rate": _fit_text(fits, "steering rate"),
        "full-throttle": _fit_text(fits, "full throttle (power)"),
    }
    power = _true_power(truth)
    rows = []
    for name, unit, man in _REPORT_SPEC:
        if name in fd:
            val, true = fd[name], td.get(name)
        elif name == "steer_tau":
            val, true = tyres["steer_tau"], tau_true
        elif name in ("pedal p_thr", "p_thr (full throttle)"):
            # The one pedal-map number with a true value: engine power at the wheels per kg.
            val = pedal_vals[name] if name in pedal_vals else limits[name]
            true = power
        elif name in limits:
            val = limits[name]
            true = getattr(truth, name, None) if name == "steer_rate_max" else None
        elif name in pedal_vals:
            val, true = pedal_vals[name], None  # the powertrain is nonlinear: no true map
        else:
            val = getattr(fitted, name)
            true = getattr(tp, name) if tp is not None else None
        err = 100.0 * (val / true - 1.0) if true else None
        rows.append(
            {
                "name": name,
                "unit": unit,
                "fitted": float(val),
                "true": None if true is None else float(true),
                "error_pct": err,
                "fit": fit_of[man],
                "manoeuvre": man,
            }
        )
    return rows


def _fit_text(fits: dict[str, Any], name: str) -> str:
    """The report's fit column for fit ``name``: its RMS residual, or that it did not run."""
    return f"RMS {fits[name].rms:.3g} {fits[name].unit}" if name in fits else "not identified"


def _true_power(truth: VehicleParams | ModelParams | None) -> float | None:
    """The true power at the wheels per kg, W/kg: the simulated car's engine or a map's p_thr."""
    if hasattr(truth, "power_max"):
        return truth.power_max * truth.driveline_efficiency / truth.m
    if isinstance(truth, ModelParams):
        return truth.pedal.p_thr
    return None
