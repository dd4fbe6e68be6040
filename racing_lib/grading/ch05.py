"""Checks of the exercises of chapter 05 (the coupled MPC).

Exercise notebook: ``exercises/05_mpc.ipynb``. Every check compares the reader's function with
:mod:`racing_lib.control.mpc` or :mod:`racing_lib.model` on the same cases.

* 5.1 :func:`check_heuristic_trajectory`: the smoothly blended linearization trajectory
  ``xi_hat_k = xi_ref_k + lambda_k (xi_0 - xi_ref_0)``.
* 5.2 :func:`check_steering_lag`: the discrete first-order steering actuator in the QP.
* 5.3 :func:`check_pedal_inversion`: the pedal that produces the planned a_x (Appendix C).
* 5.4 :func:`check_lateral_mpc`: a tracking MPC's QP (cost, dynamics, bounds) for the lateral
  error of a car, which the reader writes and solves (:func:`lateral_mpc_problem`).
* 5.5 :func:`check_mpc_lap`: the capstone. The reader builds the coupled MPC's own QP in OSQP's
  form from each period's linear model (:class:`racing_lib.control.mpc.StepQP`); the library
  solves it inside the controller, which drives a lap (:func:`drive_capstone_lap`). Graded on the
  lap, after a check of three single periods that names a wrong QP's mistake
  (``racing_lib.grading._qp_capstone``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from racing_lib.control.mpc import (
    CoupledMPC,
    CvxpyTrackingQP,
    StepQP,
    TrackingQP,
    steering_lag_coefficients,
)
from racing_lib.experiments.lap import LapResult, LapSpec, make_car, run_lap
from racing_lib.geometry import FrenetTracker, Track
from racing_lib.grading._qp_capstone import (
    ReaderQP,
    Situation,
    check_format,
    diagnose_step,
    osqp_form,
)
from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_array,
    as_float,
    as_tuple,
    call,
    differs,
    every_case,
    grade,
    refuse_library,
)
from racing_lib.interfaces import Observation
from racing_lib.model import PedalMap, identified_params
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import figure_eight_track, load_track

__all__ = [
    "LAP_EY_MAX",
    "LAP_VX_MAE",
    "CapstoneRun",
    "LateralMPCProblem",
    "capstone_lap",
    "capstone_situations",
    "check_heuristic_trajectory",
    "check_lateral_mpc",
    "check_mpc_lap",
    "check_pedal_inversion",
    "check_steering_lag",
    "drive_capstone_lap",
    "lateral_mpc_problem",
]

_NAMES = ("v_x", "v_y", "r", "e_psi", "e_y", "s")
_UNITS = ("m/s", "m/s", "rad/s", "rad", "m", "m")


@functools.lru_cache(maxsize=1)
def _mpc():
    """A coupled MPC on the expressway's centerline plan (built once: about 4 s)."""
    track = load_track("expressway")
    return CoupledMPC(Trajectory.from_centerline(track, identified_params()), track=track)


def _library_heuristic(mpc, xi0: np.ndarray, xi_ref: np.ndarray) -> np.ndarray:
    """The heuristic trajectory exactly as CoupledMPC.step builds it."""
    return mpc.heuristic_trajectory(xi0, xi_ref)


