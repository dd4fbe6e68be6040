"""Tests of racing_lib.model.lateral and racing_lib.model.prediction against independent truths.

* The lateral linearization against the classic linear bicycle model written out by hand from the
  axles' cornering stiffnesses (state matrix, input matrix, characteristic polynomial, steady-state
  yaw-rate gain and understeer gradient), including the load shift of longitudinal transfer.
* The open-loop prediction error is zero when the recorded "car" is the model itself, and it is
  the known drag deceleration when only the drag differs.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from racing_lib.errors import ModelError
from racing_lib.model import VX_GUARD, Drive, Model, ModelOptions, ModelParams, X
from racing_lib.model.equations import VX_GUARD_WIDTH
from racing_lib.model.lateral import lateral_analysis, lateral_linearization, understeer_gradient
from racing_lib.model.prediction import (
    format_prediction_table,
    predict_open_loop,
    prediction_errors,
    prediction_table,
)
from racing_lib.tracks import circle_track

P = ModelParams()


def _slip_speed(v: float) -> float:
    """The model's documented smooth lower bound on v_x in the slip angles (equal to v within
    ~1e-4 m/s here); using it keeps the hand formulas exact."""
    return 0.5 * (v + VX_GUARD + math.sqrt((v - VX_GUARD) ** 2 + VX_GUARD_WIDTH**2))


def _bicycle(p: ModelParams, v: float, C_f: float, C_r: float) -> tuple[np.ndarray, np.ndarray]:
    """The textbook linear bicycle in (v_y, r), written out by hand."""
    a, b, m, iz = p.l_f, p.l_r, p.m, p.I_zz
    w = _slip_speed(v)
    A = np.array(
        [
            [-(C_f + C_r) / (m * w), -v - (a * C_f - b * C_r) / (m * w)],
            [-(a * C_f - b * C_r) / (iz * w), -(a * a * C_f + b * b * C_r) / (iz * w)],
        ]
    )
    B = np.array([C_f / m, a * C_f / iz])
    return A, B


def _stiffness(p: ModelParams, F_zf: float, F_zr: float) -> tuple[float, float]:
    return (p.mu * F_zf * p.B_f * p.C_f * p.D_f, p.mu * F_zr * p.B_r * p.C_r * p.D_r)


# ----------------------------------------------------------------------------- linear lateral model


@pytest.mark.parametrize("v", [8.0, 20.0, 45.0])
def test_lateral_matrices_are_the_textbook_bicycle(v):
    C_f, C_r = _stiffness(P, *P.static_loads())
    A, B = _bicycle(P, v, C_f, C_r)
    sys = lateral_linearization(P, v)
    np.testing.assert_allclose(np.asarray(sys.A), A, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(sys.B).ravel(), B, rtol=1e-9)


@pytest.mark.parametrize("v", [8.0, 20.0, 45.0])
def test_eigenvalues_are_the_roots_of_the_characteristic_polynomial(v):
    C_f, C_r = _stiffness(P, *P.static_loads())
    a, b, m, iz = P.l_f, P.l_r, P.m, P.I_zz
    # s^2 + c1 s + c0 with the classic coefficients (w: the slip-angle speed, ~v)
    w = _slip_speed(v)
    c1 = (C_f + C_r) / (m * w) + (a * a * C_f + b * b * C_r) / (iz * w)
    c0 = (C_f * C_r * (a + b) ** 2) / (m * iz * w * w) + (b * C_r - a * C_f) * v / (iz * w)
    roots = np.sort_complex(np.roots([1.0, c1, c0]))
    eig = np.sort_complex(lateral_analysis(P, [v]).eigenvalues[0])
    np.testing.assert_allclose(eig, roots, rtol=1e-9)


def test_understeer_gradient_and_yaw_gain_match_the_hand_formula():
    C_f, C_r = _stiffness(P, *P.static_loads())
    L = P.wheelbase
    K = P.m / L * (P.l_r / C_f - P.l_f / C_r)
    assert K > 0.0  # the default car understeers
    # (the model's smoothed slip-angle speed moves K by < 3e-4 relative at 10 m/s)
    for v in (10.0, 30.0):
        assert understeer_gradient(P, v) == pytest.approx(K, rel=5e-4)
    speeds = np.array([10.0, 25.0, 40.0])
    res = lateral_analysis(P, speeds)
    np.testing.assert_allclose(res.yaw_rate_gain, speeds / (L + K * speeds**2), rtol=1e-4)
    assert res.characteristic_speed == pytest.approx(math.sqrt(L / K), rel=3e-4)
    assert math.isinf(res.critical_speed)
    # The yaw-rate gain peaks at the characteristic speed.
    v_ch = res.characteristic_speed
    peak = lateral_analysis(P, [0.8 * v_ch, v_ch, 1.25 * v_ch]).yaw_rate_gain
    assert peak[1] > peak[0] and peak[1] > peak[2]


def test_braking_shifts_load_forward_only_with_longitudinal_transfer():
    accel, v = -6.0, 30.0
    dW = P.m * accel * P.h_c / P.wheelbase  # negative: load moves to the front
    F_zf0, F_zr0 = P.static_loads()
    A_hand, _ = _bicycle(P, v, *_stiffness(P, F_zf0 - dW, F_zr0 + dW))
    sys = lateral_linearization(P, v, ModelOptions(), accel=accel)
    np.testing.assert_allclose(np.asarray(sys.A), A_hand, rtol=1e-9)
    # Without the transfer the loads stay static whatever the deceleration.
    A_static, _ = _bicycle(P, v, *_stiffness(P, F_zf0, F_zr0))
    off = ModelOptions(longitudinal_weight_transfer=False)
    np.testing.assert_allclose(
        np.asarray(lateral_linearization(P, v, off, accel=accel).A), A_static, rtol=1e-9
    )
    # Braking unloads the rear axle: the car understeers less.
    assert understeer_gradient(P, v, accel=accel) < understeer_gradient(P, v)


def test_an_oversteering_car_is_unstable_above_its_critical_speed():
    over = P.replace(B_f=14.0, B_r=8.0)  # swap the axles' stiffness: now the rear is softer
    C_f, C_r = _stiffness(over, *over.static_loads())
    K = over.m / over.wheelbase * (over.l_r / C_f - over.l_f / C_r)
    assert K < 0.0
    v_crit = math.sqrt(-over.wheelbase / K)
    res = lateral_analysis(over, [0.9 * v_crit, 1.1 * v_crit])
    assert res.critical_speed == pytest.approx(v_crit, rel=1e-4)
    assert res.stable.tolist() == [True, False]


def test_lateral_outputs_include_the_lateral_acceleration():
    v = 25.0
    sys = lateral_linearization(P, v)
    x = np.array([0.3, 0.1])
    u = 0.02
    x_dot = np.asarray(sys.A) @ x + np.asarray(sys.B).ravel() * u
    y = np.asarray(sys.C) @ x + np.asarray(sys.D).ravel() * u
    assert y[2] == pytest.approx(x_dot[0] + x[1] * v)


def test_too_slow_operating_point_is_refused():
    with pytest.raises(ModelError, match="v_x >= 2"):
        lateral_linearization(P, 0.5)


# ----------------------------------------------------------------------------- prediction error


@pytest.fixture(scope="module")
def model_drive():
    """A 'recorded drive' produced by the model itself on a circle (commands varying)."""
    track = circle_track(radius=150.0, width=20.0)
    rng = np.random.default_rng(3)
    n = 60
    steer = np.arctan(P.wheelbase / 150.0) + 0.01 * np.sin(0.2 * np.arange(n))
    pedal = np.clip(0.2 + 0.3 * rng.standard_normal(n), -0.6, 1.0)
    xi0 = np.array([[22.0, 0.0, 22.0 / 150.0, 0.0, 0.3, 5.0]])
    states = predict_open_loop(Model(P), xi0, steer[None, :], pedal[None, :], track)[:, 0, :]
    x, y, psi = track.centerline.to_cartesian(states[:, X.S], states[:, X.EY], states[:, X.EPSI])
    # One sample per observation, each with the command sent after it (none after the last).
    log = Drive(
        t=0.1 * np.arange(n + 1),
        x=x,
        y=y,
        psi=psi,
        vx=states[:, X.VX],
        vy=states[:, X.VY],
        r=states[:, X.R],
        steer=np.append(steer, steer[-1]),
        pedal=np.append(pedal, pedal[-1]),
    )
    return log, track


def test_prediction_error_is_zero_when_the_car_is_the_model(model_drive):
    log, track = model_drive
    res = prediction_errors(log, track, P, ModelOptions(), horizons=(0.5, 1.0))
    assert res.n_windows == 60 - 10 + 1
    for name, rms in res.rms.items():
        assert np.all(rms < 1e-6), (name, rms)


def test_prediction_without_drag_misses_by_the_drag_deceleration(model_drive):
    log, track = model_drive
    res = prediction_errors(log, track, P, ModelOptions(drag=False), horizons=(0.1,))
    # Over one period the missing deceleration is C_xw v^2 / m (to first order in dt).
    v = np.asarray(log.vx)[res.starts]
    expected = P.C_xw * v**2 / P.m * 0.1
    np.testing.assert_allclose(res.errors["v_x"][:, 0], expected, rtol=0.05)


def test_rms_over_some_windows(model_drive):
    log, track = model_drive
    res = prediction_errors(log, track, P, ModelOptions(drag=False), horizons=(0.1,))
    v = np.asarray(log.vx)[res.starts]
    fast = v > np.median(v)
    # Drag grows with v^2: the fast windows miss by more than the slow ones, and the two RMS
    # combine into the overall one.
    hi, lo = res.rms_over("v_x", 0.1, fast), res.rms_over("v_x", 0.1, ~fast)
    assert hi > lo > 0.0
    n_hi, n_lo = fast.sum(), (~fast).sum()
    assert res.at("v_x", 0.1) == pytest.approx(np.sqrt((n_hi * hi**2 + n_lo * lo**2) / v.size))
    assert np.isnan(res.rms_over("v_x", 0.1, np.zeros(v.size, dtype=bool)))


def test_prediction_table_and_format(model_drive):
    log, track = model_drive
    rows = prediction_table(log, track, P, horizons=(0.5, 1.0), stride=5)
    assert [r.label for r in rows][0].startswith("full model")
    assert rows[0].at("v_x", 1.0) < 1e-6 < rows[1].at("v_x", 1.0)  # "no drag" is worse
    # Without drag every window overestimates the speed; the exact model misses none.
    assert rows[1].fraction_above("v_x", 1.0, 1e-6) == 1.0
    assert rows[0].fraction_above("v_x", 1.0, 1e-6) == 0.0
    assert rows[1].percentile("v_x", 1.0, 50) == pytest.approx(
        float(np.median(rows[1].errors["v_x"][:, 1]))
    )
    text = format_prediction_table(rows, digits=3)
    assert len(text.splitlines()) == 1 + len(rows)
    assert "v_x @0.5s [m/s]" in text


def test_bad_horizons_and_short_logs_are_refused(model_drive):
    log, track = model_drive
    with pytest.raises(ModelError, match="one of each per sample"):
        prediction_errors(SimpleNamespace(**{**vars(log), "steer": log.steer[:-1]}), track, P)
    with pytest.raises(ModelError, match="multiple of the control period"):
        prediction_errors(log, track, P, horizons=(0.25,))
    with pytest.raises(ModelError, match="shorter than the longest horizon"):
        prediction_errors(log, track, P, horizons=(10.0,))
    with pytest.raises(ModelError, match="v_min"):
        prediction_errors(log, track, P, horizons=(0.5,), v_min=40.0)
