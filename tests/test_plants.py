"""Tests of racing_lib.plants: CommonRoad's single-track drift model as a racing_lib plant.

The truths are the package's own: its ``vehicle_dynamics_std`` (the transcription must compute
its derivative), its constraint functions and parameter sets (the wrapper must respect the car's
limits), plus what any car must do (a circle of the kinematic radius at low speed, walls that stop
it and are counted as the simulated car counts them).
"""

from __future__ import annotations

import importlib
import math
import sys

import casadi as ca
import numpy as np
import pytest

from racing_lib.errors import ControlError, PlantError
from racing_lib.geometry import Path, Track
from racing_lib.interfaces import Plant
from racing_lib.sim import SimulatedCar
from racing_lib.vehicle import VehicleParams

vm = pytest.importorskip("vehiclemodels.vehicle_dynamics_std")
from test_sim import stadium  # noqa: E402  (the same test track as the simulated car's tests)
from vehiclemodels.vehicle_parameters import setup_vehicle_parameters  # noqa: E402

from racing_lib.plants.commonroad import (  # noqa: E402
    CommonRoadAt,
    CommonRoadCar,
    _casadi_field,
    _python_field,
    data_sheet,
    vehicle_parameters,
)
from racing_lib.plants.std import N_STATE, std_vector_field  # noqa: E402

BMW = 2


def open_area(radius: float = 300.0, width: float = 250.0) -> Track:
    a = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    return Track(Path(radius * np.cos(a), radius * np.sin(a)), width, width, name="area")


def random_states(p, rng: np.random.Generator, n: int) -> list[list[float]]:
    """States over the package's range: standstill and crawling (the kinematic blend) to 60 m/s,
    large slip angles and steering, wheels slipping and locked."""
    out = []
    for k in range(n):
        v = rng.uniform(-0.3, 0.6) if k % 3 == 0 else rng.uniform(0.0, 60.0)
        beta, delta = rng.uniform(-0.6, 0.6), rng.uniform(-1.1, 1.1)
        rolling = v * math.cos(beta) / p.R_w
        x = [rng.uniform(-100, 100), rng.uniform(-100, 100), delta, v, rng.uniform(-7, 7),
             rng.uniform(-2, 2), beta]  # fmt: skip
        x += [rolling * rng.uniform(0.8, 1.2) + rng.uniform(-1.0, 1.0) for _ in range(2)]
        out.append(x)
    return out


# --------------------------------------------------------------------------- the transcription


@pytest.mark.parametrize("vehicle", [1, 2, 3])
def test_the_transcription_computes_the_packages_std_derivative(vehicle):
    """std_vector_field (CasADi) == vehiclemodels' vehicle_dynamics_std, state by state."""
    p = setup_vehicle_parameters(vehicle_id=vehicle)
    xs, us = ca.SX.sym("x", N_STATE), ca.SX.sym("u", 2)
    field = std_vector_field(ca.vertsplit(xs), [us[0], us[1]], p)
    f = ca.Function("f", [xs, us], [ca.vertcat(*field)])
    rng = np.random.default_rng(vehicle)
    for x in random_states(p, rng, 2000):
        u = [rng.uniform(-1.0, 1.0), rng.uniform(-15.0, 15.0)]  # beyond the limits, too
        ref = np.array(vm.vehicle_dynamics_std(list(x), list(u), p), dtype=float)
        got = np.array(f(x, u), dtype=float).ravel()
        # Relative to each entry's size, and to 1 for entries that cancel to about zero.
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(ref).max()))


def test_the_plants_field_is_the_same_with_both_engines():
    """The command mapping (servo, pedal) then std: CasADi transcription == package function."""
    p = vehicle_parameters(BMW)
    xs, cmd = ca.SX.sym("x", N_STATE), ca.SX.sym("c", 3)
    field = _casadi_field(ca.vertsplit(xs), cmd[0], cmd[1], cmd[2], p)
    f = ca.Function("f", [xs, cmd], [ca.vertcat(*field)])
    rng = np.random.default_rng(7)
    for x in random_states(p, rng, 500):
        c = [rng.uniform(-1.2, 1.2), rng.uniform(-1.0, 1.0), rng.uniform(0.02, 0.2)]
        ref = np.array(_python_field(x, *c, p), dtype=float)
        got = np.array(f(x, c), dtype=float).ravel()
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(ref).max()))


