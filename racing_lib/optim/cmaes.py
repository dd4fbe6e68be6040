"""CMA-ES over a box of positive parameters, resumable and parallel; it knows nothing of racing.

:class:`CmaTuner` / :func:`tune`: CMA-ES (pycma) over positive parameters searched in log10 space
inside a box (:class:`SearchSpace`), for any evaluation function ``f(params: dict) -> float``.
Candidates of a generation are evaluated through any ``concurrent.futures.Executor`` (a process
pool, or a Dask client's executor), every generation is checkpointed atomically, and an
interrupted run resumes to exactly the result of an uninterrupted one. The racing layer is
:mod:`racing_lib.experiments.tuning`.

Examples
--------
The machinery on a function whose minimum is known (at p = 10 and q = 0.1):

>>> import math
>>> def f(p):
...     return (math.log10(p["p"]) - 1.0) ** 2 + (math.log10(p["q"]) + 1.0) ** 2
>>> space = SearchSpace.from_bounds({"p": (1e-3, 1.0, 1e3), "q": (1e-3, 1.0, 1e3)})
>>> res = tune(f, space, TuningSettings(max_generations=60, seed=1), progress=False)
>>> round(res.best_weights["p"], 1), round(res.best_weights["q"], 2)
(10.0, 0.1)
"""

from __future__ import annotations

import dataclasses
import math
import os
import pickle
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path as FilePath
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.errors import ControlError
from racing_lib.io import JSONObject, atomic_write_bytes, atomic_write_json, jsonable

if TYPE_CHECKING:
    # dask is an optional dependency (the "distributed" extra)
    from distributed import Client

__all__ = ["CmaTuner", "ExecutorLike", "SearchSpace", "TuningResult", "TuningSettings", "tune"]

ExecutorLike: TypeAlias = "Executor | Client"
"""Where candidates are evaluated: a ``concurrent.futures.Executor``, or a Dask
``distributed.Client`` (used through ``client.get_executor()``)."""


# --------------------------------------------------------------------------------------------------
# Search space and settings


