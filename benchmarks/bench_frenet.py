"""Speed of the Frenet projection: FrenetTracker.project (per sub-step) and Path.to_frenet.

Prints median times; no asserts (timings depend on the machine). Run:

    python benchmarks/bench_frenet.py
"""

from __future__ import annotations

import time

import numpy as np
from _script import argument_parser, run

from racing_lib.geometry import FrenetTracker
from racing_lib.tracks import expressway_track, load_track, shortcut_track


def _median_us(fn, args: list[tuple], repeat: int = 5) -> float:
    """Median over `repeat` runs of the mean time per call, microseconds."""
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for a in args:
            fn(*a)
        runs.append((time.perf_counter() - t0) / len(args) * 1e6)
    return float(np.median(runs))


def main() -> None:
    argument_parser(__doc__).parse_args()
    rng = np.random.default_rng(0)
    for name in ("expressway", "shortcut"):
        expressway_track.cache_clear()
        shortcut_track.cache_clear()
        t0 = time.perf_counter()
        track = load_track(name)
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        load_track(name)
        cached = time.perf_counter() - t0
        path = track.centerline

        # A car-like sequence: 1 m apart (50 m/s at 20 ms sub-steps), weaving across the road.
        s = np.arange(0.0, path.length, 1.0)
        e_y = 0.8 * np.minimum(track.width_left(s), track.width_right(s)) * np.sin(s / 40.0)
        x, y, _ = path.to_cartesian(s, e_y)
        pts = list(zip(x.tolist(), y.tolist(), strict=True))
        tracker = FrenetTracker(path)
        tracker.project(*pts[0])
        t_track = _median_us(tracker.project, pts)

        idx = rng.integers(0, len(pts), 300)
        some = [pts[i] for i in idx]
        t_global = _median_us(path.to_frenet, some)
        t0 = time.perf_counter()
        path.to_frenet(x, y)
        t_vec = (time.perf_counter() - t0) / len(x) * 1e6
        t_pos = _median_us(path.position, [(float(v),) for v in s[:2000]])

        print(f"{name}: length {path.length:.1f} m, {len(path.knots)} knots")
        print(f"  build (first load)           {build * 1e3:9.1f} ms")
        print(f"  load again (cached)          {cached * 1e6:9.2f} us")
        print(f"  FrenetTracker.project        {t_track:9.2f} us per call (local tracking)")
        print(f"  Path.to_frenet, scalar       {t_global:9.2f} us per call (global search)")
        print(f"  Path.to_frenet, vectorized   {t_vec:9.2f} us per point ({len(x)} points)")
        print(f"  Path.position, scalar        {t_pos:9.2f} us per call")


if __name__ == "__main__":
    run(main)
