"""A car of your own in one call: identify it (once, cached), plan with its model, race it.

The paper's recipe for a car it did not write (Gran Turismo Sport): drive manoeuvres, identify
the planning model from the logs, plan with that model, and let the MPC predict with it.
:func:`race_car` does all of it for any :class:`~racing_lib.experiments.sysid.CarUnderTest`, or
for a car named on the command line (``racing-lib lap --car commonroad:vehicle2``):

1. :func:`identify_car` drives the manoeuvres of :func:`racing_lib.experiments.sysid.collect_logs`
   and fits the model (:func:`racing_lib.experiments.sysid.identify`), then keeps the resulting
   :class:`~racing_lib.model.CarModel` in a JSON file, so the next run of the same car starts
   from it (a few seconds saved for CommonRoad's cars, minutes for a slow simulator). The file is
   named by a fingerprint of the car, its data sheet, the manoeuvres and the identification's
   code, so an edited car or a newer racing_lib is identified anew;
2. :func:`racing_lib.experiments.pipeline.race` plans with that model and drives the car's own
   plant (``LapSpec.car``) with the MPC predicting with it.

Named cars (:func:`named_car`): ``sim`` (the simulated car, identified like any other) and
``commonroad:vehicle1`` ... ``commonroad:vehicle3`` (CommonRoad's single-track drift model with
the package's parameter sets; the ``[commonroad]`` extra).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from racing_lib.config import fast_mode
from racing_lib.errors import ArgumentError, ModelError
from racing_lib.experiments.pipeline import RaceResult, check_speed_scale, race
from racing_lib.experiments.sysid import CarUnderTest, collect_logs, identify, simulated_car
from racing_lib.io import atomic_write_json
from racing_lib.model import CarModel, ModelParams
from racing_lib.plants import CARS
from racing_lib.provenance import code_digest
from racing_lib.tracks import load_track

__all__ = ["CARS", "NamedCar", "car_cache_dir", "identify_car", "named_car", "race_car"]

#: Version of the cache file; a file of another version is identified anew.
_CACHE_FORMAT = 1


@dataclass(frozen=True)
class NamedCar:
    """A car to identify and race, with its name (the cache file's) and data-sheet limits.

    Attributes
    ----------
    name : str
        Names the car in reports and its cache file.
    car : CarUnderTest
        Its plant factory and what is known of it beforehand.
    steer_max : float or None
        The data sheet's steering-angle limit, rad (None: not given).
    """

    name: str
    car: CarUnderTest
    steer_max: float | None = None


def named_car(name: str) -> NamedCar:
    """The car ``name`` (one of :data:`CARS`).

    Raises
    ------
    ArgumentError
        An unknown name (the message lists the known ones).
    PlantError
        A CommonRoad car without the ``[commonroad]`` extra installed (the message says how to
        install it).
    """
    if name == "sim":
        return NamedCar("sim", simulated_car())
    if name in CARS and name.startswith("commonroad:vehicle"):
        # The optional extra, imported only for its cars (PlantError with the pip command).
        from racing_lib.plants.commonroad import CommonRoadAt, data_sheet, vehicle_parameters

        vehicle = int(name.removeprefix("commonroad:vehicle"))
        steer_max = float(vehicle_parameters(vehicle).steering.max)
        return NamedCar(name, CarUnderTest(CommonRoadAt(vehicle), data_sheet(vehicle)), steer_max)
    known = ", ".join(sorted(CARS))
    raise ArgumentError(
        f"unknown car {name!r}; the cars known by name are: {known}. A car of your own goes "
        "through the library: racing_lib.experiments.own_car.race_car(CarUnderTest(...), ...)."
    )


def car_cache_dir() -> Path:
    """Where identified cars are kept: ``$XDG_CACHE_HOME/racing-lib/cars`` (``~/.cache/...``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "racing-lib" / "cars"


def _fingerprint(car: NamedCar, seed: int, fast: bool) -> str:
    """What the identified model depends on, hashed (16 hex characters).

    The car (its name, plant factory as it describes itself, data sheet and steering limit), the
    manoeuvres (seed, fast or full) and the code that drives and fits them: change any of these
    and the kept model no longer applies, so the car is identified anew.
    """
    known = car.car.known
    sheet = known.to_dict() if hasattr(known, "to_dict") else dataclasses.asdict(known)
    inputs = {
        "car": car.name,
        "plant": _describe(car.car.make_plant),
        "known": sheet,
        "steer_max": car.steer_max,
        "seed": seed,
        "fast": fast,
        "code": code_digest(("racing_lib.experiments.sysid",)),
    }
    text = json.dumps(inputs, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _describe(factory: object) -> dict[str, object]:
    """A plant factory as data: its class or function name, its text and its attributes."""
    kind = type(factory)
    name = getattr(factory, "__qualname__", None) or f"{kind.__module__}.{kind.__qualname__}"
    attributes = vars(factory) if hasattr(factory, "__dict__") else {}
    return {"name": name, "text": str(factory), "attributes": attributes}


def _cache_file(folder: Path, car: NamedCar, fingerprint: str) -> Path:
    safe = "".join(c if c.isalnum() or c in "-_" else "-" for c in car.name)
    return folder / f"{safe}-{fingerprint}.json"


def identify_car(
    car: NamedCar,
    *,
    seed: int = 0,
    fast: bool | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    refresh: bool = False,
    report: Callable[[str], None] | None = None,
) -> CarModel:
    """The identified model of ``car``, from its cache file or from fresh manoeuvres.

    Parameters
    ----------
    car : NamedCar
        The car (:func:`named_car`, or ``NamedCar("my-car", CarUnderTest(...))``).
    seed : int
        Seed of the manoeuvres' randomness.
    fast : bool, optional
        Fewer, shorter manoeuvres (default :func:`racing_lib.config.fast_mode`). Their shorter
        logs give a wider grip margin to a car that slid in them (CommonRoad's BMW: 8.5-17 %
        against 3.0-3.8 % with the full set).
    cache_dir : path, optional
        Folder of the cache files (default :func:`car_cache_dir`).
    refresh : bool
        Identify anew even when a cache file exists.
    report : callable, optional
        Called with a line of text at each step (and with the identification's report).

    Returns
    -------
    CarModel
        The identified model (:meth:`~racing_lib.experiments.sysid.IdentificationResult.car_model`:
        the identified steering actuator, top speed and grip margin).

    Raises
    ------
    ModelError
        The data could not determine a parameter (the message names the manoeuvre, what it
        reached and what to change), or a sub-model fits its data poorly.
    """
    say = report or (lambda _line: None)
    fast = fast_mode() if fast is None else bool(fast)
    fingerprint = _fingerprint(car, seed, fast)
    path = _cache_file(Path(cache_dir or car_cache_dir()), car, fingerprint)
    if path.exists() and not refresh:
        model = _read_cache(path, fingerprint)
        if model is not None:
            say(f"identified model of {car.name} from {path}")
            return model
        say(f"{path} is damaged or of another car or version: identifying anew")
    say(f"identifying {car.name}: driving the manoeuvres ({'fast' if fast else 'full'} set) ...")
    logs = collect_logs(seed=seed, fast=fast, car=car.car)
    known = car.car.known
    known = known if isinstance(known, ModelParams) else ModelParams.from_vehicle(known)
    result = identify(logs, known=known, steer_max=car.steer_max)
    say(result.report())
    if not result.success:
        raise ModelError(
            f"identification of {car.name}: {', '.join(result.poor_fits())} explain too little "
            "of their data to plan with (report above). Drive more or other manoeuvres "
            "(collect_logs(fast=False)), or check the car's plant for noise or faults."
        )
    model = result.car_model()
    record = {"format": _CACHE_FORMAT, "car": car.name, "fingerprint": fingerprint}
    record |= {"seed": seed, "fast": fast}
    record |= {"model": model.to_dict(), "report": result.report()}
    atomic_write_json(path, record)
    say(f"identified model of {car.name} kept in {path}")
    return model


def _read_cache(path: Path, fingerprint: str) -> CarModel | None:
    """The model of a cache file, or None when it is damaged or made for something else."""
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or record.get("format") != _CACHE_FORMAT:
        return None
    if record.get("fingerprint") != fingerprint:
        return None
    try:
        return CarModel.from_dict(record["model"])
    except (KeyError, TypeError, ValueError, ModelError):
        return None


def race_car(
    car: str | NamedCar,
    track: Any = "expressway",
    *,
    seed: int = 0,
    trials: int = 1,
    speed_scale: float = 1.0,
    identify_seed: int = 0,
    fast: bool | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    refresh: bool = False,
    report: Callable[[str], None] | None = None,
    # Any: forwarded to racing_lib.experiments.pipeline.race, whose keywords differ in type.
    **race_kwargs: Any,
) -> RaceResult:
    """Identify a car (cached), plan a track with its model and race it: the recipe in one call.

    Parameters
    ----------
    car : str or NamedCar
        A name of :data:`CARS` or a car of your own.
    track : str, path or Track
        As for :func:`~racing_lib.experiments.pipeline.race`.
    seed, trials : int
        Seed of the first lap and the number of laps.
    speed_scale : float
        As for :func:`~racing_lib.experiments.pipeline.race`: the share of the plan's speeds
        driven, in (0, 1].
    identify_seed : int
        Seed of the identification's manoeuvres (kept apart from the laps' ``seed``, so that laps
        of several seeds are driven with one model).
    fast, cache_dir, refresh : optional
        As for :func:`identify_car`.
    report : callable, optional
        Called with a line of text at each step.
    **race_kwargs
        More arguments of :func:`~racing_lib.experiments.pipeline.race` (``method``,
        ``controller``, ``weights``, ``progress``, ``on_lap`` ...).

    Returns
    -------
    RaceResult
    """
    named = named_car(car) if isinstance(car, str) else car
    if not isinstance(named, NamedCar):
        raise ArgumentError(
            f"car must be a name ({', '.join(sorted(CARS))}) or a NamedCar, got "
            f"{type(car).__name__}."
        )
    check_speed_scale(speed_scale)  # bad input is refused before the car is driven at all
    trk = load_track(track)
    model = identify_car(
        named, seed=identify_seed, fast=fast, cache_dir=cache_dir, refresh=refresh, report=report
    )
    return race(
        trk,
        seed=seed,
        trials=trials,
        model=model,
        car=named.car.make_plant,
        speed_scale=speed_scale,
        report=report,
        **race_kwargs,
    )
