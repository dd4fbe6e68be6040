"""Tests of the iterated curvature-optimal QP on a small oval."""

from __future__ import annotations

import math

import numpy as np
import pytest

from racing_lib.errors import PlanningError
from racing_lib.model import identified_params
from racing_lib.planning.curvature import solve_curvature, steady_cornering
from racing_lib.planning.curvature_settings import CurvatureSettings
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks.segments import Arc, Straight, track_from_segments

SETTINGS = CurvatureSettings(spacing=5.0)


@pytest.fixture(scope="module")
def oval():
    layout = [Straight(200), Arc(50, math.pi), Straight(200), Arc(50, math.pi)]
    return track_from_segments(layout, width=12.0, name="oval", transition=20.0)


@pytest.fixture(scope="module")
def result(oval):
    return solve_curvature(oval, identified_params(), settings=SETTINGS)


def test_qp_line_stays_inside_the_track(oval, result):
    assert result.success, result.status
    grid = result.grid
    half = 0.5 * SETTINGS.car_width + 0.3  # open track: 0.3 m clearance
    assert np.all(result.e_y <= oval.width_left(grid.s) - half + 1e-6)
    assert np.all(result.e_y >= -(oval.width_right(grid.s) - half) - 1e-6)
    # The trajectory's own (x, y) agree with the Frenet offsets.
    _, e_y, _ = oval.centerline.to_frenet(result.trajectory.x, result.trajectory.y)
    np.testing.assert_allclose(e_y, result.e_y, atol=1e-3)


def test_qp_line_is_straighter_and_faster_than_the_centerline(oval, result):
    centre = Trajectory.from_centerline(oval, identified_params(), spacing=5.0)
    line = result.trajectory
    # Integral of kappa^2 over the lap (trapezoid on the nodes).
    k2_line = np.sum(line.kappa**2 * np.diff(np.append(line.s, line.length)))
    k2_centre = np.sum(centre.kappa**2 * np.diff(np.append(centre.s, centre.length)))
    assert k2_line < 0.95 * k2_centre
    assert line.lap_time < centre.lap_time - 0.3
    assert line.method == "curvature"
    # A U-turn between parallel straights has its largest radius on the outside edge: the line
    # uses the width by moving outwards (right of the counter-clockwise centerline) in the arcs.
    in_arcs = np.abs(result.grid.kappa) > 0.019
    room = oval.width_right(result.grid.s[in_arcs]) - (0.5 * SETTINGS.car_width + 0.3)
    assert np.all(result.e_y[in_arcs] < -0.5 * room)  # more than half-way to the outer edge


def test_history_records_each_qp(result):
    assert len(result.history) == result.iterations
    assert len(result.lap_times) == result.iterations + 1
    assert result.solve_time > 0 and result.qp_time > 0


def test_steady_cornering_matches_the_model_equilibrium():
    # At the steady-cornering point the model's lateral accelerations vanish (v_y_dot = r_dot = 0
    # up to the small F_yf sin(delta) coupling), an independent check of the slip inversion.
    from racing_lib.model import Model, ModelOptions, ModelParams

    params = ModelParams()
    model = Model(params, ModelOptions(drag=False, longitudinal_weight_transfer=False))
    v, kappa = 20.0, 1 / 60.0
    vy, r, delta = steady_cornering(np.array([v]), np.array([kappa]), params)
    xi = np.array([v, vy[0], r[0], 0.0, 0.0, 0.0])
    xdot = model.xi_dot(xi, [delta[0], 0.0], kappa=0.0)
    assert abs(xdot[1]) < 0.05 * v * r[0]  # v_y_dot small against the centripetal v r
    assert abs(xdot[2]) < 0.05


def test_infeasible_qp_names_the_solver_and_status(oval):
    # A steering limit far too small for the 50 m arcs: the linearized dynamics cannot turn.
    settings = CurvatureSettings(spacing=5.0, delta_max=0.005)
    with pytest.raises(PlanningError) as err:
        solve_curvature(oval, identified_params(), settings=settings)
    msg = str(err.value)
    assert "CLARABEL (via cvxpy)" in msg
    assert "infeasible" in msg


def test_track_narrower_than_the_car_is_refused():
    layout = [Straight(100), Arc(40, math.pi), Straight(100), Arc(40, math.pi)]
    narrow = track_from_segments(layout, width=2.5, name="lane")
    with pytest.raises(PlanningError, match="too narrow"):
        TrackGrid.from_track(narrow, spacing=5.0)