def check_heuristic_trajectory(heuristic_trajectory) -> CheckResult:
    """Exercise 5.1: ``heuristic_trajectory(xi0, xi_ref) -> xi_hat``, all shape (N+1, 6).

    ``xi0`` (6,) is the car's state, ``xi_ref`` (N+1, 6) the plan at stages 0..N. Compared with the
    trajectory :class:`racing_lib.control.mpc.CoupledMPC` linearizes along (relative 1e-9).
    """

    def body() -> str:
        mpc = _mpc()
        situations = [
            # s0, offsets of the car from the plan: (v_x, v_y, r, e_psi, e_y)
            (400.0, (-3.0, 0.2, 0.05, 0.04, 1.5), "1.5 m left of the plan and 3 m/s slow"),
            (2900.0, (2.0, -0.4, -0.1, -0.08, -2.0), "2 m right of the plan and 2 m/s fast"),
            (4000.0, (0.0, 0.0, 0.0, 0.0, 0.0), "exactly on the plan"),
        ]
        n = mpc.settings.horizon
        for s0, offset, what in situations:
            xi_ref, _, _ = mpc.reference(s0)
            xi0 = xi_ref[0].copy()
            xi0[:5] += offset
            expected = _library_heuristic(mpc, xi0, xi_ref)
            given_xi0, given_ref = xi0.copy(), xi_ref.copy()
            got = as_array(
                call(heuristic_trajectory, given_xi0, given_ref),
                expected.shape,
                f"heuristic_trajectory (N + 1 = {n + 1} stages of 6 states)",
            )
            for name, given, original in (("xi0", given_xi0, xi0), ("xi_ref", given_ref, xi_ref)):
                if not np.array_equal(given, original):
                    raise Wrong(
                        f"with the car {what}, your function changed {name} in place: the "
                        f"controller still needs {'the plan' if name == 'xi_ref' else 'the state'}"
                        f" afterwards. Build xi_hat as a new array (or work on a copy)."
                    )
            err = np.abs(got - expected) - 1e-9 * (1.0 + np.abs(expected))
            if np.any(err > 0):
                k, i = np.unravel_index(int(np.argmax(err)), err.shape)
                g, e = got[k, i], expected[k, i]
                msg = (
                    f"with the car {what}, your linearization point at stage k = {k} "
                    f"({k * mpc.settings.dt:.1f} s ahead) has {_NAMES[i]} = {g:.3f} {_UNITS[i]}; "
                    f"the controller uses {e:.3f} {_UNITS[i]} (expected xi_hat[{k}, {i}] = "
                    f"{e:.4f}, got {g:.4f})."
                )
                lam = 1.0 - np.arange(n + 1) / n
                moving = xi_ref + lam[:, None] * (xi0[None, :] - xi_ref)
                if not np.any(np.abs(got - moving) > 1e-9 * (1.0 + np.abs(moving))):
                    msg += (
                        " You blended in the offset from each stage of the plan: the offset is "
                        "xi_0 - xi_ref_0, the car's offset now, shrunk by lambda_k."
                    )
                elif k == 0:
                    msg += " At k = 0 the trajectory starts at the car's own state, xi_0."
                elif k == n:
                    msg += " At k = N it has blended completely into the plan: xi_hat_N = xi_ref_N."
                else:
                    msg += " lambda_k falls linearly from 1 at k = 0 to 0 at k = N."
                raise Wrong(msg)
        return (
            "your heuristic trajectory starts at the car, blends linearly into the plan over the "
            f"{n} stages and matches CoupledMPC in all three situations."
        )

    return grade("5.1 Heuristic trajectory", body, weight=2.0)


def check_steering_lag(steering_lag) -> CheckResult:
    """Exercise 5.2: ``steering_lag(tau, dt) -> (a, w)`` of the first-order steering actuator.

    ``delta_{k+1} = a delta_k + (1 - a) delta_cmd`` and the period's mean angle
    ``w delta_k + (1 - w) delta_cmd``; compared with
    :func:`racing_lib.control.mpc.steering_lag_coefficients` (relative 1e-9).
    """

    def check_case(case: tuple[float, float]) -> None:
        tau, dt = case
        a_exp, w_exp = steering_lag_coefficients(tau, dt)
        a, w = as_tuple(call(steering_lag, tau, dt), 2, "steering_lag")
        a, w = as_float(a, "a"), as_float(w, "w")
        actuator = f"with a lag of tau = {tau * 1000:.0f} ms and a period of {dt * 1000:.0f} ms"
        if differs(a, a_exp, tol=1e-12, rel=1e-9):
            raise Wrong(
                f"{actuator}, your wheels cover {1 - a:.1%} of the way to a new command in "
                f"one period; the actuator covers {1 - a_exp:.1%} (expected a = {a_exp:.6f}, "
                f"got {a:.6f}).",
                hint="Solve delta_dot = (delta_cmd - delta) / tau over dt exactly.",
            )
        if differs(w, w_exp, tol=1e-12, rel=1e-9):
            raise Wrong(
                f"{actuator}, your mean steering angle over the period keeps {w:.1%} of the "
                f"old angle; the actuator keeps {w_exp:.1%} (expected w = {w_exp:.6f}, got "
                f"{w:.6f}).",
                hint="Average the exponential over the period: w = tau / dt (1 - a).",
            )

    def body() -> str:
        refuse_library(
            steering_lag,
            {"steering_lag_coefficients": steering_lag_coefficients},
            "solve the lag's differential equation over one period.",
        )
        every_case(((0.08, 0.1), (0.2, 0.1), (0.05, 0.05), (0.3, 0.02)), check_case)
        return "the lag coefficients agree with the controller's for slow and fast actuators."

    return grade("5.2 Steering lag", body, weight=1.0)


