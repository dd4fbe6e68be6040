"""Where a run may write: output files and folders checked before any work starts.

The command line refuses an output place it cannot write (a file where a folder is needed, a
read-only folder, a missing parent it cannot create) with one ``error:`` line, before it plans,
drives or tunes anything, and without leaving a file behind.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path as FilePath

from racing_lib.errors import RacingLibError

__all__ = ["check_output_dir", "check_output_file"]


def _nearest_existing(path: FilePath) -> FilePath:
    """The path itself or its closest ancestor that exists."""
    here = path.absolute()
    while not here.exists() and here != here.parent:
        here = here.parent
    return here


def _check_writable_dir(folder: FilePath, flag: str, target: FilePath) -> None:
    """Whether ``folder`` is, or can be created as, a folder we may write in.

    ``folder`` is, or can be created as, a folder we may write in (nothing is left behind:
    the test is a temporary file created and removed at once).
    """
    base = _nearest_existing(folder)
    if not base.is_dir():
        raise RacingLibError(
            f"{flag} {target}: {base} is a file, so no folder can be made below it; choose "
            "another place."
        )
    if not (os.access(base, os.W_OK | os.X_OK) and _can_create_in(base)):
        raise RacingLibError(
            f"{flag} {target}: cannot write in {base} (permission denied or a read-only file "
            "system); choose a folder you can write to."
        )


def _can_create_in(folder: FilePath) -> bool:
    """Whether a file can be created in ``folder``: tried with a temporary file, removed at once.

    ``os.access`` alone says yes to root everywhere, even where the kernel refuses files (such as
    /proc), so the only sure test is to try.
    """
    try:
        fd, probe = tempfile.mkstemp(prefix=".racing_lib_probe_", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True


def check_output_file(value: str, flag: str = "--out") -> None:
    """Refuse an output file that could not be written, before any work starts.

    Raises
    ------
    RacingLibError
        The place is a folder, lies below a file, or cannot be written.
    """
    _unreadable_place_is_an_error(_check_output_file, value, flag)


def check_output_dir(value: str, flag: str = "--out") -> None:
    """Refuse an output folder that could not be made or written in, before any work starts."""
    _unreadable_place_is_an_error(_check_output_dir, value, flag)


def _unreadable_place_is_an_error(check, value: str, flag: str) -> None:
    try:
        check(value, flag)
    except OSError as exc:  # a folder on the way that we may not even look into
        raise RacingLibError(
            f"{flag} {value}: cannot look there ({exc.strerror or exc}); choose a folder you can "
            "write to."
        ) from None


def _check_output_file(value: str, flag: str) -> None:
    target = FilePath(value)
    if target.is_dir():
        raise RacingLibError(f"{flag} {value}: that is a folder; give a file name, e.g. plan.csv.")
    _check_writable_dir(target.parent, flag, target)


def _check_output_dir(value: str, flag: str) -> None:
    target = FilePath(value)
    if target.exists() and not target.is_dir():
        raise RacingLibError(f"{flag} {value}: that is a file, not a folder; choose a folder.")
    _check_writable_dir(target, flag, target)
