"""The course's figures, one visual language for every chapter.

Every function takes an optional ``ax`` (or ``axes``), draws, and returns what it drew; none calls
``plt.show()``. Lines are given as anything with ``x`` and ``y`` arrays (a planned
:class:`~racing_lib.planning.trajectory.Trajectory`, a :class:`~racing_lib.experiments.lap.LapLog`)
or as an ``(x, y)`` pair.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from racing_lib.geometry import Track

if TYPE_CHECKING:
    # Only named in annotations: importing the experiments (the ablation package, the laps) loads
    # the controllers, a third of a second that the chapters' figures do not need.
    from matplotlib.animation import FuncAnimation

    from racing_lib.experiments.ablation.rows import TableRow
    from racing_lib.experiments.lap import LapLog


class XYLine(Protocol):
    """Anything with ``x`` and ``y`` arrays, m: a Trajectory, a LapLog, a Path."""

    @property
    def x(self) -> ArrayLike:
        """The points' x coordinates, m."""
        ...

    @property
    def y(self) -> ArrayLike:
        """The points' y coordinates, m."""
        ...


#: A line to draw: an object with ``x`` and ``y`` arrays, or an ``(x, y)`` pair of arrays, m.
Line = XYLine | tuple[ArrayLike, ArrayLike]

#: Colours of the recurring lines, so that "plan" looks the same in every chapter.
COLORS: dict[str, str] = {
    "centerline": "0.55",
    "boundary": "0.15",
    "plan": "tab:blue",
    "closed loop": "tab:orange",
    "best lap": "tab:green",
    "curvature-optimal": "tab:purple",
    "time-optimal": "tab:blue",
}


#: The widest figure that the book shows at its natural size [in]: its text column is about 900 px
#: wide on a desktop screen, and figures are drawn at 100 dpi. A wider figure is shrunk into the
#: column, and its legends with it; ``tests/test_figures.py`` keeps every figure within this.
COLUMN_WIDTH_IN = 9.0

#: The smallest font size [pt] a figure may use, for the same reason.
SMALLEST_FONT_PT = 8.0


def set_style() -> None:
    """The course's matplotlib defaults (sizes readable in a notebook and in the book)."""
    plt.rcParams.update(
        {
            "figure.figsize": (8.0, 4.5),
            "figure.dpi": 100,
            "axes.grid": True,
            "grid.alpha": 0.3,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "legend.frameon": False,
            "font.size": 10,
        }
    )


def _xy(line: Line) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(line, tuple | list) and len(line) == 2:
        return np.asarray(line[0], dtype=float), np.asarray(line[1], dtype=float)
    return np.asarray(line.x, dtype=float), np.asarray(line.y, dtype=float)


def _color(label: str, index: int) -> str:
    return COLORS.get(label, f"C{(index + 3) % 10}")


