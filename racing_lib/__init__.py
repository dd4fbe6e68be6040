"""racing_lib: model-based planning and control for time-trial racing.

The library behind the racing-lab course, in one-way layers (each imports only from those below
it; CONTRIBUTING.md maps them): geometry and tracks -> vehicle -> model -> interfaces and the
simulated car -> planning -> control -> experiments -> face (command line, figures, notebooks).
"""

from racing_lib.errors import (
    ControlError,
    ModelError,
    PlanningError,
    PlantError,
    RacingLibError,
    TrackError,
)

__version__ = "0.1.0"

__all__ = [
    "ControlError",
    "ModelError",
    "PlanningError",
    "PlantError",
    "RacingLibError",
    "TrackError",
    "__version__",
]
