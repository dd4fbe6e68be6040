"""The paper's coupled MPC: one QP over the longitudinal and lateral dynamics.

The QP is linearized along the heuristic trajectory that blends the measured state into the
plan.
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from racing_lib.control.mpc.base import MPCBase, PlanTable
from racing_lib.control.mpc.linearize import augment_steering_lag
from racing_lib.control.mpc.qp_osqp import TrackingQP
from racing_lib.control.mpc.qp_problem import (
    QPData,
    QPShape,
    QPSolution,
    StepQP,
)
from racing_lib.control.mpc.settings import COUPLED_SLICE, COUPLED_STATES, MX, MPCSettings
from racing_lib.errors import ControlError
from racing_lib.geometry import Track
from racing_lib.interfaces import Command, Observation
from racing_lib.model import NU, CarModel, U, X
from racing_lib.planning.trajectory import Trajectory

__all__ = ["LEARNED_SLIP_SHARE", "CoupledMPC", "QPSolver"]

#: With a learned model, the MPC keeps the front tyres' slip angle where they give at most this
#: share of their peak force (the planner's ``TimeOptimalSettings.slip_force_share``), unless the
#: model has a slip margin of its own (``CarModel.slip_share``).
LEARNED_SLIP_SHARE = 0.95


class QPSolver(Protocol):
    """What solves the coupled MPC's QP each period (:meth:`CoupledMPC.use_qp`).

    :class:`~racing_lib.control.mpc.qp_osqp.TrackingQP` is one; anything with the same
    ``solve`` is another. A ``rescues`` attribute (QPs handed to a second solver), if present,
    is counted in :meth:`CoupledMPC.stats`.
    """

    def solve(self, data: QPData) -> QPSolution:
        """The solution of the QP with these numbers (``success`` False when there is none)."""
        ...


class CoupledMPC(MPCBase):
    """The paper's coupled MPC: one QP for steering and longitudinal acceleration.

    Parameters
    ----------
    plan : Trajectory
        The planned trajectory; ``plan.path`` is the Frenet reference line.
    model : CarModel, optional
        The model to predict with: parameters (the pedal map gives the ``a_x`` bounds and turns
        the solved ``a_x`` into a pedal), effects and steering actuator. Default: the one the
        plan carries (``plan.model``), so that plan and controller agree.
    track : Track, optional
        Gives the e_y band (track edges relative to the plan, minus half the car width and the
        margin) and the road pitch. Without it the band is open and the road flat.
    settings : MPCSettings, optional
        Horizon, weights, margins, fallbacks, QP settings.
    band : (band_min, band_max), optional
        Override of the e_y band per plan node (or scalars), m.

    Attributes
    ----------
    front_slip_limit : float or None
        With a model that carries a learned correction: the front slip angle the steering
        command keeps to (rad; :meth:`steering_within_slip`; the model's ``slip_share`` of the
        peak force, or :data:`LEARNED_SLIP_SHARE`). None for a model as identified, whose MPC is
        the paper's.

    Examples
    --------
    >>> from racing_lib.planning.trajectory import Trajectory
    >>> from racing_lib.sim import SimulatedCar
    >>> from racing_lib.model import CarModel, identified_params
    >>> from racing_lib.tracks import load_track
    >>> track = load_track("shortcut")
    >>> params = identified_params()
    >>> model = CarModel(params, grip_margin=0.2)  # a plan with a fifth of the grip in reserve
    >>> plan = Trajectory.from_centerline(track, model.planning_params()).with_model(model)
    >>> mpc = CoupledMPC(plan, track=track)  # predicts with the model the plan carries
    >>> car = SimulatedCar(track, start_speed=float(plan.vx[0]))
    >>> obs = car.reset(seed=0)
    >>> mpc.reset(obs)
    >>> cmd = mpc.step(obs)
    >>> bool(-1.0 <= cmd.pedal <= 1.0 and abs(cmd.steer) <= mpc.model.steer_max)
    True
    >>> mpc.stats()
    {'qp_failures': 0.0, 'fallback_shifted': 0.0, 'fallback_brake': 0.0, 'qp_rescues': 0.0}

    A whole lap: ``racing_lib.experiments.lap.run_lap(car, mpc, plan, track=track, seed=0)``.
    """

    def __init__(
        self,
        plan: Trajectory,
        model: CarModel | None = None,
        *,
        track: Track | None = None,
        settings: MPCSettings | None = None,
        band: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        super().__init__(plan, model, track=track, settings=settings, band=band)
        st = self.settings
        shape = QPShape.make(
            n_state=len(MX),
            n_input=NU,
            horizon=st.horizon,
            state_weights=st.state_weights(),
            rate_weights=[st.w_ddelta, st.w_dax],
            rate_limits=[self.model.steer_rate_max * st.dt, np.inf],
            band_index=MX.EY,
            slack_linear=st.slack_linear,
            slack_quadratic=st.slack_quadratic,
        )
        self._shape = shape
        self.qp = TrackingQP(shape, st.qp)
        self._qp_list = [self.qp]
        self._lam_used = self._lam if st.smooth_transition else np.zeros_like(self._lam)
        self._shift_buffer = []
        # A learned correction may change how the model answers the steering (on circuits with
        # hairpins, it cut the yaw response under hard braking fourfold), and an MPC predicting
        # with it then steered the front tyres far past their peak and ran wide. The planner
        # bounds the slip angles; with a learned model the MPC does too, on the front axle,
        # which the steering acts on. The model as identified is left as the paper has it.
        params = self.model.params
        share = LEARNED_SLIP_SHARE if self.model.slip_share is None else self.model.slip_share
        self.front_slip_limit = (
            params.slip_angle_at(share)[0] if params.correction is not None else None
        )

    def use_qp(self, solver: QPSolver) -> None:
        """Solve each period's QP with ``solver`` instead of the built-in OSQP fast path.

        Everything else (reference, linearization, bounds, fallbacks, the pedal) stays as it is,
        so a lap then compares QP solvers alone. ``solver.solve`` receives each period's
        :class:`~racing_lib.control.mpc.QPData`; with :attr:`qp_shape` it is the whole QP
        (:meth:`StepQP.from_parts(mpc.qp_shape, data) <racing_lib.control.mpc.StepQP.from_parts>`).
        Exercise 5.5 drives a lap with the reader's own QP this way
        (:func:`racing_lib.grading.ch05.check_mpc_lap`).
        """
        if not callable(getattr(solver, "solve", None)):
            raise ControlError(
                f"use_qp needs an object with solve(data) -> QPSolution, got "
                f"{type(solver).__name__}."
            )
        self.qp = solver
        self._qp_list = [solver]
        self._rescues_at_reset = sum(getattr(qp, "rescues", 0) for qp in self._qp_list)

    @property
    def qp_shape(self) -> QPShape:
        """The fixed structure of each period's QP: sizes, weights, rate limits, slack penalty."""
        return self._shape

    @property
    def last_step_qp(self) -> StepQP | None:
        """The QP of the last period as a :class:`~racing_lib.control.mpc.StepQP` (a copy).

        Its linear model, reference, weights and bounds, with units; None before the first step.
        """
        if self.last_qp_data is None:
            return None
        return StepQP.from_parts(self._shape, self.last_qp_data)

    @property
    def blend_weights(self) -> np.ndarray:
        """``lambda_k``, k = 0..N, of the heuristic trajectory, shape (N+1,).

        ``lambda_k``, k = 0..N, of the heuristic trajectory: 1 falling linearly to 0 (all 0
        without the smooth transition), shape (N+1,).
        """
        return self._lam_used.copy()

    def heuristic_trajectory(self, xi0: np.ndarray, xi_ref: np.ndarray) -> np.ndarray:
        """The states the model is linearized at (the paper's heuristic trajectory).

        The states the model is linearized at: ``xi_hat_k = xi_ref_k + lambda_k (xi0 -
        xi_ref_0)`` (the paper's heuristic trajectory).

        Parameters
        ----------
        xi0 : ndarray (6,)
            The car's state (order of :class:`racing_lib.model.X`).
        xi_ref : ndarray (N+1, 6)
            The plan at stages 0..N (:meth:`reference`).

        Returns
        -------
        ndarray (N+1, 6)
            From the measured state at stage 0 to the plan at stage N.
        """
        return xi_ref + self._lam_used[:, None] * (xi0 - xi_ref[0])[None, :]

    @staticmethod
    def reserved_lateral_acceleration(xi_hat: np.ndarray, xi_ref: np.ndarray) -> np.ndarray:
        """The lateral acceleration the a_x bounds' friction ellipse reserves, m/s^2, (N,).

        At stages 0..N-1, the smaller of two magnitudes: the one the car is expected to have,
        ``v_x r`` of the heuristic trajectory, and the one the plan's line asks for at the
        heuristic speed, ``v_x^2 r_ref / v_ref`` (its curvature ``r_ref / v_ref``). The first
        alone closed the ellipse on a yaw wobble under hard braking that the line does not need
        (0.3 rad/s at 40 m/s is 12 m/s^2, the whole ellipse): the brake was cut for a period,
        again and again, and the car reached a hairpin several m/s too fast and ran wide (three
        of fifty generated circuits, ``benchmarks/bench_robustness.py``). The second alone keeps
        grip for a line the car is not on.
        """
        n = xi_hat.shape[0] - 1
        v_ref = np.maximum(xi_ref[:n, X.VX], 1.0)
        on_line = xi_hat[:n, X.VX] ** 2 * xi_ref[:n, X.R] / v_ref
        expected = xi_hat[:n, X.VX] * xi_hat[:n, X.R]
        return np.minimum(np.abs(on_line), np.abs(expected))

    def steering_within_slip(self, xi_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Steering bounds that keep the front slip angle within :attr:`front_slip_limit`, rad.

        ``alpha_f = delta - (v_y + l_f r) / v_x`` at the heuristic states of stages 0..N-1, so
        ``delta`` stays within ``front_slip_limit`` of ``(v_y + l_f r) / v_x``, inside the
        steering limits. Each stage's bounds are widened where needed to what the steering rate
        limit can reach from the last command, so the QP always has a solution.

        Parameters
        ----------
        xi_hat : ndarray (N, 6)
            The heuristic states of stages 0..N-1.

        Returns
        -------
        lower, upper : ndarray (N,)
            Bounds of the steering command, rad.
        """
        limit = float(self.front_slip_limit or np.inf)
        v_x = np.maximum(xi_hat[:, X.VX], 1.0)
        heading = (xi_hat[:, X.VY] + self.model.params.l_f * xi_hat[:, X.R]) / v_x
        lower, upper = heading - limit, heading + limit
        rate = self._shape.rate_limits[U.DELTA] * np.arange(1, len(heading) + 1)
        last = self._u_prev[U.DELTA]
        lower = np.minimum(lower, last + rate)
        upper = np.maximum(upper, last - rate)
        steer_max = self.model.steer_max
        return np.clip(lower, -steer_max, steer_max), np.clip(upper, -steer_max, steer_max)

    def step(self, obs: Observation) -> Command:
        """One control period: project, build the QP along the heuristic trajectory, solve."""
        st = self.settings
        N = st.horizon
        t0 = time.perf_counter()
        xi0 = self.current_state(obs)
        t1 = time.perf_counter()
        xi_ref, u_ref, rows = self.reference(xi0[X.S])
        xi_hat = self.heuristic_trajectory(xi0, xi_ref)
        # The same transition for the inputs, from the last command to the plan's: linearizing
        # at the plan's steering while the front tyres are working at a very different angle
        # gets the sign of the tyre-force slope wrong when the car is near the grip limit.
        u_hat = u_ref + self._lam_used[:, None] * (self._u_prev - u_ref[0])[None, :]
        kappa = rows[:N, PlanTable.KAPPA]
        theta = rows[:N, PlanTable.THETA]
        # State-dependent a_x limits at the heuristic states, stages 0..N-1.
        a_y = self.reserved_lateral_acceleration(xi_hat, xi_ref)
        a_min, a_max = self.ax_limits(xi_hat[:N], a_y)
        u_min, u_max = np.empty((N, NU)), np.empty((N, NU))
        u_min[:, U.DELTA], u_min[:, U.AX] = -self.model.steer_max, a_min
        u_max[:, U.DELTA], u_max[:, U.AX] = self.model.steer_max, a_max
        if self.front_slip_limit is not None:
            u_min[:, U.DELTA], u_max[:, U.DELTA] = self.steering_within_slip(xi_hat[:N])
        # Linearize only at inputs the QP may choose: after a hard brake (or a fallback) the last
        # a_x can lie far outside this step's bounds, and the tyre slopes there made the
        # prediction unstable enough for OSQP to report the QP infeasible.
        u_lin = np.minimum(np.maximum(u_hat[:N], u_min), u_max)  # np.clip, without its wrapper
        t2 = time.perf_counter()
        A, B, d = self.linearize(xi_hat[:N], u_lin, kappa, theta)
        t3 = time.perf_counter()
        idx = COUPLED_SLICE
        A_q, B_q, d_q = augment_steering_lag(
            A[:, idx, idx], B[:, idx, :], d[:, idx], U.DELTA, self.model.steer_tau, st.dt
        )
        x_ref = np.zeros((N, len(MX)))
        x_ref[:, : len(COUPLED_STATES)] = xi_ref[1:, idx]
        x0 = np.empty(len(MX))  # the coupled states, then the estimated steering angle
        x0[:-1] = xi0[idx]
        x0[-1] = self._delta_est
        data = QPData(
            x0=x0,
            A=A_q,
            B=B_q,
            d=d_q,
            x_ref=x_ref,
            u_prev=self._u_prev,
            u_min=u_min,
            u_max=u_max,
            band_min=rows[1:, PlanTable.BMIN],
            band_max=rows[1:, PlanTable.BMAX],
        )
        t3b = time.perf_counter()
        sol = self.qp.solve(data)
        t4 = time.perf_counter()
        self.last_qp_data = data
        self.last_solution = sol
        cmd = self._conclude(sol.u if sol.success else None, sol.status, xi0, u_ref[0])
        self._record_timing(t0, t1, t2, t3, t3b, t4)
        return cmd
