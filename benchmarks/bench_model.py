"""Speed of the model's hot paths (run: ``python benchmarks/bench_model.py``).

Prints the median wall time of
* linearizing 20 and 30 stages in one call of the mapped CasADi Function (the MPC's per-step work),
  both raw (CasADi in/out) and through :meth:`racing_lib.model.Model.linearize` (numpy in/out);
* one spatial RK4 step evaluation (the planner's building block).

Times are order-of-magnitude on a shared machine; no assertion is made on them.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import casadi as ca
import numpy as np
from _script import argument_parser, run

from racing_lib.model import NX, Model, X, discrete_linearization, discretize


def _median_ms(fn: Callable[[], object], repeats: int = 300) -> float:
    for _ in range(10):  # warm-up
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def _stages(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xi = np.zeros((n, NX))
    xi[:, X.VX] = rng.uniform(15.0, 40.0, n)
    xi[:, X.VY] = rng.uniform(-0.5, 0.5, n)
    xi[:, X.R] = rng.uniform(-0.3, 0.3, n)
    xi[:, X.EPSI] = rng.uniform(-0.1, 0.1, n)
    xi[:, X.EY] = rng.uniform(-2.0, 2.0, n)
    xi[:, X.S] = np.linspace(0.0, 100.0, n)
    u = np.column_stack([rng.uniform(-0.05, 0.05, n), rng.uniform(-5.0, 2.0, n)])
    kappa = rng.uniform(-0.02, 0.02, n)
    return xi, u, kappa


def main() -> None:
    argument_parser(__doc__).parse_args()
    rng = np.random.default_rng(0)
    model = Model()
    print(f"casadi {ca.__version__}; model options: {model.options}")
    for n in (20, 30):
        xi, u, kappa = _stages(n, rng)
        mapped = discrete_linearization(model.params, model.options, 0.1, "rk4", "time").map(n)
        args = [ca.DM(xi.T), ca.DM(u.T), ca.DM(kappa[None, :]), ca.DM.zeros(1, n)]
        t_raw = _median_ms(lambda m=mapped, a=args: m(*a))
        t_np = _median_ms(lambda x=xi, v=u, k=kappa: model.linearize(x, v, 0.1, k))
        print(
            f"linearize {n} stages (time RK4, map): {t_raw:.3f} ms casadi, "
            f"{t_np:.3f} ms via Model.linearize (numpy)"
        )
    step = discretize(model.params, model.options, 3.0, "rk4", "spatial")
    xi0, u0, k0 = _stages(1, rng)
    args1 = [ca.DM(xi0[0]), ca.DM(u0[0]), float(k0[0]), 0.0]
    t_step = _median_ms(lambda: step(*args1), repeats=2000)
    print(f"one spatial RK4 step (ds = 3 m): {1e3 * t_step:.1f} us")


if __name__ == "__main__":
    run(main)
