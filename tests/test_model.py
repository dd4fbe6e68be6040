"""Tests of racing_lib.model against independent truths: a plain numpy transcription of the paper's
equations (with the load-transfer loop solved by fixed-point iteration), finite differences, the
linear bicycle model's steady-state yaw rate, and the two forms (time, space) against each other."""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import fsolve

from racing_lib.errors import ModelError
from racing_lib.model import (
    NU,
    NX,
    Model,
    ModelOptions,
    ModelParams,
    PedalMap,
    U,
    X,
    discrete_linearization,
    discretize,
    jacobians,
    spatial_dynamics,
    time_dynamics,
)

ALL_OPTIONS = [
    ModelOptions(d, lon, lat)
    for d in (False, True)
    for lon in (False, True)
    for lat in (False, True)
]


def random_points(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """Racing-like states and inputs: moving forward, moderate slip, on a curved line."""
    xi = np.zeros((n, NX))
    xi[:, X.VX] = rng.uniform(8.0, 50.0, n)
    xi[:, X.VY] = rng.uniform(-1.0, 1.0, n)
    xi[:, X.R] = rng.uniform(-0.5, 0.5, n)
    xi[:, X.EPSI] = rng.uniform(-0.3, 0.3, n)
    xi[:, X.EY] = rng.uniform(-4.0, 4.0, n)
    xi[:, X.S] = rng.uniform(0.0, 4000.0, n)
    u = np.column_stack([rng.uniform(-0.15, 0.15, n), rng.uniform(-10.0, 4.0, n)])
    kappa = rng.uniform(-0.05, 0.05, n)
    theta = rng.uniform(-0.08, 0.08, n)
    return xi, u, kappa, theta


def reference_xi_dot(
    p: ModelParams, o: ModelOptions, xi: np.ndarray, u: np.ndarray, kappa: float, theta: float
) -> tuple[np.ndarray, float]:
    """The paper's Eq. 2-15 and Appendix A in numpy; Delta W by plain fixed-point iteration.

    Returns xi_dot and the residual of the implicit load-transfer equation after the iteration.
    """
    vx, vy, r, epsi, ey, _ = xi
    delta, ax = u
    L = p.l_f + p.l_r
    g = p.g

    def tyre(alpha: float, Fz: float, B: float, C: float, D: float) -> float:
        return p.mu * Fz * D * math.sin(C * math.atan(B * alpha))

    alpha_f = delta - (vy + p.l_f * r) / vx  # vx >> VX_GUARD here
    alpha_r = -(vy - p.l_r * r) / vx
    Fzf0 = p.m * g * math.cos(theta) * p.l_r / L
    Fzr0 = p.m * g * math.cos(theta) * p.l_f / L
    Fxw = p.C_xw * vx**2 if o.drag else 0.0
    Rx = p.c_rr * p.m * g * math.cos(theta)

    def vx_dot_of(dW: float) -> float:
        Fyf = tyre(alpha_f, Fzf0 - dW, p.B_f, p.C_f, p.D_f)
        return ax - (Fyf * math.sin(delta) + Rx + Fxw) / p.m - g * math.sin(theta) + r * vy

    dW = 0.0
    if o.longitudinal_weight_transfer:
        for _ in range(60):
            dW = p.m * vx_dot_of(dW) * p.h_c / L
    vxd = vx_dot_of(dW)
    residual = abs(dW - p.m * vxd * p.h_c / L) if o.longitudinal_weight_transfer else 0.0
    Fzf, Fzr = Fzf0 - dW, Fzr0 + dW
    Fyf = tyre(alpha_f, Fzf, p.B_f, p.C_f, p.D_f)
    Fyr = tyre(alpha_r, Fzr, p.B_r, p.C_r, p.D_r)
    vyd = (Fyf * math.cos(delta) + Fyr) / p.m - r * vx
    rd = (p.l_f * Fyf * math.cos(delta) - p.l_r * Fyr) / p.I_zz
    if o.lateral_weight_transfer:
        # Four wheels, each with its own load (Appendix A)
        ay = vyd + r * vx
        dWF = p.m * ay * p.h_c / p.l_t * p.l_r / L
        FyFL = tyre(alpha_f, (Fzf - dWF) / 2, p.B_f, p.C_f, p.D_f)
        FyFR = tyre(alpha_f, (Fzf + dWF) / 2, p.B_f, p.C_f, p.D_f)
        vyd = ((FyFL + FyFR) * math.cos(delta) + Fyr) / p.m - r * vx
        rd = (
            (FyFL + FyFR) * math.cos(delta) * p.l_f
            - Fyr * p.l_r
            + 0.5 * (FyFL - FyFR) * math.sin(delta) * p.l_t
        ) / p.I_zz
    sd = (vx * math.cos(epsi) - vy * math.sin(epsi)) / (1 - kappa * ey)
    out = np.array([vxd, vyd, rd, r - kappa * sd, vx * math.sin(epsi) + vy * math.cos(epsi), sd])
    return out, residual


# --- the equations -------------------------------------------------------------------------------


@pytest.mark.parametrize("options", ALL_OPTIONS, ids=lambda o: o.label())
def test_matches_numpy_transcription_of_paper(options: ModelOptions) -> None:
    rng = np.random.default_rng(1)
    params = ModelParams(B_r=12.0, C_r=1.7)
    model = Model(params, options)
    xi, u, kappa, theta = random_points(rng, 40)
    got = model.xi_dot(xi, u, kappa, theta)
    for i in range(len(xi)):
        want, _ = reference_xi_dot(params, options, xi[i], u[i], kappa[i], theta[i])
        # Slip angles use a smoothed v_x: relative error ~ 1e-4 at 8 m/s
        np.testing.assert_allclose(got[i], want, rtol=2e-4, atol=1e-4)


def test_load_transfer_loop_is_solved_exactly() -> None:
    """The closed form satisfies Delta W = m v_x_dot h_c / L and Eq. 5 to round-off."""
    rng = np.random.default_rng(2)
    params = ModelParams()
    model = Model(params)
    xi, u, kappa, theta = random_points(rng, 500)
    u[:, U.DELTA] = rng.uniform(-0.4, 0.4, len(u))  # stronger coupling than in practice
    xdot = model.xi_dot(xi, u, kappa, theta)
    t = model.terms(xi, u, kappa, theta)
    L = params.wheelbase
    # Eq. 12: the transfer used is the one the resulting acceleration implies
    res_w = t["delta_W"] - params.m * xdot[:, X.VX] * params.h_c / L
    # Eq. 5 with the loads and front force the model used
    rhs = (
        u[:, U.AX]
        - (t["F_yf"] * np.sin(u[:, U.DELTA]) + t["R_x"] + t["F_xw"]) / params.m
        - params.g * np.sin(theta)
        + xi[:, X.R] * xi[:, X.VY]
    )
    res_x = xdot[:, X.VX] - rhs
    assert np.max(np.abs(res_w)) < 1e-8  # N, on loads of ~1e4 N
    assert np.max(np.abs(res_x)) < 1e-11  # m/s^2
    # and the front force is the Pacejka force of the transferred load
    phi = params.mu * params.D_f * np.sin(params.C_f * np.arctan(params.B_f * t["alpha_f"]))
    np.testing.assert_allclose(t["F_yf"], phi * t["F_zf"], rtol=1e-12, atol=1e-9)


def test_time_and_spatial_forms_agree() -> None:
    rng = np.random.default_rng(3)
    for options in (ModelOptions(), ModelOptions(lateral_weight_transfer=True)):
        model = Model(ModelParams(), options)
        xi, u, kappa, theta = random_points(rng, 50)
        xdot = model.xi_dot(xi, u, kappa, theta)
        dxds = model.dxi_ds(xi, u, kappa, theta)
        s_dot = model.terms(xi, u, kappa, theta)["s_dot"]
        np.testing.assert_allclose(dxds * s_dot[:, None], xdot, rtol=1e-12, atol=1e-12)
        assert np.all(dxds[:, X.S] == 1.0)
        # s_dot from Eq. 4, independently
        want = (xi[:, X.VX] * np.cos(xi[:, X.EPSI]) - xi[:, X.VY] * np.sin(xi[:, X.EPSI])) / (
            1 - kappa * xi[:, X.EY]
        )
        np.testing.assert_allclose(s_dot, want, rtol=1e-13)


def test_finite_at_standstill_and_reverse_slip() -> None:
    model = Model()
    xi = np.array([0.0, 0.1, 0.05, 0.0, 0.0, 0.0])
    assert np.all(np.isfinite(model.xi_dot(xi, [0.2, 1.0])))
    A, B = model.jacobians(xi, [0.2, 1.0])
    assert np.all(np.isfinite(A)) and np.all(np.isfinite(B))


# --- derivatives and discretization --------------------------------------------------------------


def central_difference(fn, x: np.ndarray, h: float) -> np.ndarray:
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((np.asarray(fn(x + e)).ravel() - np.asarray(fn(x - e)).ravel()) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("domain", ["time", "spatial"])
def test_jacobians_match_finite_differences(domain: str) -> None:
    rng = np.random.default_rng(4)
    options = ModelOptions(lateral_weight_transfer=True)
    params = ModelParams()
    f = (time_dynamics if domain == "time" else spatial_dynamics)(params, options)
    jac = jacobians(params, options, domain)
    xi, u, kappa, theta = random_points(rng, 10)
    for i in range(len(xi)):
        A, B = (np.asarray(m) for m in jac(xi[i], u[i], kappa[i], theta[i]))
        A_fd = central_difference(lambda x, i=i: f(x, u[i], kappa[i], theta[i]), xi[i], 1e-6)
        B_fd = central_difference(lambda v, i=i: f(xi[i], v, kappa[i], theta[i]), u[i], 1e-7)
        np.testing.assert_allclose(A, A_fd, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(B, B_fd, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(("domain", "h"), [("time", 0.1), ("spatial", 3.0)])
def test_discrete_linearization_is_exact_to_first_order(domain: str, h: float) -> None:
    rng = np.random.default_rng(5)
    params, options = ModelParams(), ModelOptions()
    F = discretize(params, options, h, "rk4", domain)
    lin = discrete_linearization(params, options, h, "rk4", domain)
    xi, u, kappa, theta = random_points(rng, 5)
    scale_x = np.array([1.0, 0.2, 0.1, 0.05, 0.5, 1.0])
    scale_u = np.array([0.02, 1.0])
    for i in range(len(xi)):
        A, B, d = (np.asarray(m) for m in lin(xi[i], u[i], kappa[i], theta[i]))
        # Affine model reproduces the nonlinear step at the point itself
        at_point = np.asarray(F(xi[i], u[i], kappa[i], theta[i])).ravel()
        np.testing.assert_allclose(A @ xi[i] + B @ u[i] + d.ravel(), at_point, rtol=1e-12)
        dx = scale_x * rng.standard_normal(NX)
        du = scale_u * rng.standard_normal(NU)
        errors = []
        for eps in (1e-1, 5e-2, 2.5e-2):
            x1, u1 = xi[i] + eps * dx, u[i] + eps * du
            exact = np.asarray(F(x1, u1, kappa[i], theta[i])).ravel()
            errors.append(np.linalg.norm(exact - (A @ x1 + B @ u1 + d.ravel())))
        ratios = np.array(errors[:-1]) / np.array(errors[1:])
        # Second-order remainder: halving the perturbation quarters the error
        assert np.all((ratios > 3.0) & (ratios < 5.0)), ratios


def test_mapped_linearization_equals_single_point_calls() -> None:
    rng = np.random.default_rng(6)
    model = Model()
    xi, u, kappa, theta = random_points(rng, 7)
    A, B, d = model.linearize(xi, u, 0.1, kappa, theta)
    assert A.shape == (7, NX, NX) and B.shape == (7, NX, NU) and d.shape == (7, NX)
    for i in range(7):
        A1, B1, d1 = model.linearize(xi[i], u[i], 0.1, kappa[i], theta[i])
        np.testing.assert_allclose(A[i], A1, rtol=1e-14)
        np.testing.assert_allclose(B[i], B1, rtol=1e-14)
        np.testing.assert_allclose(d[i], d1, rtol=1e-14)


def test_rk4_is_fourth_order_and_spatial_step_advances_s_exactly() -> None:
    model = Model()
    xi0 = np.array([25.0, 0.3, 0.2, 0.05, 0.5, 100.0])
    u0 = np.array([0.03, -2.0])

    def integrate(h: float, n: int) -> np.ndarray:
        x = xi0
        for _ in range(n):
            x = model.step(x, u0, h, kappa=0.01)
        return x

    ref = integrate(0.003125, 320)
    e1 = np.linalg.norm(integrate(0.05, 20) - ref)
    e2 = np.linalg.norm(integrate(0.025, 40) - ref)
    assert 12.0 < e1 / e2 < 24.0  # 2^4 = 16 as h -> 0 (about 19.5 here)
    x_next = model.step(xi0, u0, 3.0, kappa=0.01, domain="spatial")
    assert x_next[X.S] == pytest.approx(103.0, abs=1e-12)
    # variable-step Function: one more input h
    F_h = discretize(model.params, model.options, None, "euler", "spatial")
    assert F_h.n_in() == 5
    np.testing.assert_allclose(
        np.asarray(F_h(xi0, u0, 0.01, 0.0, 2.0)).ravel(),
        xi0 + 2.0 * model.dxi_ds(xi0, u0, 0.01),
        rtol=1e-13,
    )


# --- each option changes exactly its own terms ----------------------------------------------------


def test_drag_switch_changes_only_vx_dot_by_drag_over_mass() -> None:
    rng = np.random.default_rng(7)
    params = ModelParams()
    xi, u, kappa, theta = random_points(rng, 30)
    on = Model(params, ModelOptions(drag=True, longitudinal_weight_transfer=False))
    off = Model(params, ModelOptions(drag=False, longitudinal_weight_transfer=False))
    diff = off.xi_dot(xi, u, kappa, theta) - on.xi_dot(xi, u, kappa, theta)
    np.testing.assert_allclose(diff[:, X.VX], params.C_xw * xi[:, X.VX] ** 2 / params.m, rtol=1e-10)
    others = [i for i in X if i != X.VX]
    assert np.max(np.abs(diff[:, others])) < 1e-12
    # With load transfer on, the same drag change passes through the loop's gain 1/(1 - k h_c/L)
    on = Model(params, ModelOptions(drag=True))
    off = Model(params, ModelOptions(drag=False))
    diff = off.xi_dot(xi, u, kappa, theta) - on.xi_dot(xi, u, kappa, theta)
    alpha_f = on.terms(xi, u, kappa, theta)["alpha_f"]
    k = (
        params.mu
        * params.D_f
        * np.sin(params.C_f * np.arctan(params.B_f * alpha_f))
        * np.sin(u[:, U.DELTA])
    )
    gain = 1.0 / (1.0 - k * params.h_c / params.wheelbase)
    np.testing.assert_allclose(
        diff[:, X.VX], gain * params.C_xw * xi[:, X.VX] ** 2 / params.m, rtol=1e-10
    )


def test_longitudinal_transfer_switch_moves_load_front_to_rear() -> None:
    rng = np.random.default_rng(8)
    params = ModelParams()
    xi, u, kappa, theta = random_points(rng, 30)
    u[:, U.DELTA] = 0.0  # no F_yf sin(delta) coupling: v_x_dot must not change
    on = Model(params, ModelOptions(longitudinal_weight_transfer=True))
    off = Model(params, ModelOptions(longitudinal_weight_transfer=False))
    x_on, x_off = on.xi_dot(xi, u, kappa, theta), off.xi_dot(xi, u, kappa, theta)
    t_on, t_off = on.terms(xi, u, kappa, theta), off.terms(xi, u, kappa, theta)
    np.testing.assert_allclose(x_on[:, X.VX], x_off[:, X.VX], rtol=1e-13, atol=1e-13)
    kin = [X.EPSI, X.EY, X.S]
    np.testing.assert_array_equal(x_on[:, kin], x_off[:, kin])
    dW = params.m * x_on[:, X.VX] * params.h_c / params.wheelbase
    np.testing.assert_allclose(t_on["F_zf"], t_off["F_zf"] - dW, rtol=1e-12)
    np.testing.assert_allclose(t_on["F_zr"], t_off["F_zr"] + dW, rtol=1e-12)
    # Lateral force per unit load is unchanged, so v_y_dot and r_dot change by the load shift
    phi_f = t_off["F_yf"] / t_off["F_zf"]
    phi_r = t_off["F_yr"] / t_off["F_zr"]
    np.testing.assert_allclose(
        x_on[:, X.VY] - x_off[:, X.VY], (-phi_f * dW + phi_r * dW) / params.m, atol=1e-10
    )
    np.testing.assert_allclose(
        x_on[:, X.R] - x_off[:, X.R],
        (-params.l_f * phi_f * dW - params.l_r * phi_r * dW) / params.I_zz,
        atol=1e-10,
    )
    # Braking (v_x_dot < 0) loads the front axle
    braking = x_on[:, X.VX] < 0
    assert np.all(t_on["F_zf"][braking] > t_off["F_zf"][braking])


def test_lateral_transfer_adds_only_the_appendix_a_yaw_moment() -> None:
    rng = np.random.default_rng(9)
    params = ModelParams()
    xi, u, kappa, theta = random_points(rng, 30)
    base = Model(params, ModelOptions())
    four = Model(params, ModelOptions(lateral_weight_transfer=True))
    x_b, x_4 = base.xi_dot(xi, u, kappa, theta), four.xi_dot(xi, u, kappa, theta)
    t_4 = four.terms(xi, u, kappa, theta)
    same = [X.VX, X.VY, X.EPSI, X.EY, X.S]
    np.testing.assert_allclose(x_4[:, same], x_b[:, same], rtol=1e-12, atol=1e-12)
    # Appendix A: r_dot^4w - r_dot^bicycle = -0.5 l_t F_y(Delta W_F) sin(delta) / I_zz
    L = params.wheelbase
    dWF = params.m * t_4["a_y"] * params.h_c / params.l_t * params.l_r / L
    np.testing.assert_allclose(t_4["delta_W_F"], dWF, rtol=1e-12)
    Fy_dWF = (
        params.mu * dWF * params.D_f * np.sin(params.C_f * np.arctan(params.B_f * t_4["alpha_f"]))
    )
    expected = -0.5 * params.l_t * Fy_dWF * np.sin(u[:, U.DELTA]) / params.I_zz
    np.testing.assert_allclose(x_4[:, X.R] - x_b[:, X.R], expected, rtol=1e-9, atol=1e-12)
    # Left turn in steady state (delta > 0, a_y > 0, F_yf > 0): the moment opposes the turn, and
    # it is small next to the main yaw moment (second order in delta)
    xi_t = np.array([20.0, 0.0, 0.2, 0.0, 0.0, 0.0])
    u_t = np.array([0.04, 0.0])
    d_r = four.xi_dot(xi_t, u_t)[X.R] - base.xi_dot(xi_t, u_t)[X.R]
    t = base.terms(xi_t, u_t)
    main = params.l_f * t["F_yf"] / params.I_zz
    assert d_r < 0 and abs(d_r) < 0.02 * main


# --- steady-state cornering against the linear bicycle model --------------------------------------


@pytest.mark.parametrize("v", [10.0, 25.0])
def test_steady_state_yaw_rate_matches_linear_bicycle(v: float) -> None:
    # Different rear stiffness so that the car understeers (equal B C D would be neutral)
    params = ModelParams(B_r=12.0)
    model = Model(params, ModelOptions())
    delta = 0.004  # rad: small slip angles, linear tyres

    def residual(z: np.ndarray) -> np.ndarray:
        v_y, r, a_x = z
        xdot = model.xi_dot(np.array([v, v_y, r, 0.0, 0.0, 0.0]), np.array([delta, a_x]))
        return xdot[[X.VX, X.VY, X.R]] * np.array([1.0, 1.0, 10.0])

    v_y, r, a_x = fsolve(residual, np.array([0.0, v * delta / params.wheelbase, 0.5]), xtol=1e-13)
    assert np.max(np.abs(residual(np.array([v_y, r, a_x])))) < 1e-9
    L = params.wheelbase
    # Slopes of the tyre curves at zero slip, static loads: C_alpha = mu F_z0 B C D
    C_af = params.mu * params.m * params.g * params.l_r / L * params.B_f * params.C_f * params.D_f
    C_ar = params.mu * params.m * params.g * params.l_f / L * params.B_r * params.C_r * params.D_r
    assert params.cornering_stiffness() == pytest.approx((C_af, C_ar), rel=1e-12)
    K_us = params.m / L * (params.l_r / C_af - params.l_f / C_ar)  # rad per m/s^2
    assert K_us > 0
    r_linear = v * delta / (L + K_us * v**2)
    assert r == pytest.approx(r_linear, rel=2e-3)
    # a_x balances drag, rolling resistance and the small front-force component (Eq. 5)
    F_yf = model.terms(np.array([v, v_y, r, 0.0, 0.0, 0.0]), np.array([delta, a_x]))["F_yf"]
    resist = params.C_xw * v**2 + params.c_rr * params.m * params.g + F_yf * math.sin(delta)
    assert a_x == pytest.approx(resist / params.m - r * v_y, rel=1e-9)
    # and the understeer really matters at this speed: a neutral car would turn faster
    assert r < v * delta / L


# --- pedal map -----------------------------------------------------------------------------------


def test_pedal_map_round_trip_limits_and_continuity() -> None:
    rng = np.random.default_rng(10)
    pm = PedalMap(m_0=0.8, m_xi=(-0.05, 0.01, 0.0, 0.0, 0.0, 0.0), m_thr=3.5, m_brk=10.0)
    xi, _, _, _ = random_points(rng, 200)
    u_p = rng.uniform(-1.0, 1.0, 200)
    np.testing.assert_allclose(pm.pedal(pm.ax(xi, u_p), xi), u_p, atol=1e-12)
    a_min, a_max = pm.limits(xi)
    a_0 = pm.ax(xi, np.zeros(200))
    assert np.all(a_min < a_0) and np.all(a_0 < a_max)
    np.testing.assert_allclose(a_max, pm.ax(xi, np.ones(200)))
    np.testing.assert_allclose(a_min, pm.ax(xi, -np.ones(200)))
    # continuous at u_p = 0, slopes m_thr and m_brk on either side
    eps = 1e-9
    assert pm.ax(xi[0], eps) - pm.ax(xi[0], 0.0) == pytest.approx(pm.m_thr * eps, rel=1e-5)
    assert pm.ax(xi[0], 0.0) - pm.ax(xi[0], -eps) == pytest.approx(pm.m_brk * eps, rel=1e-5)
    # out of reach accelerations clip to the pedal ends
    assert pm.pedal(a_max[0] + 5.0, xi[0]) == 1.0
    assert pm.pedal(a_min[0] - 5.0, xi[0]) == -1.0
    # scalar in, float out
    assert isinstance(pm.ax(xi[0], 0.3), float)
    assert isinstance(pm.limits(xi[0])[0], float)
    # speed-only convenience for speed profiles
    v = np.array([[10.0, 20.0], [30.0, 40.0]])
    lo, hi = pm.limits_at_speed(v)
    assert lo.shape == v.shape
    np.testing.assert_allclose(hi, pm.m_0 + pm.m_xi[X.VX] * v + pm.m_thr)
    np.testing.assert_allclose(lo, pm.m_0 + pm.m_xi[X.VX] * v - pm.m_brk)
    # symbolic use (planner bounds) agrees with numpy
    xs, us = ca.SX.sym("xi", NX), ca.SX.sym("u_p")
    f = ca.Function("ax", [xs, us], [pm.ax(xs, us), *pm.limits(xs)])
    for i in range(5):
        got = [float(v) for v in f(xi[i], u_p[i])]
        assert got == pytest.approx([pm.ax(xi[i], u_p[i]), *pm.limits(xi[i])], rel=1e-13)


def test_pedal_map_power_and_braking_limits() -> None:
    """The throttle gain follows min(m_thr, p_thr / v_x); braking stops at -a_brk_max."""
    rng = np.random.default_rng(11)
    pm = PedalMap(m_0=0.0, m_xi=(0.0,) * NX, m_thr=4.0, m_brk=12.0, p_thr=50.0, a_brk_max=10.0)
    xi, _, _, _ = random_points(rng, 200)
    xi[:, X.VX] = rng.uniform(2.0, 60.0, 200)
    v = xi[:, X.VX]
    gain = np.minimum(4.0, 50.0 / v)  # independent: the hyperbola meets m_thr at 12.5 m/s
    np.testing.assert_allclose(pm.ax(xi, np.ones(200)), gain)
    np.testing.assert_allclose(pm.ax(xi, 0.5 * np.ones(200)), 0.5 * gain)
    lo, hi = pm.limits(xi)
    np.testing.assert_allclose(hi, gain)
    np.testing.assert_allclose(lo, -10.0)  # the tyres, not the brakes (-12), bound braking
    # braking is linear (12 per unit pedal) down to 0.8 of the limit, then bends to it
    assert pm.ax(xi[0], -0.5) == pytest.approx(-6.0)
    assert pm.ax(xi[0], -8.0 / 12.0) == pytest.approx(-8.0)
    assert pm.ax(xi[0], -1.0) == pytest.approx(-10.0)
    brake = pm.ax(np.repeat(xi[:1], 101, axis=0), np.linspace(-1.0, 0.0, 101))
    assert np.all(np.diff(brake) > 0.0)  # monotone, hence invertible
    u_p = rng.uniform(-1.0, 1.0, 200)
    np.testing.assert_allclose(pm.pedal(pm.ax(xi, u_p), xi), u_p, atol=1e-12)
    # symbolic (planner) and numeric agree, limits included
    xs, us = ca.SX.sym("xi", NX), ca.SX.sym("u_p")
    f = ca.Function("ax", [xs, us], [pm.ax(xs, us), *pm.limits(xs)])
    for i in range(5):
        got = [float(val) for val in f(xi[i], u_p[i])]
        assert got == pytest.approx([pm.ax(xi[i], u_p[i]), *pm.limits(xi[i])], rel=1e-13)
    assert PedalMap.from_dict(pm.to_dict()) == pm
    with pytest.raises(ModelError, match="p_thr must be > 0"):
        PedalMap(p_thr=-1.0)
    with pytest.raises(ModelError, match="a_brk_max must be > 0"):
        PedalMap(a_brk_max=0.0)


@pytest.mark.parametrize("limited", [False, True])
def test_pedal_of_one_value_is_the_array_result_bit_for_bit(limited: bool) -> None:
    """The controller's one-value path (Python floats) gives exactly the array path's numbers."""
    rng = np.random.default_rng(12)
    extra = {"p_thr": 50.0, "a_brk_max": 10.0} if limited else {}
    pm = PedalMap(m_0=0.3, m_xi=(-0.02, 0.01, 0.0, 0.0, 0.0, 0.0), m_thr=4.0, m_brk=12.0, **extra)
    xi, _, _, _ = random_points(rng, 300)
    xi[:, X.VX] = rng.uniform(-2.0, 60.0, 300)  # below 1 m/s too, where the gain's floor acts
    xi[3:5, X.VX] = [np.inf, -np.inf]  # no throttle gain left at an infinite speed
    # Every branch: throttle, linear brake, past the brake knee, and beyond both ends (clipped).
    a_x = rng.uniform(-16.0, 8.0, 300)
    a_x[0] = pm._base(xi[0])[0]  # exactly on the switch from brake to throttle
    a_x[1:3] = [np.nan, -0.0]
    a_x[5:7] = [np.inf, -np.inf]
    batch = pm.pedal(a_x, xi)
    one = [pm.pedal(float(a), row) for a, row in zip(a_x, xi, strict=True)]
    assert all(isinstance(u_p, float) for u_p in one)
    assert np.array_equal(np.array(one), batch, equal_nan=True)
    assert np.array_equal(np.signbit(one), np.signbit(batch))
    assert np.isnan(one[1]) and np.all(np.abs(batch[2:]) <= 1.0)


def test_pedal_map_single_slope_is_the_paper_map_and_coefficients_round_trip() -> None:
    M = np.array([-0.04, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0])
    pm = PedalMap.from_linear(M)
    xi = np.array([30.0, 0.1, 0.0, 0.0, 0.0, 0.0])
    for u_p in (-1.0, -0.3, 0.0, 0.7):
        assert pm.ax(xi, u_p) == pytest.approx(M @ np.append(xi, u_p))
    pm2 = PedalMap()
    assert PedalMap.from_coefficients(pm2.coefficients()) == pm2
    with pytest.raises(ModelError, match="9 numbers"):
        PedalMap.from_coefficients(np.zeros(8))


# --- parameters ----------------------------------------------------------------------------------


def test_params_json_round_trip(tmp_path) -> None:
    params = ModelParams(mu=1.1, pedal=PedalMap(m_thr=2.5))
    path = tmp_path / "model.json"
    params.save(path)
    assert ModelParams.load(path) == params
    assert ModelParams.from_dict(params.to_dict()) == params
    assert hash(ModelParams.from_dict(params.to_dict())) == hash(params)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"m": 0.0}, "m must be > 0"),
        ({"I_zz": -5.0}, "I_zz must be > 0"),
        ({"mu": float("nan")}, "mu must be finite"),
        ({"C_xw": -0.1}, "C_xw must be >= 0"),
        ({"C_f": 2.5}, "C_f"),
        ({"h_c": "high"}, "h_c must be a number"),
    ],
)
def test_bad_parameters_raise(changes: dict, match: str) -> None:
    with pytest.raises(ModelError, match=match):
        ModelParams(**changes)


