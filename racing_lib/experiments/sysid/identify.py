"""Identification: the planning model's parameters from logs, step by step, and its report.

The method is described in :mod:`racing_lib.experiments.sysid`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path as FsPath
from typing import Any

from racing_lib.config import fast_mode
from racing_lib.errors import ModelError
from racing_lib.experiments.sysid.lateral import (
    GRIP_QUANTILE,
    _fit_braking_stability,
    _fit_lateral,
    _fit_steer_rate,
    _front_force_sin,
    _grip_uncertainty,
)
from racing_lib.experiments.sysid.limits import collect_logs
from racing_lib.experiments.sysid.longitudinal import (
    _fit_brake_limit,
    _fit_coast_down,
    _fit_full_throttle,
    _fit_pedal,
)
from racing_lib.experiments.sysid.manoeuvres import MANOEUVRES
from racing_lib.experiments.sysid.report import _report_rows
from racing_lib.experiments.sysid.samples import (
    _MIN_SAMPLES,
    Derivative,
    FitStats,
    _Samples,
    _samples,
)
from racing_lib.io import atomic_write_json, jsonable
from racing_lib.model import GRIP_MARGIN, CarModel, ModelOptions, ModelParams
from racing_lib.model.drive import Drive
from racing_lib.model.identified import shipped_fit_path
from racing_lib.vehicle import (
    VehicleParams,
)

__all__ = ["TOLERANCES", "IdentificationRecord", "IdentificationResult", "identify", "main", "run"]

#: Relative tolerances the identification is tested against (``tests/test_sysid.py``), chosen from
#: what the data can honestly give. The simulated car's tyres are load sensitive and share their
#: friction between longitudinal and lateral force, which the planning model's do not; its nominal
#: ``B, C, D`` are therefore not exactly the best planning-model fit, and the individual ``B`` and
#: ``C`` trade against each other (so only the peak ``mu D`` and the cornering stiffness
#: ``mu F_z0 B C D`` are toleranced). The fitted peak is the *axle's* effective one: in a fast
#: corner the inner wheel carries little load and the load-sensitive tyres lose grip to the
#: transfer, so it lies below the single tyre's ``mu D``. Observed over seeds 1-4 and 7, full and
#: fast data, with the car's actuation noise: drag and rolling resistance within 0.1 %; front peak
#: -15.6 to -16.3 %; rear peak -15.7 to -17.6 % (``C`` at its lower bound of 1.2, see
#: ``_fit_axle``); cornering stiffnesses within 6 %; ``I_zz`` -3 to -5.5 %; steering lag within
#: 1.5 %.
#: An identification as JSON (:meth:`IdentificationResult.to_dict`, the body of the shipped
#: ``identified_params.json``): the model's parameters, the steering lag, the report's rows, the
#: fit statistics, notes and the grip margin's measurement. Its values are numbers, strings,
#: lists and nested objects, hence ``Any``.
IdentificationRecord = dict[str, Any]

#: The widest grip margin an identification gives its plans (-). A model whose lateral
#: acceleration is off by more than this share of its peak in 1 % of the samples (a log with a
#: long slide, or a model of the wrong shape) is not one to plan with at all: its report says so,
#: and the plans keep this share, below the half of the friction that CarModel accepts.
MAX_GRIP_MARGIN = 0.45

#: The least R^2 a sub-model must reach for :attr:`IdentificationResult.success`: it explains at
#: least half of the variance of what it predicts.
R2_FLOOR = 0.5

TOLERANCES: dict[str, float] = {
    "C_xw": 0.10,
    "c_rr": 0.25,
    "I_zz": 0.15,
    "mu*D_f": 0.20,
    "mu*D_r": 0.22,
    "C_alpha_f": 0.20,
    "C_alpha_r": 0.20,
}


# --------------------------------------------------------------------------------------------------
# Result and entry points
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class IdentificationResult:
    """What :func:`identify` found.

    Attributes
    ----------
    params : ModelParams
        The identified parameter set (known values ``m, l_f, l_r, h_c, l_t, mu, g`` passed through),
        with its :class:`~racing_lib.model.PedalMap`.
    steer_tau : float
        Identified time constant of the steering actuator, s (not part of the planning model; the
        controller may compensate it).
    fits : dict of FitStats
        Residuals, R^2 and conditioning of each regression.
    rows : list of dict
        The report table: ``name, unit, fitted, true, error_pct, fit, manoeuvre`` per value.
    notes : tuple of str
        Findings worth reading (e.g. whether the car has engine braking at pedal 0).
    n_samples : int
        Control periods in the logs.
    elapsed : float
        Wall time of the identification, s.
    steer_rate_max : float
        Identified rate limit of the steering actuator, rad/s (``inf``: none seen; ``nan``: no
        steering-rate manoeuvre in the logs).
    steer_max : float or None
        The data sheet's steering-angle limit, rad (passed through; None: not given).
    v_top : float
        Top speed reached at full throttle, m/s (``nan``: no full-throttle manoeuvre).
    v_top_governed : bool
        The car stopped accelerating at ``v_top`` (a governed top speed, which plans must keep
        below), rather than the run ending while it still gained speed.
    braking_stable : bool or None
        Whether a small yaw died out when the car braked with the steering held (the
        braking-stability manoeuvre; None: not in the logs). A car that diverged gets plans
        that keep the model's lateral dynamics stable (:meth:`car_model`).
    stability_margin : float or None
        For a car that diverged: by how much faster it diverged than the model predicted, 1/s.
        Its plans keep the model's lateral dynamics stable, with no eigenvalue between minus
        this margin and zero unless both are (:attr:`racing_lib.model.CarModel.lateral_stability`).
    braking_growth : tuple of float
        The yaw's growth rate in the braking-stability run, measured and as the identified model
        predicts it over the same samples, 1/s (NaN without the run).
    grip_uncertainty : float
        How far the identified model's lateral acceleration may be from the car's: 99 % of its
        predictions on the samples of circles, steps and laps (which the tyre fit left out)
        lie within this share of its peak lateral acceleration (-; NaN: not measured). It is the
        grip margin of the plans (:meth:`car_model`).
    grip_samples : int
        The samples ``grip_uncertainty`` was measured on.
    """

    params: ModelParams
    steer_tau: float
    fits: dict[str, FitStats]
    rows: list[dict[str, Any]] = field(default_factory=list)
    notes: tuple[str, ...] = ()
    n_samples: int = 0
    elapsed: float = 0.0
    steer_rate_max: float = math.nan
    steer_max: float | None = None
    v_top: float = math.nan
    v_top_governed: bool = False
    braking_stable: bool | None = None
    stability_margin: float | None = None
    braking_growth: tuple[float, float] = (math.nan, math.nan)
    grip_uncertainty: float = math.nan
    grip_samples: int = 0

    @property
    def success(self) -> bool:
        """Whether every sub-model explains its data: R^2 >= :data:`R2_FLOOR` (NaN: not judged).

        The fits that cannot determine a parameter raise instead (:class:`ModelError`); this is
        the quality of those that ran, on the data each was fitted to. Held-out scores are
        reported, not judged: their R^2 depends on how much the held-out blocks happen to vary
        (a block of coasting barely does, and a small residual then gives a small R^2).
        """
        return not self.poor_fits()

    def poor_fits(self) -> list[str]:
        """The sub-models whose R^2 is below :data:`R2_FLOOR`, by fit name."""
        return [
            k
            for k, f in self.fits.items()
            if "held out" not in k and math.isfinite(f.r2) and f.r2 < R2_FLOOR
        ]

    @property
    def grip_margin(self) -> float:
        """The share of friction the identified car's plans leave unused (-).

        The identified :attr:`grip_uncertainty`: what the model cannot promise, the plan does not
        ask for. It is capped at :data:`MAX_GRIP_MARGIN` (the report then says the model is too
        uncertain to plan with); logs without samples to measure it (never the case for an
        identification that fitted the tyres) fall back to :data:`~racing_lib.model.GRIP_MARGIN`.
        """
        share = self.grip_uncertainty
        return min(share, MAX_GRIP_MARGIN) if math.isfinite(share) else GRIP_MARGIN

    def car_model(
        self,
        grip_margin: float | None = None,
        # Any: forwarded to CarModel, whose fields have different types.
        **fields: Any,
    ) -> CarModel:
        """The identified car as a model to plan and race with: parameters and steering lag.

        Parameters
        ----------
        grip_margin : float, optional
            Share of the identified friction the planner leaves unused (default: the identified
            :attr:`grip_margin`, from the model's lateral-acceleration error).
        **fields
            Other :class:`~racing_lib.model.CarModel` fields (options, edge margin); steering
            limits given here replace the identified ones.

        Notes
        -----
        The steering actuator is the identified one: its lag ``steer_tau`` (s), its rate limit
        ``steer_rate_max`` (rad/s) when the steering-rate manoeuvre found one, and the data
        sheet's angle limit ``steer_max`` (rad) when it was given to :func:`identify`; the top
        speed ``v_top`` (m/s) where the full-throttle run found a governed one; laterally stable
        plans (``lateral_stability``) for a car that diverged in yaw when it braked with the
        steering held; a grip margin from the model's measured error. What was not identified
        keeps :class:`~racing_lib.model.CarModel`'s default (the edge margin: how far the car
        strays from its line is the controller's, measured on laps, not the model's).
        """
        actuator: dict[str, Any] = {"steer_tau": self.steer_tau}
        if math.isfinite(self.steer_rate_max):
            actuator["steer_rate_max"] = self.steer_rate_max
        if self.steer_max is not None:
            actuator["steer_max"] = self.steer_max
        if self.v_top_governed and math.isfinite(self.v_top):
            actuator["v_top"] = self.v_top
        if self.braking_stable is False and self.stability_margin is not None:
            actuator["lateral_stability"] = self.stability_margin
        margin = self.grip_margin if grip_margin is None else grip_margin
        return CarModel(self.params, grip_margin=margin, **(actuator | fields))

    def value(self, name: str) -> float:
        """A fitted value by its report name (e.g. ``"C_xw"``, ``"mu*D_f"``, ``"C_alpha_r"``)."""
        for row in self.rows:
            if row["name"] == name:
                return float(row["fitted"])
        raise ModelError(f"no identified value {name!r}; known: {[r['name'] for r in self.rows]}.")

    def errors(self) -> dict[str, float]:
        """Relative error ``fitted / true - 1`` of every value that has a true counterpart."""
        return {
            r["name"]: r["fitted"] / r["true"] - 1.0
            for r in self.rows
            if r["true"] is not None and r["true"] != 0.0
        }

    def within_tolerance(self, tolerances: dict[str, float] | None = None) -> dict[str, bool]:
        """Per toleranced value (default :data:`TOLERANCES`): ``|fitted/true - 1| <= tol``."""
        tol = TOLERANCES if tolerances is None else tolerances
        err = self.errors()
        missing = sorted(set(tol) - set(err))
        if missing:
            raise ModelError(
                f"no true value for {missing}: pass truth=VehicleParams(...) or "
                "truth=ModelParams(...) to identify()."
            )
        return {k: abs(err[k]) <= t for k, t in tol.items()}

    def report(self) -> str:
        """The fitted-vs-true table and the fit statistics as aligned text."""
        head = ("value", "unit", "fitted", "true", "error", "from")
        lines = []
        for r in self.rows:
            true = "-" if r["true"] is None else f"{r['true']:.5g}"
            err = "-" if r["error_pct"] is None else f"{r['error_pct']:+.1f} %"
            lines.append((r["name"], r["unit"], f"{r['fitted']:.5g}", true, err, r["manoeuvre"]))
        widths = [max(len(x[i]) for x in [head, *lines]) for i in range(len(head))]
        fmt = "  ".join(f"{{:<{w}}}" for w in widths)
        out = [fmt.format(*head), fmt.format(*("-" * w for w in widths))]
        out += [fmt.format(*x) for x in lines]
        out.append("")
        fhead = ("fit", "samples", "RMS residual", "R^2", "cond")
        flines = [
            (f.name, str(f.n), f"{f.rms:.4g} {f.unit}", f"{f.r2:.4f}", f"{f.cond:.3g}")
            for f in self.fits.values()
        ]
        fw = [max(len(x[i]) for x in [fhead, *flines]) for i in range(len(fhead))]
        ffmt = "  ".join(f"{{:<{w}}}" for w in fw)
        out += [ffmt.format(*fhead), ffmt.format(*("-" * w for w in fw))]
        out += [ffmt.format(*x) for x in flines]
        out += ["", self._verdict(), self._grip_text()]
        out += ["", *(f"note: {n}" for n in self.notes)]
        out.append(f"{self.n_samples} control periods, identified in {self.elapsed:.1f} s.")
        return "\n".join(out)

    def _verdict(self) -> str:
        """The report's quality section: success, and the sub-models that fit poorly."""
        poor = self.poor_fits()
        if not poor:
            return (
                f"success: every sub-model explains its data (R^2 >= {R2_FLOOR:g} each; "
                "a NaN R^2 is a fit with nothing to explain, e.g. a car without drag)"
            )
        worst = ", ".join(f"{k} (R^2 {self.fits[k].r2:.3f})" for k in poor)
        return f"NO success: sub-models below R^2 {R2_FLOOR:g}: {worst}"

    def _grip_text(self) -> str:
        """The report's line on the grip margin and where it comes from."""
        share = self.grip_uncertainty
        if not math.isfinite(share):
            return (
                f"grip margin: {self.grip_margin:.1%}, the default ({self.grip_samples} samples "
                "of circles, steps or laps to measure it)"
            )
        measured = (
            f"the model's lateral-acceleration error that {GRIP_QUANTILE:.0%} of its "
            f"predictions on {self.grip_samples} samples of circles, steps and laps stay within, "
            "as a share of its peak"
        )
        if share > MAX_GRIP_MARGIN:
            return (
                f"grip margin: capped at {self.grip_margin:.0%}; {measured}, is {share:.0%}: a "
                "model this uncertain is not one to plan with. Look for slides or wall contacts "
                "in the laps, or drive the full manoeuvre set (collect_logs(fast=False))"
            )
        return f"grip margin: {self.grip_margin:.1%}, {measured}"

    def to_dict(self) -> IdentificationRecord:
        """JSON-ready summary (parameters, steering lag, table, fit statistics, grip error)."""
        return {
            "model_params": self.params.to_dict(),
            "steer_tau": self.steer_tau,
            "rows": self.rows,
            "fits": {k: dict(vars(v)) for k, v in self.fits.items()},
            "notes": list(self.notes),
            "n_samples": self.n_samples,
            "grip_uncertainty": jsonable(self.grip_uncertainty),
            "grip_samples": self.grip_samples,
        }


