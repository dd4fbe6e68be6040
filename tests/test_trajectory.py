"""Tests of Trajectory: the centerline plan, interpolation and the plan CSV file."""

from __future__ import annotations

import math

import numpy as np
import pytest

from racing_lib.errors import PlanningError
from racing_lib.model import CarModel, ModelOptions, ModelParams
from racing_lib.planning.plan_file import PLAN_COLUMNS, PLAN_FORMAT_VERSION, plan_digest
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import circle_track

G = 9.81


@pytest.fixture(scope="module")
def circle_plan():
    track = circle_track(radius=80.0, width=10.0, name="circle80")
    traj = Trajectory.from_centerline(
        track, ModelParams(c_rr=0.0), options=ModelOptions(drag=False), spacing=4.0
    )
    return track, traj


def test_centerline_plan_on_a_circle(circle_plan):
    track, traj = circle_plan
    v = math.sqrt(1.25 * G * 80.0)
    assert traj.method == "centerline"
    assert traj.track_name == "circle80"
    assert traj.track_checksum == track.checksum()
    np.testing.assert_allclose(traj.vx, v, rtol=1e-5)  # the spline circle is not exact
    np.testing.assert_allclose(traj.kappa, 1 / 80.0, rtol=1e-3)
    np.testing.assert_allclose(traj.r, v / 80.0, rtol=1e-3)
    assert traj.path.length == pytest.approx(2 * math.pi * 80.0, rel=1e-4)
    assert traj.lap_time == pytest.approx(2 * math.pi * 80.0 / v, rel=1e-4)
    # t increases from 0 along the lap.
    assert traj.t[0] == 0.0 and np.all(np.diff(traj.t) > 0)


def test_interpolate_returns_node_values_and_wraps(circle_plan):
    _, traj = circle_plan
    k = 17
    st = traj.interpolate(traj.s[k])
    assert st.x == pytest.approx(traj.x[k])
    assert st.vx == pytest.approx(traj.vx[k])
    # One lap further is the same place; time continues between the last node and the lap end.
    st2 = traj.interpolate(traj.s[k] + traj.length)
    assert st2.y == pytest.approx(traj.y[k])
    mid = traj.interpolate(0.5 * (traj.s[-1] + traj.length))
    assert traj.t[-1] < mid.t < traj.lap_time
    arr = traj.interpolate(np.array([0.0, 10.0]))
    assert arr.x.shape == (2,)


def test_plan_csv_round_trip(tmp_path, circle_plan):
    track, traj = circle_plan
    path = tmp_path / "plan.csv"
    traj.save_csv(path)
    text = path.read_text()
    assert ",".join(PLAN_COLUMNS) in text
    assert "# track: circle80" in text
    assert not list(tmp_path.glob(".*tmp"))  # atomic write leaves no temporary file
    back = Trajectory.load_csv(path, track=track)
    for name in ("s", "x", "y", "psi", "kappa", "vx", "vy", "r", "ax", "delta", "t"):
        np.testing.assert_allclose(getattr(back, name), getattr(traj, name), rtol=1e-8, atol=1e-8)
    assert back.lap_time == pytest.approx(traj.lap_time, abs=1e-6)
    assert back.length == pytest.approx(traj.path.length, abs=1e-5)
    assert back.method == "centerline"
    assert back.model == traj.model == CarModel(ModelParams(c_rr=0.0), ModelOptions(drag=False))
    assert back.model_options == {
        "drag": False,
        "longitudinal_weight_transfer": True,
        "lateral_weight_transfer": False,
    }


def test_a_plan_file_brings_its_model_back_exactly(tmp_path, circle_plan):
    track, traj = circle_plan
    model = CarModel(
        ModelParams(c_rr=0.0, mu=1.1 / 3.0),  # a float whose decimal form does not end
        ModelOptions(drag=False),
        steer_tau=0.0831,
        grip_margin=0.07,
        edge_margin=0.6,
    )
    path = tmp_path / "plan.csv"
    traj.with_model(model).save_csv(path)
    back = Trajectory.load_csv(path, track=track)
    assert back.model == model  # every parameter bit for bit, the margins included
    edited = tmp_path / "edited.csv"
    edited.write_text(path.read_text().replace('"grip_margin": 0.07', '"grip_margin": 0.0'))
    with pytest.raises(PlanningError, match="fails its checksum"):
        Trajectory.load_csv(edited)


