"""Speed and closed-loop benchmark of the MPC tracking controllers.

Prints, for each horizon, the median and 99th percentile of the whole controller step and of each
of its parts (projection on the plan, reference lookup, batched linearization, building the QP
data with the a_x bounds, the QP solve, the command and pedal map),
measured over a closed-loop lap of the simulated car; the QP alone through the OSQP fast path and
through the cvxpy reference; and the lap results of the coupled MPC (lap time against the plan,
v_x and e_y mean absolute errors, wall contacts) on the time-optimal plan of the track, falling
back to a centerline plan with a speed profile when the time-optimal planner is not available.

Usage::

    python benchmarks/bench_mpc.py                       # expressway, N = 20 25 30
    python benchmarks/bench_mpc.py --track shortcut --horizons 25 --seeds 0 1 2
    python benchmarks/bench_mpc.py --plan centerline --ablation

Never run inside the tests: timings depend on the machine and its load.
"""

from __future__ import annotations

import math
import time

import numpy as np
from _script import argument_parser, run

from racing_lib.control.mpc import CoupledMPC, DecoupledMPC, MPCSettings
from racing_lib.control.mpc.qp_cvxpy import CvxpyTrackingQP
from racing_lib.control.mpc.qp_osqp import TrackingQP
from racing_lib.control.mpc.qp_problem import QPSettings
from racing_lib.experiments.configs import (
    configuration_name,
    tuned_weights,
)
from racing_lib.experiments.lap import run_lap
from racing_lib.model import CarModel
from racing_lib.model.identified import identified_params
from racing_lib.planning.trajectory import Trajectory
from racing_lib.sim import SimulatedCar
from racing_lib.tracks import load_track

PARTS = ("project", "reference", "linearize", "build", "qp", "pedal", "total")


def conservative(params):
    """The identified parameters with the margins the simulated car needs (measured with
    benchmarks/bench_mpc.py: full brake about -11 m/s^2 where the map says -12.3, full throttle at
    45-50 m/s about half the map's value, combined-slip grip below mu D): mu 1.1, 60 % of the
    map's throttle and 88 % of its brake."""
    import dataclasses

    pedal = dataclasses.replace(
        params.pedal, m_thr=0.6 * params.pedal.m_thr, m_brk=0.88 * params.pedal.m_brk
    )
    return params.replace(mu=1.1, pedal=pedal)


def make_plan(track, params, method: str) -> Trajectory:
    """The time-optimal plan if asked and available, else the centerline at its speed profile."""
    if method in ("time-optimal", "time-optimal-margin"):
        try:
            from racing_lib.planning.time_optimal import solve_time_optimal

            tic = time.perf_counter()
            plan_params = conservative(params) if method == "time-optimal-margin" else params
            res = solve_time_optimal(track, plan_params)
            print(f"time-optimal plan: {time.perf_counter() - tic:.1f} s to solve")
            return res.trajectory
        except Exception as exc:  # the planner is optional for this benchmark
            print(f"time-optimal planner not usable ({exc!r}); falling back to the centerline")
    # A speed profile with some grip in reserve (the identified model slightly overrates the car).
    # Planned with mu = 1.0, and labelled so: the model it carries keeps that share of grip
    # in reserve, and an MPC predicting with the full parameters agrees with it.
    reserve = CarModel(params, grip_margin=1.0 - 1.0 / params.mu)
    return Trajectory.from_centerline(track, params.replace(mu=1.0)).with_model(reserve)


class PlanStart:
    """The simulated car, reset onto the plan 60 m before the line (position, heading, speed).

    ``SimulatedCar`` starts on the centerline; a time-optimal plan may be metres away from it
    there, and the MPC's first seconds would then measure the start, not the tracking.
    """

    def __init__(self, car: SimulatedCar, plan: Trajectory, before: float = 60.0) -> None:
        self.car = car
        self.dt = car.dt
        st = plan.interpolate(plan.length - before)
        beta = math.atan2(st.vy, st.vx)  # the car's yaw is the line's heading minus its side slip
        self._state = (st.x, st.y, st.psi - beta, st.vx, st.vy, st.r, st.delta)

    def reset(self, seed: int | None = None):
        self.car.reset(seed=seed)
        return self.car.set_state(*self._state)

    def step(self, steer_rad: float, pedal: float):
        return self.car.step(steer_rad, pedal)

    def __getattr__(self, name: str):
        return getattr(self.car, name)  # wall_contacts, offtrack_time, ...