def test_bad_inputs_raise() -> None:
    with pytest.raises(ModelError, match="m_brk must be > 0"):
        PedalMap(m_brk=0.0)
    with pytest.raises(ModelError, match="6 entries"):
        PedalMap(m_xi=(1.0, 2.0))
    with pytest.raises(ModelError, match="unknown ModelParams field"):
        ModelParams.from_dict({"mass": 1000.0})
    model = Model()
    with pytest.raises(ModelError, match=r"shape \(6,\) or \(N, 6\)"):
        model.xi_dot(np.zeros(5), [0.0, 0.0])
    with pytest.raises(ModelError, match=r"u must have shape"):
        model.xi_dot(np.zeros(6), [0.0, 0.0, 0.0])
    with pytest.raises(ModelError, match="kappa"):
        model.xi_dot(np.zeros((3, 6)), [0.0, 0.0], kappa=[0.0, 0.1])
    with pytest.raises(ModelError, match="unknown method"):
        discretize(ModelParams(), ModelOptions(), 0.1, "rk45")
    with pytest.raises(ModelError, match="step must be > 0"):
        model.step(np.zeros(6), [0.0, 0.0], -0.1)
    with pytest.raises(ModelError, match="ModelParams"):
        time_dynamics("not params")  # type: ignore[arg-type]


