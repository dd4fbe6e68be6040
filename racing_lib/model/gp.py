"""A small sparse Gaussian process, written for the learned model correction (chapter 09).

Why our own and not a library's: the correction must be evaluated inside CasADi expressions (the
time-optimal NLP and the MPC's linearization compile it with the rest of the model), so its
posterior has to be a plain formula over a handful of stored arrays, not an opaque object. The
formula is short, and so is the fit (about 150 lines of NumPy and one SciPy optimizer call), which
also keeps the package free of a 40 MB dependency for one regression.

The model, per output (each output has its own GP):

* kernel: squared exponential with one length scale per input (ARD),
  ``k(x, x') = sf^2 exp(-0.5 sum_i ((x_i - x'_i) / l_i)^2)``, on inputs standardized by the
  training data's mean and standard deviation; noise variance ``sn^2``;
* hyperparameters ``(l, sf, sn)``: maximum of the exact log marginal likelihood on a random
  subset of at most ``n_hyper`` samples (L-BFGS-B with the analytic gradient);
* posterior: the *deterministic training conditional* (DTC, Seeger et al. 2003; Quinonero-Candela
  and Rasmussen 2005) on ``M`` inducing inputs ``Z`` picked by farthest-point sampling among the
  training inputs, so that the rare states (the car at its limit) get inducing points as well
  as the common ones. (The centres of k-means, which follow the data's density instead, were
  tried: on the expressway their first learned plan went 0.5 s further and left the track
  where the car brakes from its top speed.) With ``Sigma = (K_ZZ + sn^-2 K_ZX K_XZ)^-1``:

  ``mean(x) = k_xZ w``, ``w = sn^-2 Sigma K_ZX y``;
  ``var(x) = k_xx - k_xZ (K_ZZ^-1 - Sigma) k_Zx``.

  Far from the data the mean returns to zero (the prior) and the variance to ``sf^2``: a learned
  correction of a model falls back to the model itself where it has seen nothing.

Everything is deterministic under the ``seed`` of :func:`fit_sparse_gp`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.optimize import minimize

from racing_lib.errors import ModelError

__all__ = [
    "CasadiGP",
    "SparseGP",
    "casadi_arrays",
    "casadi_mean",
    "casadi_std",
    "farthest_points",
    "fit_sparse_gp",
    "packed_size",
]

#: Added to kernel diagonals (relative to sf^2) so that Cholesky factorizations stay stable.
JITTER = 1e-8


def _sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances between the rows of ``a`` (n, d) and ``b`` (m, d)."""
    d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.maximum(d, 0.0)


def _kernel(a: np.ndarray, b: np.ndarray, lengths: np.ndarray, sf: float) -> np.ndarray:
    return sf**2 * np.exp(-0.5 * _sq_dist(a / lengths, b / lengths))