def test_a_drive_is_the_same_with_the_compiled_transcription_and_the_package():
    track = stadium(straight=600.0, radius=100.0, width=5.0, boundary="walls")
    cars = [CommonRoadCar(track, BMW, start_s=20.0, start_speed=15.0, engine=e)
            for e in ("casadi", "python")]  # fmt: skip
    # Weaving, throttle then brake, and into the left wall.
    commands = [(0.03 * math.sin(0.3 * k) + (0.05 if k > 60 else 0.0), 0.8 if k < 40 else -0.6)
                for k in range(80)]  # fmt: skip
    obs = [[car.step(*c) for c in commands] for car in cars]
    a, b = (np.array([[o.x, o.y, o.psi, o.vx, o.vy, o.r] for o in run]) for run in obs)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    assert cars[0].wall_contacts == cars[1].wall_contacts > 0


def test_the_chosen_substeps_are_converged(monkeypatch):
    """Four times as many RK4 substeps move a 10 s drive (throttle, weaving, braking) by < 1 mm."""

    def drive(refine: int) -> np.ndarray:
        car = CommonRoadCar(open_area(), BMW, start_speed=20.0)
        chosen = CommonRoadCar.substeps
        monkeypatch.setattr(car, "substeps", lambda: refine * chosen(car))
        car.reset()
        commands = [(0.01 * math.sin(0.5 * k), 0.6 if k < 50 else -0.5) for k in range(100)]
        return np.array([[o.x, o.y, o.vx, o.vy] for o in (car.step(*c) for c in commands)])

    np.testing.assert_allclose(drive(1), drive(4), rtol=0, atol=1e-3)


# --------------------------------------------------------------------------- the car's limits


def test_the_steering_servo_keeps_the_cars_rate_and_angle_limits():
    car = CommonRoadCar(open_area(), BMW, start_speed=10.0)
    p = car.params.steering
    car.reset()
    rate, _ = car.model_inputs(0.3, 0.0)
    assert rate == pytest.approx(p.v_max)  # 0.3 rad away: the servo asks 6 rad/s, gets 0.4
    steer = [car.state_info()["steer"]]
    for _ in range(40):
        car.step(5.0, 0.0)  # far beyond the angle limit
        steer.append(car.state_info()["steer"])
    steps = np.diff(steer)
    assert steps.max() <= p.v_max * car.dt + 1e-9  # never faster than the car's steering rate
    assert steps[0] == pytest.approx(p.v_max * car.dt, rel=1e-6)
    assert max(steer) <= p.max + 1e-9
    assert steer[-1] == pytest.approx(p.max, abs=1e-3)  # at the limit and held there
    rate, _ = car.model_inputs(5.0, 0.0)
    assert abs(rate) < 1e-9  # the command is clipped to the limit: the servo holds it there


def test_the_pedal_maps_to_the_packages_acceleration_limits():
    car = CommonRoadCar(open_area(), BMW, start_speed=30.0)
    lon = car.params.longitudinal
    car.reset()
    _, a = car.model_inputs(0.0, 1.0)
    assert a == pytest.approx(lon.a_max * lon.v_switch / 30.0)  # the power limit at speed
    _, a = car.model_inputs(0.0, -1.0)
    assert a == pytest.approx(-lon.a_max)
    _, a = car.model_inputs(0.0, -0.5)
    assert a == pytest.approx(-0.5 * lon.a_max)
    obs = car.reset()
    car.set_state(obs.x, obs.y, obs.psi, vx=5.0)
    _, a = car.model_inputs(0.0, 0.5)
    assert a == pytest.approx(0.5 * lon.a_max)  # below v_switch: no power limit
    car.set_state(obs.x, obs.y, obs.psi, vx=0.0)
    _, a = car.model_inputs(0.0, -1.0)
    assert a == 0.0  # a brake does not drive a standing car backwards