def start_car(track, plan) -> PlanStart:
    return PlanStart(SimulatedCar(track, start_s=track.length - 60.0, start_speed=60.0), plan)


def step_timings(track, plan, params, horizon: int, n_steps: int) -> dict[str, np.ndarray]:
    """Per-part controller times (ms) over ``n_steps`` closed-loop steps."""
    mpc = CoupledMPC(plan, CarModel(params), track=track, settings=MPCSettings(horizon=horizon))
    car = start_car(track, plan)
    obs = car.reset(seed=0)
    mpc.reset(obs)
    times: dict[str, list[float]] = {p: [] for p in PARTS}
    for _ in range(n_steps):
        cmd = mpc.step(obs)
        for p in PARTS:
            times[p].append(1e3 * mpc.last_timing[p])
        obs = car.step(cmd.steer, cmd.pedal)
    return {p: np.asarray(v) for p, v in times.items()}


def qp_timings(track, plan, params, horizon: int, n_steps: int) -> dict[str, np.ndarray]:
    """The QPs of a closed-loop run, re-solved by a fresh fast QP and by the cvxpy reference."""
    mpc = CoupledMPC(plan, CarModel(params), track=track, settings=MPCSettings(horizon=horizon))
    car = start_car(track, plan)
    obs = car.reset(seed=0)
    mpc.reset(obs)
    data = []
    for _ in range(n_steps):
        cmd = mpc.step(obs)
        data.append(mpc.last_qp_data)
        obs = car.step(cmd.steer, cmd.pedal)
    # The fast path solves every problem in sequence (warm starts as in the controller); every
    # tenth one is also solved by cvxpy and by the fast path at tight tolerances.
    fast = TrackingQP(mpc.qp.shape, mpc.settings.qp)
    tight = TrackingQP(mpc.qp.shape, QPSettings(eps_abs=1e-9, eps_rel=1e-9, polish=True,
                                                max_iter=100000))  # fmt: skip
    ref = CvxpyTrackingQP(mpc.qp.shape)
    out: dict[str, list[float]] = {"osqp fast path": [], "cvxpy + osqp": [], "du default": [],
                                   "du tight": []}  # fmt: skip
    for i, d in enumerate(data):
        t0 = time.perf_counter()
        a = fast.solve(d)
        out["osqp fast path"].append(1e3 * (time.perf_counter() - t0))
        if i % 10:
            continue
        t1 = time.perf_counter()
        b = ref.solve(d)
        out["cvxpy + osqp"].append(1e3 * (time.perf_counter() - t1))
        c = tight.solve(d)
        if a.success and b.success and c.success:
            out["du default"].append(float(np.max(np.abs(a.u[0] - b.u[0]))))
            out["du tight"].append(float(np.max(np.abs(c.u - b.u))))
    return {k: np.asarray(v) for k, v in out.items()}


def print_table(title: str, rows: dict[str, np.ndarray]) -> None:
    print(f"\n{title}")
    print(f"  {'part':<16}{'median ms':>10}{'p99 ms':>10}")
    for name, v in rows.items():
        print(f"  {name:<16}{np.median(v):>10.3f}{np.percentile(v, 99):>10.3f}")


def lap_rows(track, plan, params, seeds, controllers) -> None:
    print(f"\nlaps on {track.name} ({plan.method} plan, planned lap {plan.planned_lap_time:.2f} s)")
    print(
        f"  {'controller':<22}{'seed':>5}{'done':>6}{'lap s':>9}{'vs plan':>9}{'vx MAE':>8}"
        f"{'ey MAE':>8}{'ey max':>8}{'walls':>6}{'off s':>7}{'ms med':>8}{'ms p99':>8}  fallbacks"
    )
    for label, make in controllers:
        for seed in seeds:
            tic = time.perf_counter()
            res = run_lap(start_car(track, plan), make(plan), plan, track=track, seed=seed)
            m = res.metrics
            gap = 100.0 * (m.lap_time_s / plan.planned_lap_time - 1.0)
            st = m.controller_stats
            print(
                f"  {label:<22}{seed:>5}{m.completed!s:>6}{m.lap_time_s:>9.2f}{gap:>8.1f}%"
                f"{m.vx_mae_mps:>8.2f}{m.ey_mae_m:>8.3f}{m.ey_max_m:>8.2f}{m.wall_contacts:>6}"
                f"{m.offtrack_time_s:>7.2f}{m.solve_time_ms_median:>8.2f}{m.solve_time_ms_p99:>8.2f}"
                f"  {int(st.get('qp_failures', 0))}/{int(st.get('fallback_brake', 0))}"
                f"  ({time.perf_counter() - tic:.0f} s wall)"
            )