def test_functions_are_cached_and_options_are_distinct() -> None:
    assert time_dynamics(ModelParams(), ModelOptions()) is time_dynamics()
    assert time_dynamics(ModelParams(), ModelOptions(drag=False)) is not time_dynamics()
    assert ModelOptions().label() == "drag+lon"
    assert ModelOptions(False, False, False).label() == "plain"


def test_from_vehicle_takes_the_true_values() -> None:
    from racing_lib.vehicle import VehicleParams

    assert ModelParams.from_vehicle(VehicleParams()) == ModelParams()
    car = VehicleParams(mu=1.1, h_c=0.5)
    params = ModelParams.from_vehicle(car, pedal=PedalMap(m_thr=2.0))
    assert (params.mu, params.h_c, params.pedal.m_thr) == (1.1, 0.5, 2.0)
    with pytest.raises(ModelError, match="lacks the model parameter"):
        ModelParams.from_vehicle(object())


def test_a_pedal_map_that_ends_short_of_the_full_pedal() -> None:
    # A car whose wheels lock beyond pedal -0.5: braking is linear to there, and no deeper
    # pedal is ever asked for.
    full = PedalMap(m_0=0.0, m_xi=(0.0,) * 6, m_thr=5.0, m_brk=11.5)
    locking = dataclasses.replace(full, brake_max=0.5)
    assert locking.full_brake() == pytest.approx(5.75)
    xi = np.zeros(6)
    xi[X.VX] = 30.0
    lo, hi = locking.limits(xi)
    assert lo == pytest.approx(-5.75) and hi == pytest.approx(5.0)
    assert locking.pedal(-9.0, xi) == pytest.approx(-0.5)  # clipped where the map ends
    assert locking.pedal(-2.3, xi) == pytest.approx(-0.2)  # linear before it
    assert full.pedal(-9.0, xi) == pytest.approx(-9.0 / 11.5)
    assert PedalMap.from_dict(locking.to_dict()) == locking
    for bad in (0.0, -0.5, 1.5, float("nan")):
        with pytest.raises(ModelError, match="brake_max"):
            dataclasses.replace(full, brake_max=bad)


