"""IPOPT as the planners use it: the solver and its options, and what to try when it refuses them.

Shared by the time-optimal NLP (:mod:`racing_lib.planning.time_optimal`) and the best lap
(:mod:`racing_lib.planning.best_lap`), with the trapezoid lap time both minimise.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.time_optimal_settings import IpoptSettings

__all__ = ["ipopt_solver", "option_advice", "trapezoid_lap_time"]


def option_advice(st: IpoptSettings) -> str:
    """What to check when IPOPT refuses the options of settings ``st`` (any planner's)."""
    extra = f"ipopt_options {st.ipopt_options!r}, " if st.ipopt_options else ""
    return (
        f"check the IPOPT options of the settings ({extra}tol {st.tol!r}, max_iter "
        f"{st.max_iter!r}, print_level {st.print_level!r}): an unknown name, a value out of "
        "range or a linear solver this build lacks"
    )


def trapezoid_lap_time(inv_sdot: ca.SX | ca.MX, grid: TrackGrid) -> ca.SX | ca.MX:
    """Lap time (s) from the nodes' 1/s_dot (s/m), by the trapezoid rule on the periodic grid.

    ``inv_sdot`` is a CasADi row (1 x N) of the nodes' 1/s_dot; the result is of its kind.

    Each node's weight is half of the two intervals (m) it touches, so the sum runs once round
    the lap. Shared with :mod:`racing_lib.planning.best_lap`.
    """
    w_node = 0.5 * (grid.ds + np.roll(grid.ds, 1))
    return ca.mtimes(inv_sdot, ca.DM(w_node))


def ipopt_solver(
    name: str,
    nlp: dict[str, ca.SX | ca.MX],
    st: IpoptSettings,
    derivatives: dict[str, ca.Function] | None = None,
    defaults: tuple[tuple[str, str | float], ...] = (),
) -> ca.Function:
    """CasADi's IPOPT ``nlpsol`` for ``nlp`` with the planners' options.

    The exact Hessian (CasADi differentiates the model symbolically, so it costs little) and the
    adaptive barrier update; ``st`` supplies ``print_level``, ``max_iter``, ``tol`` and any
    ``ipopt_options`` that override these. ``derivatives`` may hold ready-made ``grad_f``,
    ``jac_g`` and ``hess_lag`` functions (:class:`~racing_lib.planning.time_optimal_nlp.
    StructuredNLP`); ``defaults`` are IPOPT options of the caller, applied before
    ``st.ipopt_options``. Shared with :mod:`racing_lib.planning.best_lap`.
    """
    ipopt = {
        "print_level": st.print_level,
        "max_iter": st.max_iter,
        "tol": st.tol,
        "hessian_approximation": "exact",
        "mu_strategy": "adaptive",
        "sb": "yes",
    }
    ipopt.update(dict(defaults))
    ipopt.update(dict(st.ipopt_options))
    opts = {"ipopt": ipopt, "print_time": False, **(derivatives or {})}
    try:
        return ca.nlpsol(name, "ipopt", nlp, opts)
    except RuntimeError as exc:
        # CasADi checks the options as it builds the solver; its message is a long trace.
        said = [line for line in str(exc).splitlines() if "option" in line.lower()]
        detail = said[-1].strip() if said else str(exc).splitlines()[-1].strip()
        raise PlanningError(
            f"IPOPT refused the options of the {name} NLP ({detail[:200]}). Try: "
            f"{option_advice(st)}."
        ) from None
