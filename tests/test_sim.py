"""Tests of racing_lib.sim: the simulated car against analytic truths and its contract."""

from __future__ import annotations

import dataclasses
import math
from functools import cache

import casadi as ca
import numpy as np
import pytest

from racing_lib.errors import ControlError, PlantError, RacingLibError
from racing_lib.geometry import (
    Path,
    Track,
)
from racing_lib.interfaces import (
    Observation,
    Plant,
)
from racing_lib.jit import c_compiler
from racing_lib.sim import SimulatedCar
from racing_lib.vehicle import CASADI_OPS, VehicleParams, static_axle_loads
from racing_lib.vehicle.dynamics import (
    RK4_IN,
    RK4_OUT,
    SimState,
    car_vector_field,
    rk4_substep_function,
)

P = VehicleParams()
G = P.g


@cache
def stadium(straight: float = 3000.0, radius: float = 200.0, width: float = 20.0,
            boundary: str = "open") -> Track:  # fmt: skip
    """Counter-clockwise stadium; s = 0 at the start of the bottom straight, heading +x."""
    pts = [(i * 5.0, -radius) for i in range(int(straight / 5.0))]
    n_arc = int(math.pi * radius / 5.0)
    for i in range(n_arc):
        a = -math.pi / 2 + math.pi * i / n_arc
        pts.append((straight + radius * math.cos(a), radius * math.sin(a)))
    pts += [(straight - i * 5.0, radius) for i in range(int(straight / 5.0))]
    for i in range(n_arc):
        a = math.pi / 2 + math.pi * i / n_arc
        pts.append((radius * math.cos(a), radius * math.sin(a)))
    xy = np.array(pts)
    return Track(Path(xy[:, 0], xy[:, 1]), width, width, boundary=boundary, name="stadium")


@cache
def big_circle(radius: float = 300.0, width: float = 250.0) -> Track:
    """An open circular area wide enough that nothing leaves it."""
    a = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    return Track(Path(radius * np.cos(a), radius * np.sin(a)), width, width, name="circle")


def drive(car: SimulatedCar, steer: float, pedal: float, steps: int) -> list[Observation]:
    return [car.step(steer, pedal) for _ in range(steps)]


# --------------------------------------------------------------------------- longitudinal


def test_coast_down_matches_the_closed_form():
    """Pedal 0 on a flat straight: m dv/dt = -C_xw v^2 - c_rr m g, solved with atan/tan."""
    car = SimulatedCar(stadium(), start_s=10.0, start_speed=40.0)
    car.reset()
    obs = drive(car, 0.0, 0.0, 300)
    f_r = P.c_rr * P.m * G
    v_c = math.sqrt(f_r / P.C_xw)
    t = np.array([o.t for o in obs])
    v_exact = v_c * np.tan(np.arctan(40.0 / v_c) - t * math.sqrt(P.C_xw * f_r) / P.m)
    v_sim = np.array([o.vx for o in obs])
    np.testing.assert_allclose(v_sim, v_exact, rtol=1e-6)
    assert v_sim[-1] < 33.0  # it did slow down noticeably


def test_top_speed_is_about_190_kmh():
    car = SimulatedCar(stadium(), start_s=10.0, start_speed=45.0)
    car.reset()
    v = max(o.vx for o in drive(car, 0.0, 1.0, 450))
    assert 50.0 < v < 55.0
    assert car.state_info()["gear"] == len(P.gear_ratios)


def test_full_brake_from_30_mps_is_about_one_g():
    car = SimulatedCar(stadium(), start_s=10.0, start_speed=30.0)
    car.reset()
    obs = drive(car, 0.0, -1.0, 20)
    decel = (30.0 - obs[-1].vx) / obs[-1].t
    assert 0.9 * G < decel < 1.3 * G


def test_zero_to_100_kmh_and_gears_shift_up():
    car = SimulatedCar(stadium(), start_s=10.0, start_speed=0.0)
    obs = car.reset()
    gears = [car.state_info()["gear"]]
    while obs.vx < 100.0 / 3.6 and obs.t < 20.0:
        obs = car.step(0.0, 1.0)
        gears.append(car.state_info()["gear"])
    assert 8.0 < obs.t < 14.0
    assert gears[0] == 1 and gears[-1] >= 3
    assert all(b >= a for a, b in zip(gears, gears[1:], strict=False))  # only up while speeding up


# --------------------------------------------------------------------------- lateral