def test_the_car_model_carries_its_top_speed() -> None:
    from racing_lib.model import DEFAULT_V_TOP, CarModel

    model = CarModel(ModelParams())
    assert model.v_top == DEFAULT_V_TOP
    fast = model.replace(v_top=60.0)
    assert CarModel.from_dict(fast.to_dict()) == fast
    assert fast.differences(model) == []  # the top speed is the planner's; it predicts nothing
    with pytest.raises(ModelError, match="v_top"):
        model.replace(v_top=0.0)


def test_the_lateral_eigenvalue_test_is_the_shifted_blocks_determinant_and_trace():
    from racing_lib.model import lateral_eigenvalue_test
    from racing_lib.model.lateral import lateral_linearization

    params = ModelParams()
    test = lateral_eigenvalue_test(params, ModelOptions())
    model = Model(params, ModelOptions())
    for v, accel, sigma in ((30.0, 0.0, 0.0), (45.0, -8.0, 0.0), (20.0, -3.0, 1.5)):
        eig = np.linalg.eigvals(lateral_linearization(params, v, accel=accel).A)
        xi = np.array([v, 0, 0, 0, 0, 0.0])
        a_x = accel - float(model.xi_dot(xi, [0.0, 0.0])[X.VX])  # as the linearization picks it
        det, trace = (float(x) for x in test(xi, [0.0, a_x], 0.0, 0.0, sigma))
        assert det == pytest.approx(float(np.prod(eig + sigma).real), rel=1e-9)
        assert trace == pytest.approx(float(np.sum(eig + sigma).real), rel=1e-9)


