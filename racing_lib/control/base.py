"""What every controller looks like to the lap runner.

A controller receives only what a driver of the real plant would see (the spatial
:class:`~racing_lib.sim.Observation`) and returns a steering angle and a pedal command. Anything it
needs beyond that (a reference, a model, weights) it is given when it is built.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from racing_lib.sim import Observation


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

    def reset(self, obs: Observation) -> None: ...

    def step(self, obs: Observation) -> Command: ...

    def stats(self) -> dict[str, float]: ...
