"""The course's diagrams: the car in the Frenet frame, and the planning and control pipeline.

Drawn with matplotlib from a few named coordinates, so that they render the same in JupyterLab and
in the book and need no image files. Each function takes an optional ``ax``, draws and returns it.

* :func:`draw_frenet_frame`: the car, its reference line and the quantities of the model (paper,
  Fig. 2): arc length s, lateral error e_y, heading error e_psi, the body velocities v_x, v_y, the
  steering angle delta and the distances l_f, l_r.
* :func:`draw_pipeline`: the two-stage planner, the MPC, the car and the tuner (paper, Fig. 3 and
  Fig. 1).
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch, Polygon

__all__ = ["draw_frenet_frame", "draw_pipeline"]


def _arrow(ax: Axes, start, end, color: str = "k", style: str = "-|>", lw: float = 1.3, **kw):
    ax.add_patch(
        FancyArrowPatch(start, end, arrowstyle=style, mutation_scale=12, color=color, lw=lw, **kw)
    )


def _box(ax: Axes, center, width: float, height: float, color: str, angle: float = 0.0):
    """A rectangle of ``width`` x ``height`` centred at ``center``, turned by ``angle`` (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    corners = [(-width / 2, -height / 2), (width / 2, -height / 2), (width / 2, height / 2),
               (-width / 2, height / 2)]  # fmt: skip
    pts = [(center[0] + c * x - s * y, center[1] + s * x + c * y) for x, y in corners]
    ax.add_patch(Polygon(pts, closed=True, facecolor=color, edgecolor="k", lw=1.0, zorder=3))


def draw_frenet_frame(ax: Axes | None = None) -> Axes:
    """The car relative to its reference line, with the model's symbols (schematic, not to scale).

    Parameters
    ----------
    ax : matplotlib Axes, optional
        Where to draw (default: a new 7 x 4.6 inch figure).

    Returns
    -------
    Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(7.0, 4.6))
    # A reference line bending left: an arc of radius 14 around (0, 14), from below the car.
    radius, centre = 14.0, np.array([0.0, 14.0])
    a = np.linspace(-math.pi / 2 - 0.55, -math.pi / 2 + 0.75, 200)
    line = centre + radius * np.column_stack([np.cos(a), np.sin(a)])
    ax.plot(line[:, 0], line[:, 1], color="0.45", lw=2.0, zorder=1)
    ax.annotate("reference line", line[-1], xytext=(-5, 4), textcoords="offset points",
                ha="right", color="0.35")  # fmt: skip
    # The foot point of the car on the line, its tangent and normal.
    a0 = -math.pi / 2 + 0.1
    foot = centre + radius * np.array([math.cos(a0), math.sin(a0)])
    psi_ref = a0 + math.pi / 2
    tangent = np.array([math.cos(psi_ref), math.sin(psi_ref)])
    normal = np.array([-tangent[1], tangent[0]])
    e_y, e_psi = 3.6, 0.35
    car = foot + e_y * normal
    psi = psi_ref + e_psi
    heading = np.array([math.cos(psi), math.sin(psi)])
    left = np.array([-heading[1], heading[0]])
    ax.plot(*foot, "o", color="0.3", zorder=4)
    ax.annotate("$s$", foot, xytext=(6, -14), textcoords="offset points", fontsize=13)
    _arrow(ax, foot, foot + 3.2 * tangent, color="0.3")
    ax.annotate(r"$\psi_\mathrm{ref}(s)$", foot + 3.2 * tangent, xytext=(4, -12),
                textcoords="offset points", color="0.3")  # fmt: skip
    # e_y along the normal, from the line to the car's centre of gravity.
    _arrow(ax, foot, car, color="tab:red", style="<|-|>")
    ax.annotate("$e_y$", foot + 0.35 * (car - foot), xytext=(-24, 0), textcoords="offset points",
                color="tab:red", fontsize=13)  # fmt: skip
    # The car: body, axles, front wheel steered by delta.
    l_f, l_r, delta = 1.3, 1.1, 0.3
    _box(ax, car + 0.1 * heading, 3.3, 1.4, "#dbe8f6", psi)
    front, rear = car + l_f * heading, car - l_r * heading
    _box(ax, front, 0.75, 0.26, "0.25", psi + delta)
    _box(ax, rear, 0.75, 0.26, "0.25", psi)
    ax.plot(*car, "ko", ms=5, zorder=5)
    ax.plot(*np.column_stack([rear, front]), color="k", lw=0.8, zorder=4)
    ax.annotate("$l_f$", (car + front) / 2, xytext=(-4, 6), textcoords="offset points")
    ax.annotate("$l_r$", (car + rear) / 2, xytext=(-4, 6), textcoords="offset points")
    # Heading error: the reference direction at the car, and the car's axis.
    _arrow(ax, car, car + 3.6 * tangent, color="0.55", style="-", lw=1.0, linestyle="--")
    arc = np.linspace(psi_ref, psi, 30)
    ax.plot(car[0] + 3.0 * np.cos(arc), car[1] + 3.0 * np.sin(arc), color="tab:purple", lw=1.2)
    ax.annotate(r"$e_\psi$", car + 3.1 * np.array([math.cos(psi_ref + e_psi / 2),
                math.sin(psi_ref + e_psi / 2)]), xytext=(4, -2), textcoords="offset points",
                color="tab:purple", fontsize=13)  # fmt: skip
    # Body velocities and the yaw rate.
    _arrow(ax, car, car + 4.6 * heading, color="tab:blue")
    ax.annotate("$v_x$", car + 4.6 * heading, xytext=(4, 0), textcoords="offset points",
                color="tab:blue", fontsize=13)  # fmt: skip
    _arrow(ax, car, car + 1.6 * left, color="tab:blue")
    ax.annotate("$v_y$", car + 1.6 * left, xytext=(-18, 2), textcoords="offset points",
                color="tab:blue", fontsize=13)  # fmt: skip
    spin = np.linspace(psi + 2.2, psi + 4.0, 30)
    ax.plot(car[0] + 0.8 * np.cos(spin), car[1] + 0.8 * np.sin(spin), color="tab:green", lw=1.2)
    tip = [car + 0.8 * np.array([math.cos(t), math.sin(t)]) for t in spin[-2:]]
    _arrow(ax, tip[0], tip[1], color="tab:green")
    r_label = car + 0.8 * np.array([math.cos(spin[0]), math.sin(spin[0])])
    ax.annotate("$r$", r_label, xytext=(-12, 2), textcoords="offset points", color="tab:green",
                fontsize=13)  # fmt: skip
    # Steering angle at the front wheel.
    wheel_dir = np.array([math.cos(psi + delta), math.sin(psi + delta)])
    ax.plot(*np.column_stack([front, front + 1.5 * heading]), color="0.5", lw=0.8, ls=":")
    ax.plot(*np.column_stack([front, front + 1.5 * wheel_dir]), color="tab:orange", lw=1.2)
    ax.annotate(r"$\delta$", front + 1.5 * wheel_dir, xytext=(2, 2), textcoords="offset points",
                color="tab:orange", fontsize=13)  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlim(foot[0] - 8.0, foot[0] + 9.0)
    ax.set_ylim(foot[1] - 2.0, foot[1] + 7.5)
    ax.axis("off")
    return ax


#: The pipeline's boxes: name -> (x, y) of the centre, label, colour.
_STAGES: dict[str, tuple[tuple[float, float], str, str]] = {
    "track": ((0.95, 3.0), "track\n(centerline,\nwidths, grade)", "#eeeeee"),
    "model": ((0.95, 1.2), "vehicle model\n(identified\nfrom data, ch. 02)", "#eeeeee"),
    "qp": ((3.6, 3.0), "curvature QP,\niterated (ch. 03)", "#dbe8f6"),
    "nlp": ((6.25, 3.0), "time-optimal\nNLP (ch. 04)", "#dbe8f6"),
    "mpc": ((6.25, 1.2), "coupled MPC,\nQP per period\n(ch. 05)", "#fde2c8"),
    "car": ((9.3, 1.2), "simulated car\n(double track,\ngears, walls)", "#e3f1dd"),
    "cma": ((9.3, 3.0), "CMA-ES tuning\nof the MPC\nweights (ch. 06)", "#f0e0f4"),
}


def draw_pipeline(ax: Axes | None = None) -> Axes:
    """The planning and control pipeline of the course (the paper's Fig. 3 with Fig. 1's loop).

    Offline: the track and the identified model feed the curvature QP, whose line can warm-start
    the time-optimal NLP (dashed: the paper's order, optional in ``racing_lib``, which starts the
    NLP cold by default; chapter 04 measures both). Online: the coupled MPC tracks the plan and
    drives the car, whose state it measures every period. CMA-ES tunes the MPC's weights from the
    scores of whole laps.

    Parameters
    ----------
    ax : matplotlib Axes, optional
        Where to draw (default: a new 9 x 4 inch figure).

    Returns
    -------
    Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(9.0, 4.0))
    w, h = 1.85, 1.15
    for (x, y), label, color in _STAGES.values():
        ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h, boxstyle="round,pad=0.04",
                                    facecolor=color, edgecolor="0.3", lw=1.0))  # fmt: skip
        ax.text(x, y, label, ha="center", va="center", fontsize=9)

    def edge(a: str, b: str, text: str = "", dy: float = 0.0, rad: float = 0.0,
             linestyle: str = "-", below: str = "") -> None:  # fmt: skip
        """An arrow from box ``a`` to box ``b``, ``text`` above its middle, ``below`` under it."""
        (xa, ya), (xb, yb) = _STAGES[a][0], _STAGES[b][0]
        sx = w / 2 if xb > xa else (-w / 2 if xb < xa else 0.0)
        sy = h / 2 if yb > ya else (-h / 2 if yb < ya else 0.0)
        start = (xa + (sx if sx else 0.0), ya + dy + (sy if not sx else 0.0))
        end = (xb - (sx if sx else 0.0), yb + dy - (sy if not sx else 0.0))
        _arrow(ax, start, end, connectionstyle=f"arc3,rad={rad}", linestyle=linestyle)
        mid = ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2)
        if text:
            ax.text(mid[0], mid[1] + 0.12, text, ha="center", va="bottom", fontsize=8, color="0.25")
        if below:
            ax.text(mid[0], mid[1] - 0.12, below, ha="center", va="top", fontsize=8, color="0.25")

    edge("track", "qp", "grid")
    edge("model", "qp")
    edge("qp", "nlp", "warm\nstart", linestyle="--", below="optional")
    edge("model", "mpc", "same model", dy=-0.25)
    edge("nlp", "mpc", "")
    ax.text(6.35, 2.1, "plan", fontsize=8, color="0.25")
    edge("mpc", "car", "steer, pedal", dy=0.2)
    edge("car", "mpc", "state", dy=-0.25)
    edge("car", "cma", "")
    ax.text(9.4, 2.1, "lap score $J$", fontsize=8, color="0.25")
    edge("cma", "mpc", "", rad=0.25)
    ax.text(7.55, 2.45, "weights", fontsize=8, color="0.25", rotation=30)
    ax.text(3.6, 4.0, "offline: plan once per track", ha="center", fontsize=9, style="italic")
    ax.text(7.8, 0.15, "online: every 0.1 s", ha="center", fontsize=9, style="italic")
    ax.set_xlim(-0.1, 10.4)
    ax.set_ylim(0.0, 4.3)
    ax.set_aspect("equal")
    ax.axis("off")
    return ax
