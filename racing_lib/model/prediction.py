"""The planning model's open-loop prediction error against a recorded drive.

Taught in notebook 02 ("the race vehicle model"). How far off is :mod:`racing_lib.model` over a
short horizon? :func:`prediction_errors` replays a recorded drive
(:class:`~racing_lib.model.drive.Drive`): from every recorded state it integrates the model open
loop with the commands that were actually sent, and compares the prediction after 0.5 s, 1 s, ...
with what the car did. Switching model effects off (:class:`~racing_lib.model.ModelOptions`)
shows which of them matter -- the paper's model ablation, measured on prediction instead of lap
time. The model's linear lateral dynamics are in :mod:`racing_lib.model.lateral`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from racing_lib.errors import ModelError
from racing_lib.geometry import Track
from racing_lib.model import Model, ModelOptions, ModelParams, U, X
from racing_lib.model.actuator import lagged_steering
from racing_lib.model.drive import Drive

__all__ = [
    "ABLATION_VARIANTS",
    "ERROR_MEASURES",
    "PredictionError",
    "format_prediction_table",
    "frenet_states",
    "predict_open_loop",
    "prediction_errors",
    "prediction_table",
]


def frenet_states(log: Drive, track: Track) -> np.ndarray:
    """The model state ``xi`` of every observation of ``log`` on ``track``'s centerline.

    Parameters
    ----------
    log : Drive
        A recorded drive.
    track : Track
        The track it was driven on; its centerline is the reference line of ``e_y``, ``e_psi``
        and ``s``.

    Returns
    -------
    ndarray (M, 6)
        Rows ``[v_x, v_y, r, e_psi, e_y, s]`` (m/s, m/s, rad/s, rad, m, m); ``s`` is unwrapped so
        that it grows continuously across the start/finish line.
    """
    path = track.centerline
    x, y, psi = (np.asarray(getattr(log, k), dtype=float) for k in ("x", "y", "psi"))
    s, e_y, e_psi = path.to_frenet(x, y, psi)
    xi = np.empty((x.size, len(X)))
    xi[:, X.VX] = np.asarray(log.vx, dtype=float)
    xi[:, X.VY] = np.asarray(log.vy, dtype=float)
    xi[:, X.R] = np.asarray(log.r, dtype=float)
    xi[:, X.EPSI] = e_psi
    xi[:, X.EY] = e_y
    xi[:, X.S] = np.unwrap(np.asarray(s, dtype=float), period=float(path.length))
    return xi


def predict_open_loop(
    model: Model,
    xi0: np.ndarray,
    steer: np.ndarray,
    pedal: np.ndarray,
    track: Track,
    dt: float = 0.1,
    substeps: int = 4,
) -> np.ndarray:
    """Integrate the model open loop from a batch of states with given command sequences.

    Each control period holds the road-wheel angle and the pedal constant; the pedal becomes the
    tyre acceleration through the model's pedal map (``params.pedal``) at the *predicted* state,
    re-evaluated at every substep. Curvature and road pitch are read from ``track`` at the
    predicted ``s``. Integration: RK4 with ``substeps`` steps per period (the tyre modes are stiff
    at low speed; 4 keeps RK4 stable down to about 8 m/s for the default car).

    Parameters
    ----------
    model : Model
        The model to predict with.
    xi0 : ndarray (N, 6)
        Initial states, one per row.
    steer : ndarray (N, H)
        Road-wheel steering angle of each period, rad.
    pedal : ndarray (N, H)
        Pedal of each period, -.
    track : Track
        Supplies ``kappa(s)`` of the centerline and the grade ``theta(s)``.
    dt : float
        Control period, s.
    substeps : int
        RK4 steps per period.

    Returns
    -------
    ndarray (H + 1, N, 6)
        Predicted states at ``t = 0, dt, ..., H dt``.
    """
    xi = np.array(xi0, dtype=float, ndmin=2)
    steer = np.array(steer, dtype=float, ndmin=2)
    pedal = np.array(pedal, dtype=float, ndmin=2)
    if steer.shape != pedal.shape or steer.shape[0] != xi.shape[0]:
        raise ModelError(
            f"steer {steer.shape} and pedal {pedal.shape} must both be (N, H) with N = "
            f"{xi.shape[0]} rows, one per initial state."
        )
    if int(substeps) < 1:
        raise ModelError(f"substeps must be a positive integer, got {substeps!r}.")
    path = track.centerline
    length = float(path.length)
    h = float(dt) / int(substeps)
    out = [xi.copy()]
    u = np.empty((xi.shape[0], 2))
    for j in range(steer.shape[1]):
        u[:, U.DELTA] = steer[:, j]
        for _ in range(int(substeps)):
            s = xi[:, X.S] % length
            u[:, U.AX] = model.params.pedal.ax(xi, pedal[:, j])
            kappa = np.asarray(path.curvature(s), dtype=float)
            theta = np.asarray(track.grade(s), dtype=float)
            xi = np.atleast_2d(model.step(xi, u, h, kappa=kappa, theta=theta))
        out.append(xi.copy())
    return np.stack(out)


#: Error measures reported by :func:`prediction_errors`: name -> (description, unit).
ERROR_MEASURES: dict[str, tuple[str, str]] = {
    "v_x": ("longitudinal speed", "m/s"),
    "v_y": ("lateral speed", "m/s"),
    "r": ("yaw rate", "rad/s"),
    "e_psi": ("heading", "rad"),
    "position": ("position (hypot of the s and e_y errors)", "m"),
}


@dataclass(frozen=True)
class PredictionError:
    """Open-loop prediction error of one model variant on one recorded drive.

    Attributes
    ----------
    label : str
        Name of the variant (e.g. ``"no drag"``).
    options : ModelOptions
        Model effects of the variant.
    horizons : tuple of float
        Prediction horizons, s.
    rms : dict of str -> ndarray (n_horizons,)
        RMS error at each horizon, per measure of :data:`ERROR_MEASURES`, in its unit.
    errors : dict of str -> ndarray (n_windows, n_horizons)
        Absolute error of every window at each horizon, per measure, in its unit.
    starts : ndarray (n_windows,)
        Index of the observation each window starts from.
    s_start : ndarray (n_windows,)
        Arc length of the start points on the track centerline, m, in [0, length).
    """

    label: str
    options: ModelOptions
    horizons: tuple[float, ...]
    rms: dict[str, np.ndarray] = field(default_factory=dict)
    errors: dict[str, np.ndarray] = field(default_factory=dict)
    starts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    s_start: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_windows(self) -> int:
        """Number of prediction windows (start points) averaged over."""
        return int(self.starts.size)

    def _column(self, measure: str, horizon: float) -> int:
        if measure not in self.rms:
            raise ModelError(f"unknown measure {measure!r}; known: {sorted(self.rms)}.")
        for i, hz in enumerate(self.horizons):
            if abs(hz - horizon) < 1e-9:
                return i
        raise ModelError(f"no horizon {horizon} s; computed: {list(self.horizons)}.")

    def at(self, measure: str, horizon: float) -> float:
        """RMS error of ``measure`` at ``horizon`` (s), in the measure's unit."""
        return float(self.rms[measure][self._column(measure, horizon)])

    def rms_over(self, measure: str, horizon: float, windows: np.ndarray) -> float:
        """RMS error of ``measure`` at ``horizon`` (s) over some windows only (a boolean mask).

        ``windows`` has one entry per window (:attr:`starts`), e.g. ``log.pedal[starts] < 0`` for
        the windows that start under braking. NaN when it selects none.
        """
        col = self.errors[measure][:, self._column(measure, horizon)]
        chosen = col[np.asarray(windows, dtype=bool)]
        return float(np.sqrt(np.mean(chosen**2))) if chosen.size else float("nan")

    def percentile(self, measure: str, horizon: float, q: float) -> float:
        """The ``q``-th percentile (0-100) of the absolute error of ``measure`` at ``horizon``."""
        return float(np.percentile(self.errors[measure][:, self._column(measure, horizon)], q))

    def fraction_above(self, measure: str, horizon: float, threshold: float) -> float:
        """Share of the windows whose ``measure`` error at ``horizon`` exceeds ``threshold``, 0-1.

        Share of the windows whose absolute error of ``measure`` at ``horizon`` exceeds
        ``threshold`` (in the measure's unit), 0-1.
        """
        col = self.errors[measure][:, self._column(measure, horizon)]
        return float(np.mean(col > threshold))


