"""`Model`: the planning model for NumPy users, one state per row."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import ModelError
from racing_lib.model.equations import (
    INPUT_NAMES,
    check_args,
    check_step,
    discrete_linearization,
    discretize,
    jacobians,
    model_terms,
    spatial_dynamics,
    time_dynamics,
)
from racing_lib.model.params import ModelOptions, ModelParams
from racing_lib.model.states import NU, NX, Domain, Method, per_stage, state_rows

# The force laws are defined once, in racing_lib/vehicle/forces.py, for floats, numpy and CasADi

__all__ = ["Model"]


class Model:
    """The model for numpy users: evaluate, integrate and linearize single states or batches.

    Taught in notebook 02. Batches hold one state per row: ``xi`` of shape ``(N, 6)``, ``u`` of
    shape ``(N, 2)``; ``kappa`` and ``theta`` are scalars or shape ``(N,)``. Single states of shape
    ``(6,)`` give outputs without the batch axis.

    Parameters
    ----------
    params : ModelParams
        Parameter set (default: the paper's car).
    options : ModelOptions
        Physical effects included (default: drag and longitudinal load transfer).

    Examples
    --------
    >>> import numpy as np
    >>> from racing_lib.model import Model, X
    >>> model = Model()
    >>> xi = np.array([20.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    >>> xi_dot = model.xi_dot(xi, [0.0, 0.0])  # coasting on a straight
    >>> bool(xi_dot[X.VX] < 0)  # drag and rolling resistance slow the car
    True
    >>> A, B, d = model.linearize(np.tile(xi, (20, 1)), np.zeros((20, 2)), 0.1)  # 20 MPC stages
    >>> A.shape, B.shape, d.shape
    ((20, 6, 6), (20, 6, 2), (20, 6))
    """

    def __init__(
        self, params: ModelParams | None = None, options: ModelOptions | None = None
    ) -> None:
        self.params = ModelParams() if params is None else params
        self.options = ModelOptions() if options is None else options
        check_args(self.params, self.options)
        self.f_time = time_dynamics(self.params, self.options)
        self.f_spatial = spatial_dynamics(self.params, self.options)
        self._maps: dict[tuple[Any, ...], ca.Function] = {}

    def __repr__(self) -> str:
        return f"Model(options={self.options})"

    def _prepare(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike, theta: ArrayLike
    ) -> tuple[bool, list[np.ndarray]]:
        single = np.ndim(xi) == 1
        X_ = state_rows(xi)
        U_ = state_rows(u, "u", NU)
        n = X_.shape[0]
        if U_.shape[0] != n:
            if U_.shape[0] != 1:
                raise ModelError(f"u has {U_.shape[0]} rows but xi has {n}.")
            U_ = np.repeat(U_, n, axis=0)
        K = per_stage(kappa, n, "kappa")
        T = per_stage(theta, n, "theta")
        return single, [X_.T, U_.T, K[None, :], T[None, :]]

    def _call(self, fn: ca.Function, args: list[np.ndarray], single: bool) -> np.ndarray:
        out = np.asarray(fn(*args)).T
        return out[0] if single else out

    def xi_dot(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike = 0.0, theta: ArrayLike = 0.0
    ) -> np.ndarray:
        """Time derivative of the state, shape like ``xi``."""
        single, args = self._prepare(xi, u, kappa, theta)
        return self._call(self.f_time, args, single)

    def dxi_ds(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike = 0.0, theta: ArrayLike = 0.0
    ) -> np.ndarray:
        """Derivative of the state with respect to arc length ``s`` (per m), shape like ``xi``."""
        single, args = self._prepare(xi, u, kappa, theta)
        return self._call(self.f_spatial, args, single)

    def terms(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike = 0.0, theta: ArrayLike = 0.0
    ) -> dict[str, np.ndarray]:
        """Named intermediate quantities (see :func:`model_terms`): floats or (N,) arrays."""
        single, args = self._prepare(xi, u, kappa, theta)
        fn = model_terms(self.params, self.options)
        res = fn.call(dict(zip(INPUT_NAMES, args, strict=True)))
        out = {}
        for name, value in res.items():
            arr = np.asarray(value).ravel()
            out[name] = float(arr[0]) if single else arr
        return out

    def step(
        self,
        xi: ArrayLike,
        u: ArrayLike,
        h: float,
        kappa: ArrayLike = 0.0,
        theta: ArrayLike = 0.0,
        method: Method = "rk4",
        domain: Domain = "time",
    ) -> np.ndarray:
        """One integration step of length ``h`` (s, or m for ``domain="spatial"``)."""
        single, args = self._prepare(xi, u, kappa, theta)
        F = discretize(self.params, self.options, check_step(h), method, domain)
        return self._call(F, args, single)

    def linearize(
        self,
        xi_bar: ArrayLike,
        u_bar: ArrayLike,
        h: float,
        kappa: ArrayLike = 0.0,
        theta: ArrayLike = 0.0,
        method: Method = "rk4",
        domain: Domain = "time",
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Affine discrete model(s) ``xi_next ~= A xi + B u + d`` around the point(s).

        For a batch of N points returns ``A`` (N, 6, 6), ``B`` (N, 6, 2), ``d`` (N, 6), computed in
        one call of a mapped CasADi Function (built once per N); for one point (6,) the batch axis
        is dropped.
        """
        single, args = self._prepare(xi_bar, u_bar, kappa, theta)
        n = args[0].shape[1]
        key = (check_step(h), method, domain, n)
        fn = self._maps.get(key)
        if fn is None:
            lin = discrete_linearization(self.params, self.options, key[0], method, domain)
            fn = lin if n == 1 else lin.map(n)
            self._maps[key] = fn
        A, B, d = fn(*args)
        A = np.asarray(A).reshape(NX, n, NX).transpose(1, 0, 2)
        B = np.asarray(B).reshape(NX, n, NU).transpose(1, 0, 2)
        d = np.asarray(d).T
        if single:
            return A[0], B[0], d[0]
        return A, B, d

    def jacobians(
        self,
        xi: ArrayLike,
        u: ArrayLike,
        kappa: ArrayLike = 0.0,
        theta: ArrayLike = 0.0,
        domain: Domain = "time",
    ) -> tuple[np.ndarray, np.ndarray]:
        """Continuous Jacobians ``A_c`` (6, 6) and ``B_c`` (6, 2) at one point (numpy)."""
        single, args = self._prepare(xi, u, kappa, theta)
        if not single:
            raise ModelError("Model.jacobians takes one state of shape (6,); loop for batches.")
        A, B = jacobians(self.params, self.options, domain)(*args)
        return np.asarray(A), np.asarray(B)
