"""Controllers: the nominal pure-pursuit driver and the MPCs of chapter 05."""

from __future__ import annotations

from typing import Any

from racing_lib.control.base import Command, Controller
from racing_lib.errors import ControlError

CONTROLLER_NAMES = ("nominal", "coupled-mpc", "decoupled-mpc")


def build_controller(
    name: str,
    trajectory: Any,
    *,
    track: Any = None,
    options: Any = None,
    weights: dict[str, float] | None = None,
    smooth_transition: bool = True,
) -> Controller:
    """Build a controller by its command-line name for a planned trajectory.

    Parameters
    ----------
    name : str
        One of :data:`CONTROLLER_NAMES`.
    trajectory : Trajectory
        The plan to track.
    track : Track, optional
        The track (the MPCs derive their lateral bounds from its edges).
    options : ModelOptions, optional
        Model effects the MPCs predict with.
    weights : dict, optional
        MPC weights overriding the defaults.
    smooth_transition : bool
        MPC: blend the linearization trajectory from the current state to the plan.
    """
    if name == "nominal":
        from racing_lib.control.nominal import NominalController

        return NominalController.from_trajectory(trajectory)
    raise ControlError(f"unknown controller {name!r}; choose one of {', '.join(CONTROLLER_NAMES)}.")


__all__ = ["CONTROLLER_NAMES", "Command", "Controller", "build_controller"]