def _horizon_steps(horizons: Sequence[float], dt: float) -> list[int]:
    steps = []
    for hz in horizons:
        k = int(round(float(hz) / dt))
        if k < 1 or abs(k * dt - float(hz)) > 1e-6:
            raise ModelError(
                f"each horizon must be a positive multiple of the control period {dt} s; "
                f"got {hz!r}."
            )
        steps.append(k)
    return steps


def prediction_errors(
    log: Drive,
    track: Track,
    params: ModelParams,
    options: ModelOptions | None = None,
    horizons: Sequence[float] = (0.5, 1.0),
    *,
    label: str | None = None,
    steer_tau: float = 0.0,
    stride: int = 1,
    v_min: float = 5.0,
    dt: float | None = None,
    substeps: int = 4,
) -> PredictionError:
    """Open-loop prediction error of the model against a recorded drive.

    From every ``stride``-th observation ``k`` (whose window stays above ``v_min``), the model
    starts at the measured state ``xi_k`` (:func:`frenet_states`) and is driven open loop by the
    recorded commands ``k, k+1, ...`` (:func:`predict_open_loop`); after each horizon ``T`` the
    prediction is compared with the measured state at ``t_k + T``. Nothing is re-fitted: this is
    how far the model, as a planner or an MPC would use it, drifts from the car. Taught in
    notebook 02.

    Parameters
    ----------
    log : Drive
        The drive (e.g. ``LapResult.log`` or a manoeuvre of ``sysid.collect_logs``). It should
        contain no wall contact: the model knows no walls.
    track : Track
        The track it was driven on.
    params : ModelParams
        Model parameters (e.g. :func:`racing_lib.model.identified.identified_params`).
    options : ModelOptions, optional
        Model effects (default ``ModelOptions()``).
    horizons : sequence of float
        Prediction horizons, s, multiples of the control period.
    label : str, optional
        Name of the variant (default: ``options.label()``).
    steer_tau : float
        Time constant of the steering actuator, s: commands become road-wheel angles through
        :func:`racing_lib.model.actuator.lagged_steering` (0: the command is the angle).
    stride : int
        Use every ``stride``-th observation as a start point.
    v_min : float
        Skip windows in which the measured ``v_x`` drops below this, m/s.
    dt : float, optional
        Control period, s (default: from the log's time stamps).
    substeps : int
        RK4 steps per control period.

    Returns
    -------
    PredictionError
        RMS errors of ``v_x``, ``v_y``, ``r``, ``e_psi`` and position at each horizon.

    Raises
    ------
    ModelError
        Inconsistent log arrays, bad horizons, or no usable window.
    """
    options = ModelOptions() if options is None else options
    t = np.asarray(log.t, dtype=float)
    steer_cmd = np.asarray(log.steer, dtype=float)
    pedal = np.asarray(log.pedal, dtype=float)
    if not steer_cmd.size == pedal.size == t.size:
        raise ModelError(
            f"the log has {t.size} observations, {steer_cmd.size} steering and {pedal.size} "
            "pedal commands; a Drive has one of each per sample (the command sent after the "
            "observation)."
        )
    if dt is None:
        dt = float(np.median(np.diff(t))) if t.size > 1 else 0.1
    steps = _horizon_steps(horizons, dt)
    h_max = max(steps)
    xi_meas = frenet_states(log, track)
    delta = lagged_steering(steer_cmd, steer_tau, dt)

    # Start points whose whole window lies within the observations and above v_min.
    last_start = t.size - 1 - h_max
    if last_start < 0:
        raise ModelError(
            f"the log ({t.size} observations) is shorter than the longest horizon "
            f"({h_max} periods)."
        )
    starts = np.arange(0, last_start + 1, max(int(stride), 1))
    vx = xi_meas[:, X.VX]
    ok = np.array([vx[k : k + h_max + 1].min() >= v_min for k in starts], dtype=bool)
    starts = starts[ok]
    if starts.size == 0:
        raise ModelError(
            f"no prediction window of {h_max * dt:.1f} s stays above v_min = {v_min} m/s; "
            "use a log of faster driving or lower v_min."
        )
    window = starts[:, None] + np.arange(h_max)[None, :]
    pred = predict_open_loop(
        Model(params, options),
        xi_meas[starts],
        delta[window],
        pedal[window],
        track,
        dt=dt,
        substeps=substeps,
    )
    errors: dict[str, list[np.ndarray]] = {name: [] for name in ERROR_MEASURES}
    for k in steps:
        err = pred[k] - xi_meas[starts + k]
        errors["v_x"].append(np.abs(err[:, X.VX]))
        errors["v_y"].append(np.abs(err[:, X.VY]))
        errors["r"].append(np.abs(err[:, X.R]))
        errors["e_psi"].append(np.abs((err[:, X.EPSI] + math.pi) % (2.0 * math.pi) - math.pi))
        errors["position"].append(np.hypot(err[:, X.S], err[:, X.EY]))
    table = {name: np.column_stack(cols) for name, cols in errors.items()}
    return PredictionError(
        label=options.label() if label is None else label,
        options=options,
        horizons=tuple(float(hz) for hz in horizons),
        rms={name: np.sqrt(np.mean(e**2, axis=0)) for name, e in table.items()},
        errors=table,
        starts=starts,
        s_start=xi_meas[starts, X.S] % float(track.centerline.length),
    )