def identify(
    logs: Sequence[Drive],
    known: ModelParams | None = None,
    truth: VehicleParams | ModelParams | None = None,
    derivative: Derivative = "interval",
    fit_steer_lag: bool = True,
    steer_max: float | None = None,
) -> IdentificationResult:
    """Identify the planning model's parameters from driving logs.

    Parameters
    ----------
    logs : sequence of Drive
        Logs of the manoeuvres in :data:`MANOEUVRES` (see :func:`collect_logs`).
    known : ModelParams, optional
        Supplies the values taken as known: ``m, l_f, l_r, h_c, l_t, mu, g`` (default: the paper's
        table, ``ModelParams()``).
    truth : VehicleParams or ModelParams, optional
        The true car, only for the report's "true" column.
    derivative : {"interval", "savgol"}
        How derivatives are taken (see the module docstring).
    fit_steer_lag : bool
        Identify a first-order steering-actuator lag with the lateral parameters (recommended:
        otherwise the lag is mistaken for yaw inertia).
    steer_max : float, optional
        The data sheet's steering-angle limit, rad, passed through to
        :meth:`IdentificationResult.car_model` (default: ``known.steer_max`` if it has one).

    Returns
    -------
    IdentificationResult

    Raises
    ------
    ModelError
        Logs too short, or lacking the excitation some parameter needs (the message names the
        parameter and the manoeuvre to add).
    """
    t0 = time.perf_counter()
    kp = ModelParams() if known is None else known
    if not isinstance(kp, ModelParams):
        raise ModelError(f"known must be a ModelParams; got {type(kp).__name__}.")
    S = _checked_samples(logs, derivative)
    fitted, tyres, fits, notes = _fit_all(kp, S, fit_steer_lag)
    fitted, limits = _fit_limits(fitted, S, tyres, fits, notes)
    rows = _report_rows(fitted, tyres, fits, truth, limits)
    grip, n_grip = _grip_uncertainty(fitted, S, tyres["steer_tau"])
    sheet_steer = steer_max if steer_max is not None else getattr(kp, "steer_max", None)
    return IdentificationResult(
        params=fitted,
        steer_tau=tyres["steer_tau"],
        fits=fits,
        rows=rows,
        notes=tuple(notes),
        n_samples=int(S.vx.size),
        elapsed=time.perf_counter() - t0,
        steer_rate_max=limits["steer_rate_max"],
        steer_max=None if sheet_steer is None else float(sheet_steer),
        v_top=limits["top speed"],
        v_top_governed=bool(limits["top speed governed"]),
        braking_stable=limits["braking stable"],
        stability_margin=limits["stability margin"],
        braking_growth=limits["braking growth"],
        grip_uncertainty=grip,
        grip_samples=n_grip,
    )