def _pedal_by_sign_of_a_x(pedal_map: Any, a_x: float, coasting: float) -> float:
    """The tempting mistake: the slope chosen by the sign of a_x instead of a_x - coasting."""
    slope = pedal_map.m_thr if a_x >= 0 else pedal_map.m_brk
    return float(np.clip((a_x - coasting) / slope, -1.0, 1.0))


def check_pedal_inversion(pedal_for) -> CheckResult:
    """Exercise 5.3: ``pedal_for(pedal_map, a_x, xi) -> u_p`` in [-1, 1].

    The inverse of the pedal map of Appendix C, compared with
    :meth:`racing_lib.model.PedalMap.pedal` (1e-9), including requests beyond full throttle or
    full brake (which must be clipped), a light deceleration that drag and rolling resistance
    overshoot at speed (throttle, although a_x < 0) and a light acceleration that the coasting
    term exceeds at low speed (brake, although a_x > 0). An answer that calls ``pedal_map.pedal``
    is refused.
    """
    pedal_map = PedalMap(m_0=0.8, m_xi=(-0.05, 0.0, 0.0, 0.0, 0.0, 0.0), m_thr=3.5, m_brk=10.0)
    # (v_x m/s, a_x m/s^2); coasting gives 0.8 - 0.05 v_x: -1.2 at 40 m/s, +0.55 at 5 m/s.
    cases = [(40.0, 1.0), (40.0, -6.0), (20.0, 0.0), (15.0, 5.0), (50.0, -15.0), (30.0, -0.7),
             (40.0, -0.5), (5.0, 0.3)]  # fmt: skip

    def check_case(case: tuple[float, float]) -> None:
        v_x, a_x = case
        xi = np.array([v_x, 0.0, 0.0, 0.0, 0.0, 0.0])
        expected = float(pedal_map.pedal(a_x, xi))
        got = as_float(call(pedal_for, pedal_map, a_x, xi.copy()), "pedal_for")
        if not differs(got, expected, tol=1e-9):
            return
        doing = f"{'accelerate' if a_x > 0 else 'brake'} at {abs(a_x):.1f} m/s^2"
        if a_x == 0.0:
            doing = "hold the speed"
        coasting = pedal_map.m_0 + float(np.dot(pedal_map.m_xi, xi))
        msg = (
            f"to {doing} at {v_x:.0f} m/s your driver sets the pedal to {got:+.3f}; the "
            f"map needs {expected:+.3f} (expected u_p = {expected:.4f}, got {got:.4f})."
        )
        telling, hint = 0.0, ""
        if abs(expected) == 1.0 and abs(got) > 1.0:
            telling, hint = 1.0, "The pedal ends at +-1: clip requests the car cannot meet."
        elif not differs(got, _pedal_by_sign_of_a_x(pedal_map, a_x, coasting), tol=1e-9):
            pedal = "throttle" if expected > 0 else "brake"
            telling = 2.0
            hint = (
                f"With the pedal released the car already does {coasting:+.2f} m/s^2 here, so "
                f"{a_x:+.1f} m/s^2 needs {pedal}: choose throttle or brake by the sign of "
                "a_x - (m_0 + m_xi . xi), not by the sign of a_x."
            )
        elif not differs(got, float(pedal_map.pedal(a_x - pedal_map.m_0 + coasting, xi)), tol=1e-9):
            # The pedal for a_x - m_0 instead of a_x - (m_0 + m_xi . xi).
            telling = 1.0
            hint = (
                f"With the pedal released the car does m_0 + m_xi . xi = {coasting:+.2f} m/s^2 "
                f"here, not m_0 = {pedal_map.m_0:+.2f}: m_xi . xi (drag and rolling resistance) "
                "grows with the speed."
            )
        elif not differs(
            got,
            np.clip(a_x / (pedal_map.m_thr if a_x >= 0 else pedal_map.m_brk), -1, 1),
            tol=1e-9,
        ):
            telling = 1.0
            hint = (
                "The car accelerates by m_0 + m_xi . xi with the pedal released; "
                "the pedal only has to add the difference."
            )
        raise Wrong(msg, telling, hint)

    def body() -> str:
        refuse_library(
            pedal_for,
            {"pedal": PedalMap.pedal},
            "invert the map from its coefficients m_0, m_xi, m_thr and m_brk.",
        )
        every_case(cases, check_case)
        return (
            "your pedal inversion agrees with PedalMap.pedal, clipping included, also where "
            "the coasting term decides between throttle and brake."
        )

    return grade("5.3 Pedal from acceleration", body, weight=1.0)