def test_a_plan_file_of_the_previous_format_loads_without_a_model(tmp_path, circle_plan):
    _, traj = circle_plan
    path = tmp_path / "plan.csv"
    traj.save_csv(path)
    lines = path.read_text().splitlines()
    body = [
        line.replace(f"format_version: {PLAN_FORMAT_VERSION}", "format_version: 2")
        for line in lines[:-1]
        if not line.startswith("# model:")
    ]
    text = "\n".join(body)
    old = tmp_path / "v2.csv"
    old.write_text(text + f"\n# sha256: {plan_digest(text)}\n")
    back = Trajectory.load_csv(old)
    assert back.model is None and back.model_options == {}
    np.testing.assert_array_equal(back.vx, Trajectory.load_csv(path).vx)


def test_plan_for_another_track_is_refused(tmp_path, circle_plan):
    _, traj = circle_plan
    path = tmp_path / "plan.csv"
    traj.save_csv(path)
    other = circle_track(radius=90.0, width=10.0, name="circle90")
    with pytest.raises(PlanningError) as err:
        Trajectory.load_csv(path, track=other)
    msg = str(err.value)
    assert "circle80" in msg and "circle90" in msg
    assert "racing-lib plan --track circle90" in msg


def test_not_a_plan_file_is_refused(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("# x_m,y_m\n1,2\n")
    with pytest.raises(PlanningError, match="not a racing_lib plan"):
        Trajectory.load_csv(bad)


def _damaged(lines: list[str], how: str) -> str:
    """A plan file's text damaged in one of the ways a user's copy can be."""
    header = next(i for i, line in enumerate(lines) if line.startswith("s_m"))
    rows, last = lines[header + 1 : -1], lines[-1:]

    def faster(line: str) -> str:
        fields = line.split(",")
        fields[5] = repr(float(fields[5]) * 1.5)
        return ",".join(fields) + ("" if fields[-1].endswith("\n") else "\n")

    if how == "cut at a row boundary":
        return "".join(lines[: header + 1] + rows[: len(rows) // 2])
    if how == "cut inside a row":
        return "".join(lines[: header + 1] + rows[:10]) + rows[10][:15]
    if how == "header only":
        return "".join(lines[: header + 1])
    if how == "lap time edited":
        return "".join(
            line.replace("planned_lap_time_s: ", "planned_lap_time_s: 1") for line in lines
        )
    if how == "speeds scaled by 1.5":
        return "".join(lines[: header + 1] + [faster(line) for line in rows] + last)
    if how == "rows spliced on":
        return "".join(lines + rows[:5])
    if how == "checksum line removed":
        return "".join(lines[:-1])
    raise AssertionError(how)


@pytest.mark.parametrize(
    ("how", "says"),
    [
        ("cut at a row boundary", "cut short"),
        ("cut inside a row", "data row 11 has"),
        ("header only", "no rows"),
        ("lap time edited", "fails its checksum"),
        ("speeds scaled by 1.5", "fails its checksum"),
        ("rows spliced on", "spliced"),
        ("checksum line removed", "cut short"),
    ],
)
def test_a_damaged_plan_file_is_refused(tmp_path, circle_plan, how, says):
    track, traj = circle_plan
    good = tmp_path / "plan.csv"
    traj.save_csv(good)
    bad = tmp_path / "damaged.csv"
    bad.write_text(_damaged(good.read_text().splitlines(keepends=True), how))
    with pytest.raises(PlanningError) as err:
        Trajectory.load_csv(bad, track=track)
    msg = str(err.value)
    assert says in msg and "damaged.csv" in msg and "re-plan" in msg


def test_a_plan_file_survives_windows_line_endings_and_a_bom(tmp_path, circle_plan):
    track, traj = circle_plan
    good = tmp_path / "plan.csv"
    traj.save_csv(good)
    text = good.read_text()
    copy = tmp_path / "copied.csv"
    copy.write_bytes(("\ufeff" + text.replace("\n", "\r\n")).encode("utf-8"))
    back = Trajectory.load_csv(copy, track=track)
    np.testing.assert_array_equal(back.vx, Trajectory.load_csv(good).vx)


def test_an_old_plan_file_without_checksum_is_refused(tmp_path, circle_plan):
    _, traj = circle_plan
    good = tmp_path / "plan.csv"
    traj.save_csv(good)
    old = tmp_path / "old.csv"
    old.write_text(
        good.read_text().replace(f"format_version: {PLAN_FORMAT_VERSION}", "format_version: 1")
    )
    with pytest.raises(PlanningError, match="older racing_lib without a checksum"):
        Trajectory.load_csv(old)


def test_inconsistent_arrays_are_refused(circle_plan):
    _, traj = circle_plan
    with pytest.raises(PlanningError, match="one value per node"):
        Trajectory(
            s=traj.s,
            x=traj.x,
            y=traj.y,
            psi=traj.psi,
            kappa=traj.kappa,
            vx=traj.vx[:-1],
            vy=traj.vy,
            r=traj.r,
            ax=traj.ax,
            delta=traj.delta,
            t=traj.t,
        )
