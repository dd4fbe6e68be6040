"""Re-tune the shipped MPC weights of every configuration, by the one protocol the course states.

Usage::

    python tools/retune_shipped.py                      # main, then every ablation row
    python tools/retune_shipped.py --configs no-drag    # rows only (start from the shipped main)
    python tools/retune_shipped.py --out weights.json   # elsewhere than the shipped file

The protocol (chapter 06 and 07 state it): the mean objective over the generated circuits of
:func:`racing_lib.experiments.configs.main_tuning_tracks`, one seeded lap each, 12 generations of
pycma's default population; ``main`` starts from the MPC's default weights and every other row from
main's result. No circuit the course or the benchmarks report on is among the tuning circuits.

Run it after a change to the MPC, the planner or the simulated car, then commit the file and
regenerate the ablation table (CONTRIBUTING.md says how). 7-13 min per configuration on two cores
(2026-12-07). Interrupted, it resumes from the checkpoints in ``--work-dir``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from racing_lib.experiments.configs import (
    TUNING_CONFIGS,
    generate_tuned_weights,
    main_tuning_tracks,
)
from racing_lib.optim.cmaes import TuningSettings

#: The protocol's budget and seeds.
GENERATIONS = 12
SEEDS = (0,)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", nargs="+", default=list(TUNING_CONFIGS), choices=TUNING_CONFIGS)
    ap.add_argument("--out", type=Path, default=None, help="JSON file (default: the shipped one)")
    ap.add_argument("--work-dir", type=Path, default=Path("runs/retune"), help="checkpoints")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)

    tracks = main_tuning_tracks()
    # popsize=None: pycma's default population even in fast mode, which would shrink it.
    settings = TuningSettings.default(max_generations=GENERATIONS, seed=0, popsize=None)
    for name in args.configs:
        t0 = time.perf_counter()
        results = generate_tuned_weights(
            (name,),
            track=tracks,
            seeds=SEEDS,
            settings=settings,
            workers=args.workers,
            out=args.out,
            work_dir=args.work_dir,
            progress=True,
            initial=None if name == "main" else "main",
        )
        print(f"{name}: objective {results[name].best_objective:+.3f} "
              f"in {time.perf_counter() - t0:.0f} s")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
