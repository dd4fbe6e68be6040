"""Controllers: the nominal pure-pursuit driver and the MPCs of chapter 05."""

from __future__ import annotations

from typing import Any

from racing_lib.errors import ControlError
from racing_lib.interfaces import Controller

CONTROLLER_NAMES = ("nominal", "coupled-mpc", "decoupled-mpc")


def build_controller(
    name: str,
    trajectory: Any,
    *,
    track: Any = None,
    options: Any = None,
    weights: dict[str, float] | None = None,
    smooth_transition: bool = True,
    params: Any = None,
    steer_tau: float | None = None,
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
    params : ModelParams, optional
        The model the MPCs predict with: the one the plan was made with, so that plan and
        controller agree (default: the identified set,
        :func:`racing_lib.model.identified.identified_params`).
    steer_tau : float, optional
        Time constant of the car's steering lag the MPCs compensate, s (default:
        ``MPCSettings.steer_tau``); pass the identified one for a car identified from its logs.
    """
    if name == "nominal":
        from racing_lib.control.nominal import NominalController

        return NominalController.from_trajectory(trajectory)
    if name in ("coupled-mpc", "decoupled-mpc"):
        import dataclasses

        from racing_lib.control.mpc import CoupledMPC, DecoupledMPC, MPCSettings
        from racing_lib.model.identified import identified_params

        settings = MPCSettings(smooth_transition=smooth_transition)
        if steer_tau is not None:
            settings = dataclasses.replace(settings, steer_tau=float(steer_tau))
        if weights:
            known = {f.name for f in dataclasses.fields(MPCSettings)}
            unknown = sorted(set(weights) - known)
            if unknown:
                raise ControlError(
                    f"unknown MPC weight(s) {unknown}; valid names are the fields of MPCSettings "
                    "such as w_vx, w_vy, w_r, w_epsi, w_ey, w_ddelta."
                )
            settings = dataclasses.replace(settings, **weights)
        cls = CoupledMPC if name == "coupled-mpc" else DecoupledMPC
        # By default the controllers predict with the model identified from driving data (ch. 02).
        model = identified_params() if params is None else params
        return cls(trajectory, params=model, options=options, track=track, settings=settings)
    raise ControlError(f"unknown controller {name!r}; choose one of {', '.join(CONTROLLER_NAMES)}.")


__all__ = ["CONTROLLER_NAMES", "build_controller"]
