"""The paper's Table I and Table II on the simulated car: rows, runner, cache, table (chapter 07).

Every row of the paper's experiments is one configuration of the pipeline, planned once and then
driven for N seeded closed-loop laps (ten, as in the paper):

* Table I, the expressway (walled): the configurations of
  :data:`racing_lib.experiments.configs.TUNING_CONFIGS`, that is ``main`` (time-optimal plan, drag
  and longitudinal weight transfer, coupled MPC, smooth reference transition) and the ablations that
  remove or add one element (``no-drag``, ``no-longitudinal-weight-transfer``,
  ``lateral-weight-transfer``, ``curvature-plan``, ``decoupled``, ``no-smooth-transition``);
* Table I, the sharper open track ``shortcut``: ``shortcut-main`` and
  ``shortcut-lateral-weight-transfer``;
* Table II: ``best-lap``, the coupled MPC (with the ``main`` weights) tracking the best possible
  lap of the expressway (:mod:`racing_lib.planning.best_lap`), our stand-in for the paper's
  human-best recording.

Each row uses the MPC weights tuned for its configuration
(:func:`racing_lib.experiments.configs.tuned_weights`), or the MPC's defaults when none are shipped;
the row records which.

Results are cached in a folder (default ``runs/ablation``): one JSON file per finished row and one
plan CSV per plan, each named by a hash of everything that determines it (track geometry,
configuration, controller, model options and parameters, weights, seeds, fast mode, and the
source code of the modules involved). A rerun reuses every row whose hash matches and recomputes
the others; an interrupted run keeps every row it finished (writes are atomic).

The table of the full run is shipped with the package (:func:`shipped_table`), so that notebook
07 loads it in seconds; :func:`generate_ablation_table` recomputes it.

For the figures, each row keeps a ``profile`` of its first seed's lap and of its plan, sampled every
:data:`~racing_lib.experiments.ablation.profiles.PROFILE_SPACING` m of the track centerline
(``s_m``, the same grid for every row of a track, so rows can be overlaid); values are None where
the car never got (a lap that stopped):

* ``profile["plan"]``: ``vx_mps`` (planned v_x), ``kappa_radpm`` (curvature of the planned line,
  1/m), ``delta_rad`` (planned steering angle), ``n_m`` (offset of the line from the centerline,
  m, left positive: ``track.centerline.to_cartesian(s_m, n_m)`` draws it);
* ``profile["closed_loop"]``: ``vx_mps``, ``steer_rad`` (steering command), ``kappa_radpm``
  (path curvature r / v_x), ``ey_m`` (lateral error to the plan), ``n_m`` (offset from the
  centerline).

Modules: :mod:`~racing_lib.experiments.ablation.rows` (the rows),
:mod:`~racing_lib.experiments.ablation.keys` (cache keys),
:mod:`~racing_lib.experiments.ablation.runner` (plans, laps, the cache),
:mod:`~racing_lib.experiments.ablation.profiles` (what the figures draw),
:mod:`~racing_lib.experiments.ablation.table` (the tables, shipped and stale rows),
:mod:`~racing_lib.experiments.ablation.check` (a recomputed row against the shipped one),
:mod:`~racing_lib.experiments.ablation.verify` (whether the shipped numbers are still the code's,
by one recomputed lap per row, and the restamping of their keys after a refactor) and
:mod:`~racing_lib.experiments.ablation.paper` (the paper's own numbers, and the measures compared
with them).

Examples
--------
The shipped table, as the paper prints it:

>>> from racing_lib.experiments.ablation import format_table, shipped_table
>>> print(format_table(shipped_table()))  # doctest: +ELLIPSIS
row  planned lap [s]  closed-loop lap [s]  v_x MAE [m/s]  e_y MAE [m]  wall contacts  completed
---...
main ...
no-drag ...
...
best-lap ...

Two rows, two trials each, on two worker processes (minutes, so skipped by the tests):

>>> rows = run_ablation(["main", "decoupled"], trials=2, workers=2)  # doctest: +SKIP
"""

from racing_lib.experiments.ablation.rows import (
    DEFAULT_TRIALS,
    FAST_TRIALS,
    AblationRow,
    ablation_rows,
    default_trials,
    select_rows,
)
from racing_lib.experiments.ablation.runner import (
    DEFAULT_OUT,
    run_ablation,
)
from racing_lib.experiments.ablation.table import (
    SHIPPED_TABLE_FILE,
    format_table,
    generate_ablation_table,
    load_table,
    shipped_table,
    shipped_table_header,
    stale_rows,
    table_records,
)
from racing_lib.experiments.ablation.verify import RowCheck, probe, restamp_table, verify_table

__all__ = [
    "DEFAULT_OUT",
    "DEFAULT_TRIALS",
    "FAST_TRIALS",
    "SHIPPED_TABLE_FILE",
    "AblationRow",
    "RowCheck",
    "ablation_rows",
    "default_trials",
    "format_table",
    "generate_ablation_table",
    "load_table",
    "probe",
    "restamp_table",
    "run_ablation",
    "select_rows",
    "shipped_table",
    "shipped_table_header",
    "stale_rows",
    "table_records",
    "verify_table",
]