#: The paper's model ablation as prediction variants: label -> options.
ABLATION_VARIANTS: dict[str, ModelOptions] = {
    "full model (drag + lon. transfer)": ModelOptions(),
    "no drag": ModelOptions(drag=False),
    "no longitudinal transfer": ModelOptions(longitudinal_weight_transfer=False),
    "with lateral transfer": ModelOptions(lateral_weight_transfer=True),
}


def prediction_table(
    log: Drive,
    track: Track,
    params: ModelParams,
    variants: Mapping[str, ModelOptions] | None = None,
    horizons: Sequence[float] = (0.5, 1.0),
    **kwargs: int | float | None,
) -> list[PredictionError]:
    """:func:`prediction_errors` for several model variants on the same drive.

    Parameters
    ----------
    log, track, params, horizons
        As for :func:`prediction_errors`.
    variants : mapping of label -> ModelOptions, optional
        Default :data:`ABLATION_VARIANTS` (the paper's ablation: the full model, no drag, no
        longitudinal load transfer, with lateral load transfer).
    **kwargs
        Passed on to :func:`prediction_errors` (``steer_tau``, ``stride``, ...).

    Returns
    -------
    list of PredictionError
        One per variant, in order. Format with :func:`format_prediction_table`.
    """
    variants = ABLATION_VARIANTS if variants is None else variants
    return [
        prediction_errors(log, track, params, opts, horizons, label=label, **kwargs)
        for label, opts in variants.items()
    ]


