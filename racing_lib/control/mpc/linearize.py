"""The linear time-varying model the MPC predicts with.

The planning model linearized and discretized per stage, with the steering actuator's lag
appended as a state.
"""

from __future__ import annotations

import functools
import math

import casadi as ca
import numpy as np

from racing_lib.jit import compiled_or_interpreted, fix_inputs
from racing_lib.model import (
    NU,
    NX,
    ModelOptions,
    ModelParams,
    discretize,
    jacobians,
    time_dynamics,
)
from racing_lib.model.actuator import steering_lag_coefficients
from racing_lib.model.equations import correction_as_input, correction_inputs

__all__ = [
    "augment_steering_lag",
    "continuous_linearization",
    "expm_batch",
    "substep_linearization",
    "zero_order_hold",
]


@functools.lru_cache(maxsize=16)
def substep_linearization(
    params: ModelParams, options: ModelOptions, dt: float, substeps: int, jit: bool = False
) -> ca.Function:
    """CasADi Function ``(xi_bar, u_bar, kappa, theta) -> (A_d, B_d, d_d)`` of chained RK4 steps.

    CasADi Function ``(xi_bar, u_bar, kappa, theta) -> (A_d, B_d, d_d)`` of ``substeps`` chained
    RK4 steps of the model's :func:`~racing_lib.model.discretize` (step ``dt / substeps``).

    Same contract as :func:`racing_lib.model.discrete_linearization`, whose single RK4 step of
    0.1 s is unstable at low speed. With ``jit`` the Function is compiled to machine code by the
    system C compiler (about 1-4 s, once per parameter set: :mod:`racing_lib.jit` caches the
    build on disk by the hash of its code), which makes it about eight times faster than CasADi's
    interpreter; without a compiler it falls back to the interpreter with a warning. A learned
    correction's data are an input of the compiled code, so every correction of one layout
    shares its build (:func:`racing_lib.model.equations.correction_as_input`).
    """
    build, values = correction_as_input(params)
    return fix_inputs(_substep_linearization(build, options, dt, substeps, jit), values)


@functools.lru_cache(maxsize=16)
def _substep_linearization(
    params: ModelParams, options: ModelOptions, dt: float, substeps: int, jit: bool
) -> ca.Function:
    """:func:`substep_linearization` of parameters whose correction, if any, is a template.

    A template's data symbol is the Function's last input.
    """
    data = correction_inputs(params)
    F = discretize(params, options, dt / substeps, "rk4", "time")
    xi, u = ca.SX.sym("xi", NX), ca.SX.sym("u", NU)
    kappa, theta = ca.SX.sym("kappa"), ca.SX.sym("theta")
    x = xi
    for _ in range(substeps):
        x = F(x, u, kappa, theta)
    A = ca.jacobian(x, xi)
    B = ca.jacobian(x, u)
    d = x - ca.mtimes(A, xi) - ca.mtimes(B, u)
    fn = ca.Function("racing_lib_mpc_lin", [xi, u, kappa, theta, *data], [A, B, d])
    if jit:
        (fn,) = compiled_or_interpreted([fn], "the MPC linearization", "MPCSettings(jit=False)")
    return fn


def packed_map(lin: ca.Function, horizon: int) -> ca.Function:
    """``lin`` mapped over the horizon, with one input and one dense output.

    Parameters
    ----------
    lin : casadi.Function
        ``(xi (6), u (2), kappa, theta) -> (A (6x6), B (6x2), d (6))`` of one stage.
    horizon : int
        Number of stages N.

    Returns
    -------
    casadi.Function
        ``Z (10 x N) -> (54 x N)``: column k stacks stage k's state, input, curvature and pitch,
        and returns ``[vec(A_k); vec(B_k); d_k]`` (column-major). Converting CasADi's matrices
        to numpy costs tens of microseconds each, as much as the compiled linearization itself,
        so one packed matrix each way saves a third of the step's linearization time.
    """
    nx, nu = lin.size1_in(0), lin.size1_in(1)
    z = ca.MX.sym("z", nx + nu + 2, horizon)
    A, B, d = lin.map(horizon)(z[:nx, :], z[nx : nx + nu, :], z[nx + nu, :], z[nx + nu + 1, :])
    out = ca.vertcat(ca.reshape(A, nx * nx, horizon), ca.reshape(B, nx * nu, horizon), d)
    return ca.Function("linearization_packed", [z], [ca.densify(out)])


