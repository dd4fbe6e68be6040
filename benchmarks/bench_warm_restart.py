"""Warm-starting IPOPT with multipliers: does a previous solve make the time-optimal NLP cheaper?

Issue 14 asks whether IPOPT's own warm start (``warm_start_init_point`` with the primal and dual
values of a previous solve, small ``warm_start_*`` pushes, a small ``mu_init``) beats the cold
start. For each track this script plans as ``plan(track, "time-optimal", start="cold")`` does
(grip margin on, the 3 m grid) and then re-solves the same NLP in three ways:

* ``restart``: from the cold solve's own solution and multipliers, with IPOPT's adaptive barrier
  (the planner's default). The best a warm start can hope for: it already sits on the optimum.
* ``restart-mono``: the same, with the monotone barrier from ``mu_init`` 1e-8.
* ``coarse``: a cold solve on a 6 m grid, its solution and multipliers interpolated to the 3 m
  grid (multipliers of the path constraints and bounds scaled by the ratio of node spacings,
  because the objective weighs each node by its spacing), then the monotone warm start.

Per track it prints IPOPT iterations, wall time (s, the NLP's build included) and the planned
lap time (s) of each way; then how many tracks each way needed fewer iterations than the cold
start on, and the medians of iterations. Times are this machine's; never run inside the tests.
The public :func:`racing_lib.planning.plan` takes no multipliers, so this script drives the
planner's internal problem directly.

Usage::

    python benchmarks/bench_warm_restart.py                 # the built-in tracks
    python benchmarks/bench_warm_restart.py TRACKS_DIR      # plus every *.csv there
"""

from __future__ import annotations

import dataclasses
import statistics
import time
import warnings
from typing import Any

import numpy as np
from _script import argument_parser, run, tracks_to_measure

from racing_lib.model import identified_model
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.time_optimal import (
    _SCALE,
    _VARS,
    TimeOptimalSettings,
    _initial_guess,
    _problem,
    clear_cache,
)
from racing_lib.planning.time_optimal_nlp import NXS

#: IPOPT's warm start: take the given multipliers and keep the point where it is.
WARM_START = (
    ("warm_start_init_point", "yes"),
    ("warm_start_bound_push", 1e-6),
    ("warm_start_bound_frac", 1e-6),
    ("warm_start_slack_bound_push", 1e-6),
    ("warm_start_slack_bound_frac", 1e-6),
    ("warm_start_mult_bound_push", 1e-6),
)
MONOTONE = (("mu_strategy", "monotone"), ("mu_init", 1e-8))
COARSE_SPACING = 6.0  # m


def solve(track: Any, params: Any, options: Any, st: TimeOptimalSettings, warm=None) -> dict:
    """One IPOPT solve of the planner's NLP; ``warm`` = (x, lam_x, lam_g) scaled, or cold."""
    grid = TrackGrid.from_track(track, st.spacing, st.car_width, st.margin)
    t0 = time.perf_counter()
    prob, _ = _problem(grid, track, params, options, st)
    grip = params.peak_acceleration()
    lbx, ubx = prob.bounds(np.full(grid.n, -grip), np.full(grid.n, grip), 190.0 / 3.6)
    if warm is None:
        z0, _ = _initial_guess(grid, params, "cold", 10.0)
        kw = {"x0": (z0 / _SCALE[:, None]).ravel(order="F")}
    else:
        kw = {"x0": warm[0], "lam_x0": warm[1], "lam_g0": warm[2]}
    kw["x0"] = np.clip(kw["x0"], lbx, ubx)
    sol = prob.solver(lbx=lbx, ubx=ubx, lbg=prob.lbg, ubg=prob.ubg, **kw)
    wall = time.perf_counter() - t0
    stats = prob.solver.stats()
    x = np.asarray(sol["x"], float).ravel()
    s_dot = np.asarray(prob.lap_fn(x)[1], float).ravel()
    lap = float(np.sum(0.5 * grid.ds * (1.0 / s_dot + 1.0 / np.roll(s_dot, -1))))
    return {
        "grid": grid,
        "x": x,
        "lam_x": np.asarray(sol["lam_x"], float).ravel(),
        "lam_g": np.asarray(sol["lam_g"], float).ravel(),
        "iterations": int(stats["iter_count"]),
        "wall_s": wall,
        "lap_s": lap,
        "ok": bool(stats["success"]),
    }


