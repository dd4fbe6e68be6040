"""Model predictive tracking controllers: the coupled MPC of the paper and the decoupled baseline.

Taught in notebook 05. Both follow a planned :class:`~racing_lib.planning.trajectory.Trajectory`
in Frenet coordinates relative to the *plan's own line* (``trajectory.path``), so the reference
lateral offset is zero and the reference heading error is the plan's side-slip (see
:meth:`CoupledMPC.reference`). Both linearize the one model of :mod:`racing_lib.model` (never a
copy of its equations) and solve one small QP per control period with the OSQP fast path of
:mod:`racing_lib.control.mpc.qp_osqp`.

:class:`CoupledMPC` (paper Section "Tracking Controller")
    One QP over the coupled longitudinal and lateral dynamics, states
    ``[v_x, v_y, r, e_psi, e_y]`` and inputs ``[delta, a_x]``, linearized along the *heuristic
    trajectory* ``xi_hat_k = xi_ref_k + lambda_k (xi_0 - xi_ref_0)`` with ``lambda_k`` falling
    linearly from 1 to 0 over the horizon (``smooth_transition=False``: all ``lambda_k = 0``, the
    paper's ablation). The ``a_x`` bounds come from the pedal map at the heuristic states, and the
    solved ``a_x`` becomes a pedal command through the map's inverse (paper Appendix C).

:class:`DecoupledMPC` (the paper's controller ablation)
    A longitudinal MPC (state ``v_x``, input ``a_x``) and a lateral MPC (states
    ``[v_y, r, e_psi, e_y]``, input ``delta``, speed assumed to follow the reference), each
    linearized about the reference alone; the other subsystem's variables are frozen at their
    reference values.

Why the arc length ``s`` is not a QP state: it carries no cost and no constraint, and it enters
the other equations only through the curvature ``kappa(s)``, which the linearization evaluates
at the heuristic ``s_hat_k`` as a fixed parameter. Its row of the linear model therefore never
feeds back into the other five states; dropping it removes one sixth of the QP without changing
its solution.

Why the reference is spaced by time: stage ``k`` is the plan at time ``t_plan(s_0) + k dt``
(interpolated along the plan's own time stamps), which is where a car that follows the plan
exactly is after ``k`` control periods. Spacing by ``v_ref(s_0) dt`` would be the same on a
straight but would put the stages in the wrong places where the plan brakes or accelerates.

Robustness: a QP that does not report a solution never stops the lap. The controller applies the
next input of the previous solution (shifted), and when none is left a safe braking command; each
event is counted (:meth:`stats`) and logged.

Modules: :mod:`~racing_lib.control.mpc.settings` (weights, horizon, limits),
:mod:`~racing_lib.control.mpc.linearize` (the linear time-varying model),
:mod:`~racing_lib.control.mpc.base` (what both controllers share),
:mod:`~racing_lib.control.mpc.coupled`, :mod:`~racing_lib.control.mpc.decoupled`, and the QP:
:mod:`~racing_lib.control.mpc.qp_problem` (its data), :mod:`~racing_lib.control.mpc.qp_osqp` (the
fast path) and :mod:`~racing_lib.control.mpc.qp_cvxpy` (the readable reference).
"""

from racing_lib.control.mpc.coupled import CoupledMPC, QPSolver
from racing_lib.control.mpc.decoupled import DecoupledMPC
from racing_lib.control.mpc.linearize import augment_steering_lag, expm_batch
from racing_lib.control.mpc.qp_cvxpy import CvxpyTrackingQP
from racing_lib.control.mpc.qp_osqp import TrackingQP, solve_with_clarabel
from racing_lib.control.mpc.qp_problem import (
    SOLVED_STATUSES,
    QPData,
    QPSettings,
    QPShape,
    QPSolution,
    StepQP,
    tracking_cost,
)
from racing_lib.control.mpc.settings import MX, MPCSettings
from racing_lib.model.actuator import steering_lag_coefficients

__all__ = [
    "MX",
    "SOLVED_STATUSES",
    "CoupledMPC",
    "CvxpyTrackingQP",
    "DecoupledMPC",
    "MPCSettings",
    "QPData",
    "QPSettings",
    "QPShape",
    "QPSolution",
    "QPSolver",
    "StepQP",
    "TrackingQP",
    "augment_steering_lag",
    "expm_batch",
    "solve_with_clarabel",
    "steering_lag_coefficients",
    "tracking_cost",
]