def unpack_linearization(
    packed: ca.DM | np.ndarray, horizon: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``A (N, 6, 6), B (N, 6, 2), d (N, 6)`` from the output of :func:`packed_map`.

    ``packed`` is the CasADi matrix, or its elements in column-major order as a numpy array
    (:class:`racing_lib.jit.BufferedFunction`); the results are views of it.
    """
    nx, nu = NX, NU
    flat = packed if isinstance(packed, np.ndarray) else np.array(packed.elements())
    out = flat.reshape(horizon, nx * (nx + nu + 1))
    A = out[:, : nx * nx].reshape(horizon, nx, nx).transpose(0, 2, 1)
    B = out[:, nx * nx : nx * (nx + nu)].reshape(horizon, nu, nx).transpose(0, 2, 1)
    return A, B, out[:, nx * (nx + nu) :]


def continuous_linearization(params: ModelParams, options: ModelOptions) -> ca.Function:
    """CasADi Function ``(xi, u, kappa, theta) -> (A_c, B_c, c)``: the model linearized in time.

    ``xi_dot ~= A_c xi + B_c u + c`` near the point, with ``c = f - A_c xi - B_c u``.
    """
    f = time_dynamics(params, options)
    jac = jacobians(params, options, "time")
    xi, u = ca.SX.sym("xi", NX), ca.SX.sym("u", NU)
    kappa, theta = ca.SX.sym("kappa"), ca.SX.sym("theta")
    A_c, B_c = jac(xi, u, kappa, theta)
    c = f(xi, u, kappa, theta) - ca.mtimes(A_c, xi) - ca.mtimes(B_c, u)
    return ca.Function("lin_continuous", [xi, u, kappa, theta], [A_c, B_c, c])


def expm_batch(M: np.ndarray, order: int = 8, max_norm: float = 0.5) -> np.ndarray:
    """Matrix exponentials of a batch of small matrices, shape (N, n, n).

    Scaling and squaring with a Taylor polynomial: divide by 2^j so that the largest infinity norm
    in the batch is at most ``max_norm``, sum the series to ``order`` (truncation error below
    ``max_norm^(order+1) / (order+1)!``, about 5e-9 relative at the defaults), then square j times.
    Written out because it is a fixed, short sequence of batched matrix products: for the MPC's
    25 matrices of 9 x 9 it takes a fraction of a millisecond every time, where
    ``scipy.linalg.expm`` took from 0.3 to 200 ms on the same machine.
    """
    n = M.shape[-1]
    norm = float(np.abs(M).sum(axis=-1).max()) if M.size else 0.0
    j = max(0, math.ceil(math.log2(norm / max_norm))) if norm > max_norm else 0
    X = M / (2.0**j)
    eye = np.eye(n)
    E = np.broadcast_to(eye, M.shape).copy()
    for k in range(order, 0, -1):  # Horner: I + X (I + X/2 (I + X/3 (...)))
        E = eye + (X @ E) / k
    for _ in range(j):
        E = E @ E
    return E


def zero_order_hold(A_c: np.ndarray, B_c: np.ndarray, c: np.ndarray, dt: float) -> tuple:
    """Exact discretization over ``dt`` of ``xi_dot = A_c xi + B_c u + c`` with ``u`` held.

    ``expm(dt [[A_c, B_c, c], [0, 0, 0]]) = [[A_d, B_d, d_d], [0, I, 0]]``, batched over stages.
    """
    N, n, m = B_c.shape
    M = np.zeros((N, n + m + 1, n + m + 1))
    M[:, :n, :n] = A_c * dt
    M[:, :n, n : n + m] = B_c * dt
    M[:, :n, n + m] = c * dt
    Phi = expm_batch(M)
    return Phi[:, :n, :n], Phi[:, :n, n : n + m], Phi[:, :n, n + m]


def augment_steering_lag(
    A: np.ndarray, B: np.ndarray, d: np.ndarray, steer_col: int, tau: float, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Append the actual steering angle as the last state of a batch of discrete models.

    The vehicle model sees the steering *angle*; the controller sets the *command*, which the
    actuator follows with a first-order lag. The vehicle's input over a period is approximated by
    the period's mean angle ``w delta_k + (1 - w) delta_cmd,k`` (coefficients from
    :func:`racing_lib.model.actuator.steering_lag_coefficients`), and the angle itself becomes a
    state: ``delta_{k+1} = a delta_k + (1 - a) delta_cmd,k``.

    Parameters
    ----------
    A : ndarray, shape (N, n, n)
    B : ndarray, shape (N, n, m)
    d : ndarray, shape (N, n)
        The models ``x_{k+1} = A x_k + B u_k + d`` with the steering angle in column
        ``steer_col`` of ``B``.
    steer_col : int
        Which input is the steering.
    tau, dt : float
        Lag time constant and period, s.

    Returns
    -------
    A_aug (N, n+1, n+1), B_aug (N, n+1, m), d_aug (N, n+1)
    """
    N, n, m = B.shape
    a, w = steering_lag_coefficients(tau, dt)
    A_aug = np.zeros((N, n + 1, n + 1))
    A_aug[:, :n, :n] = A
    A_aug[:, :n, n] = w * B[:, :, steer_col]
    A_aug[:, n, n] = a
    B_aug = np.zeros((N, n + 1, m))
    B_aug[:, :n, :] = B
    B_aug[:, :n, steer_col] *= 1.0 - w
    B_aug[:, n, steer_col] = 1.0 - a
    d_aug = np.zeros((N, n + 1))
    d_aug[:, :n] = d
    return A_aug, B_aug, d_aug