class LateralMPCProblem(NamedTuple):
    """One period's QP of a lateral tracking MPC (exercise 5.4).

    A car at speed ``v`` follows its line with errors x = (e_y, e_psi) (m, rad) and steers with
    delta (rad). Over one period ``dt`` the kinematic model gives ``x_{k+1} = A x_k + B delta_k
    + d_k``, where d_k is what the line's curvature kappa_k does to the errors.

    Attributes
    ----------
    A : ndarray (2, 2); B : ndarray (2,); d : ndarray (N, 2)
        The discrete model, stages k = 0..N-1.
    x0 : ndarray (2,)
        The measured errors now, (m, rad).
    q : ndarray (2,)
        Weights of e_y^2 (1/m^2) and e_psi^2 (1/rad^2) at stages 1..N.
    r : float
        Weight of the steering steps (delta_k - delta_{k-1})^2, 1/rad^2.
    delta_prev : float
        The command applied in the last period, rad (delta_{-1}).
    delta_max : float
        Steering bound, rad.
    """

    A: np.ndarray
    B: np.ndarray
    d: np.ndarray
    x0: np.ndarray
    q: np.ndarray
    r: float
    delta_prev: float
    delta_max: float


def lateral_mpc_problem(
    x0: tuple[float, float],
    delta_prev: float,
    kappa: np.ndarray,
    v: float = 20.0,
    dt: float = 0.1,
    wheelbase: float = 2.7,
    delta_max: float = 0.08,
) -> LateralMPCProblem:
    """The QP data of a kinematic car at ``v`` (m/s) on a line of curvatures ``kappa`` (1/m)."""
    A = np.array([[1.0, v * dt], [0.0, 1.0]])
    B = np.array([v * v * dt * dt / (2.0 * wheelbase), v * dt / wheelbase])
    kappa = np.asarray(kappa, dtype=float)
    d = np.column_stack([-0.5 * v * v * dt * dt * kappa, -v * dt * kappa])
    q = np.array([1.0, 10.0])
    return LateralMPCProblem(A, B, d, np.array(x0, float), q, 50.0, float(delta_prev), delta_max)


def _lateral_cost(problem: LateralMPCProblem, delta: np.ndarray) -> float:
    """The MPC's cost of the steering sequence ``delta`` (N,), by simulating the model."""
    x = problem.x0.copy()
    cost, previous = 0.0, problem.delta_prev
    for k, u in enumerate(delta):
        x = problem.A @ x + problem.B * u + problem.d[k]
        cost += float(problem.q @ (x * x)) + problem.r * (u - previous) ** 2
        previous = u
    return cost


