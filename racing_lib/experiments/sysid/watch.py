"""What the test driver watches: the manoeuvres' settings and the loss-of-control watchdog.

A driver testing a car nobody has driven before does not know its limits: the throttle may spin
the driven wheels (power oversteer in a corner), a hard brake may lock them, the tyres may give
less than the data sheet says. The manoeuvres of :mod:`racing_lib.experiments.sysid.manoeuvres`
therefore drive with a :class:`_Watchdog` that sees only what the plant reports (``x, y, psi, v_x,
v_y, r, t``) and compares it with the steady state the manoeuvre is meant to hold:

* the yaw rate against the path's ``v_x kappa`` (on the proving grounds' constant-radius circles
  that is the exact steady state, whatever the tyres), and
* the body slip ``|v_y| / v_x`` against a bound a car under control stays well inside.

When either leaves its band, the car is losing grip: the watchdog lifts the throttle (and releases
a brake to a share of what locked it) until the car is back inside the bands for a while, records
where the limit was (:class:`LimitEvent`), and from then on caps the throttle below the level
that broke traction and lets it rise only gently. Nothing changes until a limit is detected: a car
that never leaves the bands (the simulated car in its normal manoeuvres) is driven exactly as
before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = ["LimitEvent", "ManoeuvreSettings"]


@dataclass(frozen=True)
class ManoeuvreSettings:
    """How the identification manoeuvres find a car's limits without losing it.

    The defaults suit cars from karts to vans (tested on the simulated car, a kart and CommonRoad
    vehicles 1-3); none of them is tuned to one car. The watchdog's bands are twice what the
    simulated car reaches in its normal manoeuvres, so that it never trips there.

    Attributes
    ----------
    slip_limit : float
        Body slip ``|v_y| / v_x`` (about the side-slip angle, rad) beyond which the car is losing
        grip, on top of the kinematic body slip ``l_r |kappa|`` of the path (a tight hairpin at
        walking pace has that much without any tyre slip). The fits drop samples beyond 0.1.
    yaw_limit : float
        Yaw-rate deviation from the path's steady state ``v_x kappa``, rad/s, beyond which the car
        is rotating away from the circle it follows (oversteer: spinning or locked rear wheels).
    settle : float
        Time after the start in which the watchdog does not judge, s: a flying start on a circle
        begins with no yaw rate, off the steady state until the car has turned in.
    recovery : float
        Time the car must stay inside both bands before the watchdog gives the pedal back, s.
    backoff : float
        After a trip, the throttle is capped at ``backoff`` times the throttle that broke traction
        (and a brake released to ``backoff`` times the brake that locked the wheels), -.
    throttle_rate : float
        After a trip, the largest rise of the throttle per second, 1/s (a gentle foot).
    speed_backoff : float
        After a trip in a manoeuvre that may slow down (steps, laps, the coast-down's run-up), no
        throttle above ``speed_backoff`` times the speed of the trip, -: a car that loses its
        composure at a speed is driven below it.
    min_brake : float
        The brake cap never drops below this, - (half a pedal is what the steps use).
    yaw_damping : float
        After a trip, the follower's steering gets a yaw damper: minus ``yaw_damping`` times the
        steering that would cancel the yaw-rate error kinematically, ``L (r - v_x kappa) / v_x``,
        -. A car whose steering rate is limited (or whose yaw is lightly damped) can turn pure
        pursuit's corrections into a growing oscillation at speed; the damper calms it.
    min_throttle : float
        The throttle cap never drops below this, - (the car must still hold its speed).
    max_trips : int
        Trips in one run after which a limit-seeking ramp (the circles' rising speed) stops rising
        and holds the last level that stayed inside the bands.
    steer_rate_speed : float
        Speed of the steering-rate manoeuvre, m/s (low, so that large steering steps stay in the
        tyres' linear range).
    steer_rate_ay : float
        Lateral acceleration the steering-rate steps ask for at their extreme, as a share of
        ``mu g`` (sets the step size, rad).
    full_throttle_time : float
        Longest full-throttle run of the top-speed manoeuvre, s.
    """

    slip_limit: float = 0.07
    yaw_limit: float = 0.1
    settle: float = 1.0
    recovery: float = 1.0
    backoff: float = 0.6
    throttle_rate: float = 0.2
    speed_backoff: float = 0.9
    min_throttle: float = 0.05
    min_brake: float = 0.5
    yaw_damping: float = 1.5
    max_trips: int = 2
    steer_rate_speed: float = 10.0
    steer_rate_ay: float = 0.3
    full_throttle_time: float = 60.0


@dataclass(frozen=True)
class LimitEvent:
    """One loss of control the watchdog saw and backed off from.

    Attributes
    ----------
    t : float
        Time of the trip, s.
    vx : float
        Speed, m/s.
    a_y : float
        Path lateral acceleration ``v_x^2 kappa`` at the trip, m/s^2.
    pedal : float
        The pedal in use when the car left the bands, -.
    reason : str
        Which band it left (side slip or yaw rate) and by how much.
    """

    t: float
    vx: float
    a_y: float
    pedal: float
    reason: str


@dataclass
class _Watchdog:
    """Filters a manoeuvre's pedal: untouched until the car leaves its bands (module docstring).

    Parameters
    ----------
    settings : ManoeuvreSettings
        The bands and the back-off.
    kappa : float or None
        Curvature of the path the car follows, 1/m (None: do not watch the yaw rate, e.g. where
        steering steps rotate the car on purpose).
    dt : float
        Control period, s.
    slow_down : bool
        Whether a trip also caps the speed (``ManoeuvreSettings.speed_backoff``); the circles keep
        their speed levels and back off by level instead.
    wheelbase : float
        ``l_f + l_r`` of the car, m (for the yaw damper; 0: no damper).
    l_r : float
        Distance from the centre of gravity to the rear axle, m (the kinematic body slip).
    watch_yaw : bool
        Whether to judge the yaw rate (laps do not: pure pursuit cuts a track's corners and
        scrapes its walls, so the yaw rate strays from the centre line's by design).
    yaw_extra : float
        Widens the yaw-rate band by this much, rad/s: the yaw rate a manoeuvre's own steering
        steps add to the path's.
    """

    settings: ManoeuvreSettings
    kappa: float | None
    dt: float
    yaw_extra: float = 0.0
    wheelbase: float = 0.0
    l_r: float = 0.0
    watch_yaw: bool = True
    slow_down: bool = False
    v_cap: float = math.inf
    events: list[LimitEvent] = field(default_factory=list)
    _calm: int = 0
    _age: int = 0
    _recovering: bool = False
    _cap: float = 1.0
    _brake_cap: float = 1.0
    _last: float = 0.0

    def lost(self, obs: Any) -> str | None:
        """Why the car is out of its bands at ``obs`` (None: under control)."""
        if obs.vx < 3.0:
            return None
        s = self.settings
        slip = abs(obs.vy) / obs.vx
        band = s.slip_limit + (self.l_r * abs(self.kappa) if self.kappa is not None else 0.0)
        if slip > band:
            return f"body slip |v_y|/v_x = {slip:.3f} > {band:.3f}"
        if self.kappa is not None and self.watch_yaw:
            dev = abs(obs.r - obs.vx * self.kappa)
            if dev > s.yaw_limit + self.yaw_extra:
                return f"yaw rate {obs.r:+.3f} rad/s is {dev:.3f} from the path's steady state"
        return None

    @property
    def tripped(self) -> bool:
        """Whether a limit has been met in this run."""
        return bool(self.events)

    def __call__(self, obs: Any, pedal: float) -> float:
        """The pedal to send at ``obs`` instead of the manoeuvre's ``pedal`` (both -)."""
        s = self.settings
        self._age += 1
        reason = self.lost(obs) if self._age * self.dt > s.settle else None
        if reason is not None:
            if not self._recovering:
                self._trip(obs, reason)
            self._recovering, self._calm = True, 0
        elif self._recovering:
            self._calm += 1
            if self._calm * self.dt >= s.recovery:
                self._recovering = False
        if not self.events:
            self._last = pedal
            return pedal
        if self._recovering:
            # Off both pedals: no drive torque to spin the wheels, no brake to lock them.
            out = 0.0
        elif pedal >= 0.0:
            cap = self._cap if obs.vx <= self.v_cap else 0.0
            out = min(pedal, cap, max(self._last, 0.0) + s.throttle_rate * self.dt)
        else:
            out = max(pedal, -self._brake_cap)
        self._last = out
        return out

    def steer(self, obs: Any, steer: float, kappa: float | None = None) -> float:
        """The follower's ``steer`` (rad), with the yaw damper once a limit has been met.

        ``kappa`` (1/m) is the path's curvature at the car (default: the watchdog's own).
        """
        k = self.kappa if kappa is None else kappa
        if not self.events or k is None or self.wheelbase <= 0.0:
            return steer
        vx = max(float(obs.vx), 5.0)
        return steer - self.settings.yaw_damping * self.wheelbase * (obs.r - vx * k) / vx

    def _trip(self, obs: Any, reason: str) -> None:
        """Record the limit and lower the caps below what broke traction."""
        s = self.settings
        used = self._last
        if used > 0.0:
            self._cap = max(min(self._cap, used) * s.backoff, s.min_throttle)
        elif used < 0.0:
            self._brake_cap = max(min(self._brake_cap, -used) * s.backoff, s.min_brake)
        if self.slow_down:
            self.v_cap = min(self.v_cap, s.speed_backoff * float(obs.vx))
        a_y = obs.vx**2 * self.kappa if self.kappa is not None else math.nan
        self.events.append(LimitEvent(float(obs.t), float(obs.vx), float(a_y), used, reason))
