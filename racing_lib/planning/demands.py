"""What a plan asks of the car, along the whole lap, against what the car has.

A controller cannot follow a plan the car cannot drive. Before driving a plan on a new circuit,
:func:`plan_demands` evaluates, at every node, the quantities that decide whether it is drivable,
and reports the largest of each against its limit:

* **tyre use**: the share of the identified friction ellipse the plan uses (the planner's g-g
  ellipse; 1 = the model's limit, ``1 - GRIP_MARGIN`` what plans are made for). The accelerations
  come from the plan's own motion, not from a tyre model: laterally ``dv_y/dt + r v_x``, along the
  car ``dv_x/dt - r v_y`` plus what drag and rolling resistance take, so the measure does not
  depend on the friction the plan was made with;
* **front and rear slip angles** against those of the Pacejka peaks;
* **yaw rate** (information: what the tyres allow is in the tyre use);
* **steering angle and steering rate** against the car's actuator (angle and slew-rate limits);
* **drive power**, ``m a_x v_x`` when accelerating, against the engine's power at the wheels;
* **edge clearance**: the smallest gap between the car's side and a track edge (with a track);
* **grade**: the steepest road pitch along the plan (with a track; information, no limit).

Taught in notebook 08 (your own circuit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.geometry import Track
from racing_lib.model.params import ModelParams
from racing_lib.planning.trajectory import Trajectory
from racing_lib.vehicle import VehicleParams
from racing_lib.vehicle.forces import NUMPY_OPS, slip_angles

__all__ = [
    "Demand",
    "ellipse_axes",
    "ellipse_use",
    "format_demands",
    "motion_accelerations",
    "plan_demands",
]


@dataclass(frozen=True)
class Demand:
    """The largest value of one quantity along a plan.

    Attributes
    ----------
    name : str
        What is measured (``"tyre use"``, ``"rear slip"`` ...).
    unit : str
        Unit of ``peak`` and ``limit``.
    peak : float
        The largest value along the lap (for the edge clearance: the smallest gap between the
        car's side and an edge, m).
    s : float
        Arc length of the plan where it occurs, m.
    limit : float
        What the car has (NaN where there is no limit).
    """

    name: str
    unit: str
    peak: float
    s: float
    limit: float

    @property
    def share(self) -> float:
        """``peak / limit``: above 1 the car cannot do what the plan asks.

        ``peak / limit``: above 1 the car cannot do what the plan asks (NaN without a limit,
        and for the edge clearance, whose limit is 0 m: negative means over the edge).
        """
        if not math.isfinite(self.limit) or self.limit == 0.0:
            return math.nan
        return self.peak / self.limit


def _largest(
    name: str, unit: str, values: np.ndarray, s: np.ndarray, limit: float, inside: np.ndarray
) -> Demand:
    k = int(np.flatnonzero(inside)[np.argmax(values[inside])])
    return Demand(name, unit, float(values[k]), float(s[k]), float(limit))


def _inside(s: np.ndarray, length: float, where: tuple[float, float] | None) -> np.ndarray:
    """The nodes in the stretch ``where`` = (start, end) of the lap, m (it may wrap past 0)."""
    if where is None or float(where[1]) - float(where[0]) >= length:
        return np.ones(s.shape, dtype=bool)
    start, end = (float(v) % length for v in where)
    inside = (s >= start) & (s <= end) if start <= end else (s >= start) | (s <= end)
    if not inside.any():
        raise PlanningError(
            f"no plan node between s = {where[0]} and {where[1]} m; give a longer stretch."
        )
    return inside


def motion_accelerations(
    t: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    r: np.ndarray,
    params: ModelParams,
    *,
    lap_time: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The accelerations the tyres must supply along a motion: the plan's or a lap's.

    Laterally ``dv_y/dt + r v_x``; along the car ``dv_x/dt - r v_y`` plus what drag and rolling
    resistance take (the tyres push against those too). From the motion alone, not from a tyre
    model, so the measure does not depend on the friction a plan was made with.

    Parameters
    ----------
    t : ndarray
        Time of each sample, s.
    vx, vy : ndarray
        Longitudinal and lateral speed, m/s.
    r : ndarray
        Yaw rate, rad/s.
    params : ModelParams
        For the drag coefficient, the mass and the rolling resistance.
    lap_time : float, optional
        Given for a closed lap (a plan): the sample after the last is the first, one lap later.
        Without it the derivatives are central differences along an open log.

    Returns
    -------
    a_long, a_lat : ndarray
        m/s^2, one per sample.
    """
    t, vx, vy, r = (np.asarray(a, dtype=float) for a in (t, vx, vy, r))
    if lap_time is not None:
        dt = np.maximum(np.append(t[1:], lap_time) - t, 1e-9)
        dvx = (np.roll(vx, -1) - vx) / dt
        dvy = (np.roll(vy, -1) - vy) / dt
    else:
        dvx, dvy = np.gradient(vx, t), np.gradient(vy, t)
    resist = (params.C_xw * vx * vx) / params.m + params.c_rr * params.g
    return dvx - r * vy + resist, dvy + r * vx


def ellipse_axes(params: ModelParams) -> tuple[float, float]:
    """The half axes of the planner's friction ellipse (its g-g diagram), m/s^2.

    At the model's full friction: along the car the smaller of the tyres' peak acceleration and
    the pedal map's full brake, across it the peak acceleration.

    Returns
    -------
    a_long_max, a_lat_max : float
    """
    grip = params.peak_acceleration()
    return min(grip, params.pedal.full_brake()), grip


def ellipse_use(a_long: np.ndarray, a_lat: np.ndarray, params: ModelParams) -> np.ndarray:
    """The share of the friction ellipse (:func:`ellipse_axes`) accelerations use (1: the rim)."""
    a_long_max, a_lat_max = ellipse_axes(params)
    return np.hypot(np.asarray(a_long) / a_long_max, np.asarray(a_lat) / a_lat_max)


def plan_demands(
    trajectory: Trajectory,
    params: ModelParams | None = None,
    vehicle: VehicleParams | None = None,
    track: Track | None = None,
    where: tuple[float, float] | None = None,
) -> list[Demand]:
    """The largest demand of each kind along ``trajectory`` (see the module notes).

    Parameters
    ----------
    trajectory : Trajectory
        The plan.
    params : ModelParams, optional
        The planning model the demands are measured with, at its full friction (default: the
        parameters of the model the plan carries, ``trajectory.model.params``).
    vehicle : VehicleParams, optional
        The car's actuator and engine (default: the simulated car's ``VehicleParams()``).
    track : Track, optional
        For the edge clearance and the grade.
    where : (float, float), optional
        Only the stretch from ``start`` to ``end`` of the plan's arc length, m (it may wrap past
        the line), for example the approach to a point where a lap went wrong.

    Returns
    -------
    list of Demand
        In the order of the module notes.
    """
    if params is None:
        if trajectory.model is None:
            raise PlanningError(
                "this plan carries no model to measure its demands with (an old plan file or "
                "the best lap): pass params, e.g. racing_lib.model.identified_params()."
            )
        params = trajectory.model.params
    vehicle = vehicle if vehicle is not None else VehicleParams()
    s = np.asarray(trajectory.s, dtype=float)
    t = np.asarray(trajectory.t, dtype=float)
    vx = np.asarray(trajectory.vx, dtype=float)
    vy = np.asarray(trajectory.vy, dtype=float)
    r = np.asarray(trajectory.r, dtype=float)
    delta = np.asarray(trajectory.delta, dtype=float)
    ax = np.asarray(trajectory.ax, dtype=float)
    inside = _inside(s, trajectory.length, where)

    a_long, a_lat = motion_accelerations(t, vx, vy, r, params, lap_time=trajectory.lap_time)
    use = ellipse_use(a_long, a_lat, params)
    t_next = np.append(t[1:], trajectory.lap_time)
    dt = np.maximum(t_next - t, 1e-9)

    v_safe = np.maximum(vx, 1.0)
    alpha_f, alpha_r = slip_angles(
        v_safe, vy, r, delta, params.l_f, params.l_r, NUMPY_OPS, small_angle=False
    )
    a_f, a_r = params.peak_slip_angle()
    steer_rate = np.abs(np.roll(delta, -1) - delta) / dt
    power = params.m * np.maximum(ax, 0.0) * vx / 1e3
    power_max = vehicle.power_max * vehicle.driveline_efficiency / 1e3
    out = [
        _largest("tyre use", "-", use, s, 1.0, inside),
        _largest("front slip", "deg", np.degrees(np.abs(alpha_f)), s, math.degrees(a_f), inside),
        _largest("rear slip", "deg", np.degrees(np.abs(alpha_r)), s, math.degrees(a_r), inside),
        _largest("yaw rate", "rad/s", np.abs(r), s, math.nan, inside),
        _largest("steering angle", "rad", np.abs(delta), s, vehicle.steer_max, inside),
        _largest("steering rate", "rad/s", steer_rate, s, vehicle.steer_rate_max, inside),
        _largest("drive power", "kW", power, s, power_max, inside),
    ]
    if track is not None:
        s_c, e_c = track.centerline.to_frenet_along(trajectory.x, trajectory.y)
        gap = np.minimum(track.width_left(s_c) - e_c, track.width_right(s_c) + e_c)
        gap = gap - 0.5 * vehicle.width
        k = int(np.flatnonzero(inside)[np.argmin(gap[inside])])
        out.append(Demand("edge clearance", "m", float(gap[k]), float(s[k]), 0.0))
        grade = np.degrees(np.abs(np.asarray(track.grade(s_c), dtype=float)))
        out.append(_largest("grade", "deg", grade, s, math.nan, inside))
    return out


def format_demands(demands: list[Demand]) -> str:
    """The demands as a small text table (value, limit, share, where)."""
    lines = [f"{'demand':<15} {'largest':>9} {'limit':>9} {'share':>7}  {'at s':>8}"]
    for d in demands:
        share = "" if math.isnan(d.share) else f"{d.share:7.2f}"
        limit = "" if math.isnan(d.limit) else f"{d.limit:9.3g}"
        lines.append(f"{d.name:<15} {d.peak:9.3g} {limit:>9} {share:>7}  {d.s:6.0f} m  ({d.unit})")
    return "\n".join(lines)