def test_a_straight_line_reaches_v_max_but_not_beyond():
    car = CommonRoadCar(stadium(straight=4000.0), BMW, start_s=5.0, start_speed=40.0)
    v_max = car.params.longitudinal.v_max
    car.reset()
    v = [car.step(0.0, 1.0).vx for _ in range(150)]
    info = car.state_info()
    assert max(v) <= v_max + 0.05
    assert v[-1] >= v_max - 0.1
    # On the way up, the power limit: about a_max v_switch / v (tyre slip takes a little).
    lon = car.params.longitudinal
    a_42 = np.interp(42.0, v, np.gradient(v, car.dt))
    assert a_42 == pytest.approx(lon.a_max * lon.v_switch / 42.0, rel=0.05)
    assert info["accel"] == 0.0  # at v_max the package's constraint cuts the throttle


def test_a_constant_steer_circle_has_the_kinematic_radius_at_low_speed():
    car = CommonRoadCar(open_area(), BMW, start_speed=5.0)
    p = car.params
    car.reset()
    delta = 0.06
    xy, r, v = [], [], []
    for _ in range(300):
        obs = car.step(delta, 0.3 * (5.0 - car.state_info()["v"]))
        xy.append((obs.x, obs.y))
        r.append(obs.r)
        v.append(math.hypot(obs.vx, obs.vy))
    pts = np.array(xy[100:])
    # Circle through the positions (algebraic least squares).
    a = np.c_[2 * pts, np.ones(len(pts))]
    c = np.linalg.lstsq(a, (pts**2).sum(axis=1), rcond=None)[0]
    radius = math.sqrt(c[2] + c[0] ** 2 + c[1] ** 2)
    # The centre of gravity's kinematic radius: the rear axle's L / tan(delta), then to the CoG.
    r_rear = (p.a + p.b) / math.tan(delta)
    assert radius == pytest.approx(math.hypot(r_rear, p.b), rel=0.03)
    assert np.mean(r[100:]) == pytest.approx(np.mean(v[100:]) / radius, rel=0.01)
    assert np.std(r[100:]) < 1e-3  # a steady circle


def test_faster_the_same_steer_drives_a_wider_circle():
    """The BMW understeers (as road cars do): at 15 m/s the yaw rate is below kinematic."""
    car = CommonRoadCar(open_area(), BMW, start_speed=15.0)
    car.reset()
    for _ in range(200):
        obs = car.step(0.05, 0.3 * (15.0 - car.state_info()["v"]))
    kinematic = obs.vx * math.tan(0.05) / (car.params.a + car.params.b)
    assert 0.5 * kinematic < obs.r < kinematic


# --------------------------------------------------------------------------- the track


def test_walls_stop_the_car_and_are_counted_as_the_simulated_car_counts_them():
    track = stadium(straight=1000.0, radius=100.0, width=5.0, boundary="walls")
    cars = [CommonRoadCar(track, BMW, start_s=50.0, start_speed=20.0),
            SimulatedCar(track, start_s=50.0, start_speed=20.0)]  # fmt: skip
    p = cars[0].params
    overhang = 0.5 * (p.l - p.a - p.b)
    front, rear = p.a + overhang, -(p.b + overhang)
    extents = []  # of the CommonRoad car's body
    for car in cars:
        obs = car.reset()
        car.set_state(obs.x, obs.y, obs.psi + 0.25, 20.0)  # 14 degrees towards the left wall
        v = [20.0]
        for _ in range(30):
            obs = car.step(0.0, 0.2)
            v.append(obs.vx)
            info = car.state_info()
            if isinstance(car, CommonRoadCar):
                sp, cp = math.sin(info["e_psi"]), math.cos(info["e_psi"])
                extents.append(info["e_y"] + max(front * sp, rear * sp) + 0.5 * p.w * abs(cp))
        assert car.wall_contacts == 1  # one hit, then scraping along: one episode
        assert 0.0 < car.wall_contact_time <= 3.0
        assert np.diff(v).min() < -1.0  # the impact cost speed
        assert abs(info["e_psi"]) < 0.05  # the impact at the nose turned the car along the wall
    assert max(extents) <= 5.0 + 1e-6
    car = cars[0]
    car.reset()
    assert car.wall_contacts == 0 and car.wall_contact_time == 0.0


