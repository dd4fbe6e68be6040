"""Benchmark of the planners: speed profile, curvature QP, time-optimal NLP (warm and cold).

Run: ``python benchmarks/bench_planning.py [TRACK ...] [--ablations]`` (default: expressway).
Prints, per track: the centerline lap time, the QP's iterations and time, the NLP's build time and,
for a warm start (from the QP) and a cold start (centerline at 10 m/s), its IPOPT iterations,
solve time, status and planned lap time. ``--ablations`` adds the planned lap times of the model
ablations (no drag, no longitudinal load transfer, with lateral load transfer). Times are wall
times on this machine; no assertions.
"""

from __future__ import annotations

import time
import warnings

from _script import argument_parser, run

from racing_lib.model import ModelOptions, ModelParams
from racing_lib.planning import (
    CurvatureSettings,
    TimeOptimalSettings,
    Trajectory,
    solve_curvature,
    solve_time_optimal,
)
from racing_lib.planning.time_optimal import clear_cache, lap_time_with_model
from racing_lib.tracks import load_track

ABLATIONS = {
    "all effects": ModelOptions(),
    "no drag": ModelOptions(drag=False),
    "no longitudinal transfer": ModelOptions(longitudinal_weight_transfer=False),
    "with lateral transfer": ModelOptions(lateral_weight_transfer=True),
}


def bench_track(name: str, spacing: float, ablations: bool) -> None:
    """Print the benchmark lines for one track."""
    track = load_track(name)
    params = ModelParams()
    print(f"== {track.name}: {track.length:.0f} m, spacing {spacing} m, {track.boundary}")
    t0 = time.perf_counter()
    centre = Trajectory.from_centerline(track, params, spacing=spacing)
    print(f"centerline: lap {centre.lap_time:.2f} s ({time.perf_counter() - t0:.2f} s)")

    qp = solve_curvature(track, params, settings=CurvatureSettings(spacing=spacing))
    t_qp_model = lap_time_with_model(qp.grid, qp.v_x, qp.v_y, qp.e_psi, qp.e_y)
    print(
        f"curvature QP: {qp.status}, {qp.iterations} QPs, {qp.solve_time:.2f} s total "
        f"({qp.qp_time:.2f} s in cvxpy/solver), lap {qp.trajectory.lap_time:.2f} s "
        f"(NLP time formula: {t_qp_model:.2f} s), max|de_y| per QP "
        f"{[round(h, 2) for h in qp.history]}"
    )
    settings = TimeOptimalSettings(spacing=spacing)
    clear_cache()
    for start in ("warm", "cold"):
        res = solve_time_optimal(
            track,
            params,
            settings=settings,
            start=qp if start == "warm" else "cold",
            raise_on_failure=False,
        )
        print(
            f"NLP {start}: {res.status}, {res.iterations} iterations, "
            f"solve {res.solve_time:.2f} s, build {res.build_time:.2f} s, lap {res.lap_time:.3f} s"
        )
    if ablations:
        for label, options in ABLATIONS.items():
            res = solve_time_optimal(
                track, params, options, settings, start="cold", raise_on_failure=False
            )
            print(
                f"ablation {label:26s}: {res.status}, lap {res.lap_time:.3f} s, "
                f"{res.iterations} it, solve {res.solve_time:.2f} s, build {res.build_time:.2f} s"
            )


def main() -> None:
    """Command-line entry point."""
    parser = argument_parser(__doc__)
    parser.add_argument("tracks", nargs="*", default=["expressway"])
    parser.add_argument("--spacing", type=float, default=3.0)
    parser.add_argument("--ablations", action="store_true")
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=UserWarning)
    for name in args.tracks:
        bench_track(name, args.spacing, args.ablations)


if __name__ == "__main__":
    run(main)