def _steady_radius(delta: float, v: float) -> tuple[float, float, SimulatedCar]:
    car = SimulatedCar(big_circle(), start_speed=v)
    obs = car.reset()
    for _ in range(300):  # a speed loop holds v; steering is constant
        obs = car.step(delta, 0.5 * (v - obs.vx) + 0.02)
    speed = math.hypot(obs.vx, obs.vy)
    return speed / obs.r, speed, car


def _understeer_gradient() -> float:
    """K_us = m / L (l_r / C_af - l_f / C_ar), rad / (m/s^2), from the tyre parameters."""
    f_zf, f_zr = static_axle_loads(P.m, P.l_f, P.l_r, P.g)

    def axle(f_z_axle: float, b: float, c: float, d: float) -> float:
        fz = 0.5 * f_z_axle  # per wheel, with the peak factor's load sensitivity
        d_eff = d * (1.0 - P.load_sensitivity * (fz - P.F_z0) / P.F_z0)
        return 2.0 * P.mu * fz * d_eff * b * c

    c_f = axle(f_zf, P.B_f, P.C_f, P.D_f)
    c_r = axle(f_zr, P.B_r, P.C_r, P.D_r)
    wheelbase = P.l_f + P.l_r
    return P.m / wheelbase * (P.l_r / c_f - P.l_f / c_r)


@pytest.mark.parametrize(("delta", "v"), [(0.05, 10.0), (0.03, 13.0)])
def test_steady_state_radius_matches_the_linear_bicycle(delta, v):
    """Small lateral acceleration: delta = (L + K_us v^2) / R."""
    radius, speed, car = _steady_radius(delta, v)
    k_us = _understeer_gradient()
    wheelbase = P.l_f + P.l_r
    predicted = (wheelbase + k_us * speed**2) / delta
    assert radius == pytest.approx(predicted, rel=0.01)
    # the check can tell: the kinematic radius L / delta is more than 3 % off
    assert abs(radius - wheelbase / delta) > 0.03 * radius
    assert car.offtrack_time == 0.0


def test_lateral_acceleration_never_exceeds_the_friction_limit():
    car = SimulatedCar(big_circle(), start_speed=8.0)
    obs = car.reset()
    a_max = 0.0
    for k in range(700):  # speed ramps up at 0.2 m/s^2 at a fixed, large steering angle
        obs = car.step(0.15, 0.5 * (8.0 + 0.02 * k - obs.vx))
        a_max = max(a_max, abs(math.hypot(obs.vx, obs.vy) * obs.r))
    assert a_max <= P.mu * G * 1.02
    assert a_max > 0.8 * P.mu * G  # and it did get near the limit


# --------------------------------------------------------------------------- walls and edges


def test_wall_contact_is_counted_and_the_car_stays_inside():
    track = stadium(straight=1000.0, radius=100.0, width=5.0, boundary="walls")
    car = SimulatedCar(track, start_s=50.0, start_speed=20.0)
    obs = car.reset()
    car.set_state(obs.x, obs.y, obs.psi + 0.25, 20.0)  # 14 degrees towards the left wall
    front, rear = P.l_f + P.overhang_front, -(P.l_r + P.overhang_rear)
    extents = []
    for _ in range(30):
        obs = car.step(0.0, 0.2)
        info = car.state_info()
        sp, cp = math.sin(info["e_psi"]), math.cos(info["e_psi"])
        extents.append(info["e_y"] + max(front * sp, rear * sp) + 0.5 * P.width * abs(cp))
    assert car.wall_contacts == 1  # one hit, then scraping along: one episode
    assert car.wall_contact_time > 0.0
    assert max(extents) <= 5.0 + 1e-6
    assert obs.vx < 19.0  # the contact cost speed
    assert abs(info["e_psi"]) < 0.05  # the impact at the nose turned the car along the wall


def test_open_track_edge_lowers_friction_and_counts_time():
    car = SimulatedCar(stadium(width=5.0), start_s=50.0, start_speed=20.0)
    obs = car.reset()
    car.set_state(obs.x, obs.y - 6.0, obs.psi, 20.0)  # right of the right edge
    car.step(0.0, 0.0)
    info = car.state_info()
    assert info["offtrack"]
    assert info["mu_wheels"] == pytest.approx((P.mu * P.offtrack_mu_factor,) * 4)
    assert car.offtrack_time == pytest.approx(0.1)


# --------------------------------------------------------------------------- contract


def _lap(seed: int | None, steps: int = 150) -> list[Observation]:
    car = SimulatedCar(big_circle(), start_speed=15.0)
    obs = car.reset(seed)
    out = []
    for _ in range(steps):
        steer = 0.01 - 0.05 * (obs.vx - 15.0)
        obs = car.step(steer, 0.3 * (18.0 - obs.vx))
        out.append(obs)
    return out


