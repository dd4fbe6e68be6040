"""Plants nobody here wrote: other people's vehicle models, each behind the `Plant` protocol.

The layer beside :mod:`racing_lib.sim` (the simulated car, which this library wrote): each module
wraps a vehicle model from elsewhere so that the lap runner
(:func:`racing_lib.experiments.lap.run_lap`) can drive it and the identification
(:class:`racing_lib.experiments.sysid.CarUnderTest`) can test it, exactly as they do the simulated
car. A wrapper maps racing_lib's commands (a steering-angle command, rad; one pedal in [-1, 1]) to
the model's own inputs, runs the model's own equations, reports an
:class:`~racing_lib.interfaces.Observation`, and meets the track as the simulated car does
(:mod:`racing_lib.vehicle.contact`: walls stop the car and are counted, open edges count the time
off the track). Controllers and planners never import this layer, as they never import the
simulator.

* :mod:`racing_lib.plants.commonroad`: CommonRoad's single-track drift model (TUM's
  ``commonroad-vehicle-models``, an optional extra: ``pip install "racing-lib[commonroad]"``).
* :mod:`racing_lib.plants.std`: its equations transcribed into CasADi, so they can be compiled.

The modules are imported on demand (``from racing_lib.plants.commonroad import CommonRoadCar``),
so that this package imports without the optional extras.
"""

__all__ = ["CARS"]

#: The cars known by name (``racing-lib lap --car NAME``,
#: :func:`racing_lib.experiments.own_car.named_car`), with what each is.
CARS = {
    "sim": "the simulated car (racing_lib.sim), identified from its logs like any other car",
    "commonroad:vehicle1": "CommonRoad's Ford Escort, single-track drift model (std)",
    "commonroad:vehicle2": "CommonRoad's BMW 320i, single-track drift model (std)",
    "commonroad:vehicle3": "CommonRoad's VW Vanagon, single-track drift model (std)",
}
