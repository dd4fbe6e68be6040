"""A small check framework for the course's exercises.

Each exercise asks the reader to write one function; its check calls that function on a few
cases, compares the answers with what :mod:`racing_lib` computes for the same cases, and returns
a :class:`CheckResult` whose text says, in physical terms, what is right or wrong ("your
projection puts the car 0.80 m left of where it is (expected e_y = 1.20 m, got 2.00 m)").

A check runs every case and reports every one that fails (:func:`every_case`), the most telling
first: the one whose message names the mistake. An exercise that rebuilds a library function
refuses an answer that calls it (:func:`refuse_library`).

A function that raises :class:`NotImplementedError` or returns ``None`` (the state of every
template) is reported as "not done yet", never as an error. A function that crashes is reported
with the exception and the case that triggered it. Each check has a weight (for a score) and a
time limit (a reader's endless loop should not hang the notebook).

Writing a check (see :mod:`racing_lib.grading.ch01` for examples)::

    def check_braking_distance(braking_distance):
        def body():
            got = as_float(call(braking_distance, 30.0), "braking_distance(30 m/s)")
            expect_close(got, library_braking_distance(30.0), tol=1e-3,
                         message="your car stops {absdiff:.1f} m off (expected {expected:.1f} m, "
                         "got {got:.1f} m)")
            return "the braking distance agrees with the library"
        return grade("9.1 Braking distance", body)
"""

from __future__ import annotations

import math
import signal
import threading
import time
import types
from collections.abc import Callable, Iterable, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal, TypeVar

import numpy as np
from numpy.typing import ArrayLike
from threadpoolctl import threadpool_limits

__all__ = [
    "CORRECT",
    "NOT_DONE",
    "CheckResult",
    "NotDone",
    "Wrong",
    "as_array",
    "as_float",
    "as_tuple",
    "call",
    "differs",
    "every_case",
    "expect_close",
    "grade",
    "refuse_library",
    "score",
]

# What the reader's function returns (call), or a case of a check (every_case).
_T = TypeVar("_T")

Status = Literal["correct", "wrong", "not done yet", "error", "too slow"]

#: Status of an exercise whose answer matches the library.
CORRECT: Status = "correct"
#: Status of an exercise whose function is still the template's (raises NotImplementedError or
#: returns None).
NOT_DONE: Status = "not done yet"

#: Default time limit of one check, s.
TIME_LIMIT = 60.0


class NotDone(Exception):
    """The reader's function has not been written yet."""


class Wrong(Exception):
    """The reader's answer is wrong; the message says how, in physical terms.

    Parameters
    ----------
    message : str
        What differs, with units.
    telling : float
        Rank among several failing cases (:func:`every_case`): higher comes first. A check gives
        a case whose hint names the mistake a higher rank than one that only says the numbers
        differ.
    hint : str
        What mistake gives that answer and what to do; :func:`every_case` says each distinct
        hint once.
    """

    def __init__(self, message: str, telling: float = 0.0, hint: str = "") -> None:
        super().__init__(f"{message} {hint}".strip())
        self.fact = message
        self.hint = hint
        self.telling = float(telling)


class _StudentCrash(Exception):
    """The reader's function raised an exception (message: which, and on what case)."""


class _TimeLimit(Exception):
    """The check ran longer than its time limit."""


@dataclass(frozen=True)
class CheckResult:
    """The verdict of one exercise check.

    Attributes
    ----------
    exercise : str
        Number and title of the exercise, e.g. ``"1.1 Frenet projection"``.
    status : {"correct", "wrong", "not done yet", "error", "too slow"}
        The verdict.
    message : str
        What was checked and, if wrong, what differs (expected vs got, with units).
    weight : float
        Points the exercise is worth.
    seconds : float
        Run time of the check, s.
    """

    exercise: str
    status: Status
    message: str
    weight: float = 1.0
    seconds: float = 0.0

    @property
    def passed(self) -> bool:
        """True when the answer is correct."""
        return self.status == CORRECT

    @property
    def points(self) -> float:
        """The weight if correct, else 0."""
        return self.weight if self.passed else 0.0

    def __str__(self) -> str:
        # Start the sentence with a capital, unless it starts with a symbol such as v_y.
        first = self.message.split(" ", 1)[0]
        message = self.message if "_" in first else self.message[:1].upper() + self.message[1:]
        return f"Exercise {self.exercise}: {self.status}. {message}"

    # The verdict is the representation, so that a check called as the last line of a notebook
    # cell shows it without a print().
    __repr__ = __str__


def score(results: Iterable[CheckResult]) -> tuple[float, float]:
    """Points earned and points possible over some check results."""
    results = list(results)
    return sum(r.points for r in results), sum(r.weight for r in results)


def _describe_args(args: tuple[object, ...]) -> str:
    parts = []
    for a in args:
        if isinstance(a, float | int | np.floating | np.integer):
            parts.append(f"{float(a):.4g}")
        elif isinstance(a, np.ndarray):
            parts.append(f"array{a.shape}")
        else:
            parts.append(type(a).__name__)
    return ", ".join(parts)


