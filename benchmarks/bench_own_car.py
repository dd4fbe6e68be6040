"""A car nobody here wrote: identified, planned, raced (``python benchmarks/bench_own_car.py``).

For each CommonRoad car (``--vehicles``, default 2 and 3: the BMW 320i and the VW Vanagon,
single-track drift model, stock limits) the recipe of ``racing_lib.experiments.own_car``:

1. identification from the fast manoeuvre set (``collect_logs(fast=True)``, ``identify``), timed;
2. on every track, the time-optimal plan with the identified model (timed), and the same plan
   made with a model written by hand from the package's data sheet (``data_sheet``: mass, axle
   distances, inertia, tyre coefficients, no drag), which says what identification bought;
3. the coupled MPC (the shipped tuned weights, nothing retuned) drives the car along the
   identified plan, scaled in speed from 100 % down to 60 % until every seed laps cleanly
   (completed, no wall contact, no time off the track). Seeds draw the car's actuation noise
   (``--steer-noise`` rad, ``--pedal-noise``; the car is deterministic without it).

Prints one row per car and track: planned lap times (identified, data sheet), the full plan's
laps (completed, walls, time off track, mean lap and its gap to the plan), the fastest clean
scale with its mean lap and gap, and the wall times of planning and driving; then the plant's
real-time factor. ``--tracks DIR --only NAME ...`` adds racetrack-database circuits.

Needs the optional extra: pip install "racing-lib[commonroad]".
"""

from __future__ import annotations

import statistics
import time
import warnings

from _script import argument_parser, run, tracks_to_measure

from racing_lib.errors import PlantError
from racing_lib.experiments.lap import LapSpec, drive_lap
from racing_lib.experiments.sysid import CarUnderTest, collect_logs, identify
from racing_lib.model import CarModel, ModelMismatchWarning
from racing_lib.planning import plan

SCALES = (1.0, 0.9, 0.8, 0.7, 0.6)


def identify_vehicle(vehicle: int) -> tuple[CarModel, float]:
    """The identified model of a CommonRoad car and the identification's wall time (s)."""
    from racing_lib.plants.commonroad import CommonRoadAt, data_sheet, vehicle_parameters

    t0 = time.perf_counter()
    car = CarUnderTest(CommonRoadAt(vehicle), data_sheet(vehicle))
    logs = collect_logs(seed=0, fast=True, car=car)
    steer_max = float(vehicle_parameters(vehicle).steering.max)
    result = identify(logs, known=car.known, steer_max=steer_max)
    return result.car_model(), time.perf_counter() - t0


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
    """Laps of ``spec`` over ``seeds``: completed, walls, time off track (s), mean lap (s)."""
    laps, walls, off, done = [], 0, 0.0, 0
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
    return {"done": done, "walls": walls, "off": off, "lap": mean}


def clean(r: dict[str, float], n: int) -> bool:
    return r["done"] == n and r["walls"] == 0 and r["off"] == 0.0


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--vehicles", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--tracks", help="a folder of racetrack-database CSV files")
    parser.add_argument("--only", nargs="+", help="track names to measure (default: all)")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steer-noise", type=float, default=0.002)
    parser.add_argument("--pedal-noise", type=float, default=0.01)
    args = parser.parse_args()
    from racing_lib.experiments.configs import tuned_weights
    from racing_lib.plants.commonroad import CommonRoadAt

    tracks = tracks_to_measure(args.tracks, args.only)
    weights = tuned_weights("main")
    seeds = list(range(args.seeds))
    warnings.simplefilter("ignore", ModelMismatchWarning)
    head = (
        f"{'car':>3} {'track':<14} {'plan id':>8} {'plan sheet':>10} {'full: ok':>8} "
        f"{'walls':>5} {'off s':>6} {'lap':>8} {'gap':>6} | {'clean at':>8} {'lap':>8} "
        f"{'gap':>6} | {'plan s':>6} {'drive s':>7}"
    )
    print(head)
    for vehicle in args.vehicles:
        model, t_id = identify_vehicle(vehicle)
        print(f"vehicle {vehicle}: identified in {t_id:.1f} s ({model.describe()})")
        factory = CommonRoadAt(
            vehicle, steer_noise_std=args.steer_noise, pedal_noise_std=args.pedal_noise
        )
        for track in tracks:
            t0 = time.perf_counter()
            traj = plan(track, "time-optimal", model).trajectory
            t_plan = time.perf_counter() - t0
            try:
                sheet = plan(track, "time-optimal", sheet_model(vehicle)).trajectory.lap_time
            except Exception:  # noqa: BLE001 - a planner failure is a result here
                sheet = float("nan")
            t0 = time.perf_counter()
            rows = {}
            for scale in SCALES:
                ref = traj.scale_speed(scale) if scale != 1.0 else traj
                spec = LapSpec(track, ref, "coupled-mpc", weights=weights, model=model, car=factory)
                rows[scale] = (drive(spec, seeds), ref.lap_time)
                if clean(rows[scale][0], len(seeds)):
                    break
            t_drive = time.perf_counter() - t0
            full, planned = rows[1.0]
            best = next(((s, r) for s, r in rows.items() if clean(r[0], len(seeds))), None)
            gap = 100.0 * (full["lap"] / planned - 1.0)
            if best is None:
                clean_txt = f"{'none':>8} {'-':>8} {'-':>6}"
            else:
                s, (r, ref_lap) = best
                clean_txt = f"{s:>7.0%} {r['lap']:>8.2f} {100.0 * (r['lap'] / ref_lap - 1):>+5.1f}%"
            print(
                f"{vehicle:>3} {track.name:<14} {planned:>8.2f} {sheet:>10.2f} "
                f"{full['done']:>4}/{len(seeds):<3} {full['walls']:>5} {full['off']:>6.1f} "
                f"{full['lap']:>8.2f} {gap:>+5.1f}% | {clean_txt} | {t_plan:>6.1f} {t_drive:>7.1f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    run(main)
