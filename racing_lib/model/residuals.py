"""What the model gets wrong on a logged lap, and a correction learned from it (chapter 09).

:func:`residual_samples` replays a recorded drive one control period at a time: from every
measured state it predicts the next with the model and the commands that were sent, and keeps
the difference of ``v_x``, ``v_y`` and ``r`` per second (the *residual accelerations*) with the
features the correction is a function of (:data:`racing_lib.model.correction.FEATURES`).
:func:`fit_correction` fits one sparse GP per residual; :func:`one_step_errors` measures a model's
one-period prediction error on drives it was not fitted on.

The residual is always taken against the model *without* its correction (the identified one), so
that each fit explains all the data so far instead of stacking corrections on corrections.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from racing_lib.errors import ModelError
from racing_lib.geometry import Track
from racing_lib.model.actuator import lagged_steering
from racing_lib.model.car_model import CarModel
from racing_lib.model.correction import CORRECTED, ModelCorrection
from racing_lib.model.drive import Drive
from racing_lib.model.equations import jacobians, model_terms
from racing_lib.model.gp import fit_sparse_gp
from racing_lib.model.numeric import Model
from racing_lib.model.prediction import frenet_states, predict_open_loop
from racing_lib.model.states import NX, U, X

__all__ = [
    "ResidualSamples",
    "fit_correction",
    "one_step_errors",
    "residual_samples",
    "without_fast_driving",
]

#: Samples below this speed are left out, m/s: the slip angles are ill-defined near standstill.
V_MIN = 5.0


@dataclass(frozen=True)
class ResidualSamples:
    """Residual accelerations of a model on recorded drives, with their features.

    Attributes
    ----------
    features : ndarray (N, 4)
        ``(v_x, alpha_f, alpha_r, a_x)`` at the start of each period (m/s, rad, rad, m/s^2).
    residuals : ndarray (N, 3)
        Measured minus predicted ``(v_x, v_y, r)`` after one period, divided by the period
        (m/s^2, m/s^2, rad/s^2).
    s : ndarray (N,)
        Arc length on the track's centerline at the start of each period, m (for plots along
        the lap).
    """

    features: np.ndarray
    residuals: np.ndarray
    s: np.ndarray

    def __len__(self) -> int:
        return int(self.features.shape[0])

    @staticmethod
    def concatenate(parts: Sequence[ResidualSamples]) -> ResidualSamples:
        """All samples of ``parts`` in one set."""
        if not parts:
            raise ModelError("no residual samples to join: drive at least one lap first.")
        return ResidualSamples(
            np.vstack([p.features for p in parts]),
            np.vstack([p.residuals for p in parts]),
            np.concatenate([p.s for p in parts]),
        )


def _base(model: CarModel) -> CarModel:
    """``model`` without its learned correction."""
    if model.params.correction is None:
        return model
    return model.replace(params=model.params.replace(correction=None))


def _one_step(log: Drive, track: Track, model: CarModel) -> tuple[np.ndarray, ...]:
    """Measured states, one-period predictions, features, model inputs and period of a drive."""
    t = np.asarray(log.t, dtype=float)
    if t.size < 3:
        raise ModelError(
            f"drive {log.name!r} has {t.size} samples; residuals need at least 3 (a lap log)."
        )
    dt = float(np.median(np.diff(t)))
    if not dt > 0.0 or np.any(np.diff(t) <= 0.0):
        raise ModelError(
            f"drive {log.name!r}: its time stamps do not increase; it is not a recorded drive."
        )
    xi = frenet_states(log, track)
    delta = lagged_steering(np.asarray(log.steer, dtype=float), model.steer_tau, dt)
    pedal = np.asarray(log.pedal, dtype=float)
    numeric = Model(model.params, model.options)
    pred = predict_open_loop(numeric, xi[:-1], delta[:-1, None], pedal[:-1, None], track, dt=dt)
    u = np.empty((t.size - 1, 2))
    u[:, U.DELTA] = delta[:-1]
    u[:, U.AX] = model.params.pedal.ax(xi[:-1], pedal[:-1])
    terms = model_terms(model.params, model.options).map(t.size - 1)
    out = terms(xi[:-1].T, u.T, 0.0, 0.0)
    names = model_terms(model.params, model.options).name_out()
    alpha_f = np.asarray(out[names.index("alpha_f")]).ravel()
    alpha_r = np.asarray(out[names.index("alpha_r")]).ravel()
    features = np.column_stack([xi[:-1, X.VX], alpha_f, alpha_r, u[:, U.AX]])
    return xi, pred[1], features, u, dt


def _constant_accelerations(
    model: CarModel,
    xi: np.ndarray,
    u: np.ndarray,
    miss: np.ndarray,
    track: Track,
    dt: float,
) -> np.ndarray:
    """The constant accelerations that, added to the model over a period, explain ``miss``.

    Dividing the miss of ``(v_x, v_y, r)`` by the period would be right only for slow dynamics.
    The lateral modes of a car at speed settle within a period, so the model's own tyre forces
    push back against an added acceleration while it acts: to first order the miss is
    ``Gamma c`` with ``Gamma = int_0^dt exp(A tau) dtau`` (rows and columns of the corrected
    states), ``A`` the model's Jacobian at the period's start. Solving for ``c`` gives the
    correction that reproduces the measured step when it is integrated with the model.
    """
    n = xi.shape[0]
    s = np.mod(xi[:, X.S], float(track.centerline.length))
    kappa = np.asarray(track.centerline.curvature(s), dtype=float)
    theta = np.asarray(track.grade(s), dtype=float)
    jac = jacobians(model.params, model.options, "time").map(n)
    a_all = np.asarray(jac(xi.T, u.T, kappa[None, :], theta[None, :])[0])  # 6 x 6n
    idx = list(CORRECTED)
    out = np.empty_like(miss)
    block = np.zeros((2 * NX, 2 * NX))
    for k in range(n):
        block[:NX, :NX] = a_all[:, NX * k : NX * (k + 1)] * dt
        block[:NX, NX:] = np.eye(NX) * dt
        gamma = expm(block)[:NX, NX:]
        out[k] = np.linalg.solve(gamma[np.ix_(idx, idx)], miss[k])
    return out


def residual_samples(log: Drive, track: Track, model: CarModel) -> ResidualSamples:
    """The residual accelerations of ``model`` (without its correction) along a drive.

    Parameters
    ----------
    log : Drive
        A recorded drive on ``track``, e.g. ``LapResult.log``; periods below :data:`V_MIN`
        are left out.
    track : Track
        The track it was driven on.
    model : CarModel
        The model whose residuals are measured: its parameters, effects and steering lag.

    Returns
    -------
    ResidualSamples

    Raises
    ------
    ModelError
        A log too short, with time stamps that do not increase, or without a period above
        :data:`V_MIN`.
    """
    base = _base(model)
    xi, pred, features, u, dt = _one_step(log, track, base)
    miss = xi[1:, list(CORRECTED)] - pred[:, list(CORRECTED)]
    residuals = _constant_accelerations(base, xi[:-1], u, miss, track, dt)
    keep = (xi[:-1, X.VX] > V_MIN) & np.all(np.isfinite(residuals), axis=1)
    if not np.any(keep):
        raise ModelError(
            f"drive {log.name!r} has no period above {V_MIN} m/s; a correction is learned from "
            "laps at speed."
        )
    s = np.mod(xi[:-1, X.S], float(track.centerline.length))
    return ResidualSamples(features[keep], residuals[keep], s[keep])


def _mirrored(samples: ResidualSamples) -> tuple[np.ndarray, np.ndarray]:
    """The samples and their mirror images: the car is the same turning left or right.

    Mirroring a drive flips the signs of the slip angles, of ``v_y`` and of ``r`` and keeps
    ``v_x`` and ``a_x``. A track turns more one way than the other, so without its mirror image
    the fit can learn a lateral correction that does not vanish on the straight (a car that
    drives crabbed); with it the lateral corrections are odd in the slip angles and the
    longitudinal one even, as they are for a left-right symmetric car.
    """
    flip_f = samples.features.copy()
    flip_f[:, 1:3] *= -1.0
    flip_r = samples.residuals.copy()
    flip_r[:, 1:3] *= -1.0
    return np.vstack([samples.features, flip_f]), np.vstack([samples.residuals, flip_r])


def without_fast_driving(samples: ResidualSamples, below_speed: float) -> ResidualSamples:
    """``samples`` without those where the car drives (``a_x > 0``) at ``below_speed`` or faster.

    The learning loop leaves out the last 2 % below the model's top speed
    (:attr:`racing_lib.experiments.learning.LearnSettings.top_speed_band`). The model caps the
    plans' speed there, while the car's drive fades into its limit: the simulated car's rev
    limiter takes 0.3 m/s^2 off the model's acceleration in that band, and the car spends 14 %
    of an expressway lap in it. A correction fitted on those samples, smooth in the speed,
    spread that loss over the speeds below (0.05-0.13 m/s^2 too little at 44-52 m/s, where the
    car had it), and the plans accelerated down the straights later than the car could.
    Braking samples stay: braking does not fade near the top speed.
    """
    keep = (samples.features[:, 0] < below_speed) | (samples.features[:, 3] <= 0.0)
    return ResidualSamples(samples.features[keep], samples.residuals[keep], samples.s[keep])


def fit_correction(
    samples: ResidualSamples,
    *,
    inducing: int = 40,
    n_hyper: int = 400,
    min_length: float = 1.0,
    seed: int = 0,
    label: str = "",
    below_speed: float | None = None,
) -> ModelCorrection:
    """One sparse GP per residual acceleration, fitted on ``samples``.

    Parameters
    ----------
    samples : ResidualSamples
        From :func:`residual_samples` (joined with :meth:`ResidualSamples.concatenate`).
    inducing : int
        Inducing inputs per GP (:func:`racing_lib.model.gp.fit_sparse_gp`).
    n_hyper : int
        Samples the hyperparameters are fitted on.
    min_length : float
        Shortest length scale, in standard deviations of each feature: a smooth mean keeps the
        MPC's linearization of the corrected model sane between and beyond the laps it saw.
    seed : int
        Seed of the hyperparameters' subset.
    label : str
        Name of the correction.
    below_speed : float, optional
        Leave out the samples where the car drives at this speed or faster, m/s
        (:func:`without_fast_driving`; None: fit all).

    Returns
    -------
    ModelCorrection
    """
    if below_speed is not None:
        samples = without_fast_driving(samples, below_speed)
    if len(samples) < 50:
        slower = "" if below_speed is None else f" (driving slower than {below_speed:g} m/s)"
        raise ModelError(
            f"{len(samples)} residual samples{slower} are too few to learn a correction from; "
            "drive at least one full lap (about 1000 samples at 10 Hz)."
        )
    features, residuals = _mirrored(samples)
    gps = [
        fit_sparse_gp(
            features,
            residuals[:, j],
            inducing=inducing,
            n_hyper=n_hyper,
            seed=seed + j,
            min_length=min_length,
        )
        for j in range(len(CORRECTED))
    ]
    return ModelCorrection(gps, label=label)


def one_step_errors(logs: Sequence[Drive], track: Track, model: CarModel) -> dict[str, float]:
    """RMS one-period prediction error of ``model`` (correction included) on ``logs``.

    Returns
    -------
    dict
        ``{"v_x": m/s^2, "v_y": m/s^2, "r": rad/s^2}``: the RMS over all periods above
        :data:`V_MIN` of (measured - predicted) / period.
    """
    errs = []
    for log in logs:
        xi, pred, _, _, dt = _one_step(log, track, model)
        err = (xi[1:, list(CORRECTED)] - pred[:, list(CORRECTED)]) / dt
        errs.append(err[xi[:-1, X.VX] > V_MIN])
    if not errs:
        raise ModelError("no drives to measure the prediction error on.")
    e = np.vstack(errs)
    return {
        name: float(np.sqrt(np.mean(e[:, j] ** 2))) for j, name in enumerate(("v_x", "v_y", "r"))
    }