def _checked_samples(logs: Sequence[Drive], derivative: Derivative) -> _Samples:
    """The fitting samples of ``logs`` (derivatives taken as ``derivative`` says), checked.

    Raises
    ------
    ModelError
        If an entry is not a :class:`~racing_lib.model.Drive` or the logs are too short.
    """
    logs = list(logs)
    bad = [type(x).__name__ for x in logs if not isinstance(x, Drive)]
    if bad:
        raise ModelError(
            f"identify() takes racing_lib.model.Drive objects; got {sorted(set(bad))}."
        )
    S = _samples(logs, derivative)
    if S.vx.size < 10 * _MIN_SAMPLES:
        raise ModelError(
            f"the logs are too short: {S.vx.size} control periods ({S.vx.size * 0.1:.0f} s) in "
            f"logs of >= 8 periods, need >= {10 * _MIN_SAMPLES}. Record the manoeuvres "
            f"{sorted(MANOEUVRES)} (racing_lib.experiments.sysid.collect_logs())."
        )
    return S


def _fit_all(
    kp: ModelParams, S: _Samples, fit_steer_lag: bool
) -> tuple[ModelParams, dict[str, float], dict[str, Any], list[str]]:
    """The four identification steps of the module docstring, in order, each using the ones before.

    Parameters
    ----------
    kp : ModelParams
        The values taken as known (mass in kg, geometry in m, mu, g in m/s^2).
    S : _Samples
        The fitting samples.
    fit_steer_lag : bool
        Identify a first-order steering lag (s) with the lateral parameters.

    Returns
    -------
    fitted : ModelParams
        The identified parameter set (tyres, resistances, pedal map).
    tyres : dict
        The lateral fit's values, ``steer_tau`` (s) included.
    fits : dict
        The quality of each fit, by name.
    notes : list of str
        What the coast-down and brake-limit fits report.
    """
    tyres, fits = _fit_lateral(kp, S, fit_steer_lag)
    fyf_sin = _front_force_sin(kp, S, tyres)
    resist, f2 = _fit_coast_down(kp, S, fyf_sin)
    notes = [str(resist.pop("note"))]
    fits |= f2
    fitted = kp.replace(**{k: v for k, v in tyres.items() if k != "steer_tau"}, **resist)
    pedal, f3 = _fit_pedal(fitted, S, fyf_sin)
    fits |= f3
    a_brk_max, brake_max, brake_note = _fit_brake_limit(fitted, S, fyf_sin)
    notes.append(brake_note)
    if brake_max < 1.0:
        # The wheels lock beyond brake_max: braking is linear up to there (the map's slope
        # m_brk), and the controller never brakes deeper. A knee towards a_brk_max would make
        # the map ask for deeper pedals than the car holds.
        pedal = dataclasses.replace(pedal, brake_max=brake_max)
        notes.append(
            f"the wheels lock beyond pedal -{brake_max:.2f}: the map ends there "
            f"({pedal.full_brake():.2f} m/s^2 at pedal -{brake_max:.2f})"
        )
    else:
        pedal = dataclasses.replace(pedal, a_brk_max=a_brk_max)
    fitted = fitted.replace(pedal=pedal)
    return fitted, tyres, fits, notes


