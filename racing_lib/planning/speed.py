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

import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import PlanningError
from racing_lib.model.car_model import DEFAULT_V_TOP
from racing_lib.model.params import ModelOptions, ModelParams, PedalMap
from racing_lib.model.states import X
from racing_lib.vehicle.params import G, VehicleParams

#: Where a parameter set leaves a value out: the planning model's defaults (the paper's table).
_DEFAULTS = ModelParams()

AccelLimits = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""Tyre acceleration limits: speeds v (m/s) -> (a_x_min, a_x_max) (m/s^2), element-wise."""


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


def _param(params: ModelParams | VehicleParams, name: str) -> float:
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


def pedal_accel_limits(pedal_map: PedalMap | AccelLimits | None) -> AccelLimits | None:
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


def speed_profile(
    s: ArrayLike,
    kappa: ArrayLike,
    params: ModelParams | VehicleParams | None = None,
    pedal_map: PedalMap | AccelLimits | None = None,
    theta: ArrayLike | None = None,
    v_top: float | None = None,
    options: ModelOptions | None = None,
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
    params : ModelParams or VehicleParams
        Planning parameters (required: no planner picks a model of its own); read: ``mu``,
        ``D_f``, ``D_r`` (the friction circle's radius is ``mu min(D_f, D_r) g``), ``m`` (kg),
        ``C_xw`` (kg/m), ``c_rr`` (-) and ``pedal``. Any object with these names serves (the
        simulated car's ``VehicleParams`` does); a missing value takes the default of
        ``ModelParams()``.
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
    >>> from racing_lib.model import ModelParams
    >>> prof = speed_profile(s, np.full(200, 1 / 50.0), ModelParams())
    >>> round(float(prof.v[0]), 2)  # sqrt(mu g R) = sqrt(1.25 * 9.81 * 50); drag is tiny here
    24.76
    """
    s, kappa, ds, length = _checked_path(s, kappa, closed, length)
    n = s.size
    theta = np.zeros(n) if theta is None else np.broadcast_to(np.asarray(theta, float), (n,))
    a_z = np.zeros(n) if a_z is None else np.broadcast_to(np.asarray(a_z, float), (n,))
    if params is None:
        raise PlanningError(
            "speed_profile needs the model's parameters (a racing_lib.model.ModelParams, or any "
            "object with its names): pass params, for example racing_lib.model.identified_params()."
        )
    car = _point_mass(params, options, v_top)
    if pedal_map is None:
        pedal_map = getattr(params, "pedal", None)
    limits = pedal_accel_limits(pedal_map)
    road = _road(params, car, kappa, theta, a_z, ds)
    forward, backward = _pass_functions(road, car, limits)
    if closed:
        v, success, passes = _closed_passes(road, forward, backward, max_passes, tol)
    else:
        v, success, passes = _open_passes(road, forward, backward, v_start), True, 1
    return _profile(s, v, road, closed, length, success, passes)


