"""The simulated car's true parameters (`VehicleParams`).

`VehicleParams` holds the true parameters of the simulated car (`racing_lib.sim.SimulatedCar`): the
paper's table for the Mazda Demio XD Touring '15 plus every value the paper does not give, each
documented once, in the dataclass. The force laws that use them are in `racing_lib.vehicle.forces`,
the equations of motion in `racing_lib.vehicle.dynamics`.

Sign conventions: x forward, y left, yaw counter-clockwise; a positive lateral acceleration (a left
turn) loads the right wheels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from racing_lib.errors import ModelError

__all__ = ["G", "VehicleParams"]

G = 9.81  # gravitational acceleration, m/s^2


@dataclass(frozen=True)
class VehicleParams:
    """True parameters of the simulated car (defaults: a Mazda Demio XD-like hatch, RWD).

    The first block is the paper's table (identified in Gran Turismo Sport). Everything else is
    our own plausible choice for a small 77 kW diesel hatch, tuned so that the car reaches about
    190 km/h (rev-limited in top gear), brakes at about 1.05 g, does 0-100 km/h in about 9 s, and
    is stable under braking and throttle in corners (mild understeer, traction control). The
    paper states front-wheel steering and rear-wheel drive; we follow it.

    Attributes
    ----------
    m : float
        Mass, kg. Paper.
    l_f : float
        Distance CoG to front axle, m. Paper.
    l_r : float
        Distance CoG to rear axle, m. Paper.
    width : float
        Body width, m (used for wall contact and track-edge checks). Paper.
    h_c : float
        Height of the centre of gravity, m (load transfer). Paper.
    mu : float
        Tyre-road friction coefficient on the track surface, -. Paper.
    C_xw : float
        Aerodynamic drag coefficient in F = C_xw v_x^2, kg/m. Paper.
    I_zz : float
        Yaw moment of inertia, kg m^2. Paper.
    g : float
        Gravitational acceleration, m/s^2.
    l_t : float
        Track width (distance between left and right wheel centres), m. Demio: 1.495 front, 1.475
        rear; we use one value.
    overhang_front : float
        Body length ahead of the front axle, m (Demio: 4.06 m long, 2.57 m wheelbase).
    overhang_rear : float
        Body length behind the rear axle, m.
    B_f, C_f, D_f : float
        Simplified Pacejka stiffness, shape and peak factors, front tyres, -. B 10, C 1.9, D 1 are
        common racing-tyre values (peak at about 0.11 rad slip).
    B_r, C_r, D_r : float
        Same for the rear tyres; B_r > B_f (stiffer per unit load) makes the car mildly understeer.
    load_sensitivity : float
        Drop of the peak factor per unit of relative load increase, -: a wheel with load F_z has
        D (1 - k (F_z - F_z0) / F_z0), F_z0 = m g / 4. It is what makes lateral load transfer cost
        grip; real tyres have 0.1-0.2.
    stiffness_load_exponent : float
        Exponent q of the tyre stiffness's load dependence, -: a wheel with load F_z uses
        B (F_z,static / F_z)^q, so its cornering stiffness grows like F_z^(1 - q) (real tyres:
        sublinear). B_f, B_r are the values at the static loads. Without it (q = 0) the high CoG
        makes the car spin under moderate braking in corners.
    min_lateral_share : float
        Share of a wheel's lateral grip kept when its longitudinal force is at the friction limit, -
        (friction ellipse; an idealized ABS / traction control keeps the wheel rolling).
    tcs_floor : float
        Traction control: a driven wheel's drive force is capped at f_peak sqrt(1 - s_y^2), s_y the
        wheel's lateral use of its peak, but never below tcs_floor f_peak, -. 1.0 switches traction
        control off. Without it full throttle out of a hairpin spins this rear-driven car.
    abs_share : float or None
        Anti-lock brakes: a wheel's brake force is capped at f_peak sqrt(abs_share^2 - s_y^2)
        (never below tcs_floor f_peak), so a braking wheel keeps at least sqrt(1 - abs_share^2)
        of its lateral grip, -. Gran Turismo's cars brake with ABS by default. None: no ABS (a
        wheel brakes up to its peak and keeps only min_lateral_share); then a hard stop on a
        gentle curve locks the lightly loaded rear and spins the car.
    c_rr : float
        Rolling resistance coefficient, - (R_x = c_rr F_z; road tyres 0.010-0.015).
    r_w : float
        Loaded wheel radius, m (185/60 R16 tyre).
    engine_rpm : tuple of float
        Engine speed grid of the full-load torque curve, rpm, increasing.
    engine_torque_max : tuple of float
        Full-load engine torque on that grid, N m (1.5 l diesel: 250 N m from 1500 to 2500 rpm,
        77 kW at 4000 rpm); zero at the last point, the rev limiter.
    power_max : float
        Engine power limit, W (77 kW). Throttle u_p scales the full-load torque; pedal 0 coasts
        (the model has no engine braking).
    launch_rpm : float
        Engine speed held by the slipping clutch at low vehicle speed, rpm.
    gear_ratios : tuple of float
        Gearbox ratios, first to top gear, -.
    final_drive : float
        Final drive ratio, -. With the top gear it puts the rev limiter at about 53 m/s.
    driveline_efficiency : float
        Engine-to-wheel efficiency, -.
    upshift_rpm : float
        Automatic gearbox shifts up above this engine speed, rpm.
    downshift_rpm : float
        Automatic gearbox shifts down below this engine speed, rpm.
    shift_time : float
        Drive torque is cut for this long during a shift, s.
    brake_force_max : float
        Total brake force at full pedal before the tyre limit, N (about 1.2 m g, so that a full
        brake is tyre-limited at the front).
    brake_front_share : float
        Share of the brake force on the front axle, -.
    steer_max : float
        Road-wheel steering angle limit, rad.
    steer_rate_max : float
        Steering rate limit of the actuator, rad/s.
    steer_tau : float
        Time constant of the steering actuator's first-order lag, s.
    offtrack_mu_factor : float
        Friction on grass / run-off relative to the track, - (open tracks).
    wall_mu : float
        Friction coefficient between the body and a wall, - (tangential impulse <= wall_mu times
        the normal impulse of a contact).
    wall_entry_keep : float
        Share of the speed kept when a wall contact begins (impact losses beyond friction), -.
    wall_release_gap : float
        A contact episode ends only once the body is this far from the wall, m (so scraping along a
        wall counts as one contact).
    steer_noise_std : float
        Standard deviation of the actuation noise added to each steering command, rad (per trial
        randomness, drawn per control step).
    pedal_noise_std : float
        Standard deviation of the noise added to each pedal command, -.
    mu_variation_std : float
        Relative standard deviation of the per-trial friction variation, - (mu (1 + std N(0, 1))).
    v_min_slip : float
        Lower clamp of the speed in slip-angle denominators, m/s (keeps the low-speed dynamics
        bounded and the integrator stable).
    v_smooth : float
        Speed scale of the smooth sign used for rolling resistance and brakes, m/s (forces fade to
        zero at standstill instead of pushing the car backwards).
    """

    # --- the paper's table ---
    m: float = 1355.2
    l_f: float = 0.9338
    l_r: float = 1.6363
    width: float = 2.008
    h_c: float = 0.6161
    mu: float = 1.25
    C_xw: float = 0.1302
    I_zz: float = 2475.33
    # --- geometry ---
    g: float = G
    l_t: float = 1.48
    overhang_front: float = 0.83
    overhang_rear: float = 0.66
    # --- tyres ---
    B_f: float = 8.0
    C_f: float = 1.9
    D_f: float = 1.0
    B_r: float = 14.0
    C_r: float = 1.9
    D_r: float = 1.0
    load_sensitivity: float = 0.1
    stiffness_load_exponent: float = 0.5
    min_lateral_share: float = 0.1
    tcs_floor: float = 0.2
    abs_share: float | None = 0.9
    c_rr: float = 0.012
    r_w: float = 0.30
    # --- powertrain (rear-wheel drive) ---
    engine_rpm: tuple[float, ...] = (
        1000.0, 1500.0, 2000.0, 2500.0, 3000.0, 3500.0, 4000.0, 4500.0, 5000.0, 5200.0,
    )  # fmt: skip
    engine_torque_max: tuple[float, ...] = (
        160.0, 250.0, 250.0, 250.0, 240.0, 215.0, 184.0, 160.0, 135.0, 0.0,
    )  # fmt: skip
    power_max: float = 77_000.0
    launch_rpm: float = 1500.0
    gear_ratios: tuple[float, ...] = (3.60, 2.10, 1.40, 1.05, 0.87, 0.74)
    final_drive: float = 4.10
    driveline_efficiency: float = 0.92
    upshift_rpm: float = 4800.0
    downshift_rpm: float = 2200.0
    shift_time: float = 0.2
    # --- brakes ---
    brake_force_max: float = 16_000.0
    brake_front_share: float = 0.8
    # --- steering actuator ---
    steer_max: float = 0.5
    steer_rate_max: float = 1.2
    steer_tau: float = 0.08
    # --- environment ---
    offtrack_mu_factor: float = 0.6
    wall_mu: float = 0.5
    wall_entry_keep: float = 0.95
    wall_release_gap: float = 0.05
    # --- per-trial randomness ---
    steer_noise_std: float = 0.002
    pedal_noise_std: float = 0.01
    mu_variation_std: float = 0.005
    # --- numerics ---
    v_min_slip: float = 1.0
    v_smooth: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
                raise ModelError(
                    f"VehicleParams.{f.name} = {value!r} is not a finite number; "
                    "pass finite floats (see the VehicleParams docstring for units)."
                )
        positive = ("m", "l_f", "l_r", "width", "h_c", "mu", "I_zz", "g", "l_t", "r_w",
                    "power_max", "final_drive", "driveline_efficiency", "steer_max",
                    "steer_rate_max", "steer_tau", "v_min_slip", "v_smooth")  # fmt: skip
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ModelError(f"VehicleParams.{name} must be > 0, got {getattr(self, name)}.")
        if len(self.engine_rpm) != len(self.engine_torque_max) or len(self.engine_rpm) < 2:
            raise ModelError(
                "VehicleParams.engine_rpm and engine_torque_max must have the same length (>= 2)."
            )
        if any(b <= a for a, b in zip(self.engine_rpm, self.engine_rpm[1:], strict=False)):
            raise ModelError("VehicleParams.engine_rpm must be strictly increasing.")
        if not self.gear_ratios or any(r <= 0 for r in self.gear_ratios):
            raise ModelError("VehicleParams.gear_ratios must be a non-empty tuple of ratios > 0.")
        if not 0.0 <= self.brake_front_share <= 1.0:
            raise ModelError("VehicleParams.brake_front_share must lie in [0, 1].")

    @property
    def wheelbase(self) -> float:
        """l_f + l_r, m."""
        return self.l_f + self.l_r

    @property
    def F_z0(self) -> float:
        """Nominal wheel load m g / 4, N (reference of the tyre load sensitivity)."""
        return self.m * self.g / 4.0