def _fit_limits(
    fitted: ModelParams,
    S: _Samples,
    tyres: dict[str, float],
    fits: dict[str, Any],
    notes: list[str],
) -> tuple[ModelParams, dict[str, float]]:
    """Step 5: the actuators' limits (steering rate, power, top speed), after the model's fits.

    Their manoeuvres feed no other fit. The full-throttle run's power limit enters the pedal map
    when the map's own fit found none (its laps and steps never ran out of power) or a larger
    one; the braking-stability run says whether plans must keep the lateral dynamics stable.

    Parameters
    ----------
    fitted : ModelParams
        The identified parameters so far.
    S : _Samples
        All samples.
    tyres : dict
        The lateral fit's values (``steer_tau`` in s).
    fits, notes : dict, list
        Extended in place with these fits' quality and findings.

    Returns
    -------
    fitted : ModelParams
        With the power limit, if it was missing.
    limits : dict
        ``steer_rate_max`` (rad/s), ``p_thr (full throttle)`` (W/kg), ``top speed`` (m/s),
        ``top speed governed``, ``braking stable`` (bool, None without the run) and
        ``stability margin`` (1/s, None for a stable car) and ``braking growth`` (measured and
        model growth rates, 1/s).
    """
    rate, rate_stats, note = _fit_steer_rate(fitted, S, tyres)
    notes.append(note)
    if rate_stats is not None:
        fits[rate_stats.name] = rate_stats
    full, full_stats, note = _fit_full_throttle(fitted, S, _front_force_sin(fitted, S, tyres))
    notes.append(note)
    if full_stats is not None:
        fits[full_stats.name] = full_stats
    # Both are power per mass at full throttle: the map's hyperbola (its gain p_thr / v on top of
    # the pedal-free m_0 + m_vx v, a few tenths of m/s^2) and the run's measured a_x v.
    measured = full["p_thr"]
    if math.isfinite(measured) and (fitted.pedal.p_thr is None or measured < fitted.pedal.p_thr):
        # The full-throttle run measures the power directly; the map's fit only infers it from
        # partial throttle through the map's form (pedal times a capped gain). A car whose
        # partial throttle is not that form (CommonRoad's: min(pedal a_max, P / v)) gets a map
        # that promises more power than full throttle gave (114 against 82 W/kg for the BMW),
        # and a plan whose straights the car cannot drive (2-4 m/s short at their ends).
        if fitted.pedal.p_thr is not None:
            notes.append(
                f"the pedal map's power limit, {fitted.pedal.p_thr:.1f} W/kg, is more than full "
                f"throttle gave ({measured:.1f} W/kg): the map keeps the measured one"
            )
        else:
            notes.append("the pedal map's power limit is the full-throttle run's")
        fitted = fitted.replace(pedal=dataclasses.replace(fitted.pedal, p_thr=measured))
    stability, note = _fit_braking_stability(fitted, ModelOptions(), S)
    notes.append(note)
    return fitted, {
        "braking stable": stability["stable"],
        "stability margin": stability["margin"],
        "braking growth": (stability["growth"], stability["model_growth"]),
        "steer_rate_max": rate,
        "p_thr (full throttle)": full["p_thr"],
        "top speed": full["v_top"],
        "top speed governed": full["governed"],
    }