@pytest.mark.parametrize("form", ["share", "demand"])
def test_both_throttle_forms_invert_and_agree_at_full_throttle(form):
    pedal = PedalMap(m_0=0.1, m_xi=(0.0,) * NX, m_thr=11.5, m_brk=11.0, p_thr=84.0, throttle=form)
    share = dataclasses.replace(pedal, throttle="share")
    for v in (5.0, 13.0, 40.0):
        xi = np.array([v, 0, 0, 0, 0, 0.0])
        assert pedal.limits(xi) == share.limits(xi)  # full throttle and full brake alike
        for u in (-0.8, -0.2, 0.0, 0.3, 0.7, 1.0):
            a = pedal.ax(xi, u)
            if u < 1.0 and (form == "share" or a < pedal.limits(xi)[1] - 1e-9):
                assert pedal.pedal(a, xi) == pytest.approx(u, abs=1e-12)
    # Partial throttle differs: CommonRoad's pedal asks for u a_max until the power caps it.
    xi = np.array([13.0, 0, 0, 0, 0, 0.0])
    demand = dataclasses.replace(pedal, throttle="demand")
    assert demand.ax(xi, 0.4) == pytest.approx(0.1 + min(0.4 * 11.5, 84.0 / 13.0))
    assert share.ax(xi, 0.4) == pytest.approx(0.1 + 0.4 * min(11.5, 84.0 / 13.0))
    assert PedalMap.from_dict(demand.to_dict()) == demand


