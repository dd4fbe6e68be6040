"""The paper's controller ablation: a longitudinal and a lateral MPC.

Each is linearized about the reference alone, with the other subsystem frozen at the reference.
"""

from __future__ import annotations

import time

import numpy as np

from racing_lib.control.mpc.base import MPCBase, PlanTable
from racing_lib.control.mpc.linearize import augment_steering_lag
from racing_lib.control.mpc.qp_osqp import TrackingQP
from racing_lib.control.mpc.qp_problem import (
    QPData,
    QPShape,
)
from racing_lib.control.mpc.settings import LATERAL_STATES, MX, MPCSettings
from racing_lib.geometry import Track
from racing_lib.interfaces import Command, Observation
from racing_lib.model import NX, CarModel, U, X
from racing_lib.planning.trajectory import Trajectory

__all__ = ["DecoupledMPC"]


class DecoupledMPC(MPCBase):
    """The baseline of the paper's controller ablation: separate longitudinal and lateral MPCs.

    The longitudinal MPC chooses ``a_x`` to track the reference ``v_x`` with the ``v_x`` row of the
    model linearized about the reference (steering, lateral states at their reference values); the
    lateral MPC chooses ``delta`` to track ``[v_y, r, e_psi, e_y]`` assuming ``v_x`` and ``a_x``
    follow the reference. Both are linearized about the reference trajectory only (no heuristic
    transition). Parameters as for :class:`~racing_lib.control.mpc.coupled.CoupledMPC`.
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
        w = st.state_weights()
        self.qp_lon = TrackingQP(
            QPShape.make(1, 1, st.horizon, state_weights=w[:, [MX.VX]], rate_weights=[st.w_dax]),
            st.qp,
        )
        self.qp_lat = TrackingQP(
            QPShape.make(
                5,
                1,
                st.horizon,
                state_weights=w[:, [MX.VY, MX.R, MX.EPSI, MX.EY, MX.DELTA]],
                rate_weights=[st.w_ddelta],
                rate_limits=[self.model.steer_rate_max * st.dt],
                band_index=3,
                slack_linear=st.slack_linear,
                slack_quadratic=st.slack_quadratic,
            ),
            st.qp,
        )
        self._qp_list = [self.qp_lon, self.qp_lat]
        self._shift_buffer = []

    def step(self, obs: Observation) -> Command:
        """One control period: two QPs linearized about the reference, then apply both inputs."""
        st = self.settings
        N = st.horizon
        t0 = time.perf_counter()
        xi0 = self.current_state(obs)
        t1 = time.perf_counter()
        xi_ref, u_ref, rows = self.reference(xi0[X.S])
        kappa = rows[:N, PlanTable.KAPPA]
        theta = rows[:N, PlanTable.THETA]
        t2 = time.perf_counter()
        A, B, d = self.linearize(xi_ref[:N], u_ref[:N], kappa, theta)
        t3 = time.perf_counter()
        a_min, a_max = self.ax_limits(xi_ref[:N])
        xr, ur = xi_ref[:N], u_ref[:N]
        # Longitudinal: v_x only; everything else frozen at the reference (moved into d).
        vx = int(X.VX)
        others = np.array([i for i in range(NX) if i != vx])
        d_lon = (
            d[:, vx]
            + np.einsum("kj,kj->k", A[:, vx, others], xr[:, others])
            + B[:, vx, U.DELTA] * ur[:, U.DELTA]
        )
        lon = QPData(
            x0=xi0[[vx]],
            A=A[:, [vx]][:, :, [vx]],
            B=B[:, [vx]][:, :, [U.AX]],
            d=d_lon[:, None],
            x_ref=xi_ref[1:, [vx]],
            u_prev=self._u_prev[[U.AX]],
            u_min=a_min[:, None],
            u_max=a_max[:, None],
        )
        # Lateral: v_y, r, e_psi, e_y with v_x and a_x at the reference; s dropped as before.
        lat_idx = LATERAL_STATES
        frozen = np.array([X.VX, X.S])
        d_lat = (
            d[:, lat_idx]
            + np.einsum("kij,kj->ki", A[:, lat_idx[:, None], frozen[None, :]], xr[:, frozen])
            + B[:, lat_idx, U.AX] * ur[:, [U.AX]]
        )
        A_lat, B_lat, d_lat = augment_steering_lag(
            A[:, lat_idx[:, None], lat_idx[None, :]],
            B[:, lat_idx][:, :, [U.DELTA]],
            d_lat,
            0,
            self.model.steer_tau,
            st.dt,
        )
        x_ref_lat = np.zeros((N, len(lat_idx) + 1))
        x_ref_lat[:, : len(lat_idx)] = xi_ref[1:, lat_idx]
        lat = QPData(
            x0=np.append(xi0[lat_idx], self._delta_est),
            A=A_lat,
            B=B_lat,
            d=d_lat,
            x_ref=x_ref_lat,
            u_prev=self._u_prev[[U.DELTA]],
            u_min=np.full((N, 1), -self.model.steer_max),
            u_max=np.full((N, 1), self.model.steer_max),
            band_min=rows[1:, PlanTable.BMIN],
            band_max=rows[1:, PlanTable.BMAX],
        )
        t3b = time.perf_counter()
        sol_lon = self.qp_lon.solve(lon)
        sol_lat = self.qp_lat.solve(lat)
        t4 = time.perf_counter()
        self.last_solution = sol_lat
        ok = sol_lon.success and sol_lat.success
        u = np.column_stack([sol_lat.u[:, 0], sol_lon.u[:, 0]]) if ok else None
        status = sol_lat.status if not sol_lat.success else sol_lon.status
        cmd = self._conclude(u, status, xi0, u_ref[0])
        self._record_timing(t0, t1, t2, t3, t3b, t4)
        return cmd
