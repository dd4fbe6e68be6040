"""The exceptions of racing_lib.

Every entry point checks its input and raises one of these with a message that names the problem and
the way out, instead of letting a deep traceback from numpy or a solver reach the user.
"""

from __future__ import annotations


class RacingLibError(Exception):
    """Base class of every error racing_lib raises on purpose."""


class TrackError(RacingLibError, ValueError):
    """A track or path is unusable: bad CSV, NaN, too few points, bad widths, crossing itself."""


class PlantError(RacingLibError):
    """A plant (the simulated car or another simulator) returned something unusable, such as NaN."""


class ModelError(RacingLibError, ValueError):
    """Bad model parameters, or identification data that cannot determine a parameter."""


class PlanningError(RacingLibError):
    """A planner failed: names the solver, its status and what to try."""


class ControlError(RacingLibError, ValueError):
    """A controller cannot produce a command, or was given an unusable one (such as NaN)."""
