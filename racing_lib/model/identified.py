"""The shipped identified parameters: what chapter 02 fitted, for every later chapter.

The file ``racing_lib/data/identified_params.json`` holds the fit of
:func:`racing_lib.experiments.sysid.identify` on the simulated car's logs; the chapters after 02
plan and control with it instead of refitting. Regenerate it with
``python -m racing_lib.experiments.sysid``.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

from racing_lib.errors import ModelError
from racing_lib.io import JSONObject, data_file
from racing_lib.model.car_model import CarModel
from racing_lib.model.params import ModelParams

__all__ = [
    "DATA_FILE",
    "GRIP_MARGIN",
    "identified_model",
    "identified_params",
    "identified_steer_tau",
    "shipped_fit",
    "shipped_fit_path",
]

#: The shipped fit, in ``racing_lib/data``.
DATA_FILE = "identified_params.json"

#: Share of the tyres' identified friction a plan leaves unused (dimensionless). A plan on the
#: model's limit asks the simulated car for grip it has only in pure slip: its tyres lose lateral
#: grip under braking (ABS) and to the load transfer, which the planning model knows nothing of.
#: Measured on the expressway with the coupled MPC (default weights, two seeds): planned on the
#: limit, the car drove 2.5 % over its plan and touched a wall; with 5 % kept, 0.8 % over and
#: clean, and the driven lap was 0.8 s faster. Identification now measures the margin of any car
#: it identifies (:attr:`racing_lib.experiments.sysid.IdentificationResult.grip_margin`, the 99th
#: percentile of the model's lateral-acceleration error): 4.6-5.2 % for this car, so the shipped
#: model, with which the controller's weights were tuned, keeps this value.
GRIP_MARGIN = 0.05


def shipped_fit_path() -> Path:
    """Where the shipped fit lives: ``racing_lib/data/identified_params.json`` in the package."""
    return data_file(DATA_FILE)


def shipped_fit() -> JSONObject:
    """The JSON of the shipped fit (``racing_lib/data/identified_params.json``)."""
    ref = data_file(DATA_FILE)
    try:
        return json.loads(ref.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelError(
            f"racing_lib/data/{DATA_FILE} is missing; regenerate it with "
            "`python -m racing_lib.experiments.sysid`."
        ) from None


@functools.cache
def identified_params() -> ModelParams:
    """The shipped identified parameter set (``racing_lib/data/identified_params.json``).

    The default parameter set of the chapters after notebook 02, so that they need not refit.
    Regenerate it with ``python -m racing_lib.experiments.sysid``.
    """
    return ModelParams.from_dict(shipped_fit()["model_params"])


def identified_steer_tau() -> float:
    """The steering lag time constant of the shipped fit (s), identified with the parameters.

    Not part of :class:`~racing_lib.model.ModelParams` (the planning model has no actuator); the
    MPC and the open-loop predictions of notebook 02 use it to turn commands into road-wheel
    angles (see :func:`~racing_lib.model.actuator.lagged_steering`).
    """
    return float(shipped_fit()["steer_tau"])


@functools.cache
def identified_model() -> CarModel:
    """The default model of every run: the shipped fit, with the default grip margin.

    The one place the default is decided; the entry points (:func:`racing_lib.planning.plan`,
    :func:`racing_lib.experiments.pipeline.race`, the command line, the tuning configurations)
    call it when they are given no model, and everything below them reads the model they pass
    on. Its parameters are :func:`identified_params` (the paper planned with its identified
    model too), its effects drag and longitudinal load transfer (the paper's main experiment)
    and its grip margin :data:`GRIP_MARGIN`.

    The steering actuator is the one the MPC has assumed since chapter 05, the simulated car's
    data sheet (lag 0.08 s, 0.5 rad, 1.2 rad/s), not the fit's own lag
    (:func:`identified_steer_tau`, a few per cent longer): every shipped result was made with
    it. A model of a car identified from its logs takes its identified lag and a grip margin
    measured from its model's error
    (:meth:`racing_lib.experiments.sysid.IdentificationResult.car_model`).
    """
    return CarModel(identified_params(), grip_margin=GRIP_MARGIN)
