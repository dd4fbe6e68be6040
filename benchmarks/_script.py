"""What every benchmark script shares: its ``--help``, its tracks and how it ends.

Each script is run as ``python benchmarks/<name>.py`` (its folder is then first on ``sys.path``,
so ``from _script import ...`` finds this module). :func:`argument_parser` shows the script's
whole docstring under ``--help``, usage examples included; :func:`run` turns the library's own
errors (a track file that does not exist, a plan that fails) into one line on stderr and exit
status 2, and Ctrl-C into exit status 130, instead of a traceback. :func:`tracks_to_measure`
loads the built-in tracks and a folder's CSV files before any work starts, and refuses a folder
or a name that would silently measure less than was asked.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from racing_lib.errors import RacingLibError, TrackError
from racing_lib.geometry import Track
from racing_lib.tracks import builtin_track_names, load_track

__all__ = ["argument_parser", "run", "tracks_to_measure"]

#: Exit status of a run stopped by bad input (argparse uses the same), and by Ctrl-C.
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


def argument_parser(doc: str | None) -> argparse.ArgumentParser:
    """An argument parser whose ``--help`` prints ``doc`` as written (line breaks kept).

    Parameters
    ----------
    doc : str or None
        The script's module docstring (``__doc__``).

    Returns
    -------
    argparse.ArgumentParser
    """
    return argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )


def tracks_to_measure(tracks_dir: str | None, only: list[str] | None) -> list[Track]:
    """The built-in tracks and every ``*.csv`` of ``tracks_dir``, loaded before any work starts.

    Parameters
    ----------
    tracks_dir : str or None
        A folder of racetrack-database CSV files, or None for the built-in tracks alone.
    only : list of str or None
        Track names to keep (file stems for CSV files); None keeps all.

    Returns
    -------
    list of Track

    Raises
    ------
    TrackError
        The folder does not exist or holds no CSV file, a file does not load, or ``only`` names
        a track that is not there (each would otherwise measure less than was asked, silently).
    """
    sources: list[str | Path] = list(builtin_track_names())
    if tracks_dir:
        folder = Path(tracks_dir)
        files = sorted(folder.glob("*.csv")) if folder.is_dir() else []
        if not files:
            raise TrackError(
                f"no track CSV files in {tracks_dir!r}: name a folder of racetrack-database "
                "files, or leave it out to measure the built-in tracks."
            )
        sources += files
    tracks = [load_track(src) for src in sources]
    if only:
        missing = sorted(set(only) - {track.name for track in tracks})
        if missing:
            known = ", ".join(track.name for track in tracks)
            raise TrackError(f"no track named {', '.join(missing)}; the tracks here: {known}.")
        tracks = [track for track in tracks if track.name in only]
    return tracks


def run(main: Callable[[], int | None]) -> NoReturn:
    """Call ``main`` and exit with its status; a library error or Ctrl-C ends it in one line.

    Parameters
    ----------
    main : callable
        The script's entry point; it returns an exit status or None (0).
    """
    try:
        status = main()
    except RacingLibError as exc:
        print(f"error: {exc}", file=sys.stderr)
        status = EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        status = EXIT_INTERRUPTED
    raise SystemExit(status or 0)
