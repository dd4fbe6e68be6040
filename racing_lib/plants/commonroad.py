"""CommonRoad's single-track drift model as a racing_lib plant: :class:`CommonRoadCar`.

CommonRoad's vehicle models (Althoff and Würsching, "CommonRoad: Vehicle Models", TUM 2020;
PyPI ``commonroad-vehicle-models``, imported as ``vehiclemodels``, BSD licence) are a car nobody
here wrote. :class:`CommonRoadCar` drives their single-track drift model ``std``
(``vehiclemodels.vehicle_dynamics_std``: a single-track chassis with load transfer, the package's
Pacejka tyres with combined slip, two wheel-spin states, blended into the kinematic model below
0.2 m/s) with any of the package's parameter sets (``vehicle_id`` 1: Ford Escort, 2: BMW 320i,
3: VW Vanagon; 4, the truck with trailer, has no single-track parameters), on a racing_lib track.

Commands (defined here once)
----------------------------
The model's inputs are the steering-angle *velocity* and the longitudinal acceleration; racing_lib
commands a steering *angle* and one pedal. Each RK4 stage maps them as follows, and the model then
applies the package's own constraint functions to the result (``steering_constraints``,
``acceleration_constraints``, called inside ``vehicle_dynamics_std``):

* steering: a proportional servo, ``delta_dot = (delta_cmd - delta) / steer_tau`` (``steer_tau``,
  default 0.05 s), where the command is first clipped to the car's angle limits
  ``[p.steering.min, p.steering.max]``. The package then saturates the rate to
  ``[p.steering.v_min, p.steering.v_max]`` and holds the angle at its limits. For the passenger
  cars of the package the rate limit (0.4 rad/s) dominates the servo: a step of 0.1 rad takes
  0.25 s, whatever ``steer_tau``.
* pedal ``u_p`` in [-1, 1]: acceleration ``a = u_p * p.longitudinal.a_max`` for throttle and brake
  alike (the package has one limit ``|a| <= a_max``, 11.5 m/s^2 for the cars), except that a brake
  (``u_p < 0``) gives ``a = 0`` once the car stands (``v <= 0``): a brake does not drive a car
  backwards. The package then caps the throttle by its power limit ``a_max v_switch / v`` above
  ``p.longitudinal.v_switch`` and cuts it at ``p.longitudinal.v_max``.

Integration
-----------
Classical RK4 with the commands held over the control period ``dt``. The stiffest mode is the
wheel spin (rate about ``R_w^2 K_x / (I_y_w v)``, several hundred per second at racing speeds,
tens of thousands near standstill), so the number of substeps is chosen per control step from that
bound at the lowest speed the step can reach, keeping ``|lambda h| <= 2`` (RK4 is stable to 2.78).
The package forbids negative wheel spin by clamping the state it is handed
(``vehicle_dynamics_std`` sets ``x[7] = max(0, x[7])`` in the caller's array, and its wheel
derivative is zero for a negative wheel speed); the integrator does the same after every substep,
``omega = max(0, omega)``. Without it a wheel that a hard brake locks overshoots below zero and
stays there, locked for good, since its derivative is then zero.
After every quarter of the period (0.025 s at ``dt = 0.1``) the car meets the track:
:class:`racing_lib.vehicle.contact.WallContact` on walled tracks (the simulated car's plastic
impact, counted with its duration; the wheel speeds are scaled with the car's speed, so the impact
adds no wheel slip); on open tracks the time with a wheel beyond the edge is counted (the
package's tyres know one friction, so the grip is not changed there).

Speed
-----
``engine="casadi"`` (default) evaluates :func:`racing_lib.plants.std.std_vector_field`, a
statement-by-statement transcription of ``vehicle_dynamics_std`` (tested equal to it to 1e-12 at
random states, ``tests/test_plants.py``), compiled to machine code by :mod:`racing_lib.jit`
(``jit=False``: CasADi's interpreter). ``engine="python"`` calls the package's own
``vehicle_dynamics_std`` directly: the reference, several times slower
(``benchmarks/bench_plants.py``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from racing_lib.errors import ControlError, PlantError
from racing_lib.geometry import FrenetTracker, Track
from racing_lib.interfaces import Observation
from racing_lib.jit import BufferedFunction, compiled_or_interpreted
from racing_lib.model import ModelParams, PedalMap
from racing_lib.plants.std import N_STATE, V_B, V_MIN, V_S, std_vector_field
from racing_lib.vehicle.contact import TrackTables, WallContact, wheels_beyond_edge

if TYPE_CHECKING:  # the optional extra, imported by the functions that need it
    from vehiclemodels.vehicle_parameters import VehicleParameters
from racing_lib.vehicle.params import VehicleParams

try:
    from vehiclemodels.init_std import init_std
    from vehiclemodels.utils.acceleration_constraints import acceleration_constraints
    from vehiclemodels.utils.steering_constraints import steering_constraints
    from vehiclemodels.vehicle_dynamics_std import vehicle_dynamics_std
    from vehiclemodels.vehicle_parameters import VehicleParameters, setup_vehicle_parameters
except ImportError as _exc:
    raise PlantError(
        "racing_lib.plants.commonroad wraps CommonRoad's vehicle models (the package "
        "commonroad-vehicle-models, imported as vehiclemodels), which is not installed here "
        f'({_exc}). Install the optional extra: pip install "racing-lib[commonroad]".'
    ) from _exc

__all__ = ["CommonRoadAt", "CommonRoadCar", "data_sheet", "vehicle_parameters"]

_TWO_PI = 2.0 * math.pi
#: What the std model reads of a parameter set (beyond the tyre, steering and longitudinal ones).
_NEEDED = ("l", "w", "m", "a", "b", "I_z", "h_s", "R_w", "I_y_w", "T_sb", "T_se")
_SPIN_BETA = 0.5 * math.pi  # rad: a slip angle beyond this means the car travels backwards


def vehicle_parameters(vehicle: int | VehicleParameters) -> VehicleParameters:
    """A CommonRoad parameter set, checked to hold what the ``std`` model needs.

    Parameters
    ----------
    vehicle : int or vehiclemodels.vehicle_parameters.VehicleParameters
        A CommonRoad vehicle id (1: Ford Escort, 2: BMW 320i, 3: VW Vanagon) or a parameter set.

    Raises
    ------
    PlantError
        An unknown id, or a set without single-track parameters (id 4, the truck with trailer).
    """
    if isinstance(vehicle, bool) or not isinstance(vehicle, int | VehicleParameters):
        raise PlantError(
            f"CommonRoadCar vehicle must be a CommonRoad vehicle id (1, 2, 3) or a "
            f"vehiclemodels VehicleParameters, got {type(vehicle).__name__}."
        )
    if isinstance(vehicle, int):
        if vehicle not in (1, 2, 3, 4):
            raise PlantError(f"CommonRoad has vehicle ids 1 to 4, got {vehicle}; use 1, 2 or 3.")
        p = setup_vehicle_parameters(vehicle_id=vehicle)
    else:
        p = vehicle
    missing = [name for name in _NEEDED if getattr(p, name, None) is None]
    missing += [f"tire.{k}" for k in ("p_kx1", "p_dy1", "p_ky1") if getattr(p.tire, k) is None]
    if missing:
        raise PlantError(
            f"the CommonRoad parameter set lacks what the single-track drift model needs "
            f"({', '.join(missing)}); vehicle id 4 (the truck with trailer) has no single-track "
            "parameters. Use vehicle 1, 2 or 3, or complete the set."
        )
    return p


def data_sheet(vehicle: int | VehicleParameters) -> ModelParams:
    """What a team would write down for a CommonRoad car before testing it, as `ModelParams`.

    Mass, axle distances, yaw inertia and the height of the sprung mass (the package's load
    transfer uses ``h_s``), the front track width, the tyres' peak lateral friction ``p_dy1`` as
    ``mu``, Pacejka factors with the package's cornering stiffness (``B C D mu = |p_ky1|``,
    ``C = p_cy1``, ``D = 1``), no drag nor rolling resistance (the ``std`` model has neither), and a
    pedal map with the package's limits: ``a_max`` for throttle and brake, the power limit
    ``a_max v_switch`` (W/kg), and the tyres' longitudinal limit ``p_dx1 g`` for the brake.

    Parameters
    ----------
    vehicle : int or VehicleParameters
        See :func:`vehicle_parameters`.
    """
    p = vehicle_parameters(vehicle)
    t, lon = p.tire, p.longitudinal
    b_y = abs(t.p_ky1) / (t.p_cy1 * t.p_dy1)
    pedal = PedalMap(
        m_0=0.0,
        m_xi=(0.0,) * 6,
        m_thr=lon.a_max,
        m_brk=lon.a_max,
        p_thr=lon.a_max * lon.v_switch,
        a_brk_max=t.p_dx1 * 9.81,
    )
    return ModelParams(
        m=p.m, l_f=p.a, l_r=p.b, h_c=p.h_s, l_t=p.T_f or p.w, mu=t.p_dy1, C_xw=0.0,
        I_zz=p.I_z, c_rr=0.0, B_f=b_y, C_f=t.p_cy1, D_f=1.0, B_r=b_y, C_r=t.p_cy1, D_r=1.0,
        g=9.81, pedal=pedal,
    )  # fmt: skip


def pedal_acceleration(pedal: float, v: float, a_max: float) -> float:
    """The acceleration input (m/s^2) the pedal in [-1, 1] asks for at speed v (m/s).

    ``pedal * a_max`` (a_max in m/s^2), but 0 for a brake once the car stands (module
    docstring); the package's ``acceleration_constraints`` apply to the result.
    """
    if pedal < 0.0 and v <= 0.0:
        return 0.0
    return pedal * a_max


def _wheel_spin_rate(p: Any) -> float:
    """``R_w^2 K_x,max / I_y_w``, m/s^2: times 1/v, a bound on the wheel-spin mode's rate, 1/s.

    ``K_x = p_kx1 F_z`` is the tyre's longitudinal slip stiffness at the largest axle load that
    the package's load transfer gives (at ``|a| = a_max``).
    """
    f_z = p.m * (p.longitudinal.a_max * p.h_s + 9.81 * max(p.a, p.b)) / (p.a + p.b)
    return p.R_w**2 * abs(p.tire.p_kx1) * f_z / p.I_y_w


def _casadi_field(x: list[Any], delta_cmd: Any, pedal: Any, tau: Any, p: Any) -> list[Any]:
    """The plant's vector field on CasADi symbols: the command mapping, then ``std``."""
    import casadi as ca

    a = ca.if_else(ca.logic_and(pedal < 0.0, x[3] <= 0.0), 0.0, pedal * p.longitudinal.a_max)
    return std_vector_field(x, [(delta_cmd - x[2]) / tau, a], p)


