"""Quasi-steady-state speed profile along a path (taught in notebook 03).

Given the curvature kappa(s) of a line, the fastest speed a car can hold is limited in three ways:

1. in a corner the tyres must supply the lateral acceleration v^2 kappa, so
   ``v <= v_max(s) = sqrt(mu (g cos theta + a_z) / |kappa|)`` (paper, Eq. MaxV), capped at a top
   speed;
2. when speeding up, the tyre acceleration a_x is limited by the powertrain (the pedal map at full
   throttle) and by what the friction ellipse leaves after cornering,
   ``a_x <= mu g sqrt(1 - (v^2 kappa / (mu g))^2)``; drag, rolling resistance and grade are
   subtracted from it;
3. when braking, the same ellipse limits the deceleration (drag and grade help).

The profile is the pointwise minimum of v_max, a forward pass with the acceleration limit and a
backward pass with the braking limit. On a closed track (a flying lap) the passes wrap around the
loop and are repeated until the speed where the loop closes stops changing.

This is a planning tool, not a model of the car: it uses the point-mass limits above with the
planning model's parameters (:class:`racing_lib.model.ModelParams`), and it is what the
curvature-optimal QP uses for its speed estimate v_hat.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import PlanningError
from racing_lib.model.params import ModelParams
from racing_lib.vehicle.params import G

#: Top speed used when neither the caller nor the parameters give one: 190 km/h, m/s.
DEFAULT_V_TOP = 190.0 / 3.6
#: Where a parameter set leaves a value out: the planning model's defaults (the paper's table).
_DEFAULTS = ModelParams()

AccelLimits = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class SpeedProfile:
    """A speed profile along a path.

    Attributes
    ----------
    s : ndarray, shape (N,)
        Arc length of the nodes, m.
    v : ndarray, shape (N,)
        Speed at the nodes, m/s.
    a_x : ndarray, shape (N,)
        Net longitudinal acceleration dv/dt between node k and k+1 (the last one wraps on a closed
        path), m/s^2.
    v_max : ndarray, shape (N,)
        The cornering limit sqrt(mu g_eff / |kappa|) capped at the top speed, m/s.
    lap_time : float
        Time to drive the path, sum of ds / v_mean with the trapezoid (harmonic) rule, s.
    success : bool
        True when the periodic passes settled.
    iterations : int
        Number of wrap-around passes done.
    length : float
        Length of the closed path, m (NaN for an open path).
    """

    s: np.ndarray
    v: np.ndarray
    a_x: np.ndarray
    v_max: np.ndarray
    lap_time: float
    success: bool
    iterations: int = 1
    length: float = float("nan")

    def __call__(self, s: ArrayLike) -> np.ndarray:
        """Speed at arc length ``s`` (m), linear interpolation, periodic on a closed path."""
        length = self.length
        if not math.isfinite(length):
            length = float(self.s[-1] + (self.s[-1] - self.s[-2]))
        return np.interp(np.asarray(s, dtype=float), self.s, self.v, period=length)


def _param(params: Any, name: str) -> float:
    """``params.name`` as a float, or the planning model's default (:class:`ModelParams`).

    Any object with the attribute names of :class:`ModelParams` serves (the simulated car's
    :class:`~racing_lib.vehicle.VehicleParams` shares them), so a value is never restated here.
    """
    value = getattr(params, name, None)
    return float(getattr(_DEFAULTS, name) if value is None else value)


def segment_times(ds: ArrayLike, v_start: ArrayLike, v_end: ArrayLike) -> np.ndarray:
    """Time to cover segments of length ``ds`` (m) from ``v_start`` to ``v_end`` (m/s), s.

    ``2 ds / (v_start + v_end)``: the segment's length over its mean speed, exact for a uniform
    acceleration along it (the trapezoidal rule for ``dt = ds / v``).
    """
    return 2.0 * ds / (v_start + v_end)


def pedal_accel_limits(pedal_map: Any) -> AccelLimits | None:
    """Adapter: a function v -> (a_x_min, a_x_max) from a pedal map, or None.

    Accepts :class:`racing_lib.model.PedalMap` (``limits(xi)`` with the state xi, evaluated at
    v_y = r = e_psi = e_y = 0) or any object with ``limits_at_speed(v)`` / ``limits(v)``, or a plain
    callable v -> (a_min, a_max).
    """
    if pedal_map is None:
        return None
    if hasattr(pedal_map, "limits_at_speed"):
        return lambda v: tuple(np.asarray(a, dtype=float) for a in pedal_map.limits_at_speed(v))
    if hasattr(pedal_map, "limits"):

        def limits(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            from racing_lib.model import X  # local: speed.py must import without the model

            v = np.atleast_1d(np.asarray(v, dtype=float))
            xi = np.zeros((v.size, len(X)))  # one state per row, as PedalMap expects
            xi[:, X.VX] = v
            lo, hi = pedal_map.limits(xi)
            return (
                np.broadcast_to(np.asarray(lo, dtype=float).ravel(), v.shape),
                np.broadcast_to(np.asarray(hi, dtype=float).ravel(), v.shape),
            )

        return limits
    if callable(pedal_map):
        return lambda v: tuple(np.asarray(a, dtype=float) for a in pedal_map(v))
    raise PlanningError(
        f"speed_profile cannot use a pedal map of type {type(pedal_map).__name__}; pass a "
        "racing_lib.model.PedalMap or a function v -> (a_x_min, a_x_max)."
    )


# long function: the forward and backward passes are closures over the tabulated pedal limits and
#   the node lists, so the per-node loops read local names only
def speed_profile(
    s: ArrayLike,
    kappa: ArrayLike,
    params: Any = None,
    pedal_map: Any = None,
    theta: ArrayLike | None = None,
    v_top: float | None = None,
    options: Any = None,
    *,
    length: float | None = None,
    closed: bool = True,
    v_start: float | None = None,
    a_z: ArrayLike | None = None,
    max_passes: int = 10,
    tol: float = 1e-6,
) -> SpeedProfile:
    """Quasi-steady-state speed profile v(s) of a path.

    Parameters
    ----------
    s : array_like, shape (N,)
        Increasing arc length of the nodes, m. On a closed path the first node is not repeated.
    kappa : array_like, shape (N,)
        Curvature of the path at the nodes, 1/m.
    params : ModelParams, optional
        Planning parameters; read: ``mu``, ``D_f``, ``D_r`` (the friction circle's radius is
        ``mu min(D_f, D_r) g``), ``m`` (kg), ``C_xw`` (kg/m), ``c_rr`` (-) and ``pedal``. Any
        object with these names serves (the simulated car's ``VehicleParams`` does); a missing
        value, or no parameters at all, takes the default of ``ModelParams()``.
    pedal_map : PedalMap or callable, optional
        Tyre acceleration limits a_x in [a_min(v), a_max(v)], m/s^2 (see
        :func:`pedal_accel_limits`); default ``params.pedal``. Without any, the tyres' friction
        mu g is the only limit.
    theta : array_like, shape (N,), optional
        Road grade, rad, positive uphill; it reduces the vertical load (cos) and adds g sin(theta)
        to the longitudinal balance.
    v_top : float, optional
        Top speed cap, m/s (default :data:`DEFAULT_V_TOP`, 190 km/h).
    options : ModelOptions, optional
        ``options.drag`` switches the aerodynamic drag C_xw v^2 on/off (default on).
    length : float, optional
        Length of a closed path, m (default: last node + one spacing).
    closed : bool
        True for a flying lap on a closed loop; False for an open path (then ``v_start`` is the
        speed at the first node, default v_max there, and the last node is not braked for anything
        beyond).
    v_start : float, optional
        Speed at the first node of an open path, m/s.
    a_z : array_like, optional
        Extra vertical acceleration (e.g. from the road's vertical curvature), m/s^2 (default 0).
    max_passes : int
        Maximum wrap-around passes on a closed path.
    tol : float
        Settling tolerance of the speed where the loop closes, m/s.

    Returns
    -------
    SpeedProfile

    Examples
    --------
    >>> import numpy as np
    >>> s = np.linspace(0.0, 2 * np.pi * 50.0, 200, endpoint=False)
    >>> prof = speed_profile(s, np.full(200, 1 / 50.0), options=None)
    >>> round(float(prof.v[0]), 2)  # sqrt(mu g R) = sqrt(1.25 * 9.81 * 50); drag is tiny here
    24.76
    """
    s = np.asarray(s, dtype=float).ravel()
    kappa = np.asarray(kappa, dtype=float).ravel()
    n = s.size
    if n < 3 or kappa.size != n:
        raise PlanningError(
            f"speed_profile needs at least 3 nodes and one curvature per node, got {n} nodes and "
            f"{kappa.size} curvatures; sample the path more finely."
        )
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(kappa))):
        raise PlanningError("speed_profile got NaN or infinite s or kappa; check the path.")
    ds = np.diff(s)
    if np.any(ds <= 0):
        raise PlanningError("speed_profile needs strictly increasing s; sort or resample the path.")
    if closed:
        if length is None:
            length = float(s[-1] - s[0] + ds[-1])
        gap = float(length - (s[-1] - s[0]))
        if gap <= 0:
            raise PlanningError(
                f"path length {length:.3f} m is not beyond the last node; pass the loop length."
            )
        ds = np.append(ds, gap)
    theta = np.zeros(n) if theta is None else np.broadcast_to(np.asarray(theta, float), (n,))
    a_z = np.zeros(n) if a_z is None else np.broadcast_to(np.asarray(a_z, float), (n,))

    if params is None:
        params = _DEFAULTS
    mu = _param(params, "mu")
    mass = _param(params, "m")
    drag_on = True if options is None else bool(getattr(options, "drag", True))
    c_xw = _param(params, "C_xw") if drag_on else 0.0
    c_rr = _param(params, "c_rr")
    if v_top is None:
        v_top = DEFAULT_V_TOP
    if mu <= 0 or mass <= 0 or v_top <= 0:
        raise PlanningError(
            f"speed_profile needs positive mu, mass and top speed, got mu={mu}, m={mass}, "
            f"v_top={v_top}; check the parameter set."
        )
    if pedal_map is None:
        pedal_map = getattr(params, "pedal", None)
    limits = pedal_accel_limits(pedal_map)

    g_eff = G * np.cos(theta) + a_z  # vertical acceleration pressing the car onto the road, m/s^2
    if np.any(g_eff <= 0):
        raise PlanningError("the road's grade or vertical acceleration lifts the car off the road.")
    # The tyres' peak: mu D with the smaller Pacejka peak factor of the two axles (the identified
    # D is below 1 where the car's load-sensitive tyres lose grip to load transfer). Planning
    # with mu g alone asked the car for 12.3 m/s^2 where it had 10.3 and slid wide when braking
    # into corners.
    d_peak = min(_param(params, "D_f"), _param(params, "D_r"))
    grip = mu * d_peak * g_eff  # friction-circle radius, m/s^2
    abs_k = np.abs(kappa)
    with np.errstate(divide="ignore"):
        v_max = np.where(abs_k > 1e-9, np.sqrt(grip / np.maximum(abs_k, 1e-12)), np.inf)
    v_max = np.minimum(v_max, v_top)

    def resist(v: float, k: int) -> float:
        # Accelerations that slow the car regardless of the pedal: drag, rolling resistance, grade.
        return c_xw * v * v / mass + c_rr * g_eff[k] + G * math.sin(theta[k])

    def ellipse(v: float, k: int) -> float:
        # What the friction circle leaves for longitudinal tyre acceleration at speed v.
        lat = v * v * abs_k[k] / grip[k]
        return grip[k] * math.sqrt(max(0.0, 1.0 - lat * lat))

    # Tabulate the pedal-map limits once (one vectorized call) and interpolate them in the passes:
    # calling the map per node would dominate the run time.
    v_tab_step = 1.25 * float(v_top) / 255.0
    if limits is not None:
        lo_tab, hi_tab = limits(np.arange(257) * v_tab_step)
        lo_list = np.asarray(lo_tab, float).ravel().tolist()
        hi_list = np.asarray(hi_tab, float).ravel().tolist()
    else:
        lo_list = hi_list = []

    def table(values: list[float], v: float) -> float:
        x = min(max(v / v_tab_step, 0.0), 255.0)
        i = int(x)
        return values[i] + (x - i) * (values[i + 1] - values[i])

    def acc_max(v: float, k: int) -> float:
        a_tyre = ellipse(v, k)
        if limits is not None:
            a_tyre = min(a_tyre, table(hi_list, v))
        return a_tyre - resist(v, k)

    def dec_max(v: float, k: int) -> float:
        a_tyre = ellipse(v, k)
        if limits is not None:
            a_tyre = min(a_tyre, -table(lo_list, v))
        return a_tyre + resist(v, k)

    v_max_list = v_max.tolist()
    ds_list = ds.tolist()

    def forward(v0: float, start: int, steps: int, out: list[float]) -> float:
        v = v0
        for i in range(steps):
            k = (start + i) % n
            kn = (k + 1) % n
            v2 = v * v + 2.0 * acc_max(v, k) * ds_list[k]
            v = min(out[kn], v_max_list[kn], math.sqrt(max(v2, 0.0)))
            out[kn] = v
        return v

    def backward(v0: float, start: int, steps: int, out: list[float]) -> float:
        v = v0
        for i in range(steps):
            k = (start - i) % n
            kp = (k - 1) % n
            v2 = v * v + 2.0 * dec_max(v, k) * ds_list[kp]
            v = min(out[kp], v_max_list[kp], math.sqrt(max(v2, 0.0)))
            out[kp] = v
        return v

    success = True
    passes = 1
    if closed:
        # Start where the path is slowest: the true profile cannot exceed v_max there, and the
        # passes from that node are close to the periodic answer after one lap.
        k0 = int(np.argmin(v_max))
        fwd = list(v_max_list)
        v_wrap = fwd[k0]
        for passes in range(1, max_passes + 1):  # noqa: B007 - passes is reported
            fwd[k0] = min(fwd[k0], v_wrap)
            v_new = forward(fwd[k0], k0, n, fwd)
            if abs(v_new - v_wrap) < tol and passes > 1:
                break
            v_wrap = v_new
        else:
            success = False
        bwd = list(fwd)
        v_wrap = bwd[k0]
        for _ in range(max_passes):
            v_new = backward(bwd[k0], k0, n, bwd)
            if abs(v_new - v_wrap) < tol:
                break
            v_wrap = v_new
        else:
            success = False
        v = np.asarray(bwd)
    else:
        prof = list(v_max_list)
        prof[0] = min(prof[0], v_max_list[0] if v_start is None else float(v_start))
        forward(prof[0], 0, n - 1, prof)
        backward(prof[-1], n - 1, n - 1, prof)
        v = np.asarray(prof)

    if np.any(v <= 0) or not np.all(np.isfinite(v)):
        raise PlanningError(
            "speed_profile found no positive speed: the car cannot overcome drag, grade or rolling "
            "resistance somewhere; check the friction coefficient and the pedal map."
        )
    # Pairs of nodes (k, k+1); on a closed path the last pair wraps to the first node.
    v_pairs, v_next = (v, np.roll(v, -1)) if closed else (v[:-1], v[1:])
    dt = segment_times(ds, v_pairs, v_next)
    a_x = (v_next**2 - v_pairs**2) / (2.0 * ds)
    if not closed:
        a_x = np.append(a_x, a_x[-1])
    return SpeedProfile(
        s=s,
        v=v,
        a_x=a_x,
        v_max=v_max,
        lap_time=float(np.sum(dt)),
        success=success,
        iterations=passes,
        length=float(length) if closed else float("nan"),
    )
