"""System identification: the planning model's parameters from logs of the (simulated) car.

Taught in notebook 02 ("identifying the race vehicle model"). The paper identified its model from
data driven in Gran Turismo Sport with a simple nominal controller; we do the same with the
simulated car of :mod:`racing_lib.sim` (or any other :class:`~racing_lib.interfaces.Plant`: see
:func:`collect_logs`), which is deliberately *not* the planning model (combined
slip, load-sensitive tyres, gears, power limit, steering lag), so the identified parameters are the
best planning-model fit to a different car -- as they were in the paper.

What a user of a real car has, and all we use: time, position, yaw, the body-frame velocities
``v_x, v_y``, the yaw rate ``r`` (the spatial observations of
:class:`~racing_lib.interfaces.Observation`), the commands sent (steering command and pedal), and
the track map (road pitch ``theta`` at the car's position). The car's internals (``state_info()``:
gear, actual steering angle, ...) are never used; only the report compares against the true
:class:`~racing_lib.vehicle.VehicleParams`.

Taken as known (the paper lists them as the car's data sheet): ``m, l_f, l_r, h_c, l_t, mu, g``.
Identified, in this order (each step uses the ones before it):

1. **Tyres, steady state** (constant-radius circles): with ``r_dot ~ 0`` the yaw-moment balance
   (Eq. 8) splits the measured lateral force ``m a_y`` between the axles without ``I_zz``:
   ``F_yf cos(delta) = m a_y l_r / L``, ``F_yr = m a_y l_f / L``. Each axle's force per unit load
   against its slip angle (Eq. 11) is fitted with the simplified Pacejka law (Eq. 9-10) by nonlinear
   least squares: ``B, C, D`` front and rear (``mu`` known, so ``D`` is the peak factor).
2. **Steering lag and yaw inertia, transients** (steering steps): the time constant of the
   steering actuator (a first-order lag of the command; the real angle is not observed) from the
   lateral balance ``m a_y = F_yf cos(delta) + F_yr`` (one-parameter nonlinear least squares), then
   ``I_zz`` by linear least squares from the yaw balance with the front force eliminated through the
   measured lateral balance, ``I_zz r_dot = l_f m a_y - L F_yr``. This form matters: the steering
   actuator's noise and lag act on the front axle, and with the front force eliminated they appear
   identically on both sides instead of only in ``r_dot`` (which biased ``I_zz`` 10 % low).
3. **Drag and rolling resistance** (coast-down, pedal 0): ``v_x_dot - r v_y + F_yf sin(delta)/m +
   g sin(theta) = -C_xw v_x^2 / m - c_rr g cos(theta)`` by linear least squares.
4. **Pedal map** (Appendix C; laps and pedal steps): the tyre acceleration
   ``a_x = v_x_dot - r v_y + (C_xw v_x^2 + R_x + F_yf sin(delta))/m + g sin(theta)``
   against ``[1, v_x, throttle, min(u_p, 0)]`` by linear least squares
   (:class:`~racing_lib.model.PedalMap`), for each throttle form (a share of full throttle, or
   an acceleration the power caps) and power corner speed; the better form is kept.

5. **Actuator limits** (their own manoeuvres, which feed none of the fits above): the steering
   rate limit from large steering steps at low speed (a one-parameter search on the lateral
   balance with a rate-limited lag), and the power per mass and top speed from a full-throttle
   run (``a_x v_x`` on its power-limited plateau). They reach
   :meth:`IdentificationResult.car_model` (``steer_rate_max``; ``steer_max`` from the data sheet
   via ``identify(steer_max=...)``), and the pedal map's power limit when the map's own data
   never ran out of power or promised more than full throttle gave. A third run brakes from
   speed with the steering held: a car whose small yaw grows by itself (CommonRoad's cars, not
   ours) gets plans that keep the model's lateral dynamics stable, with a margin (1/s) of how
   much faster the car diverged than the model predicted
   (:attr:`IdentificationResult.stability_margin`,
   :attr:`racing_lib.model.CarModel.lateral_stability`).

6. **The grip margin** (circles, steps and the laps, which the tyre and lag fits left out):
   the identified model predicts each sample's lateral acceleration, and 99 % of its errors lie
   within a share of its peak lateral acceleration (:attr:`IdentificationResult.grip_uncertainty`).
   That share is the friction the plans leave unused (:attr:`IdentificationResult.grip_margin`):
   4.6-5.2 % for the simulated car, whose load-sensitive tyres the model does not have (the 5 %
   chosen by hand for its shipped model, :data:`racing_lib.model.GRIP_MARGIN`), and 1.8-5.1 %
   for CommonRoad's three cars, whose tyres are the model's own curve (full manoeuvre set,
   seeds 0-2). A
   noisier car, or a model that fits worse, gets a wider one; so does a short log with a slide
   in it (the BMW's fast set: 8.5-17 %).

A car nobody here wrote. The manoeuvres drive with a watchdog
(:mod:`~racing_lib.experiments.sysid.watch`, :class:`ManoeuvreSettings`): a car that leaves the
steady state its manoeuvre holds (yaw rate off the path's ``v_x kappa``, or body slip beyond a
bound: wheel spin under throttle, locked wheels under a brake, tyres weaker than the data sheet)
gets its throttle lifted and then capped, its brake released and re-applied lighter, a yaw damper
on its steering and, in the circles, a speed that stops rising at the level it could hold.
Nothing changes until a limit is met, and the simulated car meets none in its manoeuvres: its
logs, hence its shipped identification, are bit for bit what they were. A lap that loses the
car anyway is driven again at a lower share of its speed profile (:func:`lap_logs`). CommonRoad's
vehicles 1-3 (:mod:`racing_lib.plants.commonroad`: no drag, no ABS, a 0.4 rad/s steering rate
limit, a governed top speed) are identified with the same settings
(``tests/test_foreign_plant.py``). A car that is lost anyway stops the run with one
:class:`~racing_lib.errors.PlantError` naming the manoeuvre and what to change; data that cannot
determine a parameter raise a :class:`~racing_lib.errors.ModelError` that says which manoeuvre
ran, what it reached, and what to change (or which manoeuvre to add, if it did not run).
:attr:`IdentificationResult.success` and the verdict of :meth:`IdentificationResult.report`
judge each sub-model's R^2.

Derivatives. The commands are held constant over each 0.1 s control period (zero-order hold) and
the plant is integrated finely in between, so the observed states are exact samples of a smooth
trajectory whose derivatives jump at every command change. The *interval* difference
``(v[k+1] - v[k]) / dt`` is then exactly the mean acceleration over the period in which command
``k`` acted, and we pair it with the period's mean state ``(v[k] + v[k+1]) / 2`` (trapezoid, second
order). A central difference or a Savitzky-Golay filter would blend two or more commands into one
derivative, which biases the pedal map and smears steering steps; they are the right choice only for
noisy measurements. The observations of the simulated car carry no measurement noise (its randomness
is in the actuation), so ``derivative="interval"`` is the default and ``derivative="savgol"``
(window 7, quadratic) is offered for noisy logs of other plants. On the same fast-mode data (seed 3)
the interval differences gave ``C_xw`` -0.0 % and ``I_zz`` -2.5 %, Savitzky-Golay -4.0 % and
+13 % (it smears the throttle-to-coast switch and the steering steps).

Data selection. Samples with the car sliding (``|v_y| > 0.1 v_x``) and the first second of each log
(unknown actuator state) are dropped everywhere; the tyre, lag and inertia fits use only the
designed manoeuvres (``circles``, ``steps``) with little longitudinal acceleration
(``|v_x_dot| < 1.5 m/s^2``), because the simulated tyres share their friction between the
longitudinal and lateral forces and laps contain wall contacts the logs cannot flag (the grip
margin's error is measured on the laps too: what the tyre fit did not see). The coast-down
also tests for engine braking at pedal 0 (a deceleration term linear in speed); the simulated car
has none, which the result's ``notes`` report.

Examples
--------
>>> from racing_lib.experiments.sysid import collect_logs, identify
>>> from racing_lib.model import identified_params
>>> from racing_lib.vehicle import VehicleParams
>>> logs = collect_logs(seed=1, fast=True)
>>> result = identify(logs, truth=VehicleParams())
>>> print(result.report())  # doctest: +ELLIPSIS
value            unit    fitted      true        error     from
---...
C_xw             kg/m    ...         0.1302      ...       coast-down
...
>>> all(result.within_tolerance().values())  # every toleranced value close to the truth
True
>>> params = identified_params()   # the shipped fit (seed 0), what later chapters use
>>> params.pedal.m_brk > params.pedal.m_thr > 0
True

Modules: :mod:`~racing_lib.experiments.sysid.manoeuvres` (what is driven, on any plant),
:mod:`~racing_lib.experiments.sysid.watch` (the watchdog and its settings),
:mod:`~racing_lib.experiments.sysid.limits` (the actuator-limit runs and :func:`collect_logs`),
:mod:`~racing_lib.experiments.sysid.samples` (logs to samples),
:mod:`~racing_lib.experiments.sysid.lateral` and :mod:`~racing_lib.experiments.sysid.longitudinal`
(the fits), :mod:`~racing_lib.experiments.sysid.identify` (the whole identification and its
report). Regenerate the shipped fit with ``python -m racing_lib.experiments.sysid``.

Bad input raises :class:`~racing_lib.errors.ModelError` naming the parameter that cannot be
determined and the manoeuvre that would determine it (see :data:`MANOEUVRES`).
"""

from racing_lib.experiments.sysid.identify import (
    TOLERANCES,
    IdentificationResult,
    identify,
    main,
    run,
)
from racing_lib.experiments.sysid.limits import collect_logs, full_throttle_log, steering_rate_log
from racing_lib.experiments.sysid.longitudinal import pedal_map_r2
from racing_lib.experiments.sysid.manoeuvres import (
    MANOEUVRES,
    CarUnderTest,
    braking_logs,
    circle_logs,
    coast_down_log,
    lap_logs,
    simulated_car,
    step_logs,
)
from racing_lib.experiments.sysid.samples import FitStats
from racing_lib.experiments.sysid.watch import LimitEvent, ManoeuvreSettings

__all__ = [
    "MANOEUVRES",
    "CarUnderTest",
    "TOLERANCES",
    "FitStats",
    "IdentificationResult",
    "LimitEvent",
    "ManoeuvreSettings",
    "braking_logs",
    "circle_logs",
    "coast_down_log",
    "collect_logs",
    "full_throttle_log",
    "identify",
    "lap_logs",
    "main",
    "pedal_map_r2",
    "run",
    "simulated_car",
    "step_logs",
    "steering_rate_log",
]