def _python_field(x: list[float], delta_cmd: float, pedal: float, tau: float, p: Any) -> list:
    """The plant's vector field with the package's own function (which clamps a copy of x)."""
    a = pedal_acceleration(pedal, x[3], p.longitudinal.a_max)
    return vehicle_dynamics_std(list(x), [(delta_cmd - x[2]) / tau, a], p)


def _rk4(field: Any, x: list[Any], h: Any, *args: Any) -> list[Any]:
    """One classical RK4 step of ``field(x, *args)`` (floats or CasADi symbols)."""
    k1 = field(x, *args)
    k2 = field([a + 0.5 * h * b for a, b in zip(x, k1, strict=True)], *args)
    k3 = field([a + 0.5 * h * b for a, b in zip(x, k2, strict=True)], *args)
    k4 = field([a + h * b for a, b in zip(x, k3, strict=True)], *args)
    c = h / 6.0
    return [
        a + c * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
        for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4, strict=True)
    ]


def _clamp_wheels(x: list[Any], fmax: Any) -> list[Any]:
    """The state with the wheel speeds ``x[7]``, ``x[8]`` clamped to >= 0, as the package does."""
    return [*x[:7], fmax(0.0, x[7]), fmax(0.0, x[8])]


_FUNCTIONS: dict[tuple[str, bool], Any] = {}