@dataclass(frozen=True, eq=False)
class SparseGP:
    """The posterior of one sparse GP, as plain arrays (picklable and JSON-able).

    Attributes
    ----------
    x_mean, x_scale : ndarray (d,)
        Standardization of the inputs: ``(x - x_mean) / x_scale``.
    z : ndarray (M, d)
        Inducing inputs, standardized.
    lengths : ndarray (d,)
        Length scales, in standardized units.
    sf, sn : float
        Signal and noise standard deviations, in the output's units.
    w : ndarray (M,)
        Weights of the posterior mean, ``mean(x) = k_xZ w``.
    c : ndarray (M, M)
        ``K_ZZ^-1 - Sigma``, of the posterior variance ``var(x) = sf^2 - k_xZ c k_Zx``.
    """

    x_mean: np.ndarray
    x_scale: np.ndarray
    z: np.ndarray
    lengths: np.ndarray
    sf: float
    sn: float
    w: np.ndarray
    c: np.ndarray

    def _k(self, x: np.ndarray) -> np.ndarray:
        xs = (np.atleast_2d(np.asarray(x, dtype=float)) - self.x_mean) / self.x_scale
        return _kernel(xs, self.z, self.lengths, self.sf)

    def mean(self, x: np.ndarray) -> np.ndarray:
        """Posterior mean at the rows of ``x`` (n, d), shape (n,)."""
        return self._k(x) @ self.w

    def std(self, x: np.ndarray) -> np.ndarray:
        """Posterior standard deviation of the latent function at the rows of ``x``, shape (n,)."""
        k = self._k(x)
        var = self.sf**2 - np.einsum("ij,jk,ik->i", k, self.c, k)
        return np.sqrt(np.maximum(var, 0.0))

    @property
    def layout(self) -> tuple[int, int]:
        """``(M, d)``: inducing inputs and input dimension (what compiled code depends on)."""
        return int(self.z.shape[0]), int(self.z.shape[1])

    def packed(self) -> np.ndarray:
        """The arrays the CasADi formulas read, in one vector (:func:`casadi_arrays` unpacks it).

        ``x_mean, x_scale, lengths, z / lengths, sf^2, (1e-3 sf)^2, w, c``, matrices column by
        column: the data that a build with the GP as an input (:mod:`racing_lib.jit`) is
        called with.
        """
        parts = [
            self.x_mean,
            self.x_scale,
            self.lengths,
            (self.z / self.lengths).ravel(order="F"),
            [self.sf**2, (1e-3 * self.sf) ** 2],
            self.w,
            self.c.ravel(order="F"),
        ]
        return np.concatenate([np.asarray(part, dtype=float).ravel() for part in parts])

    def casadi_data(self) -> CasadiGP:
        """The arrays of the CasADi formulas, as numbers (``DM``)."""
        import casadi as ca

        return casadi_arrays(ca.DM(self.packed()), *self.layout)

    def casadi_mean(self, x: Any) -> Any:
        """The posterior mean as a CasADi expression of the column ``x`` (d x 1, SX or MX)."""
        return casadi_mean(x, self.casadi_data())

    def casadi_std(self, x: Any) -> Any:
        """The posterior standard deviation as a CasADi expression of the column ``x``."""
        return casadi_std(x, self.casadi_data())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (floats exactly, as lists)."""
        return {
            "x_mean": self.x_mean.tolist(),
            "x_scale": self.x_scale.tolist(),
            "z": self.z.tolist(),
            "lengths": self.lengths.tolist(),
            "sf": float(self.sf),
            "sn": float(self.sn),
            "w": self.w.tolist(),
            "c": self.c.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SparseGP:
        """Inverse of :meth:`to_dict`; a malformed dictionary raises :class:`ModelError`."""
        try:
            gp = cls(
                x_mean=np.asarray(data["x_mean"], dtype=float),
                x_scale=np.asarray(data["x_scale"], dtype=float),
                z=np.asarray(data["z"], dtype=float),
                lengths=np.asarray(data["lengths"], dtype=float),
                sf=float(data["sf"]),
                sn=float(data["sn"]),
                w=np.asarray(data["w"], dtype=float),
                c=np.asarray(data["c"], dtype=float),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"a sparse GP's data is incomplete or malformed ({exc}).") from None
        m, d = gp.z.shape if gp.z.ndim == 2 else (0, 0)
        shapes_ok = (
            gp.x_mean.shape == gp.x_scale.shape == gp.lengths.shape == (d,)
            and gp.w.shape == (m,)
            and gp.c.shape == (m, m)
            and m > 0
        )
        if not shapes_ok:
            raise ModelError("a sparse GP's arrays do not fit together (inducing points, weights).")
        return gp


def packed_size(m: int, d: int) -> int:
    """Length of :meth:`SparseGP.packed` for ``m`` inducing inputs in ``d`` dimensions."""
    return 3 * d + m * d + 2 + m + m * m


@dataclass(frozen=True)
class CasadiGP:
    """A GP's arrays as CasADi matrices, numbers (``DM``) or symbols (``SX``): see ``packed``."""

    x_mean: Any
    x_scale: Any
    lengths: Any
    z_scaled: Any
    sf2: Any
    floor2: Any
    w: Any
    c: Any