def run(seed: int = 0, fast: bool | None = None, out: str | None = None) -> IdentificationResult:
    """Collect logs with the built-in car, identify, and write the JSON parameter file.

    Parameters
    ----------
    seed : int
        Seed of the data collection (the shipped file uses 0; tests use other seeds).
    fast : bool, optional
        Less data (default: :func:`racing_lib.config.fast_mode`).
    out : str, optional
        Output path (default: the package's ``data/identified_params.json``); ``""`` writes nothing.
    """
    t0 = time.perf_counter()
    logs = collect_logs(seed=seed, fast=fast)
    t_collect = time.perf_counter() - t0
    result = identify(logs, truth=VehicleParams())
    if out != "":
        target = FsPath(out) if out else shipped_fit_path()
        payload = result.to_dict() | {
            "seed": seed,
            "fast": fast_mode() if fast is None else fast,
            "collect_time_s": round(t_collect, 2),
            "fit_time_s": round(result.elapsed, 2),
            "generated_by": "python -m racing_lib.experiments.sysid",
            # The car the data came from: a changed VehicleParams means this file is stale.
            "vehicle_params": dataclasses.asdict(VehicleParams()),
        }
        atomic_write_json(target, payload)
    return result


def main(argv: Sequence[str] | None = None) -> int:
    """Regenerate the shipped identified parameters (the command line).

    ``python -m racing_lib.experiments.sysid [--seed S] [--fast] [--out FILE]``: regenerate the
    JSON file.
    """
    ap = argparse.ArgumentParser(
        prog="python -m racing_lib.experiments.sysid", description=main.__doc__
    )
    ap.add_argument("--seed", type=int, default=0, help="data-collection seed (default 0)")
    ap.add_argument("--fast", action="store_true", help="collect less data")
    ap.add_argument("--out", default=None, help="output JSON (default: the package's data file)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    result = run(seed=args.seed, fast=True if args.fast else None, out=args.out)
    print(result.report())
    print(f"total (collection + fit): {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0