def _checked_path(
    s: ArrayLike, kappa: ArrayLike, closed: bool, length: float | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float | None]:
    """The nodes of :func:`speed_profile` as flat arrays, checked, with their spacing.

    Parameters
    ----------
    s : array_like, shape (N,)
        Arc length of the nodes, m.
    kappa : array_like, shape (N,)
        Curvature at the nodes, 1/m.
    closed : bool
        True for a closed loop (the last spacing wraps to the first node).
    length : float or None
        Length of a closed path, m (None: last node + one spacing).

    Returns
    -------
    s (m), kappa (1/m) : ndarray (N,)
    ds : ndarray (N,) on a closed path, (N-1,) on an open one
        Distance from each node to the next, m.
    length : float or None
        The closed path's length, m (as given on an open path).

    Raises
    ------
    PlanningError
        Fewer than 3 nodes, a curvature count that differs, non-finite values, or s not increasing.
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
    return s, kappa, ds, length


@dataclass(frozen=True)
class _PointMass:
    """The car as :func:`speed_profile` sees it: friction, mass, resistances and top speed.

    Attributes
    ----------
    mu : float
        Friction coefficient, dimensionless.
    mass : float
        Mass, kg.
    c_xw : float
        Drag coefficient (0 with drag switched off), kg/m.
    c_rr : float
        Rolling resistance coefficient, dimensionless.
    v_top : float
        Top speed, m/s.
    """

    mu: float
    mass: float
    c_xw: float
    c_rr: float
    v_top: float


def _point_mass(
    params: ModelParams | VehicleParams, options: ModelOptions | None, v_top: float | None
) -> _PointMass:
    """The point-mass constants of ``params`` (see :func:`speed_profile`), checked.

    Parameters
    ----------
    params : ModelParams or alike
        Planning parameters (``mu``, ``m`` in kg, ``C_xw`` in kg/m, ``c_rr``).
    options : ModelOptions or None
        ``options.drag`` switches the drag off when false.
    v_top : float or None
        Top speed, m/s (None: :data:`DEFAULT_V_TOP`).

    Raises
    ------
    PlanningError
        If mu, the mass or the top speed is not positive.
    """
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
    return _PointMass(mu=mu, mass=mass, c_xw=c_xw, c_rr=c_rr, v_top=v_top)


@dataclass(frozen=True)
class _Road:
    """Per-node quantities of the passes of :func:`speed_profile`.

    Attributes
    ----------
    ds : ndarray
        Distance from each node to the next, m.
    theta : ndarray (N,)
        Road grade, rad.
    g_eff : ndarray (N,)
        Vertical acceleration pressing the car onto the road, m/s^2.
    abs_k : ndarray (N,)
        Absolute curvature, 1/m.
    grip : ndarray (N,)
        Radius of the friction circle, m/s^2.
    v_max : ndarray (N,)
        Cornering limit capped at the top speed, m/s.
    """

    ds: np.ndarray
    theta: np.ndarray
    g_eff: np.ndarray
    abs_k: np.ndarray
    grip: np.ndarray
    v_max: np.ndarray


def _road(
    params: ModelParams | VehicleParams,
    car: _PointMass,
    kappa: np.ndarray,
    theta: np.ndarray,
    a_z: np.ndarray,
    ds: np.ndarray,
) -> _Road:
    """The friction circle and the cornering speed limit at each node.

    Parameters
    ----------
    params : ModelParams or alike
        Read: the Pacejka peak factors ``D_f`` and ``D_r`` (dimensionless).
    car : _PointMass
        Friction coefficient and top speed (m/s).
    kappa : ndarray (N,)
        Curvature, 1/m.
    theta : ndarray (N,)
        Road grade, rad.
    a_z : ndarray (N,)
        Extra vertical acceleration, m/s^2.
    ds : ndarray
        Distance from each node to the next, m.

    Raises
    ------
    PlanningError
        If the grade or the vertical acceleration lifts the car off the road.
    """
    g_eff = G * np.cos(theta) + a_z  # vertical acceleration pressing the car onto the road, m/s^2
    if np.any(g_eff <= 0):
        raise PlanningError("the road's grade or vertical acceleration lifts the car off the road.")
    # The tyres' peak: mu D with the smaller Pacejka peak factor of the two axles (the identified
    # D is below 1 where the car's load-sensitive tyres lose grip to load transfer). Planning
    # with mu g alone asked the car for 12.3 m/s^2 where it had 10.3 and slid wide when braking
    # into corners.
    d_peak = min(_param(params, "D_f"), _param(params, "D_r"))
    grip = car.mu * d_peak * g_eff  # friction-circle radius, m/s^2
    abs_k = np.abs(kappa)
    with np.errstate(divide="ignore"):
        v_max = np.where(abs_k > 1e-9, np.sqrt(grip / np.maximum(abs_k, 1e-12)), np.inf)
    v_max = np.minimum(v_max, car.v_top)
    return _Road(ds=ds, theta=theta, g_eff=g_eff, abs_k=abs_k, grip=grip, v_max=v_max)


_Pass = Callable[[float, int, int, list[float]], float]


def _pass_functions(
    road: _Road, car: _PointMass, limits: AccelLimits | None
) -> tuple[_Pass, _Pass]:
    """The forward (accelerating) and backward (braking) passes over the nodes.

    The passes are closures over the tabulated pedal limits and the node lists, so their per-node
    loops read local names only.

    Parameters
    ----------
    road : _Road
        Per-node friction circle, grade and speed limit.
    car : _PointMass
        Mass (kg), drag (kg/m), rolling resistance and top speed (m/s).
    limits : callable or None
        Pedal-map acceleration limits v -> (a_min, a_max), m/s^2 (None: the tyres only).

    Returns
    -------
    forward, backward : callable
        ``f(v0, start, steps, out) -> v``: from speed ``v0`` (m/s) at node ``start``, walk
        ``steps`` nodes (forward: up, backward: down, wrapping), lowering ``out`` (m/s) in place
        to what the car can reach; returns the last speed, m/s.
    """
    n = road.abs_k.size
    c_xw, mass, c_rr = car.c_xw, car.mass, car.c_rr
    g_eff, theta, abs_k, grip = road.g_eff, road.theta, road.abs_k, road.grip

    def resist(v: float, k: int) -> float:
        # Accelerations that slow the car regardless of the pedal: drag, rolling resistance, grade.
        return c_xw * v * v / mass + c_rr * g_eff[k] + G * math.sin(theta[k])

    def ellipse(v: float, k: int) -> float:
        # What the friction circle leaves for longitudinal tyre acceleration at speed v.
        lat = v * v * abs_k[k] / grip[k]
        return grip[k] * math.sqrt(max(0.0, 1.0 - lat * lat))

    # Tabulate the pedal-map limits once (one vectorized call) and interpolate them in the passes:
    # calling the map per node would dominate the run time.
    v_tab_step = 1.25 * float(car.v_top) / 255.0
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

    v_max_list = road.v_max.tolist()
    ds_list = road.ds.tolist()

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

    return forward, backward


def _closed_passes(
    road: _Road, forward: _Pass, backward: _Pass, max_passes: int, tol: float
) -> tuple[np.ndarray, bool, int]:
    """The periodic profile of a flying lap: wrap-around passes until the loop closes.

    Parameters
    ----------
    road : _Road
        Per-node speed limit ``v_max``, m/s.
    forward, backward : callable
        The passes of :func:`_pass_functions`.
    max_passes : int
        Maximum wrap-around passes in each direction.
    tol : float
        Settling tolerance of the speed where the loop closes, m/s.

    Returns
    -------
    v : ndarray (N,)
        Speed at the nodes, m/s.
    success : bool
        True when both directions settled.
    passes : int
        Number of forward passes done.
    """
    n = road.v_max.size
    success = True
    passes = 1  # what is reported if max_passes < 1
    # Start where the path is slowest: the true profile cannot exceed v_max there, and the
    # passes from that node are close to the periodic answer after one lap.
    k0 = int(np.argmin(road.v_max))
    fwd = road.v_max.tolist()
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
    return np.asarray(bwd), success, passes


def _open_passes(road: _Road, forward: _Pass, backward: _Pass, v_start: float | None) -> np.ndarray:
    """The profile of an open path: one forward pass from ``v_start`` (m/s), one backward pass.

    Returns the speed at the nodes, m/s (``v_start`` None: v_max at the first node).
    """
    v_max_list = road.v_max.tolist()
    n = len(v_max_list)
    prof = list(v_max_list)
    prof[0] = min(prof[0], v_max_list[0] if v_start is None else float(v_start))
    forward(prof[0], 0, n - 1, prof)
    backward(prof[-1], n - 1, n - 1, prof)
    return np.asarray(prof)


def _profile(
    s: np.ndarray,
    v: np.ndarray,
    road: _Road,
    closed: bool,
    length: float | None,
    success: bool,
    passes: int,
) -> SpeedProfile:
    """The :class:`SpeedProfile` of the speeds ``v`` (m/s) at the nodes ``s`` (m), checked.

    Raises
    ------
    PlanningError
        If a speed is not positive and finite (the car cannot move somewhere).
    """
    if np.any(v <= 0) or not np.all(np.isfinite(v)):
        raise PlanningError(
            "speed_profile found no positive speed: the car cannot overcome drag, grade or rolling "
            "resistance somewhere; check the friction coefficient and the pedal map."
        )
    ds = road.ds
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
        v_max=road.v_max,
        lap_time=float(np.sum(dt)),
        success=success,
        iterations=passes,
        length=float(length) if closed else float("nan"),
    )
