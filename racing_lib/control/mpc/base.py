"""What the coupled and the decoupled MPC share.

The plan table, the track band, the reference, the linearization along it, the pedal bounds,
the fallback when a QP fails, and timing.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import warnings

import numpy as np

from racing_lib.control.mpc.linearize import (
    continuous_linearization,
    packed_map,
    substep_linearization,
    unpack_linearization,
    zero_order_hold,
)
from racing_lib.control.mpc.qp_osqp import TrackingQP
from racing_lib.control.mpc.qp_problem import (
    QPData,
    QPSolution,
)
from racing_lib.control.mpc.settings import MPCSettings
from racing_lib.errors import ControlError
from racing_lib.geometry import FrenetTracker, Track
from racing_lib.geometry.spline import wrap_angle
from racing_lib.interfaces import Command, Observation
from racing_lib.jit import BufferedFunction
from racing_lib.model import NU, NX, CarModel, ModelMismatchWarning, U, X, discrete_linearization
from racing_lib.model.actuator import steering_lag_coefficients
from racing_lib.planning.trajectory import Trajectory

__all__ = ["MPCBase", "PlanTable", "edge_band"]

log = logging.getLogger(__name__)


class PlanTable:
    """The plan's node values, extended by one node at s = length, for fast vectorized lookups.

    Holds, per node: v_x, v_y, r, e_psi_ref (= -atan(v_y / v_x), the plan's heading relative to
    its own line), delta, a_x, kappa, theta (road pitch), and the e_y band. Lookups are linear
    interpolation in s (periodic) and the time <-> s relation of the plan.
    """

    # Column indices of the table.
    VX, VY, R, EPSI, DELTA, AX, KAPPA, THETA, BMIN, BMAX = range(10)
    #: The columns of the states v_x, v_y, r, e_psi and of the inputs delta, a_x: the same
    #: positions as in the model's state (`X`) and input (`U`) vectors.
    STATES = slice(VX, EPSI + 1)
    INPUTS = slice(DELTA, AX + 1)

    def __init__(
        self, plan: Trajectory, theta: np.ndarray, band_min: np.ndarray, band_max: np.ndarray
    ):
        self.length = float(plan.path.length)
        self.lap_time = float(plan.planned_lap_time)
        s = np.asarray(plan.s, dtype=float)
        vx = np.asarray(plan.vx, dtype=float)
        vy = np.asarray(plan.vy, dtype=float)
        cols = np.column_stack(
            [
                vx,
                vy,
                np.asarray(plan.r, dtype=float),
                # Along its own line the planned car has e_y_dot = v_x sin(e_psi) + v_y cos(e_psi)
                # = 0, so its heading relative to the line is -atan(v_y / v_x), not zero.
                -np.arctan2(vy, np.maximum(vx, 1.0)),
                np.asarray(plan.delta, dtype=float),
                np.asarray(plan.ax, dtype=float),
                np.asarray(plan.kappa, dtype=float),
                theta,
                band_min,
                band_max,
            ]
        )
        self.s = np.append(s, self.length)
        self.table = np.vstack([cols, cols[:1]])
        # Per interval: its length and the row at its end, so that a lookup gathers each once.
        self._ds = self.s[1:] - self.s[:-1]
        self._next = self.table[1:].copy()
        t = np.asarray(plan.t, dtype=float)
        self.t = np.append(t, self.lap_time)

    def at_s(self, s: np.ndarray) -> np.ndarray:
        """Interpolated rows at arc lengths ``s`` (m, any real; wrapped), shape (len(s), 10)."""
        sq = np.mod(s, self.length)
        i = np.searchsorted(self.s, sq, side="right") - 1
        # In place rather than np.clip, whose Python wrapper costs more than the search on the
        # MPC's 26 stages. (The upper bound matters: a tiny negative s wraps to exactly length.)
        np.minimum(np.maximum(i, 0, out=i), self.s.size - 2, out=i)
        w = ((sq - self.s.take(i)) / self._ds.take(i))[:, None]
        # take() gathers rows in a third of the time of fancy indexing, with the same values.
        return self.table.take(i, axis=0) * (1.0 - w) + self._next.take(i, axis=0) * w

    def time_at(self, s: float) -> float:
        """Plan time at arc length ``s`` within the lap, s."""
        return float(np.interp(s % self.length, self.s, self.t))

    def s_at_times(self, t: np.ndarray) -> np.ndarray:
        """Unwrapped arc length (m) the plan reaches at times ``t`` (s, may exceed a lap)."""
        laps = np.floor(t / self.lap_time)
        tq = t - laps * self.lap_time
        return np.interp(tq, self.t, self.s) + laps * self.length


def edge_band(
    plan: Trajectory, track: Track, car_width: float, margin: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grade and e_y band per plan node, from the track edges.

    For each plan node the centerline projection gives ``(s_c, e_c)``; the plan point is ``e_c``
    left of the centerline, so the edges are ``w_left(s_c) - e_c`` to its left and
    ``w_right(s_c) + e_c`` to its right. Measured along the plan's normal rather than the
    centerline's, the distance is ``1 / cos`` of the angle between the lines longer, so this is
    slightly conservative. The car's
    centre must stay half its width plus ``margin`` inside. Where the plan itself comes closer to an
    edge than that, the band is widened to include the plan (e_y = 0): the reference must lie
    inside its own band, else the QP would fight the plan everywhere near that edge.

    Returns
    -------
    theta, band_min, band_max : ndarray, shape (n_nodes,)
        Road pitch at the node (rad) and the band on e_y relative to the plan (m).
    """
    x = np.asarray(plan.x, dtype=float)
    y = np.asarray(plan.y, dtype=float)
    # Along the plan, so that every node stays on its own stretch where the track crosses itself.
    s_c, e_c = track.centerline.to_frenet_along(x, y)
    inset = 0.5 * car_width + margin
    band_max = np.asarray(track.width_left(s_c), dtype=float) - e_c - inset
    band_min = -(np.asarray(track.width_right(s_c), dtype=float) + e_c - inset)
    band_max = np.maximum(band_max, 0.0)
    band_min = np.minimum(band_min, 0.0)
    theta = np.asarray(track.grade(s_c), dtype=float)
    return theta, band_min, band_max