@dataclass(frozen=True)
class SearchSpace:
    """Positive parameters searched by CMA-ES in log10 space, inside a box.

    Weights of a quadratic cost matter by their ratios, over orders of magnitude: searching
    log10(w) makes a step of 0.5 mean "about three times larger" for every weight alike.

    Attributes
    ----------
    names : tuple of str
        Parameter names (the keys of the dicts given to the evaluation function).
    initial : tuple of float
        Starting values (the CMA-ES mean at generation 0), in the parameters' own units, > 0.
    lower, upper : tuple of float
        The box, in the parameters' own units, 0 < lower <= initial <= upper.
    """

    names: tuple[str, ...]
    initial: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.names)
        if n == 0 or len(set(self.names)) != n:
            raise ControlError(
                f"SearchSpace needs at least one parameter and unique names, got {self.names}."
            )
        for attr in ("initial", "lower", "upper"):
            if len(getattr(self, attr)) != n:
                raise ControlError(
                    f"SearchSpace.{attr} has {len(getattr(self, attr))} values for {n} names; "
                    "give one value per parameter."
                )
        for name, lo, x0, hi in zip(self.names, self.lower, self.initial, self.upper, strict=True):
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= x0 <= hi):
                raise ControlError(
                    f"SearchSpace parameter {name!r}: need 0 < lower <= initial <= upper (finite), "
                    f"got {lo}, {x0}, {hi}; the search is in log10 space, so values must be > 0."
                )
            if not lo < hi:
                raise ControlError(
                    f"SearchSpace parameter {name!r}: the box [{lo}, {hi}] is empty; widen it."
                )

    @classmethod
    def from_bounds(cls, bounds: Mapping[str, tuple[float, float, float]]) -> SearchSpace:
        """Build from ``{name: (lower, initial, upper)}``."""
        names = tuple(bounds)
        return cls(
            names=names,
            initial=tuple(float(bounds[n][1]) for n in names),
            lower=tuple(float(bounds[n][0]) for n in names),
            upper=tuple(float(bounds[n][2]) for n in names),
        )

    def x0(self) -> np.ndarray:
        """The starting point in log10 space."""
        return np.log10(np.asarray(self.initial, dtype=float))

    def log_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The box in log10 space."""
        return np.log10(np.asarray(self.lower, float)), np.log10(np.asarray(self.upper, float))

    def to_params(self, x: Sequence[float]) -> dict[str, float]:
        """Parameters (own units) of a point ``x`` in log10 space, clipped into the box."""
        lo, hi = self.log_bounds()
        xc = np.clip(np.asarray(x, dtype=float), lo, hi)
        return {name: float(10.0**v) for name, v in zip(self.names, xc, strict=True)}

    def to_dict(self) -> dict[str, list[str] | list[float]]:
        """JSON-ready description."""
        return {
            "names": list(self.names),
            "initial": list(self.initial),
            "lower": list(self.lower),
            "upper": list(self.upper),
        }


@dataclass(frozen=True)
class TuningSettings:
    """Settings of the CMA-ES search.

    Attributes
    ----------
    sigma0 : float
        Initial step size in log10 units (0.5: a typical first step changes a weight by ~3x).
    popsize : int or None
        Candidates per generation (None: pycma's default 4 + floor(3 ln n), 9 for six weights).
    max_generations : int
        Budget in generations (the run also stops at pycma's own criteria, such as ``tolfun``).
    seed : int
        Seed of the CMA-ES sampling (a private ``numpy`` generator; the global one is untouched).
    tolfun : float
        Stop when the objective values of the recent generations differ by less than this.
    tolx : float
        Stop when the search steps are below this, log10 units.
    """

    sigma0: float = 0.5
    popsize: int | None = None
    max_generations: int = 30
    seed: int = 0
    tolfun: float = 1e-4
    tolx: float = 1e-4

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma0) and self.sigma0 > 0):
            raise ControlError(
                f"TuningSettings.sigma0 must be > 0 (log10 units), got {self.sigma0}."
            )
        if self.popsize is not None and int(self.popsize) < 2:
            raise ControlError(f"TuningSettings.popsize must be >= 2, got {self.popsize}.")
        if int(self.max_generations) < 0:
            raise ControlError(
                f"TuningSettings.max_generations must be >= 0, got {self.max_generations}."
            )

    @classmethod
    def default(cls, **overrides: int | float | None) -> TuningSettings:
        """The default settings, shrunk in fast mode (6 candidates x 3 generations).

        Fast mode (``RACING_LIB_FAST=1``) only lowers the budget; the algorithm is the same.
        """
        values: dict[str, int | float | None] = {}
        if fast_mode():
            values.update(popsize=6, max_generations=3)
        values.update(overrides)
        return cls(**values)

    def identity(self) -> dict[str, int | float | None]:
        """The settings that must match for a run to be resumed (all but the budget)."""
        out = dataclasses.asdict(self)
        out.pop("max_generations")
        return out


# --------------------------------------------------------------------------------------------------
# Result


@dataclass
class TuningResult:
    """What a tuning run returns.

    Attributes
    ----------
    best_weights : dict
        The best parameters evaluated (own units).
    best_objective : float
        Their objective.
    history : list of dict
        One entry per generation: ``generation``, ``candidates`` (dicts), ``x`` (log10),
        ``objectives``, ``best_objective`` and ``best_weights`` so far, ``sigma``, ``mean``
        (log10), ``elapsed`` (s since the start, across resumes).
    generations : int
        Generations completed.
    evaluations : int
        Evaluation-function calls made.
    success : bool
        At least one finite evaluation below the success threshold (for lap tuning: a completed
        lap) and no error.
    status : str
        Why the run stopped: ``'max_generations'`` or pycma's criteria (``'tolfun'``, ...).
    elapsed : float
        Wall time, s (summed over resumed parts).
    """

    best_weights: dict[str, float]
    best_objective: float
    history: list[dict[str, Any]] = field(repr=False)
    generations: int
    evaluations: int
    success: bool
    status: str
    elapsed: float

    def to_dict(self) -> JSONObject:
        """JSON-ready dict (non-finite numbers become None)."""
        return jsonable(dataclasses.asdict(self))


# --------------------------------------------------------------------------------------------------
# The generic CMA-ES machinery


class _Randn:
    """pycma's ``randn`` option backed by a private, picklable ``numpy`` generator.

    pycma draws its samples from the global ``np.random`` unless given a ``randn``; a private
    generator makes runs independent of anything else that uses the global state and travels
    with the pickled optimizer, which is what makes a resumed run identical to a straight one.
    """

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)


STATE_FILE = "cma_state.pkl"
HISTORY_FILE = "history.json"
_FORMAT = 1

#: What a non-finite value returned by an evaluation function is replaced with (CMA-ES ranks).
NONFINITE_VALUE = 1e30


class CmaTuner:
    """CMA-ES over a :class:`SearchSpace` for an evaluation function ``f(params) -> float``.

    Parameters
    ----------
    evaluate : callable
        ``f(params: dict[str, float]) -> float``, lower is better. Must be deterministic for a
        resumed run to equal a straight one, and picklable (a module-level function or a
        ``functools.partial`` of one) when run through a process pool or Dask.
    space : SearchSpace
        Parameters, starting point and box.
    settings : TuningSettings, optional
        Defaults: :meth:`TuningSettings.default` (fast mode shrinks the budget).
    success_threshold : float
        ``success`` requires the best objective to be below this (the lap tuning of
        :mod:`racing_lib.experiments.tuning` passes its penalty for an incomplete lap).
    """

    def __init__(
        self,
        evaluate: Callable[[dict[str, float]], float],
        space: SearchSpace,
        settings: TuningSettings | None = None,
        *,
        success_threshold: float = math.inf,
    ) -> None:
        if not callable(evaluate):
            raise ControlError("CmaTuner needs a callable evaluate(params) -> float.")
        self.evaluate = evaluate
        self.space = space
        self.settings = settings or TuningSettings.default()
        self.success_threshold = float(success_threshold)

    # -- CMA-ES set-up ------------------------------------------------------------------------
    def _new_strategy(self):
        import cma

        st = self.settings
        lo, hi = self.space.log_bounds()
        opts: dict[str, Any] = {
            "bounds": [lo.tolist(), hi.tolist()],
            "randn": _Randn(st.seed),
            "seed": float("nan"),  # pycma seeds the global generator otherwise; ours is private
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
            "tolfun": st.tolfun,
            "tolx": st.tolx,
            "maxiter": math.inf,  # the budget is counted here, so it can grow on resume
        }
        if st.popsize is not None:
            opts["popsize"] = int(st.popsize)
        return cma.CMAEvolutionStrategy(self.space.x0().tolist(), st.sigma0, opts)

    def _identity(self) -> dict[str, Any]:
        return {"space": self.space.to_dict(), "settings": self.settings.identity()}

    # -- checkpoints --------------------------------------------------------------------------
    def _load(self, out_dir: FilePath) -> dict[str, Any] | None:
        path = out_dir / STATE_FILE
        if not path.exists():
            return None
        try:
            # Only ever our own checkpoint, written by _save below (pickle trusts its input).
            state = pickle.loads(path.read_bytes())
        except Exception as exc:  # a foreign or damaged file
            raise ControlError(
                f"cannot read the tuning checkpoint {path} ({exc}); delete it or pass "
                "resume=False to start afresh."
            ) from exc
        if state.get("format") != _FORMAT or state.get("identity") != self._identity():
            raise ControlError(
                f"the checkpoint in {out_dir} belongs to a tuning run with another search space "
                "or other settings (only max_generations may change on resume); use another "
                "out_dir, or resume=False to overwrite it."
            )
        return state

    def _save(self, out_dir: FilePath, state: dict[str, Any], status: str) -> None:
        # The pickle is the one source of truth for resuming (one atomic write: optimizer,
        # history and counters always agree); the JSON next to it is for people and plots.
        atomic_write_bytes(out_dir / STATE_FILE, pickle.dumps(state))
        atomic_write_json(
            out_dir / HISTORY_FILE,
            jsonable(
                {
                    "format": _FORMAT,
                    "space": self.space.to_dict(),
                    "settings": dataclasses.asdict(self.settings),
                    "status": status,
                    "generations": state["generation"],
                    "evaluations": state["evaluations"],
                    "best_weights": state["best_params"],
                    "best_objective": state["best_value"],
                    "elapsed": state["elapsed"],
                    "history": state["history"],
                }
            ),
        )

    # -- the loop -----------------------------------------------------------------------------
    def run(
        self,
        *,
        executor: ExecutorLike | None = None,
        workers: int | None = 1,
        out_dir: str | os.PathLike[str] | None = None,
        resume: bool = False,
        progress: bool = True,
    ) -> TuningResult:
        """Run CMA-ES until the budget or a stopping criterion.

        Parameters
        ----------
        executor : concurrent.futures.Executor or dask Client, optional
            Where the candidates of a generation are evaluated (``executor.map``). A Dask
            ``distributed.Client`` is accepted and used through ``client.get_executor()``. The
            caller owns it (it is not shut down here).
        workers : int or None
            Without ``executor``: 1 evaluates serially in this process, N > 1 in a
            ``ProcessPoolExecutor`` of N processes made for this run, None one per CPU.
        out_dir : path, optional
            Folder for the checkpoint (``cma_state.pkl``) and the history (``history.json``),
            both rewritten atomically after every generation.
        resume : bool
            Continue from the checkpoint in ``out_dir`` if there is one (it must come from the
            same space and settings; ``max_generations`` may differ). The result equals that of
            an uninterrupted run.
        progress : bool
            Show a progress bar over the generations.

        Returns
        -------
        TuningResult
        """
        out = FilePath(out_dir) if out_dir is not None else None
        if resume and out is None:
            raise ControlError("resume=True needs out_dir, the folder of the run to continue.")
        state = self._start_state(out, resume)
        es = state["es"]
        max_gen = int(self.settings.max_generations)
        executor, own_pool = _candidate_executor(executor, workers)

        from tqdm.auto import tqdm

        bar = tqdm(
            total=max_gen,
            initial=min(state["generation"], max_gen),
            disable=not progress,
            desc="CMA-ES",
            unit="gen",
            leave=False,
        )
        t_run = time.perf_counter()
        elapsed0 = float(state["elapsed"])
        status = state.get("status") or ""
        try:
            while True:
                if state["generation"] >= max_gen:
                    status = "max_generations"
                    break
                stop = es.stop()
                if stop:
                    status = ",".join(sorted(str(k) for k in stop))
                    break
                self._generation(state, executor, elapsed0, t_run)
                if out is not None:
                    self._save(out, state, "running")
                bar.update(1)
                bar.set_postfix(best=f"{state['best_value']:.4g}")
        finally:
            bar.close()
            if own_pool is not None:
                own_pool.shutdown(cancel_futures=True)

        state["status"] = status
        state["elapsed"] = elapsed0 + time.perf_counter() - t_run
        if out is not None:
            self._save(out, state, status)
        return self._result(state, status)

    def _start_state(self, out: FilePath | None, resume: bool) -> dict[str, Any]:
        """The run's state: the checkpoint in ``out`` when resuming and there is one, else new."""
        state = self._load(out) if (resume and out is not None) else None
        if state is None:
            state = {
                "format": _FORMAT,
                "identity": self._identity(),
                "es": self._new_strategy(),
                "generation": 0,
                "evaluations": 0,
                "history": [],
                "best_params": None,
                "best_value": math.inf,
                "elapsed": 0.0,
                "status": "",
            }
        return state

    def _generation(
        self, state: dict[str, Any], executor: Executor | None, elapsed0: float, t_run: float
    ) -> None:
        """One generation: ask for candidates, evaluate them, tell the strategy, record it.

        Parameters
        ----------
        state : dict
            The run's state (strategy, counters, best so far, history), updated in place.
        executor : Executor or None
            Where the candidates are evaluated (None: serially in this process).
        elapsed0 : float
            Wall time of the run before this session (a resumed run), s.
        t_run : float
            ``time.perf_counter()`` at the start of this session, s.
        """
        es = state["es"]
        xs = es.ask()
        params = [self.space.to_params(x) for x in xs]
        if executor is None:
            raw = [self.evaluate(p) for p in params]
        else:
            raw = list(executor.map(self.evaluate, params))
        values = [float(v) if math.isfinite(float(v)) else NONFINITE_VALUE for v in raw]
        es.tell(xs, values)

        gen = state["generation"] + 1
        i_best = int(np.argmin(values))
        if values[i_best] < state["best_value"]:
            state["best_value"] = values[i_best]
            state["best_params"] = params[i_best]
        state["generation"] = gen
        state["evaluations"] += len(values)
        state["elapsed"] = elapsed0 + time.perf_counter() - t_run
        state["history"].append(
            {
                "generation": gen,
                "candidates": params,
                "x": [np.asarray(x, float).tolist() for x in xs],
                "objectives": [float(v) for v in raw],
                "best_objective": state["best_value"],
                "best_weights": state["best_params"],
                "sigma": float(es.sigma),
                "mean": np.asarray(es.mean, float).tolist(),
                "elapsed": state["elapsed"],
            }
        )
        state["status"] = "running"

    def _result(self, state: dict[str, Any], status: str) -> TuningResult:
        """The :class:`TuningResult` of a finished run's state (ended with ``status``)."""
        best = state["best_params"] or self.space.to_params(self.space.x0())
        best_value = float(state["best_value"])
        return TuningResult(
            best_weights=dict(best),
            best_objective=best_value,
            history=state["history"],
            generations=int(state["generation"]),
            evaluations=int(state["evaluations"]),
            success=bool(math.isfinite(best_value) and best_value < self.success_threshold),
            status=status,
            elapsed=float(state["elapsed"]),
        )


def _candidate_executor(
    executor: ExecutorLike | None, workers: int | None
) -> tuple[Executor | None, ProcessPoolExecutor | None]:
    """Where a run evaluates its candidates, and the pool it made for that (to shut down).

    Parameters
    ----------
    executor : Executor, dask Client or None
        The caller's executor (a Dask client is used through ``client.get_executor()``).
    workers : int or None
        Without ``executor``: 1 for this process, N > 1 for a pool of N processes, None one per
        CPU.

    Raises
    ------
    ControlError
        If ``executor`` is neither an executor nor a Dask client.
    """
    own_pool = None
    if executor is None and (workers is None or workers > 1):
        own_pool = ProcessPoolExecutor(max_workers=workers)
        executor = own_pool
    elif executor is not None and not isinstance(executor, Executor):
        if hasattr(executor, "get_executor"):  # a dask.distributed Client
            executor = executor.get_executor()
        elif not hasattr(executor, "map"):
            raise ControlError(
                f"executor must be a concurrent.futures.Executor or a Dask Client, got "
                f"{type(executor).__name__}."
            )
    return executor, own_pool


def tune(
    evaluate: Callable[[dict[str, float]], float],
    space: SearchSpace,
    settings: TuningSettings | None = None,
    *,
    executor: ExecutorLike | None = None,
    workers: int | None = 1,
    out_dir: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: bool = True,
    success_threshold: float = math.inf,
) -> TuningResult:
    """Minimize ``evaluate(params)`` over ``space`` with CMA-ES (see :meth:`CmaTuner.run`)."""
    tuner = CmaTuner(evaluate, space, settings, success_threshold=success_threshold)
    return tuner.run(
        executor=executor, workers=workers, out_dir=out_dir, resume=resume, progress=progress
    )