def track_edges(track: Track, n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """The left and right track edges as closed polylines.

    Returns
    -------
    left, right : ndarray, shape (n + 1, 2)
        Edge points in m; the first point is repeated at the end to close the loop.
    """
    s = np.linspace(0.0, track.length, n, endpoint=False)
    xl, yl, _ = track.centerline.to_cartesian(s, track.width_left(s))
    xr, yr, _ = track.centerline.to_cartesian(s, -track.width_right(s))
    left = np.column_stack([np.append(xl, xl[0]), np.append(yl, yl[0])])
    right = np.column_stack([np.append(xr, xr[0]), np.append(yr, yr[0])])
    return left, right


def plot_track(
    track: Track,
    lines: Mapping[str, Line] | None = None,
    *,
    ax: Axes | None = None,
    centerline: bool = True,
    corners: Mapping[int, float] | None = None,
    start_line: bool = True,
) -> Axes:
    """Draw a track (edges, centerline, start line) and any lines on it.

    Parameters
    ----------
    track : Track
        The track; walls are drawn solid, open edges dashed.
    lines : mapping of label -> Line, optional
        Racing lines to draw (objects with ``x``/``y`` or ``(x, y)`` pairs, m).
    ax : Axes, optional
        Where to draw; a new figure when omitted.
    centerline : bool
        Draw the centerline (thin, grey).
    corners : mapping of number -> s, optional
        Mark these corners (arc length on the centerline, m) with circled numbers.
    start_line : bool
        Draw the start/finish line at s = 0.
    """
    left, right = track_edges(track)
    if ax is None:
        # Size the figure to the track's shape so that a long circuit is not lost in white space.
        both = np.vstack([left, right])
        w, h = np.ptp(both[:, 0]), np.ptp(both[:, 1])
        aspect = float(np.clip(h / max(w, 1e-9), 0.3, 1.5))
        _, ax = plt.subplots(figsize=(9.0, max(3.0, 9.0 * aspect)))
    style = "-" if track.boundary == "walls" else "--"
    for edge in (left, right):
        ax.plot(edge[:, 0], edge[:, 1], style, color=COLORS["boundary"], lw=1.0)
    if centerline:
        cx, cy = track.centerline.position(np.linspace(0, track.length, 2000))
        ax.plot(cx, cy, ":", color=COLORS["centerline"], lw=0.8, label="centerline")
    for i, (label, line) in enumerate((lines or {}).items()):
        x, y = _xy(line)
        ax.plot(x, y, color=_color(label, i), lw=1.4, label=label)
    if start_line:
        x0, y0, _ = track.centerline.to_cartesian(
            np.array([0.0, 0.0]), np.array([track.width_left(0.0), -track.width_right(0.0)])
        )
        ax.plot(x0, y0, color="crimson", lw=2.5, label="start/finish")
    if corners:
        for number, s_c in corners.items():
            xc, yc, _ = track.centerline.to_cartesian(s_c, 2.5 * track.width_left(s_c))
            ax.annotate(
                str(number),
                (float(xc), float(yc)),
                ha="center",
                va="center",
                fontsize=9,
                bbox={"boxstyle": "circle", "fc": "white", "ec": "0.2"},
            )
    ax.set_aspect("equal")
    ax.set_xlabel("$x$ [m]")
    ax.set_ylabel("$y$ [m]")
    ax.legend(loc="best", fontsize=8)
    return ax


def plot_corners(
    track: Track,
    corners: Mapping[int, float],
    lines: Mapping[str, Line] | None = None,
    *,
    half_width: float = 90.0,
    axes: Sequence[Axes] | None = None,
) -> tuple[Figure, Sequence[Axes]]:
    """Zoom on corners: one panel per corner, centred on it, with the same lines as the overview.

    Parameters
    ----------
    track : Track
        The track.
    corners : mapping of number -> s
        Corner numbers and their arc length on the centerline, m.
    lines : mapping of label -> Line, optional
        Lines to draw in every panel.
    half_width : float
        Half the side of each square panel, m.
    axes : sequence of Axes, optional
        One per corner; a new figure with a row-major grid when omitted.
    """
    n = len(corners)
    if axes is None:
        cols = min(n, 3)
        rows = int(np.ceil(n / cols))
        fig, grid = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), squeeze=False)
        axes = list(grid.ravel())
        for extra in axes[n:]:
            extra.set_visible(False)
    fig = axes[0].figure
    for k, (ax, (number, s_c)) in enumerate(zip(axes, corners.items(), strict=False)):
        plot_track(track, lines, ax=ax, start_line=False)
        xc, yc = track.centerline.position(s_c)
        ax.set_xlim(float(xc) - half_width, float(xc) + half_width)
        ax.set_ylim(float(yc) - half_width, float(yc) + half_width)
        ax.set_title(f"corner {number}")
        if ax.get_legend() is not None:
            ax.get_legend().remove()
        # Metres on every panel, named once per row and column of the grid.
        grid_spec = ax.get_subplotspec()
        first_col = grid_spec is None or grid_spec.is_first_col()
        last_row = grid_spec is None or grid_spec.is_last_row() or k + 3 >= n
        ax.set_ylabel("$y$ [m]" if first_col else "")
        ax.set_xlabel("$x$ [m]" if last_row else "")
    if lines:
        # One legend for the grid, below it: which line is which in every panel.
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8)
        fig.tight_layout(rect=(0.0, 0.06, 1.0, 1.0))
    else:
        fig.tight_layout()
    return fig, axes


