"""What passes between a plant and a controller: observations, commands and the two protocols.

The lowest layer that plants, controllers and the lap runner share. A controller sees only
`Observation` (the spatial states a driver of the real car would see, as the paper's Gran Turismo
API gives) and answers with a `Command`; a `Plant` (the simulated car or a car nobody here wrote)
takes commands and reports observations. Nothing here imports a plant or a controller, so neither
needs the other to know what it will see.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

__all__ = ["Command", "Controller", "Observation", "Plant"]


@dataclass(frozen=True, slots=True)
class Observation:
    """What the car reports after each control step: spatial states only (as the paper's GTS API).

    Attributes
    ----------
    t : time since reset, s.
    x, y : position of the centre of gravity, m.
    psi : yaw angle, rad (continuous, not wrapped).
    vx, vy : velocity in the body frame (forward, left), m/s.
    r : yaw rate, rad/s (counter-clockwise positive).
    """

    t: float
    x: float
    y: float
    psi: float
    vx: float
    vy: float
    r: float


@runtime_checkable
class Plant(Protocol):
    """Anything the lap runner can drive: the simulated car or another simulator.

    Attributes
    ----------
    dt : control period, s.
    """

    dt: float

    def reset(self, seed: int | None = None) -> Observation:
        """Start a new trial (seeded randomness) and return the first observation."""
        ...

    def step(self, steer_rad: float, pedal: float) -> Observation:
        """Apply (steering angle command, rad; pedal in [-1, 1]) for one period dt."""
        ...


@dataclass(frozen=True)
class Command:
    """One control command, held for one control period.

    Attributes
    ----------
    steer : float
        Road-wheel steering angle command delta, rad (positive turns left).
    pedal : float
        Combined pedal u_p in [-1, 1]: throttle when >= 0, brake when < 0.
    """

    steer: float
    pedal: float


@runtime_checkable
class Controller(Protocol):
    """The interface the closed-loop runner drives.

    ``reset`` is called once with the first observation of a lap; ``step`` once per control period.
    ``stats`` returns counters worth reporting (for example MPC fallbacks); it may return ``{}``.
    """

    def reset(self, obs: Observation) -> None:
        """Start a lap from its first observation."""
        ...

    def step(self, obs: Observation) -> Command:
        """The command for the next control period."""
        ...

    def stats(self) -> dict[str, float]:
        """Counters worth reporting (may be empty)."""
        ...
