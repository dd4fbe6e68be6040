"""Tests of the best-lap NLP (the simulated car's own minimum-time lap)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from racing_lib.errors import PlanningError
from racing_lib.planning.best_lap import BestLapSettings, V, frenet_kinematics, solve_best_lap
from racing_lib.sim import SimulatedCar
from racing_lib.tracks import circle_track
from racing_lib.tracks.segments import Arc, Straight, track_from_segments
from racing_lib.vehicle import MATH_OPS, VehicleParams
from racing_lib.vehicle.dynamics import car_vector_field

RADIUS = 50.0


@pytest.fixture(scope="module")
def circle_lap():
    track = circle_track(radius=RADIUS, width=10.0)
    return track, solve_best_lap(track, settings=BestLapSettings(spacing=5.0), start="cold")


@pytest.fixture(scope="module")
def oval_lap():
    track = track_from_segments(
        [Straight(120.0), Arc(40.0, math.pi), Straight(120.0), Arc(30.0, math.pi)],
        width=10.0,
        name="oval",
    )
    return track, solve_best_lap(track, settings=BestLapSettings(spacing=4.0))


def _steady_lateral_acceleration(radius: float, v: float, steer: float) -> float:
    """Lateral acceleration (m/s^2) of the simulated car in steady cornering at constant steer.

    The car starts on a circle of ``radius`` and holds ``v`` with a PI pedal; the track is wide
    enough that it never leaves it, whatever circle the steering gives.
    """
    track = circle_track(radius=radius, width=60.0)
    p = VehicleParams()
    car = SimulatedCar(track, p)
    obs = car.set_state(radius, 0.0, math.pi / 2, v, 0.0, v / radius, steer)
    integral = 0.0
    a_y = []
    seconds = 15.0
    for k in range(int(seconds / car.dt)):
        err = v - obs.vx
        integral += err * car.dt
        obs = car.step(steer, min(1.0, max(-1.0, 0.3 * err + 0.1 * integral)))
        if k * car.dt > seconds - 3.0:
            a_y.append(math.hypot(obs.vx, obs.vy) * obs.r)
    assert car.offtrack_time == 0.0
    return float(np.mean(a_y))


def test_circle_converges_to_the_sim_cars_cornering_limit(circle_lap):
    track, res = circle_lap
    assert res.success, res.status
    sol = res.solution
    # Steady circle: constant speed and offset (the inside edge, the shortest lap).
    assert np.ptp(sol["vx"]) < 0.05
    assert np.ptp(sol["ey"]) < 0.05
    line_radius = RADIUS - float(np.mean(sol["ey"]))
    v_opt = float(np.mean(sol["vx"]))
    # Independent truth: the simulated car's largest steady lateral acceleration over the steering
    # angle at that speed, measured by driving it; the speed it allows on the planned circle.
    a_max = max(_steady_lateral_acceleration(line_radius, v_opt, d) for d in (0.11, 0.13, 0.15))
    v_truth = math.sqrt(a_max * line_radius)
    assert abs(v_opt - v_truth) / v_truth < 0.03
    # Lap time of a constant-speed circle.
    assert res.lap_time == pytest.approx(2 * math.pi * line_radius / v_opt, rel=0.01)
    traj = res.trajectory
    assert traj is not None and traj.method == "best-lap"
    assert traj.planned_lap_time == pytest.approx(res.lap_time, rel=1e-9)


def test_oval_stays_on_track_and_respects_actuators(oval_lap):
    track, res = oval_lap
    assert res.success, res.status
    assert res.start == "warm"
    sol, grid = res.solution, res.grid
    p = VehicleParams()
    tol = 1e-6
    assert np.all(sol["ey"] >= grid.ey_min - tol) and np.all(sol["ey"] <= grid.ey_max + tol)
    assert np.all(sol["fb"] >= -1e-3) and np.all(sol["fb"] <= p.brake_force_max + 1e-3)
    assert np.all(np.abs(sol["delta"]) <= p.steer_max + tol)
    # The oval has straights: the car accelerates and brakes, so the speed varies a lot.
    assert np.ptp(sol["vx"]) > 5.0
    assert np.max(sol["fb"]) > 1000.0
    # One pedal: drive and brake force (nearly) exclusive.
    assert np.max(np.minimum(sol["fd"], sol["fb"])) < 300.0
    # Track edges from the track itself (not the grid): the centre stays inside.
    assert np.all(sol["ey"] < track.width_left(grid.s)) and np.all(
        sol["ey"] > -track.width_right(grid.s)
    )


def _spatial_rates(z: np.ndarray, kappa: float, theta: float, p: VehicleParams) -> np.ndarray:
    """d(state)/ds of the sim's vector field at node values z (11,), algebraic loop closed."""
    a_tr = (z[V.AXT], z[V.AYT])
    state = [0.0, 0.0, 0.0, z[V.VX], z[V.VY], z[V.R], z[V.DELTA]]
    mu = (p.mu,) * 4
    for _ in range(6):  # fixed point of the load-transfer accelerations
        d, a_tr = car_vector_field(state, z[V.DCMD], z[V.FD], z[V.FB], theta, mu, a_tr, p)
    d, _ = car_vector_field(state, z[V.DCMD], z[V.FD], z[V.FB], theta, mu, a_tr, p)
    s_dot, e_psi_dot, e_y_dot = frenet_kinematics(
        z[V.VX], z[V.VY], z[V.R], z[V.EPSI], z[V.EY], kappa, MATH_OPS
    )
    return np.array([d[3], d[4], d[5], d[6], e_psi_dot, e_y_dot]) / s_dot


