"""A car nobody here wrote: identified, planned, raced (``python benchmarks/bench_own_car.py``).

For each CommonRoad car (``--vehicles``, default 2 and 3: the BMW 320i and the VW Vanagon,
single-track drift model, stock limits) the recipe of ``racing_lib.experiments.own_car``, as
``racing-lib lap --car commonroad:vehicleN`` runs it:

1. identification from the full manoeuvre set (``identify_car``, ``--fast`` for the smaller
   set), timed, kept in a temporary cache folder so that every run identifies afresh;
2. on every track, the time-optimal plan with the identified model (timed), and the same plan
   made with a model written by hand from the package's data sheet (``sheet_model``: mass, axle
   distances, inertia, tyre coefficients, no drag, the steering limits, the top speed);
3. the coupled MPC (the shipped tuned weights, nothing retuned) drives the car along the
   identified plan at its full speed, and, if a seed was not clean, at 90, 80 ... 60 % of it,
   until every seed laps cleanly (completed, no wall contact, no time off the track). Seeds draw
   the car's actuation noise (``--steer-noise`` rad, ``--pedal-noise``; the car is
   deterministic without it);
4. the identified model's plan without its stability margin (``lateral_stability=None``): what
   the margin bought; and the data-sheet plan, the MPC predicting with the data-sheet model: what
   identification bought. Both driven the same way at their full speed.

Prints one row per car and track: planned lap times (identified, data sheet), the full plan's
laps (completed, walls, time off track, mean lap and its gap to the plan), the fastest clean
scale with its mean lap and gap, the laps of the plan without the margin and of the data-sheet
plan, and the wall times of planning and
of one lap with the plant's real-time factor. ``--tracks DIR --only NAME ...`` adds
racetrack-database circuits.

Needs the optional extra: pip install "racing-lib[commonroad]".
"""

from __future__ import annotations

import statistics
import tempfile
import time
import warnings

from _script import argument_parser, run, tracks_to_measure

from racing_lib.errors import PlantError
from racing_lib.experiments.lap import LapSpec, drive_lap
from racing_lib.model import CarModel, ModelMismatchWarning
from racing_lib.planning import plan

SCALES = (1.0, 0.9, 0.8, 0.7, 0.6)


def identify_vehicle(vehicle: int, fast: bool) -> tuple[CarModel, float]:
    """The identified model of a CommonRoad car and the identification's wall time (s)."""
    from racing_lib.experiments.own_car import identify_car, named_car

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as cache:
        model = identify_car(named_car(f"commonroad:vehicle{vehicle}"), fast=fast, cache_dir=cache)
    return model, time.perf_counter() - t0


def sheet_model(vehicle: int) -> CarModel:
    """The model written by hand from the package's data sheet, with its steering limits."""
    from racing_lib.plants.commonroad import data_sheet, vehicle_parameters

    p = vehicle_parameters(vehicle)
    return CarModel(
        data_sheet(vehicle),
        steer_tau=0.05,
        steer_max=float(p.steering.max),
        steer_rate_max=float(p.steering.v_max),
        v_top=float(p.longitudinal.v_max),
    )


def drive(spec: LapSpec, seeds: list[int]) -> dict[str, float]:
    """Laps of ``spec`` over ``seeds``: completed, walls, time off track (s), mean lap (s).

    Also ``wall``: the wall time of one lap (s), the mean over the seeds.
    """
    laps, walls, off, done = [], 0, 0.0, 0
    t0 = time.perf_counter()
    for seed in seeds:
        try:
            m = drive_lap(spec, seed=seed).metrics
        except PlantError:  # the car spun or diverged: the lap is lost, counted as not completed
            continue
        done += int(m.completed)
        walls += m.wall_contacts
        off += m.offtrack_time_s
        if m.completed:
            laps.append(m.lap_time_s)
    mean = statistics.mean(laps) if laps else float("nan")
    wall = (time.perf_counter() - t0) / len(seeds)
    return {"done": done, "walls": walls, "off": off, "lap": mean, "wall": wall}


def clean(r: dict[str, float], n: int) -> bool:
    return r["done"] == n and r["walls"] == 0 and r["off"] == 0.0


