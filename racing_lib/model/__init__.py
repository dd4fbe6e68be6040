"""The planning and control model: a dynamic bicycle in Frenet coordinates, written once.

* :mod:`racing_lib.model.states`: the state and input vectors, indexed by :class:`X` and
  :class:`U`.
* :mod:`racing_lib.model.equations`: the equations (paper Eq. 1-15) as CasADi functions, in the
  time and the spatial domain, their Jacobians and discretizations.
* :mod:`racing_lib.model.params`: :class:`ModelParams`, :class:`ModelOptions`, :class:`PedalMap`.
* :mod:`racing_lib.model.numeric`: :class:`Model`, the same equations for NumPy users.
* :mod:`racing_lib.model.car_model`: :class:`CarModel`, what predicts the car (parameters,
  options, steering actuator, margins), the object that travels with a plan to the MPC.
* :mod:`racing_lib.model.identified`: the shipped identified parameters (chapter 02's fit) and the
  default model of every run, :func:`identified_model`.
* :mod:`racing_lib.model.actuator`: the steering lag the model leaves out.
* :mod:`racing_lib.model.correction`: :class:`ModelCorrection`, residual accelerations learned
  from laps (sparse GPs of :mod:`racing_lib.model.gp`), a parameter the equations add (chapter 09).
* :mod:`racing_lib.model.drive`: :class:`Drive`, the record of a drive (a lap, a manoeuvre).
* :mod:`racing_lib.model.lateral`: the linear analysis of the lateral dynamics.
* :mod:`racing_lib.model.prediction`: the open-loop prediction error against a recorded drive.

The names below are re-exported, so ``from racing_lib.model import ModelParams, X`` works.
Taught in notebook 02.
"""

from racing_lib.model.car_model import DEFAULT_V_TOP, CarModel, ModelMismatchWarning
from racing_lib.model.correction import ModelCorrection
from racing_lib.model.drive import Drive
from racing_lib.model.equations import (
    VX_GUARD,
    discrete_dynamics,
    discrete_linearization,
    discretize,
    frenet_kinematics,
    jacobians,
    lateral_eigenvalue_test,
    model_terms,
    spatial_dynamics,
    time_dynamics,
)
from racing_lib.model.identified import (
    GRIP_MARGIN,
    identified_model,
    identified_params,
    identified_steer_tau,
)
from racing_lib.model.numeric import Model
from racing_lib.model.params import BRAKE_KNEE, ModelOptions, ModelParams, PedalMap
from racing_lib.model.states import NU, NX, U, X

__all__ = [
    "DEFAULT_V_TOP",
    "BRAKE_KNEE",
    "GRIP_MARGIN",
    "CarModel",
    "Drive",
    "NU",
    "NX",
    "VX_GUARD",
    "Model",
    "ModelCorrection",
    "ModelMismatchWarning",
    "ModelOptions",
    "ModelParams",
    "PedalMap",
    "U",
    "X",
    "discrete_dynamics",
    "discrete_linearization",
    "discretize",
    "frenet_kinematics",
    "identified_model",
    "identified_params",
    "identified_steer_tau",
    "jacobians",
    "lateral_eigenvalue_test",
    "model_terms",
    "spatial_dynamics",
    "time_dynamics",
]