def _substep_function(p: Any, jit: bool) -> Any:
    """The RK4 substep of the plant as a CasADi Function, compiled when ``jit``.

    ``z (13) -> x (9)``: ``z = [x (9), delta_cmd (rad), pedal (-), steer_tau (s), h (s)]``. Kept
    per process and parameter set (a lap builds a new car).
    """
    key = (repr(p), bool(jit))
    if key not in _FUNCTIONS:
        _FUNCTIONS[key] = _build_substep_function(p, bool(jit))
    return _FUNCTIONS[key]


def _build_substep_function(p: Any, jit: bool) -> Any:
    import casadi as ca

    z = ca.SX.sym("z", N_STATE + 4)
    x = [z[i] for i in range(N_STATE)]
    delta_cmd, pedal, tau, h = (z[N_STATE + i] for i in range(4))
    new = _clamp_wheels(_rk4(_casadi_field, x, h, delta_cmd, pedal, tau, p), ca.fmax)
    fn = ca.Function("commonroad_std_rk4", [z], [ca.vertcat(*new)])
    if not jit:
        return fn
    (fn,) = compiled_or_interpreted(
        [fn], "CommonRoad's std model (RK4 substep)", "CommonRoadCar(jit=False)"
    )
    return fn


class CommonRoadCar:
    """CommonRoad's single-track drift model ``std`` on a racing_lib track (implements `Plant`).

    Parameters
    ----------
    track : Track
        The track: walls or open edges, as for :class:`racing_lib.sim.SimulatedCar`.
    vehicle : int or VehicleParameters
        CommonRoad vehicle id 1, 2 or 3, or a parameter set (:func:`vehicle_parameters`).
    dt : float
        Control period, s.
    start_s : float
        Arc length of the start on the centerline, m (``reset`` puts the car there).
    start_speed : float
        Initial speed (flying start), m/s.
    steer_tau : float
        Time constant of the steering servo, s (module docstring).
    engine : {'casadi', 'python'}
        ``'casadi'``: the transcription (:mod:`racing_lib.plants.std`); ``'python'``: the
        package's own ``vehicle_dynamics_std``.
    jit : bool
        With ``engine='casadi'``, compile it (:mod:`racing_lib.jit`; without a C compiler the car
        warns and uses CasADi's interpreter).
    steer_noise_std, pedal_noise_std : float
        Standard deviations of the actuation noise drawn per step after ``reset(seed)`` with a
        seed, rad and -; default 0 (deterministic).

    Attributes
    ----------
    params : VehicleParameters
        The package's parameter set.
    wall_contacts : int
        Wall contact episodes since reset.
    wall_contact_time : float
        Time touching a wall since reset, s.
    offtrack_time : float
        Time with a wheel beyond an open track's edge since reset, s.
    """

    def __init__(
        self,
        track: Track,
        vehicle: int | VehicleParameters = 2,
        dt: float = 0.1,
        start_s: float = 0.0,
        start_speed: float = 20.0,
        steer_tau: float = 0.05,
        engine: str = "casadi",
        jit: bool = True,
        steer_noise_std: float = 0.0,
        pedal_noise_std: float = 0.0,
    ) -> None:
        p = vehicle_parameters(vehicle)
        for name, value in (("dt", dt), ("steer_tau", steer_tau)):
            if not (math.isfinite(value) and value > 0.0):
                raise PlantError(f"CommonRoadCar {name} must be a positive number of seconds.")
        if not (math.isfinite(start_s) and math.isfinite(start_speed) and start_speed >= 0.0):
            raise PlantError("CommonRoadCar start_s must be finite and start_speed >= 0 m/s.")
        if engine not in ("casadi", "python"):
            raise PlantError(f"CommonRoadCar engine must be 'casadi' or 'python', got {engine!r}.")
        self.track, self.params = track, p
        self.dt, self.start_s, self.start_speed = float(dt), float(start_s), float(start_speed)
        self.steer_tau, self.engine = float(steer_tau), engine
        self.steer_noise_std, self.pedal_noise_std = float(steer_noise_std), float(pedal_noise_std)
        self._n_check = max(1, math.ceil(self.dt / 0.025 - 1e-9))  # track checks per step
        self._spin_rate = _wheel_spin_rate(p)
        if engine == "casadi":
            self._fn = BufferedFunction(_substep_function(p, bool(jit)))
        self._walls = track.boundary == "walls"
        self._tracker = FrenetTracker(track.centerline)
        self._tables = TrackTables(track)
        overhang = 0.5 * (p.l - (p.a + p.b))  # the package gives no overhangs: split evenly
        wp = VehicleParams()  # the simulated car's wall friction and losses
        self._wall = WallContact(p.m, p.I_z, p.a + overhang, -(p.b + overhang), p.w,
                                 wp.wall_mu, wp.wall_entry_keep, wp.wall_release_gap)  # fmt: skip
        t_f, t_r = 0.5 * (p.T_f or p.w), 0.5 * (p.T_r or p.w)
        self._wheels_xy = ((p.a, t_f), (p.a, -t_f), (-p.b, t_r), (-p.b, -t_r))
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
            Seed of the actuation noise (used only when a noise level is set).
        """
        self._rng = np.random.default_rng(seed) if seed is not None else None
        self._k = 0
        self._wall.reset()
        self.offtrack_time = 0.0
        self._offtrack = False
        self._inputs = (0.0, 0.0)
        path = self.track.centerline
        x0, y0 = path.position(self.start_s)
        psi0 = float(np.asarray(path.heading(self.start_s)))
        return self.set_state(float(x0), float(y0), psi0, self.start_speed)

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
        """Place the car at a state (flying starts, tests); counters and randomness are kept.

        Parameters
        ----------
        x, y : float
            Position of the centre of gravity, m.
        psi : float
            Yaw angle, rad.
        vx, vy : float
            Body-frame velocity, m/s.
        r : float
            Yaw rate, rad/s.
        delta : float
            Front-wheel steering angle, rad.

        Notes
        -----
        The wheels roll without slip (the package's ``init_std``).

        Raises
        ------
        PlantError
            A value is NaN or infinite.
        """
        values = [float(v) for v in (x, y, psi, vx, vy, r, delta)]
        if not all(math.isfinite(v) for v in values):
            raise PlantError(
                f"CommonRoadCar.set_state got a non-finite value {values}; pass finite numbers."
            )
        v, beta = _speed_and_slip(values[3], values[4])
        core = [values[0], values[1], values[6], v, values[2], values[5], beta]
        self._state = [float(c) for c in init_std(core, self.params)]
        self._tracker.reset()
        self._meet_track(0.0)
        return self._observation()

    def step(self, steer_rad: float, pedal: float) -> Observation:
        """Hold (steering-angle command, pedal) for one control period and integrate.

        Parameters
        ----------
        steer_rad : float
            Front-wheel steering-angle command, rad (clipped to the car's angle limits).
        pedal : float
            Combined pedal in [-1, 1] (throttle >= 0, brake < 0; clipped).

        Raises
        ------
        ControlError
            A command is NaN or infinite.
        PlantError
            The state became NaN or infinite, or the car spun (travels backwards).
        """
        steer, u_p = float(steer_rad), float(pedal)
        if not (math.isfinite(steer) and math.isfinite(u_p)):
            raise ControlError(
                f"CommonRoadCar.step got a non-finite command (steer_rad={steer_rad!r}, "
                f"pedal={pedal!r}) at t = {self._k * self.dt:.2f} s; the controller must return "
                "finite numbers."
            )
        if self._rng is not None and (self.steer_noise_std > 0.0 or self.pedal_noise_std > 0.0):
            noise = self._rng.standard_normal(2)
            steer += self.steer_noise_std * float(noise[0])
            u_p += self.pedal_noise_std * float(noise[1])
        st = self.params.steering
        steer = min(max(steer, st.min), st.max)
        u_p = min(max(u_p, -1.0), 1.0)
        n_check = self._n_check
        per_check = math.ceil(self.substeps() / n_check)
        h = self.dt / (n_check * per_check)
        for _ in range(n_check):
            self._integrate(steer, u_p, h, per_check)
            self._meet_track(h * per_check)
        self._k += 1
        self._inputs = self.model_inputs(steer, u_p)
        return self._observation()

    # ------------------------------------------------------------------ the mapping, exposed
    def model_inputs(self, steer_cmd: float, pedal: float) -> tuple[float, float]:
        """The model's inputs that (steering command, rad; pedal, -) give in the current state.

        Returns
        -------
        steer_rate : float
            Steering-angle velocity, rad/s, after the package's ``steering_constraints``.
        accel : float
            Longitudinal acceleration, m/s^2, after the package's ``acceleration_constraints``.
        """
        p, x = self.params, self._state
        steer_cmd = min(max(float(steer_cmd), p.steering.min), p.steering.max)
        pedal = min(max(float(pedal), -1.0), 1.0)
        rate = steering_constraints(x[2], (steer_cmd - x[2]) / self.steer_tau, p.steering)
        a = pedal_acceleration(pedal, x[3], p.longitudinal.a_max)
        return float(rate), float(acceleration_constraints(x[3], a, p.longitudinal))

    def substeps(self) -> int:
        """RK4 substeps the next control step takes (at least one per track check).

        From the wheel-spin bound (module docstring) at the lowest speed the step can reach.
        """
        v_now = abs(self._state[3])
        v_low = max(v_now - self.params.longitudinal.a_max * self.dt, 0.0)
        rate = max(self._stiffest(v_now), self._stiffest(v_low))
        n = math.ceil(self.dt * rate / 2.0)
        return min(max(n, self._n_check), 20000)

    def _stiffest(self, v: float) -> float:
        """Bound on the fastest mode's rate at speed v (m/s), 1/s: wheel spin, blended as std."""
        w_std = 0.5 * (math.tanh((v - V_S) / V_B) + 1.0)
        return w_std * self._spin_rate / max(v, V_MIN) + (1.0 - w_std) / 0.02

    # ------------------------------------------------------------------ internals
    def _integrate(self, steer: float, u_p: float, h: float, n: int) -> None:
        """Take n RK4 substeps of length h (s) with the commands held."""
        if self.engine == "python":
            x = self._state
            for _ in range(n):
                x = _rk4(_python_field, x, h, steer, u_p, self.steer_tau, self.params)
                x = _clamp_wheels(x, max)
        else:
            fn = self._fn
            z, out = fn.inputs[0], fn.outputs[0]
            z[:N_STATE] = self._state
            z[N_STATE:] = (steer, u_p, self.steer_tau, h)
            for _ in range(n):
                fn()
                z[:N_STATE] = out
            x = out.tolist()
        if not math.isfinite(sum(x)):
            self._raise("became non-finite", x)
        self._state = x

    def _meet_track(self, h: float) -> None:
        """Frenet position, walls (plastic impacts) or open edges after h seconds of driving."""
        x = self._state
        if abs(x[6]) > _SPIN_BETA and abs(x[3]) > 1.0:
            self._raise("spun: its slip angle is beyond 90 degrees (it travels backwards)", x)
        s, e_y = self._tracker.project(x[0], x[1])
        heading, wl, wr, _ = self._tables.lookup(s)
        e_psi = (x[4] - heading + math.pi) % _TWO_PI - math.pi
        sp, cp = math.sin(e_psi), math.cos(e_psi)
        if self._walls:
            v, beta = x[3], x[6]
            planar = [x[0], x[1], x[4], v * math.cos(beta), v * math.sin(beta), x[5]]
            e_y = self._wall.check(planar, h, e_y, heading, wl, wr, sp, cp)
            if self._wall.touching:
                self._set_planar(planar)
        else:
            self._offtrack = any(wheels_beyond_edge(e_y, sp, cp, wl, wr, self._wheels_xy))
            if self._offtrack:
                self.offtrack_time += h
        self._s, self._e_y, self._e_psi = s, e_y, e_psi

    def _set_planar(self, planar: list[float]) -> None:
        """Take position and velocities back from a wall impact; wheel speeds follow the speed."""
        x = self._state
        v, beta = _speed_and_slip(planar[3], planar[4])
        ratio = v / x[3] if abs(x[3]) > V_MIN else 0.0
        x[0], x[1], x[3], x[5], x[6] = planar[0], planar[1], v, planar[5], beta
        if ratio > 0.0:
            x[7], x[8] = x[7] * ratio, x[8] * ratio
        else:
            x[7:9] = init_std(x[:7], self.params)[7:9]

    def _raise(self, what: str, x: list[float]) -> None:
        names = ("x", "y", "delta", "v", "psi", "r", "beta", "omega_f", "omega_r")
        state = ", ".join(f"{n}={v:.4g}" for n, v in zip(names, x, strict=True))
        raise PlantError(
            f"CommonRoadCar: the car {what} at t = {self._k * self.dt:.2f} s ({state}). The lap "
            "is lost: check the controller's commands (a slower plan, or a model with the car's "
            "steering-rate limit) or the vehicle parameters."
        )

    def _observation(self) -> Observation:
        x = self._state
        v, beta = x[3], x[6]
        return Observation(
            self._k * self.dt, x[0], x[1], x[4], v * math.cos(beta), v * math.sin(beta), x[5]
        )

    def state_info(self) -> dict[str, float | int | bool]:
        """Internal quantities for logs; not part of the `Plant` protocol.

        Returns
        -------
        dict with ``steer`` (front-wheel angle, rad), ``v`` (m/s), ``beta`` (slip angle, rad),
        ``omega_f``, ``omega_r`` (wheel speeds, rad/s), ``steer_rate`` (rad/s) and ``accel``
        (m/s^2) (the model's inputs at the last command), ``s``, ``e_y`` (m), ``e_psi`` (rad),
        ``touching_wall``, ``offtrack``, ``wall_contacts``, ``wall_contact_time``,
        ``offtrack_time``.
        """
        x = self._state
        return {
            "steer": x[2],
            "v": x[3],
            "beta": x[6],
            "omega_f": x[7],
            "omega_r": x[8],
            "steer_rate": self._inputs[0],
            "accel": self._inputs[1],
            "s": self._s,
            "e_y": self._e_y,
            "e_psi": self._e_psi,
            "touching_wall": self._wall.touching,
            "offtrack": self._offtrack,
            "wall_contacts": self.wall_contacts,
            "wall_contact_time": self.wall_contact_time,
            "offtrack_time": self.offtrack_time,
        }


def _speed_and_slip(vx: float, vy: float) -> tuple[float, float]:
    """(v, beta) of a body-frame velocity (m/s): v takes the sign of vx, |beta| <= pi/2."""
    v = math.hypot(vx, vy)
    if v < 1e-9:
        return 0.0, 0.0
    if vx < 0.0:
        return -v, math.atan2(-vy, -vx)
    return v, math.atan2(vy, vx)


class CommonRoadAt:
    """``CarUnderTest.make_plant`` for a CommonRoad car: a picklable ``(track, start_speed)``.

    Parameters
    ----------
    vehicle : int or VehicleParameters
        See :func:`vehicle_parameters`.
    **options
        Further keyword arguments of :class:`CommonRoadCar` (``engine``, ``steer_tau``, ...).
    """

    def __init__(self, vehicle: int | VehicleParameters = 2, **options: Any) -> None:
        self.vehicle = vehicle
        self.options = options

    def __str__(self) -> str:
        """The car's name in reports, e.g. ``CommonRoad vehicle 2``."""
        what = self.vehicle if isinstance(self.vehicle, int) else "(own parameters)"
        return f"CommonRoad vehicle {what}"

    def __call__(self, track: Track, start_speed: float) -> CommonRoadCar:
        """The car at arc length 0 of ``track``, heading along it, at ``start_speed`` m/s."""
        return CommonRoadCar(track, self.vehicle, start_s=0.0, start_speed=start_speed,
                             **self.options)  # fmt: skip