def test_open_edges_count_the_time_off_the_track():
    car = CommonRoadCar(stadium(width=5.0), BMW, start_s=50.0, start_speed=20.0)
    obs = car.reset()
    car.set_state(obs.x, obs.y - 6.0, obs.psi, 20.0)  # right of the right edge
    car.step(0.0, 0.0)
    assert car.state_info()["offtrack"]
    assert car.offtrack_time == pytest.approx(0.1)


# --------------------------------------------------------------------------- the contract


def test_it_is_a_plant_and_starts_where_identification_and_laps_need_it():
    track = stadium()
    car = CommonRoadAt(BMW)(track, 12.0)
    assert isinstance(car, Plant)
    obs = car.reset(seed=3)
    heading = float(np.asarray(track.centerline.heading(0.0)))
    assert (obs.t, obs.x, obs.y, obs.psi) == (0.0, 0.0, -200.0, heading)  # the centerline's start
    assert (obs.vx, obs.vy, obs.r) == (12.0, 0.0, 0.0)
    obs = car.set_state(x=10.0, y=-199.0, psi=0.1, vx=15.0, vy=0.5, r=0.05)
    assert (obs.x, obs.y, obs.psi, obs.r) == (10.0, -199.0, 0.1, 0.05)
    assert (obs.vx, obs.vy) == pytest.approx((15.0, 0.5), abs=1e-12)
    # The wheels start rolling: no slip, no jump in the first step.
    info = car.state_info()
    assert info["omega_r"] * car.params.R_w == pytest.approx(15.0, rel=1e-12)


def test_non_finite_states_and_commands_are_one_clear_error():
    car = CommonRoadCar(stadium(), BMW)
    car.reset()
    with pytest.raises(ControlError, match="non-finite command"):
        car.step(float("nan"), 0.0)
    with pytest.raises(PlantError, match="non-finite value"):
        car.set_state(0.0, float("nan"), 0.0, 10.0)
    car._state[5] = float("nan")  # a diverged state (as a non-physical parameter set would give)
    with pytest.raises(PlantError, match=r"became non-finite at t = 0.00 s.*r=nan"):
        car.step(0.0, 0.0)


def test_a_spun_car_is_one_clear_error():
    car = CommonRoadCar(open_area(), BMW, start_speed=30.0)
    car.reset()
    with pytest.raises(PlantError, match="spun: its slip angle is beyond 90 degrees"):
        for _ in range(30):  # full brake in a gentle turn at 30 m/s: the rear wheels lock
            car.step(0.1, -1.0)


def test_it_is_deterministic_under_a_seed():
    def run(seed, noise):
        car = CommonRoadCar(open_area(), BMW, start_speed=15.0, steer_noise_std=noise,
                            pedal_noise_std=noise)  # fmt: skip
        car.reset(seed)
        return [car.step(0.02, 0.1) for _ in range(30)]

    assert run(1, 0.01) == run(1, 0.01)
    assert run(1, 0.01) != run(2, 0.01)
    assert run(1, 0.0) == run(2, 0.0) == run(None, 0.0)  # no noise: the seed does not matter


@pytest.mark.parametrize("vehicle", [1, 2, 3])
def test_each_passenger_car_of_the_package_drives(vehicle):
    car = CommonRoadCar(stadium(), vehicle, start_s=10.0, start_speed=15.0)
    car.reset()
    obs = [car.step(0.01, 0.2) for _ in range(50)]
    assert all(math.isfinite(o.x + o.y + o.vx + o.vy + o.r) for o in obs)
    assert obs[-1].vx > 15.0 and obs[-1].x > 10.0 + 5 * 15.0
    assert obs[-1].psi > 0.0  # steering left turns it left