def casadi_arrays(data: Any, m: int, d: int) -> CasadiGP:
    """Unpack a column laid out as :meth:`SparseGP.packed` (``DM`` or ``SX``) into its arrays."""
    import casadi as ca

    if data.numel() != packed_size(m, d):
        raise ModelError(f"packed GP data of {data.numel()} entries; ({m}, {d}) takes "
                         f"{packed_size(m, d)}.")  # fmt: skip
    sizes = (d, d, d, m * d, 1, 1, m, m * m)
    cuts = np.cumsum((0, *sizes))
    part = [data[int(a) : int(b)] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    return CasadiGP(
        x_mean=part[0],
        x_scale=part[1],
        lengths=part[2],
        z_scaled=ca.reshape(part[3], m, d),
        sf2=part[4],
        floor2=part[5],
        w=part[6],
        c=ca.reshape(part[7], m, m),
    )


def _casadi_k(x: Any, g: CasadiGP) -> Any:
    """``k(x, Z)`` as a CasADi column (M x 1)."""
    import casadi as ca

    xl = ((x - g.x_mean) / g.x_scale) / g.lengths
    # exp(-0.5 |x - z|^2) for every inducing point, in length-scale units
    diff = ca.repmat(xl.T, g.z_scaled.shape[0], 1) - g.z_scaled
    return g.sf2 * ca.exp(-0.5 * ca.sum2(diff**2))


def casadi_mean(x: Any, g: CasadiGP) -> Any:
    """The posterior mean ``k_xZ w`` at the column ``x`` (d x 1), a CasADi expression."""
    import casadi as ca

    return ca.dot(_casadi_k(x, g), g.w)


def casadi_std(x: Any, g: CasadiGP) -> Any:
    """The posterior standard deviation at the column ``x``, a CasADi expression."""
    import casadi as ca

    k = _casadi_k(x, g)
    var = g.sf2 - ca.dot(k, ca.mtimes(g.c, k))
    # a smooth floor keeps the square root differentiable where the GP is certain
    return ca.sqrt(ca.fmax(var, 0.0) + g.floor2)


def farthest_points(x: np.ndarray, m: int) -> np.ndarray:
    """Indices of ``m`` rows of ``x`` spread by farthest-point sampling (deterministic).

    Starts from the row nearest the mean, then repeatedly adds the row farthest from those chosen.
    """
    x = np.asarray(x, dtype=float)
    m = min(int(m), x.shape[0])
    chosen = [int(np.argmin(((x - x.mean(0)) ** 2).sum(1)))]
    dist = ((x - x[chosen[0]]) ** 2).sum(1)
    for _ in range(m - 1):
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, ((x - x[nxt]) ** 2).sum(1))
    return np.array(chosen)


