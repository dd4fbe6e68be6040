"""``--scheduler ADDRESS``: reach a Dask distributed cluster from the command line.

``racing-lib tune`` and ``racing-lib ablation --recompute`` run their laps on a cluster when given
the address of a running scheduler (``dask scheduler`` on one machine, ``dask worker ADDRESS`` on
as many as you like). The laps are the same functions of the same seeds as in local processes, so
the results are identical to a local run. The connection is made, and refused with one clear
line, before any planning or driving.
"""

from __future__ import annotations

from typing import Any

from racing_lib.errors import RacingLibError

__all__ = ["connect_scheduler"]


def connect_scheduler(address: str, timeout_s: float = 10.0) -> Any:
    """A ``distributed.Client`` of the scheduler at ``address`` that has at least one worker.

    Parameters
    ----------
    address : str
        The scheduler's address, for example ``tcp://10.0.0.5:8786``.
    timeout_s : float
        How long to wait for the scheduler, and then for a worker, s.

    Raises
    ------
    RacingLibError
        Dask distributed is not installed, no scheduler answers at ``address``, or it has no
        worker: each with what to do about it.
    """
    try:
        from distributed import Client
    except ImportError:
        raise RacingLibError(
            '--scheduler needs Dask distributed: pip install "racing-lib[distributed]" (or '
            "drop --scheduler to run the laps in local processes)."
        ) from None
    if not (isinstance(address, str) and "://" in address or ":" in str(address)):
        raise RacingLibError(
            f"--scheduler {address!r} is not a scheduler address; give one like "
            "tcp://10.0.0.5:8786 (what `dask scheduler` prints), or drop --scheduler to run "
            "locally."
        )
    try:
        client = Client(address, timeout=timeout_s)
    except (ValueError, TypeError) as exc:
        raise RacingLibError(
            f"--scheduler {address!r} is not a scheduler address ({exc}); give one like "
            "tcp://10.0.0.5:8786 (what `dask scheduler` prints)."
        ) from None
    except (OSError, TimeoutError) as exc:
        raise RacingLibError(
            f"--scheduler {address}: no Dask scheduler answered within {timeout_s:g} s "
            f"({type(exc).__name__}). Start one with `dask scheduler` and workers with "
            f"`dask worker {address}`, check the address, or drop --scheduler to run locally."
        ) from None
    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        client.close()
        raise RacingLibError(
            f"--scheduler {address}: the scheduler has no worker after {timeout_s:g} s "
            f"({type(exc).__name__}); start some with `dask worker {address}`."
        ) from None
    return client