def test_same_seed_same_lap_bit_for_bit():
    a, b, c = _lap(3), _lap(3), _lap(4)
    assert a == b  # dataclass equality: every float identical
    diff = max(abs(p.x - q.x) + abs(p.y - q.y) for p, q in zip(a, c, strict=True))
    assert 1e-6 < diff < 5.0  # another seed differs, but only slightly
    assert _lap(None) == _lap(None)


def test_nan_command_raises_a_clear_error():
    car = SimulatedCar(big_circle())
    car.reset()
    with pytest.raises(ControlError, match="non-finite command") as err:
        car.step(float("nan"), 0.0)
    assert isinstance(err.value, RacingLibError)


def test_nan_state_raises_a_plant_error():
    car = SimulatedCar(big_circle())
    car.reset()
    with pytest.raises(PlantError):
        car.set_state(0.0, 0.0, 0.0, float("nan"))
    car._state[SimState.VX] = float("nan")  # corrupt the state as a numerical blow-up would
    with pytest.raises(PlantError, match="vx=nan") as err:
        car.step(0.0, 0.0)
    assert "t = 0.00 s" in str(err.value)


def test_plant_protocol_and_observation():
    car = SimulatedCar(big_circle(), start_s=100.0, start_speed=12.0)
    assert isinstance(car, Plant)
    obs = car.reset()
    assert obs.t == 0.0 and obs.vx == 12.0 and obs.vy == 0.0
    x, y = big_circle().centerline.position(100.0)
    assert (obs.x, obs.y) == pytest.approx((float(x), float(y)))
    obs = car.step(0.0, 0.0)
    assert obs.t == pytest.approx(0.1)
    info = car.state_info()
    assert {"gear", "rpm", "steer", "s", "e_y", "a_x", "F_z"} <= set(info)


def test_steering_is_rate_limited():
    car = SimulatedCar(big_circle(), start_speed=10.0)
    car.reset()
    car.step(0.5, 0.0)
    assert car.state_info()["steer"] <= P.steer_rate_max * 0.1 + 1e-12


# --------------------------------------------------------------------------- vector field


def test_vector_field_casadi_equals_float():
    rng = np.random.default_rng(0)
    xs = ca.SX.sym("x", len(SimState))
    u = ca.SX.sym("u", 5)  # delta_cmd, f_drive, f_brake, a_x, a_y
    d, a = car_vector_field(
        xs, u[0], u[1], u[2], 0.02, (1.2, 1.2, 1.1, 1.25), (u[3], u[4]), P, CASADI_OPS
    )
    f = ca.Function("f", [xs, u], [ca.vertcat(*d, *a)])
    for _ in range(5):
        state = [*rng.normal(0, 10, 3), rng.uniform(5, 40), *rng.normal(0, 0.5, 2), 0.05]
        inp = [0.1, rng.uniform(0, 4000), rng.uniform(0, 4000), *rng.normal(0, 3, 2)]
        d_f, a_f = car_vector_field(
            state, inp[0], inp[1], inp[2], 0.02, (1.2, 1.2, 1.1, 1.25), (inp[3], inp[4]), P
        )
        np.testing.assert_allclose(
            np.asarray(f(state, inp)).ravel(), [*d_f, *a_f], rtol=1e-10, atol=1e-9
        )


def float_rk4(y0, delta_cmd, f_drive, f_brake, theta, mu_w, a_tr, h):
    """One RK4 substep of the float vector field: the reference for the compiled substep."""

    def field(y):
        return car_vector_field(y, delta_cmd, f_drive, f_brake, theta, mu_w, a_tr, P)

    k1, _ = field(y0)
    k2, _ = field([a + 0.5 * h * b for a, b in zip(y0, k1, strict=True)])
    k3, _ = field([a + 0.5 * h * b for a, b in zip(y0, k2, strict=True)])
    k4, a_g = field([a + h * b for a, b in zip(y0, k3, strict=True)])
    new = [
        a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
        for a, b1, b2, b3, b4 in zip(y0, k1, k2, k3, k4, strict=True)
    ]
    return new, a_g, (k4[SimState.VX], k4[SimState.VY])