def test_an_unknown_throttle_form_is_refused():
    with pytest.raises(ModelError, match="throttle must be one of"):
        PedalMap(throttle="linear")


def test_a_car_models_lateral_stability_is_checked_and_kept():
    from racing_lib.model import CarModel

    model = CarModel(ModelParams(), lateral_stability=1.5)
    assert CarModel.from_dict(model.to_dict()) == model
    assert "stability margin 1.50 1/s" in model.describe()
    assert CarModel(ModelParams()).lateral_stability is None
    for bad in (-1.0, True, float("nan")):
        with pytest.raises(ModelError, match="lateral_stability"):
            CarModel(ModelParams(), lateral_stability=bad)


def test_a_car_models_slip_margin_is_checked_kept_and_planned_with():
    from racing_lib.model import CarModel
    from racing_lib.planning import CurvatureSettings, TimeOptimalSettings, _with_grid

    model = CarModel(ModelParams(), slip_share=0.975)
    assert CarModel.from_dict(model.to_dict()) == model
    assert "slip to 97.5% of peak" in model.describe()
    # a model without one writes the file it wrote before the field existed
    assert "slip_share" not in CarModel(ModelParams()).to_dict()
    for bad in (0.0, 1.2, -0.5, True, float("nan")):
        with pytest.raises(ModelError, match="slip_share"):
            CarModel(ModelParams(), slip_share=bad)
    # the time-optimal planner keeps the slip angles where the model says; without one, where
    # its settings say
    assert _with_grid(TimeOptimalSettings(), 3.0, model).slip_force_share == 0.975
    plain = CarModel(ModelParams())
    assert _with_grid(TimeOptimalSettings(slip_force_share=0.9), 3.0, plain).slip_force_share == 0.9
    assert _with_grid(CurvatureSettings(), 3.0, model).spacing == 3.0