def measure_track(
    track: object, vehicle: int, model: CarModel, factory: object, seeds: list[int]
) -> str:
    """One table row: the identified plan driven (full speed, else the fastest clean scale)."""
    from racing_lib.experiments.configs import tuned_weights

    weights = tuned_weights("main")
    t0 = time.perf_counter()
    traj = plan(track, "time-optimal", model).trajectory
    t_plan = time.perf_counter() - t0
    rows = {}
    for scale in SCALES:
        ref = traj.scale_speed(scale) if scale != 1.0 else traj
        spec = LapSpec(track, ref, "coupled-mpc", weights=weights, model=model, car=factory)
        rows[scale] = (drive(spec, seeds), ref.lap_time)
        if clean(rows[scale][0], len(seeds)):
            break
    full, planned = rows[1.0]
    best = next(((s, r) for s, r in rows.items() if clean(r[0], len(seeds))), None)
    gap = 100.0 * (full["lap"] / planned - 1.0)
    if best is None:
        clean_txt = f"{'none':>8} {'-':>8} {'-':>6}"
    else:
        s, (r, ref_lap) = best
        clean_txt = f"{s:>7.0%} {r['lap']:>8.2f} {100.0 * (r['lap'] / ref_lap - 1):>+5.1f}%"
    sheet_txt = other_plan_laps(track, sheet_model(vehicle), factory, seeds, weights)
    free = model.replace(lateral_stability=None)
    free_txt = other_plan_laps(track, free, factory, seeds, weights)
    factor = full["lap"] / full["wall"] if full["done"] else float("nan")
    return (
        f"{vehicle:>3} {track.name:<14} {planned:>8.2f} {full['done']:>4}/{len(seeds):<3} "
        f"{full['walls']:>5} {full['off']:>6.1f} {full['lap']:>8.2f} {gap:>+5.1f}% | "
        f"{clean_txt} | {free_txt} | {sheet_txt} | {t_plan:>6.1f} {full['wall']:>6.1f} "
        f"{factor:>5.0f}x"
    )


def other_plan_laps(
    track: object, model: CarModel, factory: object, seeds: list[int], weights: dict
) -> str:
    """Another model's plan (lap time) and its laps at full speed: completed, walls, off, mean.

    The MPC predicts with that model too.
    """
    try:
        traj = plan(track, "time-optimal", model).trajectory
    except Exception:  # noqa: BLE001 - a planner failure is a result here
        return f"{'failed':>8} {'-':>5} {'-':>5} {'-':>6} {'-':>8}"
    spec = LapSpec(track, traj, "coupled-mpc", weights=weights, model=model, car=factory)
    r = drive(spec, seeds)
    return (
        f"{traj.lap_time:>8.2f} {r['done']:>3}/{len(seeds):<1} {r['walls']:>5} {r['off']:>6.1f} "
        f"{r['lap']:>8.2f}"
    )


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--vehicles", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--tracks", help="a folder of racetrack-database CSV files")
    parser.add_argument("--only", nargs="+", help="track names to measure (default: all)")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steer-noise", type=float, default=0.002)
    parser.add_argument("--pedal-noise", type=float, default=0.01)
    parser.add_argument("--fast", action="store_true", help="the smaller manoeuvre set")
    args = parser.parse_args()
    from racing_lib.plants.commonroad import CommonRoadAt

    tracks = tracks_to_measure(args.tracks, args.only)
    seeds = list(range(args.seeds))
    warnings.simplefilter("ignore", ModelMismatchWarning)
    print(
        f"{'car':>3} {'track':<14} {'plan id':>8} {'full: ok':>8} {'walls':>5} {'off s':>6} "
        f"{'lap':>8} {'gap':>6} | {'clean at':>8} {'lap':>8} {'gap':>6} | "
        f"{'no marg.':>8} {'ok':>5} {'walls':>5} {'off s':>6} {'lap':>8} | "
        f"{'sheet':>8} {'ok':>5} {'walls':>5} {'off s':>6} {'lap':>8} | "
        f"{'plan s':>6} {'lap s':>6} {'RT':>6}"
    )
    for vehicle in args.vehicles:
        model, t_id = identify_vehicle(vehicle, args.fast)
        print(f"vehicle {vehicle}: identified in {t_id:.1f} s ({model.describe()})")
        factory = CommonRoadAt(
            vehicle, steer_noise_std=args.steer_noise, pedal_noise_std=args.pedal_noise
        )
        for track in tracks:
            print(measure_track(track, vehicle, model, factory, seeds), flush=True)
    return 0


if __name__ == "__main__":
    run(main)