def test_the_simulators_substep_is_rk4_of_the_float_vector_field():
    # The simulator evaluates rk4_substep_function in place; it must be the float RK4 of
    # car_vector_field, across speeds, slip, full throttle and brake, and off-track friction.
    rng = np.random.default_rng(3)
    fn = rk4_substep_function(P)
    assert fn.numel_in(0) == sum(n for _, n in RK4_IN.values())
    assert fn.numel_out(0) == sum(n for _, n in RK4_OUT.values())
    for _ in range(20):
        state = [*rng.normal(0, 100, 2), rng.normal(0, 3), rng.uniform(0.5, 80),
                 *rng.normal(0, 1.0, 2), rng.normal(0, 0.2)]  # fmt: skip
        inputs = (rng.normal(0, 0.3), rng.uniform(0, 8000), rng.uniform(0, 12000) * rng.integers(2),
                  rng.normal(0, 0.05), tuple(rng.uniform(0.5, 1.3, 4)), tuple(rng.normal(0, 8, 2)),
                  0.025)  # fmt: skip
        want = float_rk4(state, *inputs)
        d, fd, fb, th, mu, a_tr, h = inputs
        got = np.asarray(fn([*state, d, fd, fb, th, *mu, *a_tr, h])).ravel()
        np.testing.assert_allclose(got, np.concatenate(want), rtol=1e-12, atol=1e-10)


def test_the_simulators_step_uses_the_rk4_layout(monkeypatch):
    # A car whose substep is the float RK4 drives the same lap start as the real one: the order
    # in which SimulatedCar fills the input is RK4_IN's.
    car = SimulatedCar(stadium(), start_speed=30.0)
    ref = SimulatedCar(stadium(), start_speed=30.0)
    car.reset(seed=4)
    ref.reset(seed=4)

    def rk4_in_python(h, delta_cmd, f_drive, f_brake):
        new, a_g, (dvx, dvy) = float_rk4(ref._state, delta_cmd, f_drive, f_brake, ref._theta,
                                         ref._mu_wheels, ref._a_transfer, h)  # fmt: skip
        ref._state, ref._a_transfer = new, a_g
        ref._a_body = (dvx - new[SimState.R] * new[SimState.VY],
                       dvy + new[SimState.R] * new[SimState.VX])  # fmt: skip

    monkeypatch.setattr(ref, "_rk4", rk4_in_python)
    for k in range(60):
        steer, pedal = 0.02 * math.sin(0.1 * k), (1.0 if k < 30 else -0.6)
        a, b = car.step(steer, pedal), ref.step(steer, pedal)
        assert a.x == pytest.approx(b.x, abs=1e-9) and a.vx == pytest.approx(b.vx, abs=1e-9)
        assert a.r == pytest.approx(b.r, abs=1e-9) and a.psi == pytest.approx(b.psi, abs=1e-9)


def test_the_compiled_substep_drives_the_interpreters_lap_bit_for_bit():
    # The car compiles its substep where a C compiler works; the numbers must be the interpreter's
    # to the last bit (no fused multiply-adds, no fast math), through gears, walls and braking.
    compiled = SimulatedCar(stadium(boundary="walls"), start_speed=30.0)
    interpreted = SimulatedCar(stadium(boundary="walls"), start_speed=30.0, jit=False)
    assert interpreted._rk4_fn.fn.class_name() == "SXFunction"
    if c_compiler()[0] is not None:
        assert compiled._rk4_fn.fn.class_name() == "External"
    logs = []
    for car in (compiled, interpreted):
        car.reset(seed=2)
        logs.append(
            [car.step(0.03 * math.sin(0.05 * k), 1.0 if k < 150 else -0.8) for k in range(300)]
        )
    assert logs[0] == logs[1]
    assert compiled.wall_contacts == interpreted.wall_contacts > 0


def test_grade_decelerates_by_g_sin_theta():
    state = [0.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.0]
    mu = (P.mu,) * 4
    flat, _ = car_vector_field(state, 0.0, 0.0, 0.0, 0.0, mu, (0.0, 0.0), P)
    theta = 0.06
    hill, _ = car_vector_field(state, 0.0, 0.0, 0.0, theta, mu, (0.0, 0.0), P)
    rolling = P.c_rr * G * (math.cos(theta) - 1.0) * math.tanh(20.0 / P.v_smooth)
    expected = -G * math.sin(theta) - rolling
    assert hill[SimState.VX] - flat[SimState.VX] == pytest.approx(expected, rel=1e-9)


def test_params_change_behaviour():
    """No traction control: full throttle out of a tight turn in second gear spins the car."""
    spin = dataclasses.replace(P, tcs_floor=1.0)
    results = []
    for params in (P, spin):
        car = SimulatedCar(big_circle(), params, start_speed=9.0)
        car.reset()
        drive(car, 0.25, 0.1, 30)
        obs = drive(car, 0.25, 1.0, 30)
        results.append(max(abs(o.vy) for o in obs))
    assert results[0] < 1.5 < results[1]