def _condensed_optimum(problem: LateralMPCProblem, first_state_weighed: int = 1) -> np.ndarray:
    """The optimal commands, by the condensed QP as bounded least squares (SciPy's BVLS).

    Another method than the reader's sparse QP. ``first_state_weighed`` 0 weighs x_0..x_{N-1}
    instead of x_1..x_N (a mistake, for hints).
    """
    from scipy.optimize import lsq_linear

    n = problem.d.shape[0]
    # x_k = A^k x0 + sum_{j<k} A^{k-1-j} (B delta_j + d_j): affine in the commands.
    gamma = np.zeros((2 * (n + 1), n))
    offset = np.zeros(2 * (n + 1))
    offset[:2] = problem.x0
    for k in range(1, n + 1):
        offset[2 * k : 2 * k + 2] = problem.A @ offset[2 * k - 2 : 2 * k] + problem.d[k - 1]
        gamma[2 * k : 2 * k + 2] = problem.A @ gamma[2 * k - 2 : 2 * k]
        gamma[2 * k : 2 * k + 2, k - 1] = problem.B
    keep = slice(2 * first_state_weighed, 2 * (first_state_weighed + n))
    weights = np.sqrt(np.tile(problem.q, n))
    steps = np.eye(n) - np.eye(n, k=-1)
    first = np.zeros(n)
    first[0] = problem.delta_prev
    rows = np.vstack([weights[:, None] * gamma[keep], np.sqrt(problem.r) * steps])
    target = np.concatenate([-weights * offset[keep], np.sqrt(problem.r) * first])
    bound = problem.delta_max
    return lsq_linear(rows, target, bounds=(-bound, bound), method="bvls", tol=1e-12).x


@functools.lru_cache(maxsize=8)
def _lateral_reference(case: int) -> tuple[LateralMPCProblem, np.ndarray]:
    """Case ``case`` of exercise 5.4 and its optimal commands."""
    problem = _LATERAL_CASES[case]()
    return problem, _condensed_optimum(problem)


_LATERAL_CASES = {
    # 1 m left of the line, heading a little out, a left bend ahead; last command straight.
    0: lambda: lateral_mpc_problem((1.0, 0.02), 0.0, np.r_[np.zeros(8), np.full(17, 1 / 80)]),
    # On the line but steering hard right from the last period, a right bend: bound active.
    1: lambda: lateral_mpc_problem((0.0, -0.01), -0.05, np.r_[np.full(10, -1 / 40), np.zeros(15)]),
    # Settled on a straight, a tight bend entered in the horizon's last period: only the last
    # predicted state x_N sees it.
    2: lambda: lateral_mpc_problem((0.2, 0.0), 0.0, np.r_[np.zeros(24), 1 / 30]),
}


def check_lateral_mpc(mpc_steering) -> CheckResult:
    """Exercise 5.4: ``mpc_steering(problem) -> delta`` (N,), rad: the MPC's optimal commands.

    ``problem`` is a :class:`LateralMPCProblem`. Checked on two situations: the commands respect
    the bound, and their cost (found by simulating the model) is the optimum to 1e-4 (relative),
    which the check finds by another method (the condensed QP as bounded least squares).
    """

    def check_case(case: int) -> None:
        problem, best = _lateral_reference(case)
        n = problem.d.shape[0]
        what = (
            f"starting {problem.x0[0]:+.1f} m off the line, last command "
            f"{problem.delta_prev:+.2f} rad"
        )
        got = as_array(call(mpc_steering, problem), (n,), "mpc_steering")
        if np.max(np.abs(got)) > problem.delta_max + 2e-4:  # a first-order solver's tolerance
            k = int(np.argmax(np.abs(got)))
            raise Wrong(
                f"{what}, your MPC steers {got[k]:+.3f} rad at stage {k}, beyond the bound "
                f"{problem.delta_max} rad.",
                2.0,
                "Bound every command: -delta_max <= delta_k <= delta_max.",
            )
        cost, optimum = _lateral_cost(problem, got), _lateral_cost(problem, best)
        if cost <= optimum * (1.0 + 1e-4) + 1e-9:
            return
        msg = (
            f"{what}, your commands cost {cost:.5f}, the best {optimum:.5f}; the first command, "
            f"the one the car gets, is {got[0]:+.4f} rad against {best[0]:+.4f} rad."
        )
        from_zero = _condensed_optimum(problem._replace(delta_prev=0.0))
        shifted = _condensed_optimum(problem, first_state_weighed=0)
        if problem.delta_prev != 0.0 and np.max(np.abs(got - from_zero)) < 1e-3:
            raise Wrong(
                msg,
                2.0,
                "Your first steering step is measured from 0: the rate term of stage 0 is "
                "r (delta_0 - delta_prev)^2, from the command the car has now.",
            )
        if (
            problem.r > 0.0
            and np.max(np.abs(got - _condensed_optimum(problem._replace(r=0.0)))) < 1e-3
        ):
            raise Wrong(
                msg,
                2.0,
                "Your commands ignore the steering-rate term r sum_k (delta_k - delta_{k-1})^2 "
                "of the cost: it keeps the steering smooth.",
            )
        if np.max(np.abs(got - shifted)) < 1e-3:
            raise Wrong(
                msg,
                2.0,
                "Your cost weighs x_0..x_{N-1}: x_0 is measured and no command changes it; "
                "weigh the predicted x_1..x_N.",
            )
        raise Wrong(
            msg,
            0.0,
            "Check the model constraints: x_{k+1} = A x_k + B delta_k + d_k, starting from x0.",
        )

    def body() -> str:
        refuse_library(
            mpc_steering,
            {"TrackingQP": TrackingQP, "CoupledMPC": CoupledMPC},
            "write the QP in cvxpy (or OSQP): the commands as variables, the cost, the model as "
            "constraints, the bounds.",
        )
        every_case(sorted(_LATERAL_CASES), check_case)
        return (
            "your MPC's QP gives the optimal steering in all three situations, bound included; "
            "its first command is what the car would get."
        )

    return grade("5.4 The tracking QP", body, weight=3.0)


