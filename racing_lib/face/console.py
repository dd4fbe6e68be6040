"""What the command line prints: messages for people on stderr, one JSON object on stdout."""

from __future__ import annotations

import json
import math
import sys
from typing import Any

__all__ = ["_clean", "_emit_json", "_say"]


def _say(*parts: object) -> None:
    """Human-readable output: always standard error, so that stdout stays pure JSON."""
    print(*parts, file=sys.stderr)


def _clean(obj: Any) -> Any:
    """Make an object JSON-safe: NaN and infinities become null."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    return obj


def _emit_json(obj: dict[str, Any]) -> None:
    """Print ``obj`` as one line of JSON on standard output (NaN as null)."""
    print(json.dumps(_clean(obj), allow_nan=False))
