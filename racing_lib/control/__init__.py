"""Controllers: the nominal pure-pursuit driver and the MPCs of chapter 05.

Each controller the command line and the pipeline know is described by a :class:`ControllerKind`:
its name, what it needs (a model to predict with, MPC weights) and how fast a reference it can
track. The pipeline asks the kind; it never tests a controller's name.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from racing_lib.control.mpc import CoupledMPC, DecoupledMPC, MPCSettings
from racing_lib.control.nominal import MODERATE_SPEED_SCALE, NominalController
from racing_lib.errors import ControlError, checked_arguments
from racing_lib.geometry import Track
from racing_lib.interfaces import Controller
from racing_lib.model import CarModel
from racing_lib.planning.trajectory import Trajectory


@dataclass(frozen=True)
class ControllerKind:
    """What the pipeline needs to know of a controller, so that it never asks for its name.

    Attributes
    ----------
    name : str
        The name on the command line and in :func:`build_controller`.
    predicts : bool
        It predicts with a model (the plan's :class:`~racing_lib.model.CarModel`), so a plan made
        with another model is a mismatch worth a warning.
    takes_weights : bool
        It has MPC weights (tuned ones are looked up for it).
    speed_scale : float
        Share of the plan's speed it is asked to track (dimensionless): the pure-pursuit driver
        has no model of grip, so it drives the plan more slowly.
    build : callable
        Makes the controller: ``build(trajectory, model, track, settings)``, with the model to
        predict with (None: the plan's) and the MPC settings (weights included).
    """

    name: str
    predicts: bool
    takes_weights: bool
    build: Callable[[Trajectory, CarModel | None, Track | None, MPCSettings], Controller]
    speed_scale: float = 1.0

    def reference(self, plan: Trajectory) -> Trajectory:
        """The reference this controller tracks for ``plan`` (a slower copy, if it must)."""
        return plan if self.speed_scale == 1.0 else plan.scale_speed(self.speed_scale)


def _nominal(
    trajectory: Trajectory, model: CarModel | None, track: Track | None, settings: MPCSettings
) -> Controller:
    """The pure-pursuit driver: it has gains of its own, and no model or MPC settings."""
    return NominalController.from_trajectory(trajectory)


def _mpc(cls: type[CoupledMPC] | type[DecoupledMPC]) -> Callable[..., Controller]:
    """The builder of an MPC class: the plan, the model to predict with, the track, settings."""

    def build(
        trajectory: Trajectory, model: CarModel | None, track: Track | None, settings: MPCSettings
    ) -> Controller:
        return cls(trajectory, model, track=track, settings=settings)

    return build


#: The controllers by name, in the order the command line lists them. A new controller is one
#: more entry here.
CONTROLLERS: dict[str, ControllerKind] = {
    kind.name: kind
    for kind in (
        ControllerKind(
            "nominal",
            predicts=False,
            takes_weights=False,
            build=_nominal,
            speed_scale=MODERATE_SPEED_SCALE,
        ),  # fmt: skip
        ControllerKind("coupled-mpc", predicts=True, takes_weights=True, build=_mpc(CoupledMPC)),
        ControllerKind(
            "decoupled-mpc", predicts=True, takes_weights=True, build=_mpc(DecoupledMPC)
        ),
    )
}
CONTROLLER_NAMES = tuple(CONTROLLERS)


def controller_kind(name: str) -> ControllerKind:
    """The :class:`ControllerKind` called ``name``; an unknown name raises :class:`ControlError`."""
    kind = CONTROLLERS.get(name) if isinstance(name, str) else None
    if kind is None:
        raise ControlError(
            f"unknown controller {name!r}; choose one of {', '.join(CONTROLLER_NAMES)}."
        )
    return kind


def mpc_settings(
    weights: Mapping[str, float] | None = None, smooth_transition: bool = True
) -> MPCSettings:
    """MPC settings with ``weights`` (fields of :class:`MPCSettings`) over the defaults."""
    settings = MPCSettings(smooth_transition=smooth_transition)
    if not weights:
        return settings
    known = {f.name for f in dataclasses.fields(MPCSettings)}
    unknown = sorted(set(weights) - known)
    if unknown:
        raise ControlError(
            f"unknown MPC weight(s) {unknown}; valid names are the fields of MPCSettings "
            "such as w_vx, w_vy, w_r, w_epsi, w_ey, w_ddelta."
        )
    return dataclasses.replace(settings, **weights)


@checked_arguments
def build_controller(
    name: str,
    trajectory: Trajectory,
    *,
    track: Track | None = None,
    model: CarModel | None = None,
    weights: Mapping[str, float] | None = None,
    smooth_transition: bool = True,
) -> Controller:
    """Build a controller by its command-line name for a planned trajectory.

    Parameters
    ----------
    name : str
        One of :data:`CONTROLLER_NAMES`.
    trajectory : Trajectory
        The reference to track (for the nominal controller, already slowed by its kind's
        ``speed_scale``: see :meth:`ControllerKind.reference`).
    track : Track, optional
        The track (the MPCs derive their lateral bounds from its edges).
    model : CarModel, optional
        The model the MPCs predict with. Default: the one the trajectory carries, the model it
        was planned with, so that plan and controller agree.
    weights : dict, optional
        MPC weights overriding the defaults.
    smooth_transition : bool
        MPC: blend the linearization trajectory from the current state to the plan.
    """
    kind = controller_kind(name)
    return kind.build(trajectory, model, track, mpc_settings(weights, smooth_transition))


__all__ = [
    "CONTROLLERS",
    "CONTROLLER_NAMES",
    "ControllerKind",
    "build_controller",
    "controller_kind",
    "mpc_settings",
]