# --------------------------------------------------------------------------------------------------
# 5.5 The capstone: the coupled MPC's QP, built by the reader, drives a lap

#: Seed of the car's per-trial randomness (friction, actuation noise) in exercise 5.5's lap.
CAPSTONE_SEED = 0
#: Largest gap |e_y| (m) to the plan that exercise 5.5's lap may reach. The library's own coupled
#: MPC reaches 1.09 m on this lap (seed 0, measured), the exercise's solution 1.08 m (another
#: solver call, without the fast path's fixed sparsity pattern: the same QP to OSQP's 1e-4).
#: The 0.4 m margin leaves room for any correct formulation of the QP (other row order, dense or
#: sparse, another scaling), which OSQP solves to its tolerance along a slightly different path.
#: The mistakes that slip past the one-period checks in tests/test_exercises.py (a line 2.5 m
#: off the plan, a timid or a stiff driver) miss it by metres, by m/s or at a wall.
LAP_EY_MAX = 1.5
#: Largest mean speed gap |v_x - v_x,ref| (m/s) over exercise 5.5's lap: the library's MPC has
#: 0.64 m/s (the solution 0.63 m/s); the margin as for :data:`LAP_EY_MAX`.
LAP_VX_MAE = 1.0
#: Simulated time after which exercise 5.5's lap is given up, s: the plan's 31 s, the 150 m
#: run-up (5 s) and a third more, for a car that crawls instead of racing.
_LAP_TIME_LIMIT = 50.0

#: The periods of the one-step pre-check: the car's offset from the plan at arc length s0 (m):
#: speed (m/s), lateral offset (m, left positive), heading (rad); and the situation in words.
#: Together they make every part of the QP count: the a_x bounds (1, 2 and 3), the soft band
#: with its slack and the steering's slew rate (2), braking (3).
_SITUATIONS = (
    (150.0, -4.0, 1.0, 0.0, "in the right-hand loop, 1 m left of the plan and 4 m/s slow"),
    (390.0, 0.0, 3.9, 0.06, "3.9 m left of the plan, beyond the band, heading for the wall"),
    (60.0, 3.0, -2.0, 0.1, "2 m right of the plan and 3 m/s fast into the right-hand loop"),
)


@functools.lru_cache(maxsize=1)
def capstone_lap() -> tuple[Track, Trajectory]:
    """The circuit and plan of exercise 5.5, built once.

    The figure-eight (:func:`racing_lib.tracks.figure_eight_track`: 808 m, walls, 10 m wide, two
    270-degree loops of 60 m radius) driven on its centerline at the identified car's speed limit
    (a planned lap of 31.2 s). Short, so that a lap with the reader's QP, built in Python at every
    period, takes a few seconds; walled, so that a wrong QP shows as wall contacts.
    """
    track = figure_eight_track()
    return track, Trajectory.from_centerline(track, identified_params())