def format_prediction_table(
    rows: Sequence[PredictionError],
    measures: Sequence[str] = ("v_x", "r", "position"),
    digits: int = 2,
    scale: Mapping[str, tuple[float, str]] | None = None,
) -> str:
    """A prediction table as aligned text: one row per variant, one column per measure and horizon.

    Parameters
    ----------
    rows : sequence of PredictionError
        From :func:`prediction_table`.
    measures : sequence of str
        Keys of :data:`ERROR_MEASURES` to show.
    digits : int
        Decimals printed (round coarsely for text that must be stable across machines).
    scale : mapping of measure -> (factor, unit), optional
        Display conversions, e.g. ``{"r": (180 / pi, "deg/s")}``.
    """
    if not rows:
        raise ModelError("format_prediction_table needs at least one PredictionError.")
    scale = dict(scale or {})
    horizons = rows[0].horizons
    heads = []
    for m in measures:
        unit = scale.get(m, (1.0, ERROR_MEASURES[m][1]))[1]
        heads += [f"{m} @{hz:g}s [{unit}]" for hz in horizons]
    width = max(len(r.label) for r in rows)
    cols = [max(len(h), digits + 4) for h in heads]
    lines = ["  ".join([" " * width, *(h.rjust(w) for h, w in zip(heads, cols, strict=True))])]
    for r in rows:
        cells = []
        for m in measures:
            factor = scale.get(m, (1.0, ""))[0]
            cells += [f"{factor * r.at(m, hz):.{digits}f}" for hz in horizons]
        lines.append(
            "  ".join(
                [r.label.ljust(width), *(c.rjust(w) for c, w in zip(cells, cols, strict=True))]
            )
        )
    return "\n".join(lines)
