"""The simulated car: the stand-in for Gran Turismo Sport, behind the `Plant` protocol.

A higher-fidelity plant than the planning model (`racing_lib.model`), so that model mismatch,
identification and the paper's ablations mean something:

* inputs at 10 Hz: a steering command (angle- and rate-limited, first-order actuator lag) and one
  pedal u_p in [-1, 1] (throttle >= 0, brake < 0); outputs only spatial states (`Observation`);
* a double-track chassis: four wheel loads with longitudinal and lateral load transfer, Pacejka
  lateral forces with tyre load sensitivity and combined slip (friction ellipse), aerodynamic drag,
  rolling resistance and road grade from the track's elevation;
* a nonlinear rear-wheel-drive powertrain (engine torque curve, power limit, six gears with
  automatic shifting and a torque cut while shifting) and brakes with a front/rear split, every
  longitudinal tyre force limited by the tyre's friction;
* walls on walled tracks (contact stops the motion into the wall, costs speed, and is counted with
  its duration); on open tracks the wheels beyond the edge lose grip;
* fixed-step RK4 inside each control step; seeded per-trial randomness (actuation noise and a small
  friction variation), bit-for-bit reproducible per seed.

The smooth part of the physics is one function, `racing_lib.vehicle.dynamics.car_vector_field`,
that runs on floats (the fast path, the `math` module) and on CasADi symbols, so a planner can
optimize a lap with the simulated car's own equations without importing the plant. The discrete
parts (gear choice, walls, edge friction) stay here, in `SimulatedCar`. Every parameter lives in
`racing_lib.vehicle.VehicleParams`; the protocol it implements, `racing_lib.interfaces.Plant`.

Taught in notebook 02 (the simulated car and its logs).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

from racing_lib.errors import ControlError, PlantError
from racing_lib.geometry import (
    FrenetTracker,
    Track,
)
from racing_lib.interfaces import Observation
from racing_lib.jit import BufferedFunction, compiled_or_interpreted
from racing_lib.vehicle.contact import TrackTables, WallContact, wheels_beyond_edge
from racing_lib.vehicle.dynamics import SimState, rk4_substep_function
from racing_lib.vehicle.forces import (
    axle_cornering_stiffness,
    drive_force,
    gear_rpm,
    static_axle_loads,
    wheel_loads,
)
from racing_lib.vehicle.params import VehicleParams

if TYPE_CHECKING:
    # casadi is only imported where a Function is built (racing_lib.vehicle.dynamics)
    import casadi as ca

__all__ = ["SimulatedCar"]

_TWO_PI = 2.0 * math.pi


@functools.lru_cache(maxsize=16)
def _substep_function(params: VehicleParams, jit: bool) -> ca.Function:
    """The car's RK4 substep (`rk4_substep_function`), compiled when ``jit`` and a C compiler work.

    Compiled code computes the interpreter's values to the last bit (`racing_lib.jit`; only a
    zero may differ in sign), in a third of its time. Kept per process, since a lap builds a new
    car: a build that failed is not tried again until the next process.
    """
    fn = rk4_substep_function(params)
    if not jit:
        return fn
    (fn,) = compiled_or_interpreted(
        [fn], "the simulated car's RK4 substep", "SimulatedCar(jit=False)"
    )
    return fn


class SimulatedCar:
    """The simulated race car on a track (implements `Plant`).

    Parameters
    ----------
    track : Track
        The track: its centerline gives the Frenet position for walls / edges, its widths the edges,
        its elevation the road grade, its ``boundary`` the edge behaviour ('walls' or 'open').
    params : VehicleParams
        The car's true parameters.
    dt : float
        Control period, s (inputs are held for dt).
    start_s : float
        Arc length of the start on the centerline, m.
    start_speed : float
        Initial forward speed (flying start), m/s.
    substep : float
        Nominal RK4 step, s; dt is split into equal substeps no longer than this. At low speed the
        substep shrinks further (the tyre dynamics stiffen like 1/v_x), so RK4 stays stable.
    jit : bool
        Evaluate the substep as machine code (built by the system C compiler once per parameter
        set, about 0.2 s, and cached on disk by :mod:`racing_lib.jit`): the same numbers as
        CasADi's interpreter, to the last bit (only a zero may differ in sign), about three times
        faster. Without a compiler the car warns and uses the interpreter.

    Attributes
    ----------
    wall_contacts : int
        Number of wall contact episodes since reset (a car scraping along a wall counts once).
    wall_contact_time : float
        Time spent touching a wall, s.
    offtrack_time : float
        Time with at least one wheel beyond the track edge (open tracks), s.

    Notes
    -----
    ``reset(seed=None)`` gives the nominal car (no noise, nominal friction); ``reset(seed)`` draws
    the trial's friction variation and its actuation noise from ``numpy.random.default_rng(seed)``.
    """

    def __init__(
        self,
        track: Track,
        params: VehicleParams | None = None,
        dt: float = 0.1,
        start_s: float = 0.0,
        start_speed: float = 20.0,
        substep: float = 0.025,
        jit: bool = True,
    ) -> None:
        p = params if params is not None else VehicleParams()
        for name, value in (("dt", dt), ("substep", substep)):
            if not (math.isfinite(value) and value > 0.0):
                raise PlantError(f"SimulatedCar {name} must be a positive number of seconds.")
        if not (math.isfinite(start_s) and math.isfinite(start_speed) and start_speed >= 0.0):
            raise PlantError("SimulatedCar start_s must be finite and start_speed >= 0 m/s.")
        self.track = track
        self.params = p
        self.dt = float(dt)
        self.start_s = float(start_s)
        self.start_speed = float(start_speed)
        self._n_base = max(1, math.ceil(self.dt / substep - 1e-9))
        # Stiffest tyre mode ~ (sum of cornering stiffnesses) (1/m + l^2/I) / v_x; RK4 is stable
        # for |lambda h| < 2.8, we keep it below 2.
        f_zf, f_zr = static_axle_loads(p.m, p.l_f, p.l_r, p.g)
        c_sum = axle_cornering_stiffness(f_zf, p.mu, p.B_f, p.C_f, p.D_f)
        c_sum += axle_cornering_stiffness(f_zr, p.mu, p.B_r, p.C_r, p.D_r)
        self._stiffness = c_sum * (1.0 / p.m + max(p.l_f, p.l_r) ** 2 / p.I_zz)
        self._walls = track.boundary == "walls"
        self._tracker = FrenetTracker(track.centerline)
        self._rk4_fn = BufferedFunction(_substep_function(p, bool(jit)))
        self._tables = TrackTables(track)
        # The edge checks (racing_lib.vehicle.contact): body corners (walls), wheels (open edges).
        self._wall = WallContact(
            p.m, p.I_zz, p.l_f + p.overhang_front, -(p.l_r + p.overhang_rear), p.width,
            p.wall_mu, p.wall_entry_keep, p.wall_release_gap,
        )  # fmt: skip
        self._wheels_xy = ((p.l_f, 0.5 * p.l_t), (p.l_f, -0.5 * p.l_t),
                           (-p.l_r, 0.5 * p.l_t), (-p.l_r, -0.5 * p.l_t))  # fmt: skip
        self.reset()

    @property
    def wall_contacts(self) -> int:
        """Wall contact episodes since reset (a car scraping along a wall counts once)."""
        return self._wall.contacts

    @property
    def wall_contact_time(self) -> float:
        """Time spent touching a wall since reset, s."""
        return self._wall.contact_time

    # ------------------------------------------------------------------ Plant API
    def reset(self, seed: int | None = None) -> Observation:
        """Place the car at ``start_s`` on the centerline, heading along it, at ``start_speed``.

        Parameters
        ----------
        seed : int or None
            Seed of the trial's randomness (friction variation, actuation noise). None: the
            nominal car, without randomness.
        """
        p = self.params
        self._seed = seed
        if seed is None:
            self._rng = None
            self._mu = p.mu
        else:
            self._rng = np.random.default_rng(seed)
            self._mu = p.mu * (1.0 + p.mu_variation_std * float(self._rng.standard_normal()))
        path = self.track.centerline
        x0, y0 = path.position(self.start_s)
        psi0 = float(np.asarray(path.heading(self.start_s)))
        self._state = [float(x0), float(y0), psi0, self.start_speed, 0.0, 0.0, 0.0]
        self._tracker.reset()
        self._k = 0
        self._gear = self._gear_for_speed(self.start_speed)
        self._shift_timer = 0.0
        self._a_transfer = (0.0, 0.0)
        self._a_body = (0.0, 0.0)
        self._delta_cmd = 0.0
        self._pedal = 0.0
        self._wall.reset()
        self.offtrack_time = 0.0
        self._offtrack = False
        self._update_track_position()
        return self._observation()

    def step(self, steer_rad: float, pedal: float) -> Observation:
        """Hold (steering command, pedal) for one control period and integrate.

        Parameters
        ----------
        steer_rad : steering angle command at the road wheels, rad (clipped to +-steer_max).
        pedal : combined pedal in [-1, 1] (throttle >= 0, brake < 0; clipped).

        Raises
        ------
        ControlError
            A command is NaN or infinite.
        PlantError
            The car's state became NaN or infinite.
        """
        steer = float(steer_rad)
        u_p = float(pedal)
        if not (math.isfinite(steer) and math.isfinite(u_p)):
            raise ControlError(
                f"SimulatedCar.step got a non-finite command (steer_rad={steer_rad!r}, "
                f"pedal={pedal!r}) at t = {self._k * self.dt:.2f} s; the controller must return "
                "finite numbers (check its solver status and fallback)."
            )
        p = self.params
        if self._rng is not None:
            noise = self._rng.standard_normal(2)
            steer += p.steer_noise_std * float(noise[0])
            u_p += p.pedal_noise_std * float(noise[1])
        steer = min(max(steer, -p.steer_max), p.steer_max)
        u_p = min(max(u_p, -1.0), 1.0)
        self._delta_cmd = steer
        self._pedal = u_p
        throttle = u_p if u_p > 0.0 else 0.0
        f_brake = -u_p * p.brake_force_max if u_p < 0.0 else 0.0

        if not math.isfinite(sum(self._state)):
            self._raise_nonfinite(self._state)
        speed = abs(self._state[SimState.VX])
        n_sub = self._n_base
        # Shrink the substep at low speed, where the tyre modes get stiff (see __init__).
        n_low = math.ceil(self.dt * self._stiffness / max(speed, p.v_min_slip) / 2.0)
        if n_low > n_sub:
            n_sub = min(n_low, 200)
        h = self.dt / n_sub
        for _ in range(n_sub):
            f_drive = self._powertrain(throttle, h)
            self._rk4(h, steer, f_drive, f_brake)
            self._update_track_position(h)
        self._k += 1
        return self._observation()

    # ------------------------------------------------------------------ internals
    def _gear_for_speed(self, v: float) -> int:
        p = self.params
        for g in range(1, len(p.gear_ratios) + 1):
            if gear_rpm(p, v, g) < p.upshift_rpm:
                return g
        return len(p.gear_ratios)

    def _powertrain(self, throttle: float, h: float) -> float:
        """Automatic gearbox (by rpm, torque cut while shifting) and drive force for one substep."""
        p = self.params
        vx = self._state[SimState.VX]
        rpm = gear_rpm(p, vx, self._gear)
        if rpm > p.upshift_rpm and self._gear < len(p.gear_ratios):
            self._gear += 1
            self._shift_timer = p.shift_time
        elif rpm < p.downshift_rpm and self._gear > 1:
            self._gear -= 1
            self._shift_timer = p.shift_time
        if self._shift_timer > 0.0:
            self._shift_timer -= h
            return 0.0
        if throttle <= 0.0:
            return 0.0  # no engine braking: pedal 0 coasts (documented in VehicleParams)
        return drive_force(p, vx, throttle, self._gear)

    def _rk4(self, h: float, delta_cmd: float, f_drive: float, f_brake: float) -> None:
        # One RK4 substep of car_vector_field, evaluated in place by a CasADi Function built from
        # it (rk4_substep_function); the loads are frozen over the substep (quasi-static, from
        # the previous substep's accelerations).
        self._rk4_fn.inputs[0][:] = (  # in the order of RK4_IN
            *self._state, delta_cmd, f_drive, f_brake, self._theta, *self._mu_wheels,
            *self._a_transfer, h,
        )  # fmt: skip
        out = self._rk4_fn()[0].tolist()
        new = out[0:7]
        if not math.isfinite(sum(new)):
            self._raise_nonfinite(new)
        self._state = new
        # The ground-force accelerations at the end of the substep set the next loads.
        self._a_transfer = (out[7], out[8])
        vx, vy, r = new[SimState.VX], new[SimState.VY], new[SimState.R]
        self._a_body = (out[9] - r * vy, out[10] + r * vx)

    def _raise_nonfinite(self, state: list[float]) -> None:
        bad = [
            f"{SimState(i).name.lower()}={v}" for i, v in enumerate(state) if not math.isfinite(v)
        ]
        old = ", ".join(f"{SimState(i).name.lower()}={v:.4g}" for i, v in enumerate(self._state))
        if state is self._state:
            old = "state was already non-finite before this step"
        raise PlantError(
            f"SimulatedCar state became non-finite ({', '.join(bad) or 'overflow'}) at "
            f"t = {self._k * self.dt:.2f} s (before the step: {old}). Likely cause: non-physical "
            "VehicleParams (e.g. a tiny mass or inertia) or a substep too long for them; check the "
            "parameters or pass a smaller `substep`."
        )

    def _update_track_position(self, h: float = 0.0) -> None:
        """Frenet position, edge friction and walls after a substep of length h."""
        st = self._state
        x, y, psi = st[SimState.X], st[SimState.Y], st[SimState.PSI]
        if not (math.isfinite(x) and math.isfinite(y)):
            self._raise_nonfinite(st)
        s, e_y = self._tracker.project(x, y)
        heading, wl, wr, grade = self._tables.lookup(s)
        e_psi = (psi - heading + math.pi) % _TWO_PI - math.pi
        sp, cp = math.sin(e_psi), math.cos(e_psi)
        self._s, self._e_y, self._e_psi = s, e_y, e_psi
        self._theta = grade
        mu = self._mu
        if self._walls:
            self._mu_wheels = (mu, mu, mu, mu)
            self._e_y = self._wall.check(st, h, e_y, heading, wl, wr, sp, cp)
            return
        # Open track: each wheel beyond the edge runs on the run-off's lower friction.
        mu_off = mu * self.params.offtrack_mu_factor
        beyond = wheels_beyond_edge(e_y, sp, cp, wl, wr, self._wheels_xy)
        off = any(beyond)
        self._mu_wheels = tuple(mu_off if b else mu for b in beyond)
        self._offtrack = off
        if off:
            self.offtrack_time += h

    def _observation(self) -> Observation:
        st = self._state
        return Observation(
            self._k * self.dt,
            st[SimState.X],
            st[SimState.Y],
            st[SimState.PSI],
            st[SimState.VX],
            st[SimState.VY],
            st[SimState.R],
        )

    # ------------------------------------------------------------------ extras for logs
    def state_info(self) -> dict[str, int | float | bool | tuple[float, ...]]:
        """Internal quantities for logs (chapter 02); not part of the `Plant` protocol.

        Returns
        -------
        dict with: ``gear``, ``rpm`` (engine, rpm), ``shifting`` (bool), ``steer`` (actual road
        wheel angle, rad), ``steer_cmd`` (rad), ``pedal`` (applied, with noise), ``s`` (m), ``e_y``
        (m), ``e_psi`` (rad), ``grade`` (rad), ``a_x``, ``a_y`` (measured body-frame acceleration
        of the CoG, m/s^2), ``F_z`` (wheel loads FL, FR, RL, RR, N), ``mu_wheels``, ``mu_trial``,
        ``touching_wall``, ``offtrack``, ``wall_contacts``, ``wall_contact_time``,
        ``offtrack_time``.
        """
        p = self.params
        vx = self._state[SimState.VX]
        f_z = wheel_loads(p, self._a_transfer[0], self._a_transfer[1], self._theta)
        return {
            "gear": self._gear,
            "rpm": max(gear_rpm(p, vx, self._gear), p.launch_rpm),
            "shifting": self._shift_timer > 0.0,
            "steer": self._state[SimState.DELTA],
            "steer_cmd": self._delta_cmd,
            "pedal": self._pedal,
            "s": self._s,
            "e_y": self._e_y,
            "e_psi": self._e_psi,
            "grade": self._theta,
            "a_x": self._a_body[0],
            "a_y": self._a_body[1],
            "F_z": tuple(float(f) for f in f_z),
            "mu_wheels": self._mu_wheels,
            "mu_trial": self._mu,
            "touching_wall": self._wall.touching,
            "offtrack": self._offtrack,
            "wall_contacts": self.wall_contacts,
            "wall_contact_time": self.wall_contact_time,
            "offtrack_time": self.offtrack_time,
        }

    def set_state(
        self,
        x: float,
        y: float,
        psi: float,
        vx: float,
        vy: float = 0.0,
        r: float = 0.0,
        delta: float = 0.0,
    ) -> Observation:
        """Place the car at a given state (tests, exercises); counters and randomness are kept.

        Raises
        ------
        PlantError
            A value is NaN or infinite.
        """
        values = [float(v) for v in (x, y, psi, vx, vy, r, delta)]
        if not all(math.isfinite(v) for v in values):
            raise PlantError(
                f"SimulatedCar.set_state got a non-finite value {values}; pass finite numbers."
            )
        self._state = values
        self._gear = self._gear_for_speed(values[SimState.VX])
        self._shift_timer = 0.0
        self._a_transfer = (0.0, 0.0)
        self._tracker.reset()
        self._update_track_position()
        return self._observation()