def _neg_log_marginal(theta: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    """Negative exact log marginal likelihood and its gradient in ``theta = log(l, sf, sn)``."""
    d = x.shape[1]
    lengths, sf, sn = np.exp(theta[:d]), np.exp(theta[d]), np.exp(theta[d + 1])
    k = _kernel(x, x, lengths, sf)
    n = x.shape[0]
    ky = k + (sn**2 + JITTER * sf**2) * np.eye(n)
    try:
        factor = cho_factor(ky, lower=True)
    except np.linalg.LinAlgError:
        return 1e25, np.zeros_like(theta)
    alpha = cho_solve(factor, y)
    logdet = 2.0 * np.log(np.diag(factor[0])).sum()
    nll = 0.5 * y @ alpha + 0.5 * logdet + 0.5 * n * np.log(2 * np.pi)
    inner = np.outer(alpha, alpha) - cho_solve(factor, np.eye(n))  # alpha alpha^T - K^-1
    grad = np.empty_like(theta)
    for i in range(d):
        diff2 = (x[:, i : i + 1] - x[:, i : i + 1].T) ** 2 / lengths[i] ** 2
        grad[i] = -0.5 * np.sum(inner * k * diff2)
    grad[d] = -0.5 * np.sum(inner * 2.0 * k)
    grad[d + 1] = -0.5 * np.trace(inner) * 2.0 * sn**2
    return float(nll), grad


def fit_sparse_gp(
    x: np.ndarray,
    y: np.ndarray,
    *,
    inducing: int = 40,
    n_hyper: int = 400,
    seed: int = 0,
    min_noise: float = 1e-3,
    min_length: float = 0.05,
) -> SparseGP:
    """Fit one output's sparse GP to samples ``(x, y)``.

    Parameters
    ----------
    x : ndarray (n, d)
        Inputs (any units; standardized inside).
    y : ndarray (n,)
        Targets.
    inducing : int
        Number of inducing inputs ``M``; more is more accurate and slower to evaluate.
    n_hyper : int
        Largest random subset the hyperparameters are fitted on (exact GP, cost ``n_hyper^3``).
    seed : int
        Seed of that subset.
    min_noise : float
        Lower bound of the noise standard deviation, in the output's units.
    min_length : float
        Lower bound of the length scales, in standard deviations of each input: a floor on how
        fast the mean may vary, so that it stays smooth where the data are sparse.

    Returns
    -------
    SparseGP

    Raises
    ------
    ModelError
        Too few samples, mismatched shapes or non-finite values.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float).ravel()
    if x.ndim != 2 or x.shape[0] != y.size:
        raise ModelError(f"GP data: x must be (n, d) and y (n,); got {x.shape} and {y.shape}.")
    if x.shape[0] < 10:
        raise ModelError(f"GP data: {x.shape[0]} samples; at least 10 are needed to fit one.")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ModelError("GP data contains NaN or infinite values; drop those samples first.")
    x_mean = x.mean(0)
    x_scale = x.std(0)
    x_scale = np.where(x_scale > 1e-9, x_scale, 1.0)
    xs = (x - x_mean) / x_scale
    d = xs.shape[1]

    rng = np.random.default_rng(seed)
    sub = rng.choice(x.shape[0], size=min(n_hyper, x.shape[0]), replace=False)
    y_sd = max(float(np.std(y)), min_noise)
    theta0 = np.concatenate(
        [
            np.full(d, np.log(max(1.0, min_length))),
            [np.log(y_sd), np.log(max(0.3 * y_sd, min_noise))],
        ]
    )
    bounds = [(np.log(min_length), np.log(max(20.0, 2 * min_length)))] * d + [
        (np.log(1e-3 * y_sd), np.log(10.0 * y_sd)),
        (np.log(min_noise), np.log(10.0 * y_sd)),
    ]
    res = minimize(
        _neg_log_marginal,
        theta0,
        args=(xs[sub], y[sub]),
        jac=True,
        method="L-BFGS-B",
        bounds=bounds,
        options={"maxiter": 200},
    )
    lengths, sf, sn = np.exp(res.x[:d]), float(np.exp(res.x[d])), float(np.exp(res.x[d + 1]))

    z = xs[farthest_points(xs, inducing)]
    m = z.shape[0]
    kzz = _kernel(z, z, lengths, sf) + JITTER * sf**2 * np.eye(m)
    kzx = _kernel(z, xs, lengths, sf)
    a = kzz + (kzx @ kzx.T) / sn**2
    a_factor = cho_factor(a, lower=True)
    w = cho_solve(a_factor, kzx @ y) / sn**2
    sigma = cho_solve(a_factor, np.eye(m))
    lzz = np.linalg.cholesky(kzz)
    kzz_inv = solve_triangular(lzz.T, solve_triangular(lzz, np.eye(m), lower=True), lower=False)
    c = kzz_inv - sigma
    return SparseGP(x_mean, x_scale, z, lengths, sf, sn, w, 0.5 * (c + c.T))