def _periodic(values: np.ndarray, rows: int, src: TrackGrid, dst: TrackGrid) -> np.ndarray:
    """Node-major (rows, n_src) values interpolated round the lap onto dst's nodes: (rows, n)."""
    a = values.reshape(rows, src.n, order="F")
    return np.stack([np.interp(dst.s, src.s, a[i], period=src.length) for i in range(rows)])


def coarse_to_fine(coarse: dict, fine_grid: TrackGrid) -> tuple[np.ndarray, ...]:
    """The coarse solve's solution and multipliers on the fine grid (scaled variables)."""
    src = coarse["grid"]
    ratio = (fine_grid.length / fine_grid.n) / (src.length / src.n)
    nv = len(_VARS)
    x = _periodic(coarse["x"], nv, src, fine_grid).ravel(order="F")
    lam_x = (ratio * _periodic(coarse["lam_x"], nv, src, fine_grid)).ravel(order="F")
    m = coarse["lam_g"].size // src.n
    lam_g = _periodic(coarse["lam_g"], m, src, fine_grid)
    # The defects' multipliers approximate the costates and do not scale with the spacing.
    lam_g[NXS:] *= ratio
    return x, lam_x, lam_g.ravel(order="F")


def bench_track(track: Any, params: Any, options: Any) -> dict[str, dict]:
    """Each way's iterations, wall time (s) and lap time (s) on one track."""
    clear_cache()
    base = TimeOptimalSettings()
    out = {"cold": solve(track, params, options, base)}
    cold = out["cold"]
    own = (cold["x"], cold["lam_x"], cold["lam_g"])
    adaptive = dataclasses.replace(base, ipopt_options=WARM_START)
    monotone = dataclasses.replace(base, ipopt_options=WARM_START + MONOTONE)
    out["restart"] = solve(track, params, options, adaptive, own)
    out["restart-mono"] = solve(track, params, options, monotone, own)
    coarse = solve(track, params, options, dataclasses.replace(base, spacing=COARSE_SPACING))
    fine = solve(track, params, options, monotone, coarse_to_fine(coarse, cold["grid"]))
    fine["iterations"] += coarse["iterations"]
    fine["wall_s"] += coarse["wall_s"]
    fine["fine_iterations"] = fine["iterations"] - coarse["iterations"]
    out["coarse"] = fine
    return out


def main() -> None:
    """Command-line entry point."""
    parser = argument_parser(__doc__)
    parser.add_argument("tracks_dir", nargs="?", help="folder of racetrack-database CSV files")
    parser.add_argument("--only", nargs="*", help="track names to keep")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    model = identified_model()  # what plan() plans with by default
    params, options = model.planning_params(), model.options
    tracks = tracks_to_measure(args.tracks_dir, args.only)
    ways = ("cold", "restart", "restart-mono", "coarse")
    print(f"{'track':13s}" + "".join(f" | {w + ' it':>15s} {'wall':>5s} {'lap':>8s}" for w in ways))
    rows = {}
    for track in tracks:
        rows[track.name] = row = bench_track(track, params, options)
        line = f"{track.name:13s}"
        for w in ways:
            r = row[w]
            its = f"{r['iterations']}"
            if w == "coarse":
                its += f" ({r['fine_iterations']} fine)"
            line += f" | {its:>15s} {r['wall_s']:5.1f} {r['lap_s']:8.3f}" + ("" if r["ok"] else "!")
        print(line, flush=True)
    print("\n(coarse: iterations on the 6 m grid plus on the 3 m grid; '!' marks a failed solve)")
    for w in ways[1:]:
        fewer = sum(r[w]["iterations"] < r["cold"]["iterations"] for r in rows.values())
        med = statistics.median(r[w]["iterations"] for r in rows.values())
        gap = max(abs(r[w]["lap_s"] / r["cold"]["lap_s"] - 1.0) for r in rows.values())
        print(
            f"{w:13s}: fewer iterations than cold on {fewer} of {len(rows)} tracks; median "
            f"{med:g} against {statistics.median(r['cold']['iterations'] for r in rows.values()):g}"
            f"; largest lap-time difference from cold {100 * gap:.3f} %"
        )


if __name__ == "__main__":
    run(main)