def main() -> None:
    ap = argument_parser(__doc__)
    ap.add_argument("--track", default="expressway")
    ap.add_argument(
        "--plan",
        choices=["time-optimal", "time-optimal-margin", "centerline"],
        default="time-optimal",
        help="time-optimal-margin: planned with grip and pedal margins (see conservative())",
    )
    ap.add_argument("--horizons", type=int, nargs="+", default=[20, 25, 30])
    ap.add_argument("--steps", type=int, default=600, help="closed-loop steps per timing run")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--ablation", action="store_true", help="also the decoupled and no-smooth MPC")
    ap.add_argument(
        "--default-weights",
        action="store_true",
        help="drive with the MPC's default weights, not the tuned ones",
    )
    args = ap.parse_args()

    params = identified_params()
    track = load_track(args.track)
    centerline = make_plan(track, params, "centerline")
    # Warm up (CasADi JIT compilation happens once per process).
    CoupledMPC(centerline, CarModel(params), track=track)
    for N in args.horizons:
        print_table(
            f"controller step, N = {N} ({args.steps} steps on {track.name})",
            step_timings(track, centerline, params, N, args.steps),
        )
    q = qp_timings(track, centerline, params, args.horizons[0], min(args.steps, 300))
    print_table(f"one QP, N = {args.horizons[0]}", {k: q[k] for k in ("osqp fast path",
                                                                      "cvxpy + osqp")})  # fmt: skip
    if q["du tight"].size:
        print(
            f"  fast path vs cvxpy, max |u difference| over {q['du tight'].size} QPs: "
            f"{np.max(q['du tight']):.1e} at tight tolerances (1e-9); "
            f"u_0 at the controller's tolerances (1e-4): median {np.median(q['du default']):.1e}, "
            f"max {np.max(q['du default']):.1e}"
        )

    plan = make_plan(track, params, args.plan)

    weights_said: set[tuple] = set()

    def settings(plan: Trajectory, controller: str, **fixed) -> MPCSettings:
        """The weights race() would drive this set-up with: its shipped CMA-ES set, else defaults.

        Tuned weights belong to the plan they were tuned on: on the centerline plan (no tuned
        configuration) the defaults are used, as racing_lib.experiments.pipeline.race does.
        """
        smooth = fixed.get("smooth_transition", True)
        config = configuration_name(controller, plan.method, None, smooth)
        tuned = None if args.default_weights or config is None else tuned_weights(config)
        said = (controller, smooth, plan.method)
        if said not in weights_said:  # once per table and controller, not once per seed
            weights_said.add(said)
            what = f"tuned for '{config}'" if tuned else "defaults"
            print(f"  ({controller}{'' if smooth else ', no smoothing'}: weights {what})")
        return MPCSettings(**fixed, **(tuned or {}))

    # Factories take the plan, so that each table drives the plan it is judged against.
    controllers = [
        (
            "coupled MPC",
            lambda p: CoupledMPC(
                p, CarModel(params), track=track, settings=settings(p, "coupled-mpc")
            ),
        )
    ]
    if args.ablation:
        controllers += [
            (
                "coupled, no smoothing",
                lambda p: CoupledMPC(
                    p,
                    CarModel(params),
                    track=track,
                    settings=settings(p, "coupled-mpc", smooth_transition=False),
                ),
            ),
            (
                "decoupled MPC",
                lambda p: DecoupledMPC(
                    p, CarModel(params), track=track, settings=settings(p, "decoupled-mpc")
                ),
            ),
        ]
    lap_rows(track, plan, params, args.seeds, controllers)
    if args.plan != "centerline":
        lap_rows(track, centerline, params, args.seeds, controllers[:1])


if __name__ == "__main__":
    run(main)