def test_the_truck_and_other_things_are_refused_with_a_reason():
    with pytest.raises(PlantError, match="vehicle id 4"):
        CommonRoadCar(stadium(), 4)
    with pytest.raises(PlantError, match="ids 1 to 4"):
        CommonRoadCar(stadium(), 7)
    with pytest.raises(PlantError, match="vehicle id"):
        CommonRoadCar(stadium(), "bmw")


def test_a_missing_extra_names_the_install_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "vehiclemodels", None)  # as if it were not installed
    for name in [m for m in sys.modules if m.startswith("vehiclemodels.")]:
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.delitem(sys.modules, "racing_lib.plants.commonroad")
    with pytest.raises(PlantError, match=r'pip install "racing-lib\[commonroad\]"'):
        importlib.import_module("racing_lib.plants.commonroad")
    monkeypatch.undo()
    assert importlib.import_module("racing_lib.plants.commonroad").CommonRoadCar


def test_the_data_sheet_carries_the_packages_numbers():
    p = vehicle_parameters(BMW)
    sheet = data_sheet(BMW)
    assert (sheet.m, sheet.l_f, sheet.l_r, sheet.I_zz) == (p.m, p.a, p.b, p.I_z)
    f_zf = sheet.static_loads()[0]
    c_f = sheet.cornering_stiffness()[0]
    assert c_f == pytest.approx(abs(p.tire.p_ky1) * f_zf)  # the package's K_y = |p_ky1| F_z
    assert sheet.C_xw == 0.0 and sheet.c_rr == 0.0
    assert VehicleParams().wall_mu > 0.0  # the walls are the simulated car's


# --------------------------------------------------------------------------- a closed-loop lap


@pytest.mark.slow
def test_the_coupled_mpc_drives_the_bmw_round_a_lap_with_a_data_sheet_model():
    """The paper's controller on a car nobody here wrote, with what its data sheet says.

    The model: the package's numbers for the BMW 320i (data_sheet) and its steering limits
    (0.4 rad/s, 1.066 rad). On the centerline plan at 80 % of its speed the lap is clean
    (seed 0: 128.4 s against the plan's 129.0 s, e_y 1.4 cm on average); at 90 % too, but from
    95 % the BMW spins in the first hairpin: the data-sheet model knows neither that a hard
    brake locks its rear wheels (no ABS, 66 % of the brake torque at the front) nor that more
    than about half throttle spins them at low speed (rear drive, no traction control).
    """
    from racing_lib.control import build_controller
    from racing_lib.experiments.lap import run_lap
    from racing_lib.model import CarModel
    from racing_lib.planning import plan
    from racing_lib.tracks import load_track

    track = load_track("shortcut")
    p = vehicle_parameters(BMW)
    model = CarModel(
        data_sheet(BMW), steer_tau=0.05, steer_max=p.steering.max, steer_rate_max=p.steering.v_max
    )
    planned = plan(track, "centerline", model)
    assert planned.success, planned.status
    traj = planned.trajectory.scale_speed(0.8)
    s0 = traj.path.length - 150.0
    v0 = float(np.interp(s0, traj.s, traj.vx, period=traj.path.length))
    car = CommonRoadCar(track, BMW, start_s=s0, start_speed=v0)
    controller = build_controller("coupled-mpc", traj, track=track, model=model)
    m = run_lap(car, controller, traj, track=track, seed=0).metrics
    assert m.completed, m
    assert m.wall_contacts == 0 and m.offtrack_time_s == 0.0, m
    assert m.ey_mae_m < 0.1 and m.vx_mae_mps < 0.5, m
    assert m.lap_time_s == pytest.approx(traj.lap_time, rel=0.03), (m.lap_time_s, traj.lap_time)