def call(fn: Callable[..., _T], *args: object, **kwargs: object) -> _T:
    """Call the reader's function; turn "not written yet" and crashes into check outcomes.

    Raises
    ------
    NotDone
        ``fn`` raised NotImplementedError or returned None.
    _StudentCrash
        ``fn`` raised any other exception (the message names it and the arguments).
    """
    if not callable(fn):
        raise Wrong(f"expected a function, got {type(fn).__name__}; pass the function itself.")
    try:
        out = fn(*args, **kwargs)
    except NotImplementedError:
        raise NotDone() from None
    except (_TimeLimit, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 - any error of the reader's code is a verdict
        name = getattr(fn, "__name__", "function")
        raise _StudentCrash(
            f"your {name}({_describe_args(args)}) raised {type(exc).__name__}: {exc}"
        ) from None
    if out is None:
        raise NotDone()
    return out


def as_float(value: object, what: str) -> float:
    """``value`` as a finite float, or :class:`Wrong` naming ``what`` was returned."""
    try:
        out = float(np.asarray(value, dtype=float).reshape(()))
    except (TypeError, ValueError):
        raise Wrong(f"{what} should be one number, got {value!r}.") from None
    if not math.isfinite(out):
        raise Wrong(f"{what} is {out}; it should be a finite number.")
    return out


def as_array(value: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as a finite float array of ``shape``, or :class:`Wrong`."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise Wrong(f"{what} should be an array of numbers, got {type(value).__name__}.") from None
    if arr.shape != shape:
        if arr.ndim == len(shape) == 2 and arr.shape == shape[::-1] and shape[0] != shape[1]:
            raise Wrong(f"{what} should have shape {shape}, got {arr.shape}: it is transposed.")
        if arr.size == math.prod(shape):
            arr = arr.reshape(shape)
        else:
            raise Wrong(f"{what} should have shape {shape}, got {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise Wrong(f"{what} contains NaN or infinite values.")
    return arr


def as_tuple(value: object, n: int, what: str) -> tuple[object, ...]:
    """``value`` as a tuple of ``n`` items, or :class:`Wrong` saying what was expected."""
    if isinstance(value, np.ndarray) and value.shape[:1] == (n,):
        return tuple(value)
    if not isinstance(value, tuple | list) or len(value) != n:
        got = f"{len(value)} values" if isinstance(value, tuple | list) else type(value).__name__
        raise Wrong(f"{what} should return {n} values, got {got}.")
    return tuple(value)


def differs(got: ArrayLike, expected: ArrayLike, *, tol: float, rel: float = 0.0) -> bool:
    """True when any element of ``got`` is off ``expected`` by more than ``tol + rel |expected|``.

    ``tol`` is absolute, in the quantity's unit; NaN in ``got`` always differs.
    """
    e = np.atleast_1d(np.asarray(expected, dtype=float))
    g = np.broadcast_to(np.atleast_1d(np.asarray(got, dtype=float)), e.shape)
    ok = np.abs(g - e) <= tol + rel * np.abs(e)
    return not bool(np.all(ok))


def refuse_degrees(got: float, expected: float, what: str) -> None:
    """Raise :class:`Wrong` when ``got`` is the angle ``expected`` (rad) given in degrees.

    Checked before the general message, which prints both angles in degrees too: converting an
    answer that already is in degrees would tell the student of a 188 deg slip angle.
    """
    deg = math.degrees(float(expected))
    if deg != 0.0 and abs(float(got) - deg) <= 1e-3 * abs(deg):
        raise Wrong(
            f"your {what} is {float(got):.4g}: that is the right angle in degrees. Return it in "
            f"radians ({float(expected):.5f} rad), as every angle in racing_lib is."
        )


def expect_close(
    got: float, expected: float, *, tol: float, message: str, rel: float = 0.0
) -> None:
    """Raise :class:`Wrong` when ``got`` is off ``expected`` by more than ``tol + rel |expected|``.

    ``message`` is a template formatted with ``expected``, ``got``, ``diff`` (got - expected) and
    ``absdiff`` (its size), e.g. ``"your car is {absdiff:.2f} m too far left (expected e_y =
    {expected:.2f} m, got {got:.2f} m)"``.
    """
    if differs(got, expected, tol=tol, rel=rel):
        g, e = float(got), float(expected)
        raise Wrong(message.format(expected=e, got=g, diff=g - e, absdiff=abs(g - e)))


def every_case(cases: Iterable[_T], check_case: Callable[[_T], None]) -> None:
    """Run ``check_case`` on every case; raise one :class:`Wrong` that reports each failure.

    The message starts with the most telling failure (highest :attr:`Wrong.telling`, then the
    first in case order) and lists the others below it, so that a reader sees at once whether a
    mistake is systematic or confined to some cases (near the start line, under braking...).
    A case that crashes or is not done yet stops the check as before.
    """
    failures: list[tuple[float, int, Wrong]] = []
    cases = list(cases)
    for k, case in enumerate(cases):
        try:
            check_case(case)
        except Wrong as exc:
            failures.append((-exc.telling, k, exc))
    if not failures:
        return
    failures.sort(key=lambda item: item[:2])
    first = failures[0][2]
    if len(failures) == 1:
        raise first
    said = {first.hint}
    lines = []
    for _, _, exc in failures[1:]:
        lines.append(f"  - {exc.fact}" + ("" if exc.hint in said else f" {exc.hint}"))
        said.add(exc.hint)
    text = str(first)
    text = text[:1].upper() + text[1:] if "_" not in text.split(" ", 1)[0] else text
    others = "\n".join(lines)
    raise Wrong(f"{len(failures)} of {len(cases)} cases are wrong. {text}\nAlso:\n{others}")


def _module_of(obj: object) -> str:
    return getattr(obj, "__module__", None) or ""


def _names_used(fn: Callable[..., object], depth: int = 3) -> list[tuple[str, object]]:
    """(name, bound object or None) of the globals, attributes and closure variables of ``fn``.

    Follows the reader's own helper functions (any function not from racing_lib) ``depth`` deep.
    """
    code = getattr(fn, "__code__", None)
    if code is None:
        return []
    globals_ = getattr(fn, "__globals__", {})
    names: set[str] = set()

    def walk(c: types.CodeType) -> None:
        names.update(c.co_names)
        for const in c.co_consts:
            if isinstance(const, types.CodeType):
                walk(const)

    walk(code)
    used = [(name, globals_.get(name)) for name in sorted(names)]
    # Names the function closes over (a function defined inside another one).
    for name, cell in zip(code.co_freevars, getattr(fn, "__closure__", None) or (), strict=False):
        try:
            used.append((name, cell.cell_contents))
        except ValueError:  # a cell not filled yet
            continue
    if depth > 0:
        for _, obj in list(used):
            if isinstance(obj, types.FunctionType) and obj is not fn:
                if not _module_of(obj).startswith("racing_lib"):
                    used += _names_used(obj, depth - 1)
    return used


def refuse_library(fn: Callable[..., object], forbidden: Mapping[str, object], task: str) -> None:
    """Raise :class:`Wrong` when the reader's function calls what the exercise asks them to write.

    Parameters
    ----------
    fn : callable
        The reader's function.
    forbidden : mapping
        Name -> library object. The answer is refused when it uses the name as an attribute or a
        global (``path.to_frenet``, ``pedal_map.pedal``), or any global bound to the object
        (``from racing_lib... import steering_lag_coefficients as f``). ``None`` matches the name
        only.
    task : str
        What the reader is asked to do instead, for the message.
    """
    for name, obj in _names_used(fn):
        # A global of the reader's own that happens to share the name is not the library's.
        library_name = obj is None or _module_of(obj).startswith("racing_lib")
        for label, target in forbidden.items():
            if (name == label and library_name) or (target is not None and obj is target):
                raise Wrong(
                    f"your function calls {label}, which does what this exercise asks you to "
                    f"write yourself: {task}"
                )


@contextmanager
def _time_limit(seconds: float | None):
    """Interrupt the block after ``seconds`` (POSIX main thread only; elsewhere no limit)."""
    usable = (
        seconds is not None
        and hasattr(signal, "setitimer")
        and threading.current_thread() is threading.main_thread()
    )
    if not usable:
        yield
        return

    def _alarm(signum: int, frame: types.FrameType | None) -> None:
        raise _TimeLimit()

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def grade(
    exercise: str,
    body: Callable[[], str],
    *,
    weight: float = 1.0,
    time_limit: float | None = TIME_LIMIT,
) -> CheckResult:
    """Run one check and turn its outcome into a :class:`CheckResult`.

    Parameters
    ----------
    exercise : str
        Number and title of the exercise.
    body : callable
        Runs the cases; returns a sentence saying what was verified when all pass; raises
        :class:`Wrong` (via :func:`expect_close` etc.) at the first wrong answer and lets
        :class:`NotDone` from :func:`call` through.
    weight : float
        Points of the exercise.
    time_limit : float or None
        Seconds before the check gives up ("too slow"); None for no limit.
    """
    tic = time.perf_counter()

    def result(status: Status, message: str) -> CheckResult:
        return CheckResult(exercise, status, message, weight, time.perf_counter() - tic)

    try:
        # One BLAS thread: the checks' small problems gain nothing from more, and on a busy
        # two-core machine (Binder) two OpenBLAS threads spin against each other: exercise 3.4's
        # own solution took 61 s instead of 6.5 s.
        with _time_limit(time_limit), threadpool_limits(limits=1, user_api="blas"):
            note = body()
    except NotDone:
        return result(
            NOT_DONE, "Replace `raise NotImplementedError` with your code, then run this again."
        )
    except Wrong as exc:
        return result("wrong", str(exc))
    except _StudentCrash as exc:
        return result("error", f"{exc}.")
    except _TimeLimit:
        return result(
            "too slow",
            f"the check did not finish within {time_limit:.0f} s; look for a loop that never ends.",
        )
    return result(CORRECT, note or "all cases agree with racing_lib.")