def plot_profiles(
    s: Mapping[str, np.ndarray] | np.ndarray,
    values: Mapping[str, np.ndarray],
    *,
    ax: Axes | None = None,
    ylabel: str = "",
    corners: Mapping[int, float] | None = None,
) -> Axes:
    """Quantities over the arc length s (curvature, speed, steering ...).

    Parameters
    ----------
    s : array or mapping of label -> array
        Arc length, m: one array shared by all lines, or one per label.
    values : mapping of label -> array
        The lines to draw.
    ax : Axes, optional
        Where to draw.
    ylabel : str
        Axis label with its unit.
    corners : mapping of number -> s, optional
        Mark corners with vertical lines.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(9, 3))
    for i, (label, v) in enumerate(values.items()):
        si = s[label] if isinstance(s, Mapping) else s
        ax.plot(si, v, color=_color(label, i), lw=1.2, label=label)
    if corners:
        for number, s_c in corners.items():
            ax.axvline(s_c, color="0.7", lw=0.8, zorder=0)
            ax.annotate(
                str(number),
                (s_c, 1.0),
                xycoords=("data", "axes fraction"),
                ha="center",
                va="bottom",
                fontsize=8,
            )
    ax.set_xlabel("$s$ [m]")
    ax.set_ylabel(ylabel)
    ax.legend(loc="best", fontsize=8)
    return ax


def plot_row_speeds(
    ax: Axes,
    row: TableRow,
    title: str,
    base: TableRow | None = None,
    corners: dict[int, float] | None = None,
) -> Axes:
    """v_x over s of one ablation row: its plan and its closed loop, the base row's plan in grey.

    Parameters
    ----------
    ax : matplotlib Axes
        Where to draw.
    row, base : TableRow
        Rows of the ablation table (their ``profile``); ``base`` is drawn as a grey reference.
    title : str
        Title of the panel.
    corners : dict, optional
        Corner number -> arc length, m, marked along the axis.
    """
    # Here, not at the top: the ablation package loads the experiments and the controllers, a
    # third of a second that the chapters' other figures do not need.
    from racing_lib.experiments.ablation.paper import row_profile

    s = np.asarray(row["profile"]["s_m"], dtype=float)
    if base is not None:
        ax.plot(s, row_profile(base, "plan", "vx_mps"), color="0.6", lw=0.9, label="main plan")
    plot_profiles(
        s,
        {
            "plan": row_profile(row, "plan", "vx_mps"),
            "closed loop": row_profile(row, "closed_loop", "vx_mps"),
        },
        ax=ax,
        ylabel=r"$v_x$ [m/s]",
        corners=corners,
    )
    ax.set_title(title, fontsize=10, pad=14)
    ax.set_xlabel("")
    return ax


def plot_lap_times(
    rows: Sequence[TableRow], ax: Axes | None = None, best: float | None = None
) -> Axes:
    """The closed-loop lap times of ablation rows, trial by trial, against each row's plan.

    Our stand-in for the paper's Fig. 5 (the distribution of human lap times with the plan's and
    the closed loop's best marked): one line per row, a dot per seeded trial, a bar at the planned
    lap, and optionally a vertical line at the best possible lap.

    Parameters
    ----------
    rows : sequence of TableRow
        Rows of the ablation table (``name``, ``planned_lap_time_s``, ``trial_metrics``).
    ax : Axes, optional
        Where to draw; a new figure when omitted.
    best : float, optional
        Lap time of the best possible lap, s, drawn as a vertical line.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(8.0, 0.45 * len(rows) + 1.2))
    for i, row in enumerate(rows):
        times = [t["lap_time_s"] for t in row["trial_metrics"] if t.get("completed")]
        jitter = 0.12 * np.sin(np.arange(len(times)) * 2.4)  # spread the dots, deterministically
        walls = [t.get("wall_contacts", 0) for t in row["trial_metrics"] if t.get("completed")]
        colors = [COLORS["closed loop"] if w == 0 else "crimson" for w in walls]
        ax.scatter(times, i + jitter, s=14, c=colors, zorder=3)
        ax.plot([row["planned_lap_time_s"]] * 2, [i - 0.3, i + 0.3], color=COLORS["plan"], lw=2.0)
    if best is not None:
        ax.axvline(best, color=COLORS["best lap"], lw=1.2, ls="--")
    ax.set_yticks(range(len(rows)), [row["name"] for row in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("lap time [s]")
    handles = [
        plt.Line2D([], [], color=COLORS["plan"], lw=2.0, label="planned lap"),
        plt.Line2D([], [], color=COLORS["closed loop"], marker="o", ls="", label="trial, clean"),
        plt.Line2D([], [], color="crimson", marker="o", ls="", label="trial, wall contact"),
    ]
    if best is not None:
        handles.append(plt.Line2D([], [], color=COLORS["best lap"], ls="--", label="best lap"))
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return ax


def lap_animation(
    track: Track,
    log: LapLog,
    *,
    frames: int = 60,
    trail: float = 8.0,
    plan: Line | None = None,
    size: tuple[float, float] = (5.5, 4.0),
) -> FuncAnimation:
    """A short animation of a logged lap on its track: the car, its recent path, its speed.

    Kept small for a notebook and the book: ``frames`` frames spread evenly over the lap, a
    figure of ``size`` inches at 72 dpi. Show it with ``IPython.display.HTML(anim.to_jshtml())``.

    Parameters
    ----------
    track : Track
        The track the lap was driven on.
    log : LapLog
        The lap (``t``, ``x``, ``y``, ``vx``, ``in_lap``).
    frames : int
        Number of frames.
    trail : float
        Length of the trail drawn behind the car, s.
    plan : Line, optional
        The planned line, drawn thin beneath.
    size : (float, float)
        Figure size, inches.

    Returns
    -------
    matplotlib.animation.FuncAnimation
    """
    from matplotlib.animation import FuncAnimation  # 7 ms, for the one function that animates

    t, x, y, vx = (np.asarray(getattr(log, k), dtype=float) for k in ("t", "x", "y", "vx"))
    lap = np.flatnonzero(np.asarray(log.in_lap))
    first, last = (int(lap[0]), int(lap[-1])) if lap.size else (0, t.size - 1)
    picks = np.linspace(first, last, frames).round().astype(int)
    steps_back = int(round(trail / max(float(np.median(np.diff(t))), 1e-9)))
    fig, ax = plt.subplots(figsize=size, dpi=72)
    plot_track(track, {"plan": plan} if plan is not None else None, ax=ax, start_line=True)
    ax.get_legend().remove()
    (path,) = ax.plot([], [], color=COLORS["closed loop"], lw=2.0)
    (car,) = ax.plot([], [], "o", color="crimson", ms=6)
    label = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9,
                    bbox={"fc": "white", "ec": "0.7"})  # fmt: skip
    fig.tight_layout()

    def draw(k: int) -> tuple[Any, ...]:
        i = picks[k]
        j = max(first, i - steps_back)
        path.set_data(x[j : i + 1], y[j : i + 1])
        car.set_data([x[i]], [y[i]])
        label.set_text(f"t = {t[i] - t[first]:5.1f} s   v = {3.6 * vx[i]:4.0f} km/h")
        return path, car, label

    anim = FuncAnimation(fig, draw, frames=frames, interval=120, blit=True)
    plt.close(fig)  # shown through the animation's HTML, not as a still
    return anim


#: The paper's gap between its closed loop and the best human lap, % (its Table II).
PAPER_GAP_PCT = 1.41


def plot_correction_along_lap(
    s: np.ndarray,
    measured: np.ndarray,
    mean: np.ndarray,
    std: np.ndarray,
    axes: Sequence[Axes] | None = None,
) -> Sequence[Axes]:
    """Residual accelerations of a lap against a learned correction's mean and +-2 std.

    Parameters
    ----------
    s : ndarray (N,)
        Arc length of each sample, m.
    measured, mean, std : ndarray (N, 3)
        The measured residuals of ``(v_x, v_y, r)`` and the correction's mean and standard
        deviation there (m/s^2, m/s^2, rad/s^2), e.g. from
        :func:`racing_lib.model.residuals.residual_samples` and
        :class:`racing_lib.model.ModelCorrection`.
    axes : two Axes, optional
        Where to draw the yaw rate's and the lateral speed's residuals; a new figure when omitted.
    """
    if axes is None:
        _, axes = plt.subplots(2, 1, figsize=(9.0, 5.5), sharex=True)
    order = np.argsort(s)
    x = np.asarray(s)[order]
    labels = {2: "r residual (rad/s$^2$)", 1: "$v_y$ residual (m/s$^2$)"}
    for ax, j in zip(axes, (2, 1), strict=True):
        m, sd = mean[order, j], std[order, j]
        ax.plot(x, measured[order, j], ".", ms=2, color="0.5", label="measured")
        ax.plot(x, m, lw=1.2, color=COLORS["plan"], label="learned mean")
        ax.fill_between(x, m - 2 * sd, m + 2 * sd, alpha=0.3, color=COLORS["plan"],
                        label="mean $\\pm$ 2 sd")  # fmt: skip
        ax.set_ylabel(labels[j])
    axes[0].legend(loc="upper right", ncol=3, fontsize=8)
    axes[-1].set_xlabel("s along the centerline (m)")
    return axes


def plot_learning(
    iterations: Sequence[Mapping[str, Any]], best_lap: float, ax: Axes | None = None
) -> Axes:
    """Planned and driven lap times over the iterations of a learning run.

    Parameters
    ----------
    iterations : sequence of dict
        The ``iterations`` of :meth:`racing_lib.experiments.learning.LearningRun.to_dict`.
    best_lap : float
        The best possible lap, s, drawn with the paper's gap (+1.41 %) and the +1.0 % goal.
    ax : Axes, optional
        Where to draw; a new figure when omitted. An iteration that was not clean (wall contacts,
        time off the track, a lap not completed) is marked by a cross at the top of the chart.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(8.0, 4.0))
    top = best_lap * 1.035
    clean = [
        it
        for it in iterations
        if it["walls"] == 0 and it["offtrack_s"] == 0 and it["completed"] == it["laps"]
    ]
    unclean = [it for it in iterations if it not in clean]
    k_all = [it["iteration"] for it in iterations]
    ax.plot(k_all, [it["planned_lap_s"] for it in iterations], "s--", color=COLORS["plan"],
            label="planned")  # fmt: skip
    ax.plot([it["iteration"] for it in clean], [it["driven_lap_s"] for it in clean], "o-",
            color=COLORS["closed loop"], label="driven, clean (mean of the seeds)")  # fmt: skip
    ax.plot([it["iteration"] for it in unclean], [top - 0.1] * len(unclean), "x",
            color="crimson", ms=9, label="driven, not clean (off the chart)")  # fmt: skip
    ax.axhline(best_lap, color="k", lw=1, label="best possible lap")
    ax.axhline(best_lap * (1 + PAPER_GAP_PCT / 100), color="crimson", lw=1, ls=":",
               label=f"+{PAPER_GAP_PCT} % (the paper's gap to the human best)")  # fmt: skip
    ax.axhline(best_lap * 1.01, color=COLORS["best lap"], lw=1, ls="-.", label="+1.0 %")
    ax.set_ylim(best_lap - 0.5, top)
    ax.set_xlabel("iteration")
    ax.set_ylabel("lap time (s)")
    ax.legend(loc="upper right", fontsize=8)
    return ax
