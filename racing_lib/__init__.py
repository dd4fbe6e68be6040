"""racing_lib: model-based planning and control for time-trial racing.

The library behind the racing-lab course. Data flows one way:
track -> vehicle/model -> planning -> control -> experiment -> plotting.
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