def test_collocation_defects_small_under_reintegration(oval_lap):
    track, res = oval_lap
    grid, sol = res.grid, res.solution
    p = VehicleParams()
    z = np.array([sol[v.name.lower()] for v in V])
    n = grid.n
    scale = np.array([30.0, 1.0, 0.5, 0.1, 0.2, 5.0])
    worst = np.zeros(6)
    steps = 8
    for k in range(n):
        k1 = (k + 1) % n
        h = grid.ds[k] / steps
        x = z[:6, k].copy()
        for i in range(steps):
            # Inputs and algebraic guesses linear between the nodes (the collocation's assumption);
            # the curvature from the centerline itself.
            def rates(frac: float, xs: np.ndarray, k=k, k1=k1) -> np.ndarray:
                zz = (1 - frac) * z[:, k] + frac * z[:, k1]
                zz[:6] = xs
                s = grid.s[k] + frac * grid.ds[k]
                kap = float(track.centerline.curvature(s))
                return _spatial_rates(zz, kap, float(grid.theta[k]), p)

            f0 = i / steps
            df = 1.0 / steps
            r1 = rates(f0, x)
            r2 = rates(f0 + df / 2, x + 0.5 * h * r1)
            r3 = rates(f0 + df / 2, x + 0.5 * h * r2)
            r4 = rates(f0 + df, x + h * r3)
            x = x + h / 6 * (r1 + 2 * r2 + 2 * r3 + r4)
        worst = np.maximum(worst, np.abs(x - z[:6, k1]) / scale)
    # End-of-interval error as a share of each state's typical magnitude. The slow states that set
    # the lap time (v_x, e_psi, e_y) are accurate to about 1 %; the fast ones (v_y, r, delta: the
    # steering lag is 0.08 s, 1-2 m at these speeds, shorter than the 4 m grid) are resolved only
    # roughly by the trapezoid rule (measured: 6 %, 4 %, 3 % at worst).
    assert np.all(worst[[V.VX, V.EPSI, V.EY]] < [0.01, 0.03, 0.01]), worst
    assert np.all(worst[[V.VY, V.R, V.DELTA]] < 0.1), worst


def test_failure_raises_planning_error_naming_ipopt():
    track = circle_track(radius=RADIUS, width=10.0)
    with pytest.raises(PlanningError, match="IPOPT"):
        solve_best_lap(track, settings=BestLapSettings(spacing=10.0, max_iter=1), start="cold")
    with pytest.raises(PlanningError, match="unknown start"):
        solve_best_lap(track, settings=BestLapSettings(spacing=10.0), start="hot")