def _off_plan(plan: Trajectory, s0: float, dvx: float, ey: float, epsi: float) -> Observation:
    """The car at ``s0`` on the plan, ``dvx`` m/s faster, ``ey`` m left, turned by ``epsi`` rad."""
    x, y = plan.path.position(s0)
    psi = float(plan.path.heading(s0))
    vx = float(np.interp(s0, plan.s, plan.vx)) + dvx
    r = float(np.interp(s0, plan.s, plan.r))
    return Observation(t=0.0, x=float(x) - ey * np.sin(psi), y=float(y) + ey * np.cos(psi),
                       psi=psi + epsi, vx=vx, vy=0.0, r=r)  # fmt: skip


@functools.lru_cache(maxsize=1)
def capstone_situations() -> tuple[Situation, ...]:
    """The three periods of exercise 5.5's pre-check, each the QP the library's MPC builds there."""
    track, plan = capstone_lap()
    mpc = CoupledMPC(plan, track=track)
    out = []
    for s0, dvx, ey, epsi, what in _SITUATIONS:
        obs = _off_plan(plan, s0, dvx, ey, epsi)
        mpc.reset(obs)
        mpc.step(obs)
        out.append(Situation(what, mpc.last_step_qp, mpc.qp_shape, mpc.last_qp_data))
    return tuple(out)


class CapstoneRun(NamedTuple):
    """Exercise 5.5's lap, as driven (:func:`drive_capstone_lap`).

    Attributes
    ----------
    result : LapResult or None
        The lap's metrics and log; None when it was ended at a wall.
    qp : ReaderQP or None
        The solver that ran the reader's QP (its times and failures); None for the library's.
    wall : (t, s) or None
        When (s after the start) and where (m along the lap) the car first touched a wall.
    """

    result: LapResult | None
    qp: ReaderQP | None
    wall: tuple[float, float] | None


class _WallReached(Exception):
    """The car touched a wall: the lap's verdict is decided."""


class _EndAtTheWall:
    """A car whose lap ends at its first wall contact (records when and where).

    A car pinned to a wall makes every QP after it ill-conditioned (OSQP gives up, Clarabel
    rescues): driving the rest of the lap took 14 s and told nothing the first contact does not.
    """

    def __init__(self, car: Any, line: Any) -> None:  # any Plant; a FrenetTracker
        self._car = car
        self._line = line
        self.dt = car.dt
        self.wall: tuple[float, float] | None = None

    def reset(self, seed: int | None = None) -> Observation:
        obs = self._car.reset(seed=seed)
        self._line.reset()
        self._line.project(obs.x, obs.y)
        return obs

    def step(self, steer_rad: float, pedal: float) -> Observation:
        obs = self._car.step(steer_rad, pedal)
        s, _ = self._line.project(obs.x, obs.y)
        if self._car.wall_contacts:
            self.wall = (float(obs.t), float(s))
            raise _WallReached()
        return obs

    def __getattr__(self, name: str) -> Any:
        return getattr(self._car, name)


def drive_capstone_lap(build_qp: Callable[[StepQP], object] | None = None) -> CapstoneRun:
    """Exercise 5.5's lap: the coupled MPC with the QP of ``build_qp`` (None: the library's own).

    Seed :data:`CAPSTONE_SEED`; the lap ends at the car's first wall contact, or after 50 s of
    simulated time.
    """
    track, plan = capstone_lap()
    mpc = CoupledMPC(plan, track=track)
    qp = None
    if build_qp is not None:
        qp = ReaderQP(mpc.qp_shape, build_qp, mpc.settings.qp)
        mpc.use_qp(qp)
    car = _EndAtTheWall(make_car(LapSpec(track=track, trajectory=plan, controller="coupled-mpc")),
                        FrenetTracker(track.centerline))  # fmt: skip
    try:
        result = run_lap(car, mpc, plan, track=track, seed=CAPSTONE_SEED, max_time=_LAP_TIME_LIMIT)
    except _WallReached:
        return CapstoneRun(None, qp, car.wall)
    return CapstoneRun(result, qp, None)


