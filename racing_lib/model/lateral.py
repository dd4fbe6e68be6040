"""The planning model's linear lateral dynamics: how the car responds to steering, across speed.

Taught in notebook 02 ("the race vehicle model"). Around straight driving at a constant speed
``v_x`` the lateral states ``[v_y, r]`` of :mod:`racing_lib.model` obey a linear, second-order
system driven by the steering angle ``delta``. :func:`lateral_linearization` takes it from the
model's exact Jacobians (so it is the model's own linearization, not a second derivation) and
returns a python-control state-space system; :func:`lateral_analysis` sweeps it over speed:
eigenvalues, natural frequency, damping, the steady-state yaw-rate gain and the understeer
gradient. The classic hand result for the same system (a linear "bicycle" with the axles'
cornering stiffnesses ``C_f``, ``C_r``) is what ``tests/test_analysis.py`` checks it against.
The model's open-loop prediction error is in :mod:`racing_lib.model.prediction`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import control
import numpy as np

from racing_lib.errors import ModelError
from racing_lib.model import Model, ModelOptions, ModelParams, U, X, jacobians

__all__ = [
    "LateralAnalysis",
    "lateral_analysis",
    "lateral_growth",
    "lateral_linearization",
    "understeer_gradient",
]

#: States of the lateral system, in order.
LATERAL_STATES = ("v_y", "r")
#: Outputs of the lateral system, in order: the states and the lateral acceleration of the CoG.
LATERAL_OUTPUTS = ("v_y", "r", "a_y")


def _check_speed(v_x: float) -> float:
    v = float(v_x)
    if not (math.isfinite(v) and v >= 2.0):
        raise ModelError(
            f"the lateral linearization needs a forward speed v_x >= 2 m/s, got {v_x!r}; the "
            "slip angles (and the model) are meant for a moving car."
        )
    return v


def lateral_linearization(
    params: ModelParams,
    v_x: float = 20.0,
    options: ModelOptions | None = None,
    accel: float = 0.0,
) -> control.StateSpace:
    """Linear lateral dynamics of the model around straight driving.

    The operating point is ``xi = [v_x, 0, 0, 0, 0, 0]`` on a straight, level road, with the tyre
    acceleration ``a_x`` that gives the net longitudinal acceleration ``accel`` (0: it balances
    drag and rolling resistance and holds the speed; < 0: braking, which with longitudinal load
    transfer loads the front axle and unloads the rear). The speed is frozen at ``v_x``, as in any
    analysis of the lateral dynamics at a given speed. The system is the ``(v_y, r)`` block of the
    model's exact
    Jacobians ``A_c = df/dxi``, ``B_c = df/du`` (:meth:`racing_lib.model.Model.jacobians`):

    ``d/dt [v_y, r] = A [v_y, r] + B delta``,   outputs ``[v_y, r, a_y]`` with
    ``a_y = v_y_dot + r v_x``.

    Taught in notebook 02 (linear analysis).

    Parameters
    ----------
    params : ModelParams
        Model parameters.
    v_x : float
        Forward speed of the operating point, m/s (>= 2).
    options : ModelOptions, optional
        Model effects (default ``ModelOptions()``). Around straight driving only the longitudinal
        load transfer (with ``accel != 0``) changes the lateral block.
    accel : float
        Net longitudinal acceleration ``v_x_dot`` of the operating point, m/s^2.

    Returns
    -------
    control.StateSpace
        States ``v_y`` (m/s), ``r`` (rad/s); input ``delta`` (rad); outputs ``v_y`` (m/s),
        ``r`` (rad/s), ``a_y`` (m/s^2).
    """
    v = _check_speed(v_x)
    model = Model(params, options)
    xi = np.zeros(len(X))
    xi[X.VX] = v
    # On a straight v_x_dot is a_x minus the resistances: pick a_x for the wanted v_x_dot.
    a_x = float(accel) - float(model.xi_dot(xi, [0.0, 0.0])[X.VX])
    A_c, B_c = model.jacobians(xi, [0.0, a_x])
    lat = [X.VY, X.R]
    A = A_c[np.ix_(lat, lat)]
    B = B_c[np.ix_(lat, [U.DELTA])]
    C = np.vstack([np.eye(2), A[0] + np.array([0.0, v])])  # a_y = v_y_dot + r v_x
    D = np.vstack([np.zeros((2, 1)), B[0]])
    return control.ss(
        A, B, C, D, inputs=["delta"], outputs=list(LATERAL_OUTPUTS), states=list(LATERAL_STATES)
    )


def understeer_gradient(
    params: ModelParams,
    v_x: float = 20.0,
    options: ModelOptions | None = None,
    accel: float = 0.0,
) -> float:
    """Understeer gradient ``K`` of the model, rad/(m/s^2), from its steady-state yaw-rate gain.

    In steady cornering the linear model turns with ``r / delta = v_x / (L + K v_x^2)``, ``L`` the
    wheelbase. ``K > 0``: understeer (the car needs more steering as it corners harder); ``K < 0``
    oversteer (unstable above the critical speed ``sqrt(-L / K)``); ``K = 0`` neutral. Computed from
    the DC gain of :func:`lateral_linearization` (for the linear model ``K`` does not depend on the
    speed). Taught in notebook 02.

    Parameters
    ----------
    params : ModelParams
        Model parameters.
    v_x : float
        Speed at which the gain is evaluated, m/s.
    options : ModelOptions, optional
        Model effects.
    accel : float
        Net longitudinal acceleration, m/s^2 (with longitudinal load transfer, braking moves the
        car towards oversteer).
    """
    p = params
    v = _check_speed(v_x)
    sys = lateral_linearization(p, v, options, accel)
    gain = float(np.real(control.dcgain(sys))[1, 0])  # r / delta
    return (v / gain - p.wheelbase) / v**2


@dataclass(frozen=True)
class LateralAnalysis:
    """The lateral dynamics across speed (result of :func:`lateral_analysis`).

    Attributes
    ----------
    speeds : ndarray (n,)
        Forward speeds, m/s.
    eigenvalues : ndarray (n, 2), complex
        Poles of the ``(v_y, r)`` system at each speed, 1/s (sorted by real part).
    natural_frequency : ndarray (n,)
        Undamped natural frequency ``omega_n = sqrt(det A)``, rad/s (NaN where ``det A <= 0``:
        one real pole is unstable).
    damping : ndarray (n,)
        Damping ratio ``zeta = -trace(A) / (2 omega_n)``, -; above 1 the poles are real (NaN
        where ``omega_n`` is).
    yaw_rate_gain : ndarray (n,)
        Steady-state yaw rate per steering angle ``r / delta``, 1/s.
    understeer_gradient : float
        ``K``, rad/(m/s^2) (see :func:`understeer_gradient`).
    characteristic_speed : float
        ``sqrt(L / K)`` for an understeering car, m/s: the speed of the largest yaw-rate gain;
        ``inf`` for a neutral or oversteering one.
    critical_speed : float
        ``sqrt(-L / K)`` for an oversteering car, m/s: above it the car is unstable; ``inf``
        otherwise.
    """

    speeds: np.ndarray
    eigenvalues: np.ndarray
    natural_frequency: np.ndarray
    damping: np.ndarray
    yaw_rate_gain: np.ndarray
    understeer_gradient: float
    characteristic_speed: float
    critical_speed: float

    @property
    def stable(self) -> np.ndarray:
        """True where both poles have a negative real part."""
        return np.all(self.eigenvalues.real < 0.0, axis=1)


def lateral_analysis(
    params: ModelParams,
    speeds: Sequence[float] | np.ndarray = (10.0, 20.0, 30.0, 40.0, 50.0),
    options: ModelOptions | None = None,
    accel: float = 0.0,
) -> LateralAnalysis:
    """Eigenvalues, damping and steady-state gain of the lateral dynamics at several speeds.

    Taught in notebook 02. See :func:`lateral_linearization` for the system.

    Parameters
    ----------
    params : ModelParams
        Model parameters.
    speeds : sequence of float
        Forward speeds, m/s (each >= 2).
    options : ModelOptions, optional
        Model effects.
    accel : float
        Net longitudinal acceleration of the operating points, m/s^2 (see
        :func:`lateral_linearization`).

    Returns
    -------
    LateralAnalysis
    """
    p = params
    v = np.asarray(speeds, dtype=float).ravel()
    if v.size == 0:
        raise ModelError("lateral_analysis needs at least one speed (m/s).")
    eig = np.empty((v.size, 2), dtype=complex)
    wn = np.empty(v.size)
    zeta = np.empty(v.size)
    gain = np.empty(v.size)
    for i, vi in enumerate(v):
        sys = lateral_linearization(p, float(vi), options, accel)
        A = np.asarray(sys.A)
        lam = np.linalg.eigvals(A)
        eig[i] = lam[np.lexsort((lam.imag, lam.real))]
        det, tr = float(np.linalg.det(A)), float(np.trace(A))
        wn[i] = math.sqrt(det) if det > 0.0 else float("nan")
        zeta[i] = -tr / (2.0 * wn[i]) if det > 0.0 else float("nan")
        gain[i] = float(np.real(control.dcgain(sys))[1, 0])
    K = understeer_gradient(p, float(v.max()), options, accel)  # most accurate at speed
    L = p.wheelbase
    return LateralAnalysis(
        speeds=v,
        eigenvalues=eig,
        natural_frequency=wn,
        damping=zeta,
        yaw_rate_gain=gain,
        understeer_gradient=K,
        characteristic_speed=math.sqrt(L / K) if K > 0.0 else math.inf,
        critical_speed=math.sqrt(-L / K) if K < 0.0 else math.inf,
    )


def lateral_growth(
    params: ModelParams,
    states: np.ndarray,
    inputs: np.ndarray,
    options: ModelOptions | None = None,
    theta: np.ndarray | None = None,
) -> np.ndarray:
    """The largest real part of the lateral eigenvalues at each of N states, 1/s.

    The ``(v_y, r)`` block of the model's Jacobian ``A_c`` at each state and input, as
    :func:`racing_lib.model.lateral_eigenvalue_test` tests it: positive where the car diverges
    by itself (under hard braking, for a car that oversteers there). Taught in notebook 08.

    Parameters
    ----------
    params : ModelParams
        Model parameters.
    states : ndarray, shape (N, 6)
        States ``[v_x, v_y, r, e_psi, e_y, s]`` (m/s, m/s, rad/s, rad, m, m); the lateral block
        depends on the first three only.
    inputs : ndarray, shape (N, 2)
        Inputs ``[delta, a_x]`` (rad, m/s^2).
    options : ModelOptions, optional
        Model effects.
    theta : ndarray, shape (N,), optional
        Road pitch at each state, rad (default level). It matters where the planner holds an
        eigenvalue at zero: on a 1 % slope the loads shift enough to move it by 0.06 1/s.

    Returns
    -------
    numpy.ndarray, shape (N,)
    """
    xi = np.atleast_2d(np.asarray(states, dtype=float))
    u = np.atleast_2d(np.asarray(inputs, dtype=float))
    n = xi.shape[0]
    pitch = np.zeros(n) if theta is None else np.asarray(theta, dtype=float).ravel()
    if xi.shape[1] != len(X) or u.shape != (n, 2) or pitch.size != n:
        raise ModelError(
            f"lateral_growth takes states of shape (N, {len(X)}), inputs of shape (N, 2) and "
            f"theta of N values; got {xi.shape}, {u.shape} and {pitch.size}."
        )
    jac = jacobians(params, options or ModelOptions()).map(n)
    a_c = np.asarray(jac(xi.T, u.T, np.zeros(n), pitch)[0])  # 6 x 6N, one block per state
    lat = [int(X.VY), int(X.R)]
    blocks = a_c.reshape(len(X), n, len(X)).transpose(1, 0, 2)[:, lat][:, :, lat]
    return np.max(np.linalg.eigvals(blocks).real, axis=1)
