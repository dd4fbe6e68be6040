"""What predicts the car: one frozen object that travels from the top of a run to the MPC.

A plan is only as good as the model it was made with, and the controller that tracks it must
predict with that same model. :class:`CarModel` gathers everything that model is: the parameters
(:class:`~racing_lib.model.params.ModelParams`, pedal map included), the effects switched on
(:class:`~racing_lib.model.params.ModelOptions`), the steering actuator the planning equations
leave out (its lag and limits), and the margins the planner kept from the model's limits.

It is chosen once, at the top of a run (:func:`racing_lib.experiments.pipeline.race`, the command
line, the tuning configurations; :func:`racing_lib.model.identified.identified_model` is the
default they share), handed to the planner, stored in the
:class:`~racing_lib.planning.Trajectory` and its plan file, and read back by the MPC from the plan
it tracks. No layer below the top picks a model of its own. Taught in notebook 04.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from racing_lib.errors import ModelError
from racing_lib.io import JSONObject
from racing_lib.model.params import ModelOptions, ModelParams
from racing_lib.vehicle import VehicleParams

__all__ = ["DEFAULT_V_TOP", "CarModel", "ModelMismatchWarning"]

#: The steering actuator assumed when none is identified: the simulated car's.
_ACTUATOR = VehicleParams()

#: The top speed a model assumes when none is identified, m/s (190 km/h): a cap on the plans
#: of the simulated car, whose power would take it faster on a long enough straight.
DEFAULT_V_TOP = 190.0 / 3.6


class ModelMismatchWarning(UserWarning):
    """A plan is driven by a controller that predicts with another model than it was made with."""


@dataclass(frozen=True)
class CarModel:
    """The model a plan is made with and an MPC predicts with (a frozen, hashable value).

    Attributes
    ----------
    params : ModelParams
        The model's parameters, pedal map included. The planner sees them with the grip margin
        applied (:meth:`planning_params`); the MPC predicts with them as they are.
    options : ModelOptions
        The physical effects the equations include (the paper's model ablations).
    steer_tau : float
        Time constant of the steering actuator's first-order lag, s (0: no lag). The planning
        equations have no actuator; the MPC carries the actual angle as an extra state, so that
        it knows a command acts only partly within the first period. At 45 m/s an unmodelled
        0.08 s lag was enough to make the closed loop oscillate and spin the car.
    steer_max : float
        Largest road-wheel steering angle, rad.
    steer_rate_max : float
        Largest steering rate, rad/s (``inf``: none), a hard constraint of the MPC on the change
        per stage: commanding faster changes than the actuator can follow makes the closed loop
        oscillate.
    grip_margin : float
        Share of the friction coefficient the planner leaves unused, in [0, 0.5): the plan is made
        with ``mu (1 - grip_margin)``. It stands in for what the model does not know about the
        car (combined slip under braking, load transfer it leaves out).
    edge_margin : float or None
        Distance the planned line keeps between the car's side and the track edge, m; None: the
        planner's default for the track's kind of boundary (walls or open edges).
    v_top : float
        Top speed, m/s: the plans keep the car's speed ``sqrt(v_x^2 + v_y^2)`` at or below it.
        A car with a governed top speed (identified at full throttle) gives no acceleration
        beyond it, whatever the pedal says; default :data:`DEFAULT_V_TOP`.
    lateral_stability : float or None
        The plans' stability margin, 1/s: they keep the model's lateral dynamics stable, with no
        eigenvalue between minus this margin and zero unless both are there (under braking, the
        eigenvalue that moves towards zero stays left of the margin; see
        :attr:`racing_lib.planning.TimeOptimalSettings.lateral_stability`), and the steering
        within its rate limit. Set by identification for a car that diverged in yaw when it
        braked with the steering held: the margin is how much faster it diverged than the
        model said. None (default): no such bound, as for the simulated car, which stays
        stable there. The learning loop scales it by its caution, as it does the slip margin
        (:mod:`racing_lib.experiments.learning`).
    slip_share : float or None
        The tyres' slip margin, in (0, 1]: the plans keep both axles' slip angles where the
        tyres give at most this share of their peak force, and an MPC predicting with a learned
        correction keeps the front axle's there too; set, it takes the place of the planner's
        setting, as the model's edge margin does. None (default): the planner's setting
        (:attr:`racing_lib.planning.TimeOptimalSettings.slip_force_share`, 95 %) and, with a
        correction, :data:`racing_lib.control.mpc.coupled.LEARNED_SLIP_SHARE`. The learning loop
        sets it from how its iterations went (:mod:`racing_lib.experiments.learning`).

    Examples
    --------
    >>> from racing_lib.model import CarModel, ModelParams
    >>> model = CarModel(ModelParams(mu=1.2), grip_margin=0.05)
    >>> round(model.planning_params().mu, 3)
    1.14
    >>> CarModel.from_dict(model.to_dict()) == model
    True
    """

    params: ModelParams
    options: ModelOptions = ModelOptions()
    steer_tau: float = _ACTUATOR.steer_tau
    steer_max: float = _ACTUATOR.steer_max
    steer_rate_max: float = _ACTUATOR.steer_rate_max
    grip_margin: float = 0.0
    edge_margin: float | None = None
    v_top: float = DEFAULT_V_TOP
    lateral_stability: float | None = None
    slip_share: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.params, ModelParams):
            raise ModelError(
                f"CarModel.params must be a racing_lib.model.ModelParams, got "
                f"{type(self.params).__name__}; identify one (racing_lib.experiments.sysid) or "
                "use racing_lib.model.identified_params()."
            )
        if not isinstance(self.options, ModelOptions):
            raise ModelError(
                f"CarModel.options must be a racing_lib.model.ModelOptions, got "
                f"{type(self.options).__name__}."
            )
        self._check_number("steer_tau", "s", lambda v: math.isfinite(v) and v >= 0.0, ">= 0")
        self._check_number("steer_max", "rad", lambda v: math.isfinite(v) and v > 0.0, "> 0")
        self._check_number("steer_rate_max", "rad/s", lambda v: v > 0.0, "> 0 (inf for none)")
        self._check_number("grip_margin", "", lambda v: 0.0 <= v < 0.5, "in [0, 0.5)")
        if self.edge_margin is not None:
            self._check_number("edge_margin", "m", lambda v: math.isfinite(v) and v >= 0, ">= 0")
        self._check_number("v_top", "m/s", lambda v: math.isfinite(v) and v > 0.0, "> 0")
        if self.lateral_stability is not None:
            self._check_number(
                "lateral_stability", "1/s", lambda v: math.isfinite(v) and v >= 0, ">= 0 or None"
            )
        if self.slip_share is not None:
            self._check_number("slip_share", "", lambda v: 0.0 < v <= 1.0, "in (0, 1] or None")

    def _check_number(self, name: str, unit: str, ok: Callable[[float], bool], rule: str) -> None:
        """Store field ``name`` as a float, refusing a value that breaks ``rule``."""
        value = getattr(self, name)
        if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
            raise ModelError(f"CarModel.{name} must be a number {rule}, got {value!r}.")
        value = float(value)
        if not ok(value):
            raise ModelError(
                f"CarModel.{name} must be {rule}{' ' + unit if unit else ''}, got {value!r}."
            )
        object.__setattr__(self, name, value)

    # --- what the planner and the controller see --------------------------------------------------
    def planning_params(self) -> ModelParams:
        """The parameters the planner plans with: friction reduced by the grip margin."""
        if not self.grip_margin:
            return self.params
        return self.params.replace(mu=self.params.mu * (1.0 - self.grip_margin))

    def replace(self, **changes: ModelParams | ModelOptions | float | None) -> CarModel:
        """A copy with some fields changed (validated)."""
        fields = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - fields)
        if unknown:
            raise ModelError(
                f"CarModel has no field(s) {unknown}; its fields are {sorted(fields)}. A "
                "parameter goes through params: model.replace(params=model.params.replace(...))."
            )
        return dataclasses.replace(self, **changes)

    def differences(self, other: CarModel) -> list[str]:
        """What changes the prediction between this model and ``other``, one text per field.

        Effects, steering actuator and parameters (``"drag: plan True, controller False"``,
        ``"parameters mu, m"``); the margins and the top speed are left out, since they are the
        planner's and do not enter a controller's prediction. Empty when the two predict alike.
        """
        pairs = [(f.name, self.options, other.options) for f in dataclasses.fields(ModelOptions)]
        pairs += [(name, self, other) for name in ("steer_tau", "steer_max", "steer_rate_max")]
        out = [
            f"{name}: plan {getattr(a, name)}, controller {getattr(b, name)}"
            for name, a, b in pairs
            if getattr(a, name) != getattr(b, name)
        ]
        mine, theirs = self.params.to_dict(), other.params.to_dict()
        changed = sorted(k for k in mine.keys() | theirs.keys() if mine.get(k) != theirs.get(k))
        if changed:
            out.append(f"parameters {', '.join(changed)}")
        return out

    def describe(self) -> str:
        """One line for people: friction, effects, steering lag and margins."""
        edge = "default" if self.edge_margin is None else f"{self.edge_margin:g} m"
        stable = (
            ""
            if self.lateral_stability is None
            else f", stability margin {self.lateral_stability:.2f} 1/s"
        )
        slip = "" if self.slip_share is None else f", slip to {100 * self.slip_share:.3g}% of peak"
        return (
            f"mu {self.params.mu:.3f}, {self.options.label()}, steering lag "
            f"{self.steer_tau:.3f} s, grip margin {100 * self.grip_margin:.2g}%, edge margin {edge}"
            f"{stable}{slip}"
        )

    # --- files ------------------------------------------------------------------------------------
    def to_dict(self) -> JSONObject:
        """JSON-ready dictionary (floats kept exactly: JSON writes their shortest repr).

        ``slip_share`` is written only when set, so the files of models without one are those
        written before it existed.
        """
        data: JSONObject = {
            "params": self.params.to_dict(),
            "options": dataclasses.asdict(self.options),
            "steer_tau": self.steer_tau,
            "steer_max": self.steer_max,
            "steer_rate_max": self.steer_rate_max,
            "grip_margin": self.grip_margin,
            "edge_margin": self.edge_margin,
            "v_top": self.v_top,
            "lateral_stability": self.lateral_stability,
        }
        if self.slip_share is not None:
            data["slip_share"] = self.slip_share
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> CarModel:
        """Inverse of :meth:`to_dict`; unknown or missing fields raise :class:`ModelError`."""
        if not isinstance(data, Mapping):
            raise ModelError(f"CarModel data must be a JSON object, got {type(data).__name__}.")
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - fields)
        if unknown or "params" not in data:
            raise ModelError(
                f"CarModel data has unknown fields {unknown} or lacks 'params'; allowed: "
                f"{sorted(fields)}. Check the file's origin and version, or re-plan."
            )
        kwargs = dict(data)
        kwargs["params"] = ModelParams.from_dict(data["params"])
        options = data.get("options", {})
        if not isinstance(options, Mapping) or set(options) - {
            f.name for f in dataclasses.fields(ModelOptions)
        }:
            raise ModelError(f"CarModel options must be ModelOptions fields, got {options!r}.")
        kwargs["options"] = ModelOptions(**options)
        return cls(**kwargs)
