"""What every benchmark script shares: its ``--help`` and how it ends.

Each script is run as ``python benchmarks/<name>.py`` (its folder is then first on ``sys.path``,
so ``from _script import ...`` finds this module). :func:`argument_parser` shows the script's
whole docstring under ``--help``, usage examples included; :func:`run` turns the library's own
errors (a track file that does not exist, a plan that fails) into one line on stderr and exit
status 2, and Ctrl-C into exit status 130, instead of a traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import NoReturn

from racing_lib.errors import RacingLibError

__all__ = ["argument_parser", "run"]

#: Exit status of a run stopped by bad input (argparse uses the same), and by Ctrl-C.
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


def argument_parser(doc: str | None) -> argparse.ArgumentParser:
    """An argument parser whose ``--help`` prints ``doc`` as written (line breaks kept)."""
    return argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )


def run(main: Callable[[], int | None]) -> NoReturn:
    """Call ``main`` and exit with its status; a library error or Ctrl-C ends it in one line."""
    try:
        status = main()
    except RacingLibError as exc:
        print(f"error: {exc}", file=sys.stderr)
        status = EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        status = EXIT_INTERRUPTED
    raise SystemExit(status or 0)
