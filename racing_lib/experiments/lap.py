"""Closed-loop experiments: the flying-lap runner, its metrics, and seeded trials.

A lap is driven by any :class:`~racing_lib.interfaces.Plant` (the simulated car or another
simulator) and any :class:`~racing_lib.interfaces.Controller`, along any reference that has a
``path`` (a :class:`~racing_lib.geometry.Path`) and ``s``/``vx`` arrays (a planned
:class:`~racing_lib.planning.trajectory.Trajectory`). The car starts some distance before the
start/finish line at the reference speed (a *flying* lap, as in a time trial); the lap is timed from
the first crossing of the line to the next, both interpolated within the control period.

Metrics are those of the paper's Table I plus what a wall-bounded track makes interesting: lap time,
longitudinal-velocity and lateral-error MAE and maximum against the reference, wall contacts and
their duration, off-track time, and controller time per step. Taught in notebook 01, used by every
chapter after it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from racing_lib.control import build_controller
from racing_lib.errors import ModelError, PlantError
from racing_lib.geometry import (
    FrenetTracker,
    Path,
    Track,
)
from racing_lib.interfaces import (
    Controller,
    Observation,
    Plant,
)
from racing_lib.model import CarModel
from racing_lib.model.drive import DRIVE_COLUMNS, Drive
from racing_lib.planning import Trajectory
from racing_lib.sim import SimulatedCar
from racing_lib.vehicle import VehicleParams

#: The lap's columns beyond those of every drive, one entry per control step.
LAP_COLUMNS = ("s_ref", "ey", "vx_ref", "s_track", "solve_ms", "in_lap")


class Reference(Protocol):
    """What the runner needs of a reference: its path and the planned speed along it."""

    path: Path
    s: np.ndarray  # arc length of the nodes along ``path``, m
    vx: np.ndarray  # planned longitudinal speed at the nodes, m/s


@dataclass(frozen=True)
class LapMetrics:
    """The numbers one lap is judged by (field names are those of the CLI's JSON).

    Attributes
    ----------
    seed : int or None
        Seed of the plant's per-trial randomness.
    completed : bool
        True when the lap was finished within the time limit.
    lap_time_s : float
        From the first to the second crossing of the start/finish line, s (NaN if not completed).
    vx_mae_mps, vx_max_err_mps : float
        Mean and maximum of |v_x - v_x,ref| over the lap, m/s.
    ey_mae_m, ey_max_m : float
        Mean and maximum of the lateral distance |e_y| to the reference path, m.
    wall_contacts : int
        Number of separate wall contacts during the lap.
    wall_contact_time_s : float
        Total time in contact with a wall, s.
    offtrack_time_s : float
        Total time with the car beyond the track edge (open tracks), s.
    solve_time_ms_median, solve_time_ms_p99 : float
        Controller time per step, ms (median and 99th percentile).
    controller_stats : dict
        Counters the controller reports (for example MPC fallbacks).
    """

    seed: int | None
    completed: bool
    lap_time_s: float
    vx_mae_mps: float
    vx_max_err_mps: float
    ey_mae_m: float
    ey_max_m: float
    wall_contacts: int
    wall_contact_time_s: float
    offtrack_time_s: float
    solve_time_ms_median: float
    solve_time_ms_p99: float
    controller_stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, int | float | dict[str, float] | None]:
        """A JSON-ready dict (NaN becomes None)."""
        out = asdict(self)
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()
        }


@dataclass(frozen=True)
class LapLog(Drive):
    """A lap's :class:`~racing_lib.model.drive.Drive`, with the lap's own columns.

    One row per control step: the observation, the command sent after it and, of the same length,
    ``s_ref`` and ``ey``, the Frenet coordinates on the reference path (m), ``vx_ref`` the
    reference speed at ``s_ref`` (m/s), ``s_track`` the arc length on the track centerline (m),
    ``solve_ms`` the controller's time for that step (ms), and ``in_lap``, True for the steps
    between the two line crossings. Times in s, positions in m, angles in rad, speeds in m/s.
    """

    s_ref: np.ndarray
    ey: np.ndarray
    vx_ref: np.ndarray
    s_track: np.ndarray
    solve_ms: np.ndarray
    in_lap: np.ndarray

    def __post_init__(self) -> None:
        super().__post_init__()
        n = self.t.size
        for key in LAP_COLUMNS:
            size = np.asarray(getattr(self, key)).size
            if size != n:
                raise ModelError(f"lap log: {key} has {size} samples, t has {n}.")

    @property
    def lap_steps(self) -> np.ndarray:
        """Mask of the lap's own steps: between its two line crossings (``in_lap``).

        Every step of a log whose car never crossed the line, so that its measures (tracking
        error, speed error) still say how it drove.
        """
        in_lap = np.asarray(self.in_lap, dtype=bool)
        return in_lap if in_lap.any() else np.ones_like(in_lap)


@dataclass
class LapResult:
    """A finished run: its metrics and its log."""

    metrics: LapMetrics
    log: LapLog


def _speed_lookup(reference: Reference) -> Callable[[np.ndarray], np.ndarray]:
    """The reference's v_x (m/s) at arc lengths s (m), for a whole log at once.

    Called once after the lap: ``np.interp`` with a period sorts its table on every call (23 us
    a call, a tenth of a control step).
    """
    s_nodes = np.asarray(reference.s, dtype=float)
    v_nodes = np.asarray(reference.vx, dtype=float)
    length = float(reference.path.length)

    def lookup(s: np.ndarray) -> np.ndarray:
        return np.interp(np.mod(s, length), s_nodes, v_nodes, period=length)

    return lookup


def _check_observation(obs: Observation, step: int) -> None:
    values = (obs.t, obs.x, obs.y, obs.psi, obs.vx, obs.vy, obs.r)
    # A finite sum has only finite terms: one test instead of seven on every step of a lap.
    if not math.isfinite(sum(values)) and not all(math.isfinite(v) for v in values):
        raise PlantError(
            f"the plant returned a non-finite observation at step {step} (t = {obs.t}): {obs}. "
            "The plant's state diverged; check its commands and parameters (a smaller time step "
            "or a valid track may help)."
        )


def _crossing_time(t0: float, t1: float, s0: float, s1: float, length: float) -> float | None:
    """Time at which the car crossed s = 0 between two steps, or None if it did not.

    A crossing is a jump from the end of the lap (s near the length) to its start (s near 0); the
    time is interpolated linearly in distance.
    """
    if s0 > 0.75 * length and s1 < 0.25 * length:
        before = length - s0
        return t0 + (t1 - t0) * before / max(before + s1, 1e-9)
    return None


def run_lap(
    plant: Plant,
    controller: Controller,
    reference: Reference,
    *,
    track: Track | None = None,
    seed: int | None = None,
    max_time: float | None = None,
    progress: bool = False,
) -> LapResult:
    """Drive one flying lap in closed loop and measure it.

    Parameters
    ----------
    plant : Plant
        The car. It is reset with ``seed``; it should start a little before the start/finish line.
    controller : Controller
        Gives a command per control period from each observation.
    reference : Reference
        The line and speed the lap is judged against (its ``path``, ``s``, ``vx``).
    track : Track, optional
        Defines the start/finish line (s = 0 of its centerline); defaults to the reference path.
    seed : int, optional
        Seed of the plant's per-trial randomness.
    max_time : float, optional
        Give up after this simulated time, s (default: 3 x the reference lap time + 60 s).
    progress : bool
        Show a progress bar over the lap distance.

    Returns
    -------
    LapResult
        Metrics and the full log; ``metrics.completed`` is False if the lap was not finished.
    """
    ref_path = reference.path
    line_path = track.centerline if track is not None else ref_path
    speed_at = _speed_lookup(reference)
    if max_time is None:
        s_nodes = np.asarray(reference.s, dtype=float)
        v_nodes = np.maximum(np.asarray(reference.vx, dtype=float), 1.0)
        ds = np.diff(np.append(s_nodes, ref_path.length))
        max_time = 3.0 * float(np.sum(ds / v_nodes)) + 60.0

    ref_tracker = FrenetTracker(ref_path)
    line_tracker = FrenetTracker(line_path)
    obs = plant.reset(seed=seed)
    _check_observation(obs, 0)
    controller.reset(obs)

    rows: list[tuple[float, ...]] = []
    bar = _progress_bar(line_path.length) if progress else None
    t_start: float | None = None
    t_end: float | None = None
    counters_at_start: dict[str, float] = {}
    s_line_prev = line_tracker.project(obs.x, obs.y)[0]
    t_prev = obs.t
    n_steps = int(math.ceil(max_time / plant.dt))
    for k in range(n_steps):
        tic = time.perf_counter()
        cmd = controller.step(obs)
        solve_ms = 1e3 * (time.perf_counter() - tic)
        s_ref, ey = ref_tracker.project(obs.x, obs.y)
        rows.append(
            (
                obs.t,
                obs.x,
                obs.y,
                obs.psi,
                obs.vx,
                obs.vy,
                obs.r,
                cmd.steer,
                cmd.pedal,
                s_ref,
                ey,
                0.0,  # vx_ref, filled in for the whole log below
                s_line_prev,
                solve_ms,
                float(t_start is not None),
            )
        )
        obs = plant.step(cmd.steer, cmd.pedal)
        _check_observation(obs, k + 1)
        s_line = line_tracker.project(obs.x, obs.y)[0]
        crossed = _crossing_time(t_prev, obs.t, s_line_prev, s_line, line_path.length)
        if bar is not None and t_start is not None:
            # tqdm throttles its own redraws; only forward progress is reported.
            bar.update(max(0, min(int(s_line), bar.total) - bar.n))
        if crossed is not None:
            if t_start is None:
                t_start = crossed
                counters_at_start = _plant_counters(plant)
            else:
                t_end = crossed
                break
        s_line_prev, t_prev = s_line, obs.t
    if bar is not None:
        bar.close()

    log = _make_log(rows)
    log.vx_ref[:] = speed_at(log.s_ref)
    metrics = _metrics(log, plant, controller, seed, t_start, t_end, counters_at_start)
    return LapResult(metrics=metrics, log=log)


def _progress_bar(total: float):
    from tqdm.auto import tqdm

    return tqdm(total=int(total), unit="m", desc="lap", leave=False)


def _plant_counters(plant: Plant) -> dict[str, float]:
    return {
        "wall_contacts": float(getattr(plant, "wall_contacts", 0)),
        "wall_contact_time": float(getattr(plant, "wall_contact_time", 0.0)),
        "offtrack_time": float(getattr(plant, "offtrack_time", 0.0)),
    }


def _make_log(rows: Sequence[tuple[float, ...]]) -> LapLog:
    names = (*DRIVE_COLUMNS, *LAP_COLUMNS)
    data = np.asarray(rows, dtype=float).reshape(-1, len(names))
    cols = {name: data[:, i].copy() for i, name in enumerate(names)}
    cols["in_lap"] = cols["in_lap"].astype(bool)
    return LapLog(**cols)


def _metrics(
    log: LapLog,
    plant: Plant,
    controller: Controller,
    seed: int | None,
    t_start: float | None,
    t_end: float | None,
    counters_at_start: dict[str, float],
) -> LapMetrics:
    completed = t_start is not None and t_end is not None
    mask = log.lap_steps
    vx_err = np.abs(log.vx[mask] - log.vx_ref[mask])
    ey = np.abs(log.ey[mask])
    end = _plant_counters(plant)
    start = counters_at_start or {k: 0.0 for k in end}
    solve = log.solve_ms
    return LapMetrics(
        seed=seed,
        completed=bool(completed),
        lap_time_s=float(t_end - t_start) if completed else float("nan"),
        vx_mae_mps=float(vx_err.mean()) if vx_err.size else float("nan"),
        vx_max_err_mps=float(vx_err.max()) if vx_err.size else float("nan"),
        ey_mae_m=float(ey.mean()) if ey.size else float("nan"),
        ey_max_m=float(ey.max()) if ey.size else float("nan"),
        wall_contacts=int(round(end["wall_contacts"] - start["wall_contacts"])),
        wall_contact_time_s=float(end["wall_contact_time"] - start["wall_contact_time"]),
        offtrack_time_s=float(end["offtrack_time"] - start["offtrack_time"]),
        solve_time_ms_median=float(np.median(solve)) if solve.size else float("nan"),
        solve_time_ms_p99=float(np.percentile(solve, 99)) if solve.size else float("nan"),
        controller_stats=dict(controller.stats()),
    )


def summarize(metrics: Iterable[LapMetrics]) -> dict[str, float | int | None]:
    """Mean, spread and best of the lap times of several trials (completed laps only).

    Returns
    -------
    dict
        ``lap_time_mean_s``, ``lap_time_std_s`` (population std, as over the paper's ten trials),
        ``lap_time_min_s`` (None when no lap was completed) and ``completed`` (count).
    """
    laps = [m.lap_time_s for m in metrics if m.completed]
    if not laps:
        return {
            "lap_time_mean_s": None,
            "lap_time_std_s": None,
            "lap_time_min_s": None,
            "completed": 0,
        }
    arr = np.asarray(laps)
    return {
        "lap_time_mean_s": float(arr.mean()),
        "lap_time_std_s": float(arr.std()),
        "lap_time_min_s": float(arr.min()),
        "completed": len(laps),
    }


_T = TypeVar("_T")


def run_trials(
    lap: Callable[[int], _T],
    seeds: Iterable[int],
    executor: Executor | None = None,
) -> list[_T]:
    """Run ``lap(seed)`` for every seed, serially or through any ``concurrent.futures.Executor``.

    Parameters
    ----------
    lap : callable
        Takes a seed and returns the lap's metrics (or any result of one trial). With a process
        pool it must be picklable (a module-level function or a ``functools.partial`` of one).
    seeds : iterable of int
        One trial per seed; results come back in the same order.
    executor : Executor, optional
        Where to run the laps (for example ``ProcessPoolExecutor`` or a Dask client's executor);
        serial in this process when omitted.
    """
    seeds = list(seeds)
    if executor is None:
        return [lap(seed) for seed in seeds]
    return list(executor.map(lap, seeds))


# --------------------------------------------------------------------------------------------------
# One lap, described by plain data (so trials can run in other processes)


#: A car as a factory: the plant on ``track`` at ``start_speed`` (m/s), at the track's start.
PlantFactory = Callable[[Track, float], Plant]


@dataclass(frozen=True)
class LapSpec:
    """Everything that defines a lap (of the simulated car, or of another), as picklable data.

    Attributes
    ----------
    track : Track
        The track driven.
    trajectory : Trajectory
        The plan (or the centerline with a speed profile) the controller tracks.
    controller : str
        ``"nominal"``, ``"coupled-mpc"`` or ``"decoupled-mpc"``.
    smooth_transition : bool
        MPC only: linearize along the smoothly blended heuristic trajectory (the paper's choice)
        instead of the reference itself.
    weights : dict or None
        MPC weights overriding the defaults (for example tuned ones).
    run_up : float
        The car starts this far before the start/finish line, on the plan, at its speed, m.
    vehicle : VehicleParams or None
        The simulated car's true parameters (default car when None); ignored with ``car``.
    model : CarModel or None
        The model the MPC predicts with; None: the one the trajectory carries (the model it was
        planned with).
    car : callable ``(track, start_speed) -> Plant``, optional
        Another car than the simulated one, as a picklable factory (the ``make_plant`` of a
        :class:`~racing_lib.experiments.sysid.CarUnderTest`, e.g.
        :class:`racing_lib.plants.commonroad.CommonRoadAt`). Its plant must offer
        ``set_state(x, y, psi, vx)`` for the flying start.
    """

    track: Track
    trajectory: Trajectory
    controller: str = "nominal"
    smooth_transition: bool = True
    weights: dict[str, float] | None = None
    run_up: float = 150.0
    vehicle: VehicleParams | None = None
    model: CarModel | None = None
    car: PlantFactory | None = None


class _StartOnPlan:
    """A car whose reset puts it on the plan ``run_up`` before the line (flying start)."""

    # Any: a SimulatedCar or a foreign plant with the same set_state (CommonRoadCar).
    def __init__(self, car: Any, pose: tuple[float, float, float, float]) -> None:
        self._car = car
        self._pose = pose
        self.dt = car.dt

    def reset(self, seed: int | None = None) -> Observation:
        self._car.reset(seed=seed)
        x, y, psi, vx = self._pose
        return self._car.set_state(x=x, y=y, psi=psi, vx=vx)

    def step(self, steer_rad: float, pedal: float) -> Observation:
        return self._car.step(steer_rad, pedal)

    def __getattr__(self, name: str) -> Any:
        # Counters (wall_contacts, ...) and state_info() of the wrapped car.
        return getattr(self._car, name)


def make_car(spec: LapSpec) -> Plant:
    """The car of ``spec``, starting ``spec.run_up`` m before the line, on the plan.

    The simulated car (``spec.vehicle``), or the plant ``spec.car`` makes.

    Raises
    ------
    PlantError
        ``spec.car`` made a plant without ``set_state``, so it cannot be put on the plan.
    """
    traj = spec.trajectory
    s0 = (traj.path.length - spec.run_up) % traj.path.length
    x0, y0 = traj.path.position(s0)
    psi0 = float(np.asarray(traj.path.heading(s0)))
    v0 = float(np.interp(s0, traj.s, traj.vx, period=traj.path.length))
    if spec.car is None:
        car: Any = SimulatedCar(spec.track, params=spec.vehicle, start_speed=v0)
    else:
        car = spec.car(spec.track, v0)
        if not callable(getattr(car, "set_state", None)):
            raise PlantError(
                f"the car's plant {type(car).__name__} has no set_state(x, y, psi, vx), so a lap "
                "cannot start it on the plan at speed; add one (the flying start of every lap "
                "needs it), or drive it with run_lap from a standing start of your own."
            )
    return _StartOnPlan(car, (float(x0), float(y0), psi0, v0))


def make_controller(spec: LapSpec) -> Controller:
    """The controller named in ``spec``, built for its trajectory."""
    return build_controller(
        spec.controller,
        spec.trajectory,
        track=spec.track,
        model=spec.model,
        weights=spec.weights,
        smooth_transition=spec.smooth_transition,
    )


def drive_lap(spec: LapSpec, seed: int | None = None, progress: bool = False) -> LapResult:
    """Drive one flying lap of the car as ``spec`` describes (the simulated car by default).

    Parameters
    ----------
    spec : LapSpec
        Track, plan, controller and options.
    seed : int, optional
        Seed of the car's per-trial randomness (friction variation and actuation noise).
    progress : bool
        Show a progress bar.
    """
    return run_lap(
        make_car(spec),
        make_controller(spec),
        spec.trajectory,
        track=spec.track,
        seed=seed,
        progress=progress,
    )