def _judge_lap(run: CapstoneRun) -> str:
    """The verdict on the reader's lap: a sentence when it is good, else :class:`Wrong`."""
    failures = ""
    if run.qp is not None and run.qp.failures:
        status = max(run.qp.failures, key=run.qp.failures.get)
        failures = (f" {sum(run.qp.failures.values())} of its QPs had no solution ({status}); "
                    "the controller then drove on the last plan it had, or braked.")  # fmt: skip
    if run.wall is not None:
        t, s = run.wall
        raise Wrong(f"with your QP the car touched the wall {t:.1f} s after the start, at "
                    f"s = {s:.0f} m of the 808 m lap; the library's MPC drives this lap without "
                    f"touching one.{failures}")  # fmt: skip
    m, log = run.result.metrics, run.result.log
    if not m.completed:
        travelled = float(np.sum(np.hypot(np.diff(log.x), np.diff(log.y))))
        raise Wrong(f"with your QP the car did not finish the lap within {_LAP_TIME_LIMIT:.0f} s "
                    f"(the plan needs 31 s); it covered {travelled:.0f} m.{failures}")  # fmt: skip
    k = int(np.argmax(np.where(log.in_lap, np.abs(log.ey), -1.0)))
    if m.ey_max_m > LAP_EY_MAX:
        raise Wrong(f"with your QP the car strayed {m.ey_max_m:.2f} m from the plan (at s = "
                    f"{log.s_track[k]:.0f} m of the 808 m lap); the library's MPC stays within "
                    f"1.09 m (bound {LAP_EY_MAX} m).{failures}")  # fmt: skip
    if m.vx_mae_mps > LAP_VX_MAE:
        raise Wrong(f"with your QP the car's speed was {m.vx_mae_mps:.2f} m/s off the plan's on "
                    f"average; the library's MPC keeps it to 0.64 m/s (bound {LAP_VX_MAE} m/s)."
                    f"{failures}")  # fmt: skip
    # Only the bounds in the verdict: the notebook compares it (nbval), and a closed loop's last
    # digits may differ on another machine. drive_capstone_lap gives the numbers.
    return (
        "your QP matches the library's in three single periods and drives the lap without "
        f"touching a wall, within {LAP_EY_MAX} m of the plan and {LAP_VX_MAE} m/s of its speed on "
        "average (the library's own MPC: 1.09 m and 0.64 m/s)."
    )


def check_mpc_lap(build_qp) -> CheckResult:
    """Exercise 5.5: ``build_qp(step) -> (P, q, A, l, u)``, the coupled MPC's QP in OSQP's form.

    ``step`` is a :class:`~racing_lib.control.mpc.StepQP`; the decision vector is
    ``z = [x_1..x_N, u_0..u_{N-1}, eps_1..eps_N]`` (``racing_lib.grading._qp_capstone``).
    First three single periods (:func:`capstone_situations`): the reader's QP, solved to high
    accuracy, must give the library's optimum; a mistake (model rows, band, bounds, slew rate,
    cost) is named. Then the lap (:func:`drive_capstone_lap`): completed, no wall contact, at
    most :data:`LAP_EY_MAX` m from the plan and :data:`LAP_VX_MAE` m/s off its speed on average.
    The library's QP builders are refused.
    """

    def body() -> str:
        refuse_library(
            build_qp,
            {
                "TrackingQP": TrackingQP,
                "CvxpyTrackingQP": CvxpyTrackingQP,
                "CoupledMPC": CoupledMPC,
                "ReaderQP": ReaderQP,
                "osqp_form": osqp_form,
                "_build_P": None,
                "_build_A_pattern": None,
            },  # fmt: skip
            "build P, q, A, l and u from the step's model, weights and bounds.",
        )
        situations = capstone_situations()
        check_format(build_qp, situations[0])  # sizes and sides: once, not in every situation
        seen: list[StepQP] = [situations[0].step]

        def check_case(k: int) -> None:
            try:
                diagnose_step(build_qp, situations[k], seen)
            finally:
                seen.append(situations[k].step)

        every_case(range(len(situations)), check_case)
        return _judge_lap(drive_capstone_lap(build_qp))

    return grade("5.5 Capstone: your QP drives a lap", body, weight=4.0)
