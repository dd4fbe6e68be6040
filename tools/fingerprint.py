"""A behaviour fingerprint: hashes of plans, laps and an identification.

They prove that a refactor moved nothing.

Run it before and after a change that should leave every number as it was, and compare::

    python tools/fingerprint.py > before.json
    ... change the code ...
    python tools/fingerprint.py > after.json
    diff before.json after.json     # empty: bit for bit the same

What it hashes (SHA-256 of the raw float64 bytes, so one changed bit changes the hash):

* plans of the expressway: the centerline, the curvature QP and the time-optimal NLP;
* closed-loop laps of seed 0 through :func:`racing_lib.experiments.pipeline.race`: the coupled MPC
  with its tuned weights, the decoupled MPC, the coupled MPC without the smooth transition, the
  coupled MPC on a plan handed over as ``reference=`` and on the same plan loaded from its file,
  and the nominal controller on the centerline plan (every logged array but the controller's
  step times, which are wall-clock);
* an identification of the simulated car from fast-mode logs (the model it yields: fitted
  parameters, steering actuator and the measured grip margin).

The hashes depend on the machine's BLAS kernel: compare runs made on the same machine.
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from racing_lib.experiments.pipeline import race
from racing_lib.planning import Trajectory, plan
from racing_lib.tracks import load_track

#: Trajectory arrays a plan is made of.
PLAN_FIELDS = ("s", "x", "y", "psi", "kappa", "vx", "vy", "r", "delta", "ax", "t")


def digest(*arrays: object) -> str:
    """SHA-256 (first 16 hex digits) of the float64 bytes of ``arrays``."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())
    return h.hexdigest()[:16]


def plan_digest(traj: Trajectory) -> str:
    """Hash of a plan's node arrays."""
    return digest(*(getattr(traj, name) for name in PLAN_FIELDS))


def lap_digest(result: object) -> str:
    """Hash of every logged array of a race's first lap but the wall-clock step times.

    Arrays only: a lap's Drive also has a name and a kind (text) and no road pitch (None).
    """
    log = result.lap.log
    names = sorted(k for k, v in vars(log).items() if isinstance(v, np.ndarray) and k != "solve_ms")
    return digest(*(getattr(log, k) for k in names))


def main() -> int:
    t0 = time.perf_counter()
    track = load_track("expressway")
    out: dict[str, str] = {}
    plans = {}
    for method in ("centerline", "curvature", "time-optimal"):
        plans[method] = plan(track, method=method).trajectory
        out[f"plan {method}"] = plan_digest(plans[method])
    laps = {
        "coupled-mpc": {"controller": "coupled-mpc"},
        "decoupled-mpc": {"controller": "decoupled-mpc"},
        "coupled-mpc, no smooth transition": {
            "controller": "coupled-mpc",
            "smooth_transition": False,
        },
        "coupled-mpc, plan as reference": {
            "controller": "coupled-mpc",
            "reference": plans["time-optimal"],
        },
    }
    for name, kwargs in laps.items():
        out[f"lap {name}"] = lap_digest(race(track, method="time-optimal", **kwargs))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plan.csv"
        plans["time-optimal"].save_csv(path)
        result = race(track, controller="coupled-mpc", reference=path)
        out["lap coupled-mpc, plan from its file"] = lap_digest(result)
    out["lap nominal"] = lap_digest(race(track, method="centerline", controller="nominal"))

    from racing_lib.experiments.sysid import collect_logs, identify
    from racing_lib.vehicle import VehicleParams

    fit = identify(collect_logs(seed=0, fast=True), truth=VehicleParams())
    # the whole model an identification yields: parameters, actuator and the measured margins
    values = json.dumps(fit.car_model().to_dict(), sort_keys=True)
    out["identification"] = hashlib.sha256(values.encode()).hexdigest()[:16]
    json.dump(out, sys.stdout, indent=1)
    print()
    print(f"fingerprint made in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
