"""The exceptions of racing_lib.

Every entry point checks its input and raises one of these with a message that names the problem and
the way out, instead of letting a deep traceback from numpy or a solver reach the user.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])


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


class ArgumentError(RacingLibError, TypeError, ValueError):
    """An entry point was called with an argument it does not have, or of the wrong kind."""


def checked_arguments(func: F) -> F:
    """Make a misspelled or missing argument of ``func`` an :class:`ArgumentError`.

    Python's own ``TypeError`` for an unknown keyword says only which name it did not expect;
    the error raised here also lists the parameters that exist, so the way out is in the message.
    Errors raised inside ``func`` pass through unchanged.
    """
    signature = inspect.signature(func)

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            signature.bind(*args, **kwargs)
        except TypeError as exc:
            names = ", ".join(n for n in signature.parameters if n not in ("self", "cls"))
            raise ArgumentError(
                f"{func.__qualname__}(): {exc}; its parameters are {names} "
                f"(see help({func.__qualname__}))."
            ) from None
        return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