def _warn_if_mismatched(planned: CarModel, used: CarModel) -> None:
    """Warn when the MPC is to predict with another model than the plan was made with.

    A plan made without drag, tracked by an MPC that models drag, asks for speeds the
    controller's model says cost more power than the plan budgeted: the lap still runs, but the
    gap to the plan then measures the mismatch as much as the controller.
    """
    differ = planned.differences(used)
    if differ:
        warnings.warn(
            f"the plan and the controller use different models ({'; '.join(differ)}); drive "
            "the plan with the model it carries (pass no model) or re-plan with this one.",
            ModelMismatchWarning,
            stacklevel=4,
        )


class MPCBase:
    """Shared machinery: plan lookup, state estimate, fallbacks, counters and timings."""

    def __init__(
        self,
        plan: Trajectory,
        model: CarModel | None = None,
        *,
        track: Track | None = None,
        settings: MPCSettings | None = None,
        band: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        if not isinstance(plan, Trajectory):
            raise ControlError(
                f"the MPC tracks a planned racing_lib Trajectory, got {type(plan).__name__}; "
                "plan one with racing_lib.planning.plan(track)."
            )
        if model is None:
            model = plan.model
        elif isinstance(model, CarModel) and plan.model is not None:
            _warn_if_mismatched(plan.model, model)
        if not isinstance(model, CarModel):
            raise ControlError(
                "the plan carries no model to predict with (an old plan file, or a plan made "
                "outside racing_lib.planning): pass one, e.g. model=racing_lib.model."
                "identified_model()."
                if model is None
                else f"model must be a racing_lib.model.CarModel, got {type(model).__name__}."
            )
        self.settings = settings or MPCSettings()
        self.model = model
        self.params = model.params
        self.options = model.options
        pedal_map = self.params.pedal
        st = self.settings
        if st.throttle_scale != 1.0 or st.brake_scale != 1.0:
            pedal_map = dataclasses.replace(
                pedal_map,
                m_thr=pedal_map.m_thr * st.throttle_scale,
                m_brk=pedal_map.m_brk * st.brake_scale,
                p_thr=None if pedal_map.p_thr is None else pedal_map.p_thr * st.throttle_scale,
            )
        self.pedal_map = pedal_map
        self.plan = plan
        self.path = plan.path
        n_nodes = len(plan.s)
        if track is not None:
            theta, bmin, bmax = edge_band(
                plan, track, self.settings.car_width, self.settings.margin
            )
        else:
            theta = np.zeros(n_nodes)
            bmin, bmax = np.full(n_nodes, -np.inf), np.full(n_nodes, np.inf)
        if band is not None:
            bmin = np.broadcast_to(np.asarray(band[0], dtype=float), (n_nodes,)).copy()
            bmax = np.broadcast_to(np.asarray(band[1], dtype=float), (n_nodes,)).copy()
        self._plan = PlanTable(plan, theta, bmin, bmax)
        self._tracker = FrenetTracker(self.path)
        N = self.settings.horizon
        # lambda_k, k = 0..N: 1 -> 0 linearly (paper Eq. for the heuristic trajectory).
        self._lam = 1.0 - np.arange(N + 1) / N
        # Plan time of stage k after stage 0, s (the settings are frozen, so once is enough).
        self._stage_times = self.settings.dt * np.arange(N + 1)
        # One batched CasADi call linearizes all N stages.
        if self.settings.discretization == "zoh":
            lin = continuous_linearization(self.params, self.options)
        elif self.settings.substeps == 1 and not self.settings.jit:
            lin = discrete_linearization(self.params, self.options, float(self.settings.dt), "rk4")
        else:
            lin = substep_linearization(
                self.params,
                self.options,
                float(self.settings.dt),
                int(self.settings.substeps),
                bool(self.settings.jit),
            )
        self._lin_map = BufferedFunction(packed_map(lin, N))
        self._counters = {"qp_failures": 0, "fallback_shifted": 0, "fallback_brake": 0}
        self._rescues_at_reset = 0
        self._qp_list: list[TrackingQP] = []  # the QPs solved each period (set by subclasses)
        self._statuses: dict[str, int] = {}
        # Wall time (s) of the parts of the last step: project (nearest point), reference,
        # linearize, build (bounds and QP data), qp (solve), pedal (command), total.
        self.last_timing: dict[str, float] = {}
        self.last_solution: QPSolution | None = None
        self.last_qp_data: QPData | None = None
        self._u_prev = np.zeros(NU)

    # --- protocol --------------------------------------------------------------------------------
    def reset(self, obs: Observation) -> None:
        """Start a lap from ``obs``: global search on the plan; clear the counters and memory."""
        self._tracker.reset()
        self._tracker.project(obs.x, obs.y)
        for key in self._counters:
            self._counters[key] = 0
        self._rescues_at_reset = sum(getattr(qp, "rescues", 0) for qp in self._qp_list)
        self._statuses.clear()
        self._shift_buffer: list[np.ndarray] = []
        self.last_solution = None
        s0 = self._tracker.s or 0.0
        ref = self._plan.at_s(np.array([s0]))[0]
        self._u_prev = np.array([self._clip_steer(ref[PlanTable.DELTA]), ref[PlanTable.AX]])
        # The actuator's angle is not observed: estimate it by running the lag model on our own
        # commands, starting from the command the plan would have given.
        self._delta_est = float(self._u_prev[U.DELTA])

    def stats(self) -> dict[str, float]:
        """Counters of the lap.

        ``qp_failures``, ``fallback_shifted``, ``fallback_brake`` and ``qp_rescues`` (QPs that OSQP
        failed and Clarabel was asked to solve; those it solved too are not failures).
        """
        out = {k: float(v) for k, v in self._counters.items()}
        rescues = sum(getattr(qp, "rescues", 0) for qp in self._qp_list)
        out["qp_rescues"] = float(rescues - self._rescues_at_reset)
        return out

    # --- pieces ----------------------------------------------------------------------------------
    def current_state(self, obs: Observation) -> np.ndarray:
        """The model state ``xi_0`` (6,) of the car relative to the plan's line."""
        s, e_y = self._tracker.project(obs.x, obs.y)
        heading = self._tracker.heading
        xi = np.empty(NX)
        xi[X.VX] = obs.vx
        xi[X.VY] = obs.vy
        xi[X.R] = obs.r
        xi[X.EPSI] = wrap_angle(obs.psi - heading)
        xi[X.EY] = e_y
        xi[X.S] = s
        return xi

    def reference(self, s0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference states, inputs and plan rows for stages k = 0..N, spaced by plan time.

        Returns
        -------
        xi_ref : ndarray, shape (N+1, 6)
            ``[v_x, v_y, r, e_psi, 0, s]`` of the plan at ``t_plan(s0) + k dt``; ``s`` unwrapped
            (it may pass the lap length).
        u_ref : ndarray, shape (N+1, 2)
            The plan's ``[delta, a_x]`` there.
        rows : ndarray, shape (N+1, 10)
            All interpolated plan columns (curvature, pitch, band) there.
        """
        st = self.settings
        times = self._plan.time_at(s0) + self._stage_times
        s_k = self._plan.s_at_times(times)
        # Stage 0 is the projection itself (interpolating back from time would add round-off).
        s_k = s_k - s_k[0] + s0
        rows = self._plan.at_s(s_k)
        xi_ref = np.zeros((st.horizon + 1, NX))
        # Slices, not one column at a time: the table keeps these columns in the model's order.
        xi_ref[:, PlanTable.STATES] = rows[:, PlanTable.STATES]
        xi_ref[:, X.S] = s_k
        u_ref = rows[:, PlanTable.INPUTS]
        return xi_ref, u_ref, rows

    def linearize(
        self, xi_bar: np.ndarray, u_bar: np.ndarray, kappa: np.ndarray, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Discrete affine models of the N stages in one CasADi call.

        Parameters
        ----------
        xi_bar : ndarray, shape (N, 6)
            Linearization states.
        u_bar : ndarray, shape (N, 2)
            Linearization inputs.
        kappa, theta : ndarray, shape (N,)
            Curvature of the plan's line (1/m) and road pitch (rad) per stage.

        Returns
        -------
        A : (N, 6, 6), B : (N, 6, 2), d : (N, 6)
            ``xi_{k+1} ~= A_k xi_k + B_k u_k + d_k``.
        """
        N = self.settings.horizon
        # The packed input's columns are stages, so in column-major order it is written row by
        # row: stage k's state, input, curvature and pitch.
        packed = self._lin_map.inputs[0].reshape(N, -1)
        nx, nu = xi_bar.shape[1], u_bar.shape[1]
        packed[:, :nx] = xi_bar
        packed[:, nx : nx + nu] = u_bar
        packed[:, nx + nu] = kappa
        packed[:, nx + nu + 1] = theta
        A, B, d = unpack_linearization(self._lin_map()[0].copy(), N)
        if self.settings.discretization == "zoh":
            A, B, d = zero_order_hold(A, B, d, self.settings.dt)
        return A, B, d

    def ax_limits(
        self, xi: np.ndarray, a_y: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(a_min, a_max)`` on a_x (m/s^2) at states ``xi`` (N, 6).

        The pedal map's full-brake and full-throttle values, the optional floor, and the friction
        left over by the lateral acceleration ``a_y`` (m/s^2; default ``v_x r`` of ``xi``; see
        :class:`MPCSettings`). The interval always contains a_x = 0 when the pedal map allows it,
        and is never empty.
        """
        st = self.settings
        a_min, a_max = self.pedal_map.limits(xi)
        a_min = np.maximum(a_min, st.ax_min_floor)
        if st.friction_ellipse:
            p = self.params
            a_tot = st.friction_scale * p.peak_acceleration()
            a_long = min(a_tot, st.friction_scale * self.pedal_map.full_brake())
            if a_y is None:
                a_y = xi[:, X.VX] * xi[:, X.R]
            # The g-g ellipse (as in the planner); keep a tenth of a_x's axis even when the
            # lateral demand exceeds the limit.
            room = a_long * np.sqrt(np.maximum(1.0 - (a_y / a_tot) ** 2, 0.01))
            a_min = np.maximum(a_min, -room)
            a_max = np.minimum(a_max, room)
        return np.minimum(a_min, a_max), a_max

    def _apply(self, steer: float, a_x: float, xi0: np.ndarray) -> Command:
        """Record the command (for the rate penalty and the lag estimate) and make it a Command."""
        a, _ = steering_lag_coefficients(self.model.steer_tau, self.settings.dt)
        self._delta_est = a * self._delta_est + (1.0 - a) * steer
        self._u_prev = np.array([steer, a_x])
        return Command(steer=steer, pedal=float(self.pedal_map.pedal(float(a_x), xi0)))

    def _clip_steer(self, steer: float) -> float:
        lim = self.model.steer_max
        return min(max(float(steer), -lim), lim)

    def _fallback(self, xi0: np.ndarray, u_ref0: np.ndarray, status: str) -> Command:
        """Shifted previous solution, else safe braking; counts and logs the event."""
        self._counters["qp_failures"] += 1
        self._statuses[status] = self._statuses.get(status, 0) + 1
        # Log the first events of a lap, then every 100th, so a long outage cannot flood the log.
        n_fail = self._counters["qp_failures"]
        level = logging.WARNING if n_fail <= 5 or n_fail % 100 == 0 else logging.DEBUG
        if self._shift_buffer:
            u = self._shift_buffer.pop(0)
            self._counters["fallback_shifted"] += 1
            log.log(
                level,
                "MPC QP failed (%s, failure %d of this lap) at s = %.1f m: applying the shifted "
                "previous solution",
                status,
                n_fail,
                xi0[X.S],
            )
            return self._apply(self._clip_steer(u[U.DELTA]), float(u[U.AX]), xi0)
        self._counters["fallback_brake"] += 1
        log.log(
            level,
            "MPC QP failed (%s, failure %d of this lap) at s = %.1f m and no previous solution "
            "is left: safe braking",
            status,
            n_fail,
            xi0[X.S],
        )
        st = self.settings
        steer = self._clip_steer(
            u_ref0[U.DELTA] - st.fallback_gain_ey * xi0[X.EY] - st.fallback_gain_epsi * xi0[X.EPSI]
        )
        a, _ = steering_lag_coefficients(self.model.steer_tau, st.dt)
        self._delta_est = a * self._delta_est + (1.0 - a) * steer
        self._u_prev = np.array([steer, 0.0])
        return Command(steer=steer, pedal=float(st.brake_pedal))

    def failure_statuses(self) -> dict[str, int]:
        """How often each solver status caused a fallback in this lap."""
        return dict(self._statuses)

    def _conclude(self, u_plan: np.ndarray | None, status: str, xi0: np.ndarray,
                  u_ref0: np.ndarray) -> Command:  # fmt: skip
        """Apply the first input of a solved plan (keeping the rest for fallbacks), or fall back.

        ``u_plan`` is the optimal input sequence, shape (N, 2), or None when the QP failed.
        """
        if u_plan is None:
            return self._fallback(xi0, u_ref0, status)
        self._shift_buffer = list(u_plan[1:])
        u0 = u_plan[0]
        return self._apply(self._clip_steer(u0[U.DELTA]), float(u0[U.AX]), xi0)

    def _record_timing(self, t0: float, t1: float, t2: float, t3: float, t3b: float,
                       t4: float) -> None:  # fmt: skip
        """Store the time of each part of the step just taken (s), for the benchmarks."""
        t5 = time.perf_counter()
        self.last_timing = {
            "project": t1 - t0,
            "reference": t2 - t1,
            "linearize": t3 - t2,
            "build": t3b - t3,
            "qp": t4 - t3b,
            "pedal": t5 - t4,
            "total": t5 - t0,
        }
