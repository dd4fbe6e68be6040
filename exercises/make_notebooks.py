"""Write the exercise notebooks and their solutions from one source (this file).

Usage (from the repository root)::

    python exercises/make_notebooks.py          # writes exercises/NN_*.ipynb and solutions/
    python tools/refresh_notebooks.py exercises/*.ipynb exercises/solutions/*.ipynb

A template and its solution differ only in the body of the functions the reader writes, so both
are generated from the same cells here and cannot drift apart (``tests/test_exercises.py`` checks
that the committed notebooks are what this script writes). The checks themselves live in the
package, ``racing_lib.grading.chNN``; they compare the reader's function with the library.
Check cells carry ``# NBVAL_CHECK_OUTPUT``: nbval then verifies that every template still says
"not done yet" and every solution says "correct".

Adding an exercise: add an entry to a chapter's ``exercises`` list below (markdown, the template
body, the solution body, the check call), write its check in ``racing_lib/grading/chNN.py``
with a test of a plausible wrong answer in ``tests/test_exercises.py``, then run the two commands
above.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

HERE = Path(__file__).resolve().parent
CHECK_MARK = "# NBVAL_CHECK_OUTPUT"
TODO = "    # YOUR CODE HERE\n    raise NotImplementedError"


@dataclass
class Exercise:
    """One exercise: the explanation, the function header, its solution body, the check call."""

    markdown: str
    header: str  # def line and docstring of the reader's function
    solution: str  # the function body (indented by four spaces)
    check: str  # the call of the check, e.g. "check_frenet_projection(frenet_projection)"
    after: str = ""  # optional code cell after the check (uses the reader's function)
    template: str = ""  # the template's body when it gives a start (default: TODO only)


@dataclass
class Chapter:
    name: str  # file name without .ipynb
    title: str
    intro: str
    imports: str
    exercises: list[Exercise] = field(default_factory=list)
    outro: str = ""


SETUP = "rng = racing_lib.face.notebook.setup(seed=0)"

# --------------------------------------------------------------------------------------------------
# Chapter 01

CH01 = Chapter(
    name="01_frenet",
    title="Exercises 01 · The Frenet frame",
    intro="""Chapter 01 described the car's position relative to the road by the Frenet coordinates
$(s, e_y, e_\\psi)$. Here you write the two maps between Cartesian and Frenet coordinates and the
kinematic equations yourself. Each exercise gives a function to complete: replace
`raise NotImplementedError` by your code and run the check below it. A check compares your function
with `racing_lib` on several cases and tells you, in metres and seconds, what differs.

Allowed tools: `numpy`, `scipy`, and the *evaluation* methods of a `racing_lib.geometry.Path`:
`path.position(s)`, `path.heading(s)`, `path.curvature(s)`, `path.sample(ds=...)`, `path.length`
(not `to_frenet` or `to_cartesian`: those are what you are rebuilding).""",
    imports="""import math

import numpy as np
from scipy.optimize import minimize_scalar

import racing_lib.face.notebook
from racing_lib.grading.ch01 import (
    check_frenet_projection,
    check_frenet_rates,
    check_frenet_to_cartesian,
)""",
    exercises=[
        Exercise(
            markdown="""## Exercise 1.1 · Projecting a point on the track

The Frenet arc length $s$ of a point $\\mathbf{p} = (x, y)$ is that of the closest point of the
reference curve,
$$s^\\star = \\arg\\min_s \\lVert \\mathbf{p} - \\mathbf{r}(s) \\rVert^2 ,$$
and $e_y$ is the signed distance to it, positive to the left:
$e_y = (\\mathbf{p} - \\mathbf{r}(s^\\star)) \\cdot \\mathbf{n}(s^\\star)$ with the left normal
$\\mathbf{n} = (-\\sin\\psi, \\cos\\psi)$.

The minimisation has many local minima on a closed track (every bend that comes near the point), so
search the whole lap coarsely first (samples every metre or so), then refine near the best sample.
Return $s$ in $[0, L)$.""",
            header='''def frenet_projection(path, x, y):
    """Frenet coordinates (s, e_y) of the point (x, y), all in m.

    s is the arc length of the closest point of `path`, in [0, path.length); e_y the signed
    distance to it, positive to the left of the direction of travel.
    """''',
            solution="""    # Global search: the nearest of samples one metre apart (avoids the wrong bend).
    s_samples = path.sample(ds=1.0)
    px, py = path.position(s_samples)
    k = int(np.argmin((px - x) ** 2 + (py - y) ** 2))

    # Local refinement: the distance is smooth near the answer; minimise it within one sample.
    def dist2(s):
        cx, cy = path.position(s % path.length)
        return (cx - x) ** 2 + (cy - y) ** 2

    s0 = s_samples[k]
    res = minimize_scalar(
        dist2, bounds=(s0 - 1.0, s0 + 1.0), method="bounded", options={"xatol": 1e-9}
    )
    s = res.x % path.length
    cx, cy = path.position(s)
    psi = path.heading(s)
    e_y = -(x - cx) * math.sin(psi) + (y - cy) * math.cos(psi)  # (p - r) . n
    return s, e_y""",
            check="check_frenet_projection(frenet_projection)",
        ),
        Exercise(
            markdown="""## Exercise 1.2 · Back to Cartesian coordinates

The inverse map needs no search: a point at arc length $s$ and lateral offset $e_y$ is
$$\\mathbf{p} = \\mathbf{r}(s) + e_y\\,\\mathbf{n}(s), \\qquad
\\mathbf{n}(s) = (-\\sin\\psi(s), \\cos\\psi(s)).$$""",
            header='''def frenet_to_cartesian(path, s, e_y):
    """Cartesian position (x, y), m, of the point at arc length s and lateral offset e_y (m)."""''',
            solution="""    cx, cy = path.position(s)
    psi = path.heading(s)
    return cx - e_y * math.sin(psi), cy + e_y * math.cos(psi)""",
            check="check_frenet_to_cartesian(frenet_to_cartesian)",
        ),
        Exercise(
            markdown="""## Exercise 1.3 · The kinematic equations

Write Eq. (2)-(4) of the paper: how fast the Frenet coordinates change for a car with body-frame
velocities $v_x$, $v_y$ and yaw rate $r$, at heading error $e_\\psi$ and offset $e_y$ from a
reference of curvature $\\kappa$:
$$\\dot{s} = \\frac{v_x\\cos e_\\psi - v_y \\sin e_\\psi}{1 - \\kappa\\,e_y},\\qquad
\\dot{e}_y = v_x \\sin e_\\psi + v_y \\cos e_\\psi,\\qquad
\\dot{e}_\\psi = r - \\kappa\\,\\dot{s}.$$
Think about the factor $1/(1 - \\kappa e_y)$ before you run the check: on the inside of a left bend
($\\kappa > 0$, $e_y > 0$) does the car's projection move faster or slower than the car?""",
            header='''def frenet_rates(v_x, v_y, r, e_psi, e_y, kappa):
    """(s_dot, e_y_dot, e_psi_dot) in m/s, m/s, rad/s (paper Eq. 2-4).

    v_x, v_y in m/s, r in rad/s, e_psi in rad, e_y in m, kappa in 1/m (> 0 for a left bend).
    """''',
            solution="""    s_dot = (v_x * math.cos(e_psi) - v_y * math.sin(e_psi)) / (1.0 - kappa * e_y)
    e_y_dot = v_x * math.sin(e_psi) + v_y * math.cos(e_psi)
    e_psi_dot = r - kappa * s_dot
    return s_dot, e_y_dot, e_psi_dot""",
            check="check_frenet_rates(frenet_rates)",
        ),
    ],
    outro="""With all three checks saying "correct", you have rebuilt the geometry that every later
chapter stands on: the planner works in $(s, e_y, e_\\psi)$, and the MPC projects the car on its plan
ten times a second.""",
)

# --------------------------------------------------------------------------------------------------
# Chapter 02

CH02 = Chapter(
    name="02_dynamics",
    title="Exercises 02 · The race-car model",
    intro="""Chapter 02 built the planning model of the paper term by term. Here you write four of its
pieces: the slip angles, the tyre force, the axle loads with load transfer, and the change from the
time domain to the spatial domain that the planner needs. Each check compares your function with
`racing_lib.model` or `racing_lib.vehicle` on several driving situations.

Parameters come as a `racing_lib.model.ModelParams` `p`: `p.m` (kg), `p.l_f`, `p.l_r`, `p.h_c`
(m), `p.mu`, `p.g` (m/s^2), Pacejka factors `p.B_f`, `p.C_f`, `p.D_f` (front) and `p.B_r`, ...
(rear).""",
    imports="""import math

import numpy as np

import racing_lib.face.notebook
from racing_lib.grading.ch02 import (
    check_axle_loads,
    check_slip_angles,
    check_spatial_dynamics,
    check_tyre_force,
)
from racing_lib.model import X""",
    exercises=[
        Exercise(
            markdown="""## Exercise 2.1 · Slip angles

A tyre makes a lateral force when the direction it rolls in differs from the direction it points in.
For the bicycle model (paper Eq. 11), with the front wheel steered by $\\delta$:
$$\\alpha_f = \\delta - \\frac{v_y + l_f\\,r}{v_x}, \\qquad \\alpha_r = -\\frac{v_y - l_r\\,r}{v_x}.$$
The numerators are the lateral velocities of the two axles: the yaw rate adds $l_f r$ at the front
and subtracts $l_r r$ at the rear.""",
            header='''def slip_angles(p, v_x, v_y, r, delta):
    """(alpha_f, alpha_r), rad, for speeds v_x, v_y (m/s), yaw rate r (rad/s), steering delta (rad)."""''',
            solution="""    alpha_f = delta - (v_y + p.l_f * r) / v_x
    alpha_r = -(v_y - p.l_r * r) / v_x
    return alpha_f, alpha_r""",
            check="check_slip_angles(slip_angles)",
        ),
        Exercise(
            markdown="""## Exercise 2.2 · The tyre force

The paper's simplified Pacejka law (Eq. 9-10) makes the lateral force proportional to the load
$F_z$ and shapes it by three factors:
$$F_y = \\mu\\,F_z\\,D\\,\\sin\\!\\big(C \\arctan(B\\,\\alpha)\\big).$$
$B$ sets the slope at small slip, $C$ where the force peaks and falls off, $D$ the peak itself.""",
            header='''def tyre_force(alpha, F_z, mu, B, C, D):
    """Lateral tyre force F_y, N, at slip angle alpha (rad) and vertical load F_z (N)."""''',
            solution="""    return mu * F_z * D * math.sin(C * math.atan(B * alpha))""",
            check="check_tyre_force(tyre_force)",
            after="""# The force curve of the front axle: linear at first, a peak, then a slow fall.
import matplotlib.pyplot as plt

from racing_lib.model import ModelParams

p = ModelParams()
F_zf, _ = p.static_loads()
alpha = np.linspace(-0.3, 0.3, 301)
try:
    force = [tyre_force(a, F_zf, p.mu, p.B_f, p.C_f, p.D_f) for a in alpha]
    plt.plot(np.degrees(alpha), np.array(force) / 1000)
    plt.xlabel("slip angle [deg]")
    plt.ylabel("F_y front [kN]")
except NotImplementedError:
    print("plot: not done yet")""",
        ),
        Exercise(
            markdown="""## Exercise 2.3 · Axle loads and load transfer

On a level road the weight $m g$ is shared by the axles in inverse proportion to their distance
from the centre of gravity, $F_{zf,0} = m g\\,l_r/L$ and $F_{zr,0} = m g\\,l_f/L$ with
$L = l_f + l_r$. Accelerating at $a_x$ pitches load backwards by (Eq. 12)
$$\\Delta W = \\frac{m\\,a_x\\,h_c}{L}, \\qquad F_{zf} = F_{zf,0} - \\Delta W, \\quad
F_{zr} = F_{zr,0} + \\Delta W;$$
braking ($a_x < 0$) moves it to the front, which is why the front tyres grip better under braking.""",
            header='''def axle_loads(p, a_x):
    """(F_zf, F_zr), N, on a level road while accelerating at a_x (m/s^2; < 0 braking)."""''',
            solution="""    L = p.l_f + p.l_r
    delta_W = p.m * a_x * p.h_c / L
    return p.m * p.g * p.l_r / L - delta_W, p.m * p.g * p.l_f / L + delta_W""",
            check="check_axle_loads(axle_loads)",
        ),
        Exercise(
            markdown="""## Exercise 2.4 · From time to space

The planner integrates the model over the track's arc length $s$ instead of time: the lap time is
then an integral over a fixed interval, and the track's curvature and width are known functions of
the integration variable. By the chain rule,
$$\\frac{\\mathrm{d}\\xi}{\\mathrm{d}s} = \\frac{\\dot\\xi}{\\dot s},$$
with $\\dot s$ from the kinematics of chapter 01. Use the time-domain model,
`model.xi_dot(xi, u, kappa=kappa)` (a `racing_lib.model.Model`; it returns $\\dot\\xi$ in the order
$[v_x, v_y, r, e_\\psi, e_y, s]$, indexed by `X.VX`, ..., `X.S`), and return the derivative with
respect to $s$. What must its last component be?""",
            header='''def spatial_dynamics(model, xi, u, kappa):
    """dxi/ds, shape (6,): the change of each state per metre along the reference.

    xi = [v_x, v_y, r, e_psi, e_y, s], u = [delta, a_x], kappa in 1/m.
    """''',
            solution="""    xi_dot = model.xi_dot(xi, u, kappa=kappa)
    s_dot = xi_dot[X.S]  # the speed of the car's projection along the reference, m/s
    return xi_dot / s_dot""",
            check="check_spatial_dynamics(spatial_dynamics)",
        ),
    ],
)

# --------------------------------------------------------------------------------------------------
# Chapter 03

CH03 = Chapter(
    name="03_curvature",
    title="Exercises 03 · Speed profile and the curvature QP",
    intro="""Chapter 03 planned a fast line in two steps that feed each other: a speed profile for
the current line, and a QP that bends the line to lower its curvature, linearized around steady
cornering at that speed. Here you write three of the pieces: the friction limit on speed in a
corner, the lap time of a speed profile, and the steady-cornering state the QP linearizes around.
Then you write a curvature QP of your own, in cvxpy, for an oval. The checks compare with
`racing_lib.planning` on the expressway, and your QP's line with the optimum found by another
method.""",
    imports="""import math

import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np

import racing_lib.face.notebook
from racing_lib.grading.ch03 import (
    check_cornering_speed,
    check_lap_time,
    check_min_curvature_qp,
    check_steady_cornering,
    line_curvature,
    oval_track,
)""",
    exercises=[
        Exercise(
            markdown="""## Exercise 3.1 · How fast through a corner?

Driving a curve of curvature $\\kappa$ at speed $v$ needs the lateral acceleration $v^2 |\\kappa|$,
which the tyres can give up to $\\mu g$ (on a level road, ignoring load transfer). So
$$v_\\max(s) = \\sqrt{\\frac{\\mu\\,g}{|\\kappa(s)|}},$$
capped at the car's top speed $v_\\text{top}$ (on a straight $\\kappa = 0$ and the tyres set no
limit). `kappa` is an array with one curvature per node; return one speed per node.""",
            header='''def cornering_speed(kappa, mu, g, v_top):
    """Friction-limited speed v_max (m/s) at each curvature kappa (1/m, array), capped at v_top."""''',
            solution="""    abs_k = np.abs(kappa)
    with np.errstate(divide="ignore"):
        v = np.sqrt(mu * g / abs_k)  # inf on straights, where the cap takes over
    return np.minimum(v, v_top)""",
            check="check_cornering_speed(cornering_speed)",
        ),
        Exercise(
            markdown="""## Exercise 3.2 · The lap time of a speed profile

A speed profile gives the speed $v_k$ at nodes $s_k$ around a closed loop of length $L$. Between two
nodes the car accelerates uniformly, so it covers the interval at the mean of the two speeds:
$$T = \\sum_{k=0}^{N-1} \\frac{2\\,\\Delta s_k}{v_k + v_{k+1}}, \\qquad
\\Delta s_k = s_{k+1} - s_k,$$
where the last interval closes the loop: from $s_{N-1}$ back to $s_0 + L$, at speeds $v_{N-1}$ and
$v_0$.""",
            header='''def lap_time(s, v, length):
    """Time (s) to drive the closed loop of `length` (m) at speeds v (m/s) at the nodes s (m)."""''',
            solution="""    ds = np.diff(np.append(s, s[0] + length))
    v_next = np.roll(v, -1)
    return float(np.sum(2.0 * ds / (v + v_next)))""",
            check="check_lap_time(lap_time)",
        ),
        Exercise(
            markdown="""## Exercise 3.3 · Steady cornering, the QP's linearization point

Each QP iteration linearizes the model around the car cornering steadily on the current line at the
estimated speed $v$: yaw rate $r = v\\kappa$ and lateral acceleration $a_y = v^2\\kappa$. Each axle
carries its static share of $a_y$; since the tyre force is proportional to the load, each axle needs
$$\\mu D \\sin(C\\arctan(B\\alpha)) = a_y / g \\quad\\Rightarrow\\quad
\\alpha = \\frac{1}{B}\\tan\\!\\Big(\\frac{1}{C}\\arcsin\\frac{a_y}{\\mu D g}\\Big)$$
(with its own $B, C, D$ front and rear). The slip-angle definitions of exercise 2.1 then give
$v_y = l_r r - v\\,\\alpha_r$ and $\\delta = \\alpha_f + (v_y + l_f r)/v$.
The cases of the check stay below the friction limit, so the arcsine exists.""",
            header='''def steady_state(p, v, kappa):
    """(v_y, r, delta) in m/s, rad/s, rad of steady cornering at speed v (m/s) on curvature kappa (1/m)."""''',
            solution="""    r = v * kappa
    a_y = v * v * kappa

    def slip(B, C, D):
        return math.tan(math.asin(a_y / (p.g * p.mu * D)) / C) / B

    alpha_f = slip(p.B_f, p.C_f, p.D_f)
    alpha_r = slip(p.B_r, p.C_r, p.D_r)
    v_y = p.l_r * r - v * alpha_r
    delta = alpha_f + (v_y + p.l_f * r) / v
    return v_y, r, delta""",
            check="check_steady_cornering(steady_state)",
        ),
        Exercise(
            markdown="""## Exercise 3.4 · Write the curvature QP yourself

Chapter 03's QP bends the line to lower its curvature. Strip it to its core and write it yourself,
for an oval: two 200 m straights joined by two bends of radius 60 m, 8 m wide, sampled every
$\\Delta s \\approx 2$ m (`oval = oval_track()`: `oval.s`, `oval.kappa`, `oval.ds`,
`oval.half_width`). The line is the lateral offset $n_k$ (m, left positive) of the centerline at each
node. For small offsets its curvature is, to first order,

$$\\kappa_k \\approx \\kappa_{c,k} + \\frac{n_{k+1} - 2 n_k + n_{k-1}}{\\Delta s^2}$$

(`line_curvature(oval, n)` evaluates it), with the indices wrapping round the loop: node $N$ is node
0. Find the line of least squared curvature that keeps a margin $m$ to both edges:

$$\\min_{n}\\ \\sum_{k} \\kappa_k^2\\, \\Delta s \\quad \\text{s.t.}\\quad
|n_k| \\le w - m .$$

The cost is a sum of squares of expressions linear in $n$, and the bounds are linear: a QP. Write it
with `cvxpy` (a `cp.Variable`, `cp.sum_squares`, `cp.Problem(...).solve()`) and return the
offsets as a NumPy array. The check runs two margins and compares the cost of your line with the
optimum found by another method.""",
            header='''def min_curvature_line(oval, margin):
    """Offsets n (N,), m, of the least-curved line round the oval within half_width - margin."""''',
            solution="""    n = cp.Variable(oval.s.size)
    # Neighbours round the loop: the node after the last is the first, and the other way round.
    after = cp.hstack([n[1:], n[:1]])
    before = cp.hstack([n[-1:], n[:-1]])
    kappa = oval.kappa + (after - 2 * n + before) / oval.ds**2
    bound = oval.half_width - margin
    problem = cp.Problem(cp.Minimize(cp.sum_squares(kappa) * oval.ds), [cp.abs(n) <= bound])
    problem.solve()
    return n.value""",
            check="check_min_curvature_qp(min_curvature_line)",
            after="""# The line you found: outside before each bend, the apex inside, outside again after it.
oval = oval_track()
try:
    n = min_curvature_line(oval, 0.5)
except NotImplementedError:
    n = np.zeros_like(oval.s)
    print("(min_curvature_line is not written yet: the centerline is shown instead)")
fig, ax = plt.subplots(2, 1, figsize=(7, 4), sharex=True)
ax[0].plot(oval.s, n)
ax[0].axhline(oval.half_width - 0.5, color="k", lw=0.8)
ax[0].axhline(-(oval.half_width - 0.5), color="k", lw=0.8)
ax[0].set_ylabel("$n$ [m]")
ax[1].plot(oval.s, oval.kappa, label="centerline")
ax[1].plot(oval.s, line_curvature(oval, n), label="your line")
ax[1].set_ylabel(r"$\\kappa$ [1/m]")
ax[1].set_xlabel("$s$ [m]")
ax[1].legend()
plt.show()""",
        ),
    ],
)

# --------------------------------------------------------------------------------------------------
# Chapter 04

CH04 = Chapter(
    name="04_time_optimal",
    title="Exercises 04 · The minimum-lap-time NLP",
    intro="""Chapter 04 replaced the curvature proxy by the lap time itself, written as an integral
over the centerline's arc length so that the NLP has a fixed horizon. Here you write that
objective, and the bound on the slip angles that keeps the planned tyres on the stable side of
their force peak. Then you write and solve a minimum-lap-time NLP of your own in CasADi, for a
point mass on an oval. The checks compare with `racing_lib.planning.time_optimal` and
`racing_lib.model`, and your NLP's lap with the optimum found by another method.""",
    imports="""import math

import casadi as ca
import numpy as np

import racing_lib.face.notebook
from racing_lib.grading.ch03 import oval_track
from racing_lib.grading.ch04 import (
    check_min_time_nlp,
    check_peak_slip_angle,
    check_spatial_lap_time,
)""",
    exercises=[
        Exercise(
            markdown="""## Exercise 4.1 · Lap time in the spatial domain

In the time domain the lap time is the free end of the horizon; in the spatial domain it is an
integral over the fixed length of the centerline,
$$T = \\int_0^L \\frac{\\mathrm{d}t}{\\mathrm{d}s}\\,\\mathrm{d}s = \\int_0^L \\frac{1}{\\dot s}\\,
\\mathrm{d}s, \\qquad \\dot s = \\frac{v_x\\cos e_\\psi - v_y\\sin e_\\psi}{1 - \\kappa\\,e_y}.$$
On the planning grid, node $k$ has states $v_{x,k}, v_{y,k}, e_{\\psi,k}, e_{y,k}$, the centerline's
curvature $\\kappa_k$, and `ds[k]` is the distance to node $k+1$ (the last one wraps to node 0).
Integrate with the trapezoid rule in $1/\\dot s$, as the NLP does:
$T = \\sum_k \\tfrac{1}{2}\\Delta s_k\\,(1/\\dot s_k + 1/\\dot s_{k+1})$.
Note how a line on the inside of a bend ($\\kappa e_y > 0$) gains time at the same speed.""",
            header='''def lap_time(ds, kappa, v_x, v_y, e_psi, e_y):
    """Lap time (s) of the states at the grid nodes (arrays), trapezoid rule in 1 / s_dot."""''',
            solution="""    s_dot = (v_x * np.cos(e_psi) - v_y * np.sin(e_psi)) / (1.0 - kappa * e_y)
    inv = 1.0 / s_dot  # time per metre of centerline, s/m
    return float(np.sum(0.5 * ds * (inv + np.roll(inv, -1))))""",
            check="check_spatial_lap_time(lap_time)",
        ),
        Exercise(
            markdown="""## Exercise 4.2 · The peak of the tyre force

Past the peak of its force curve a tyre gives less force for more slip, and a plan that uses that
region is degenerate and hard to follow. The NLP therefore bounds $|\\alpha|$ by the slip angle of
the peak. For $F_y = \\mu F_z D \\sin(C\\arctan(B\\alpha))$ the sine is largest where its argument
is $\\pi/2$; solve for $\\alpha$.""",
            header='''def peak_slip_angle(B, C):
    """Slip angle (rad, > 0) at which mu F_z D sin(C atan(B alpha)) is largest (1 < C < 2)."""''',
            solution="""    return math.tan(math.pi / (2.0 * C)) / B""",
            check="check_peak_slip_angle(peak_slip_angle)",
        ),
        Exercise(
            markdown="""## Exercise 4.3 · A minimum-time NLP of your own

Write the chapter's NLP in miniature: a point mass on the oval of exercise 3.4 (`oval_track()`),
driving its centerline. Its decision variables are the speed $v_k$ at each node and the
acceleration $a_k$ on the interval to the next node, over which it is constant, so

$$v_{k+1}^2 = v_k^2 + 2\\, a_k\\, \\Delta s \\qquad (\\text{node } N \\text{ is node } 0:
\\text{a flying lap}).$$

The tyres give a total acceleration of at most `grip` (m/s$^2$) in any direction, shared between
braking or driving and cornering, and the car tops out at `v_top`:

$$\\Big(\\frac{a_k}{a_\\text{grip}}\\Big)^2 + \\Big(\\frac{v_k^2\\,\\kappa_k}{a_\\text{grip}}\\Big)^2
\\le 1, \\qquad 1 \\le v_k \\le v_\\text{top}.$$

Minimize the lap time $T = \\sum_k 2\\,\\Delta s / (v_k + v_{k+1})$ with `casadi.Opti`
(`opti.variable`, `opti.minimize`, `opti.subject_to`, `opti.solver("ipopt")`, `opti.solve()`).
Start it from a constant 10 m/s: the cold start works here, as chapter 04 found for its NLP.
The check compares your lap with the optimum of the same problem written as a convex program in
$w = v^2$, in which the dynamics are linear and the lap time convex.""",
            header='''def min_time_speeds(oval, grip, v_top):
    """Node speeds v (N,), m/s, of the fastest lap of a point mass round the oval."""''',
            solution="""    n = oval.s.size
    opti = ca.Opti()
    v = opti.variable(n)
    a = opti.variable(n)
    v_next = ca.vertcat(v[1:], v[0])  # the lap closes: after the last node comes the first
    opti.minimize(ca.sum1(2 * oval.ds / (v + v_next)))
    opti.subject_to(v_next**2 == v**2 + 2 * a * oval.ds)
    opti.subject_to((a / grip) ** 2 + (v**2 * oval.kappa / grip) ** 2 <= 1)
    opti.subject_to(opti.bounded(1.0, v, v_top))
    opti.set_initial(v, 10.0)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes"})
    return opti.solve().value(v)""",
            check="check_min_time_nlp(min_time_speeds)",
        ),
    ],
)

# --------------------------------------------------------------------------------------------------
# Chapter 05

CAPSTONE_MARKDOWN = """## Exercise 5.5 · Capstone: your QP drives a lap

In exercise 5.4 you wrote a small tracking QP and solved it. Now build the coupled MPC's own QP,
the one chapter 05's controller solves ten times a second, and let it drive a lap. At every
control period the controller projects the car on its plan, linearizes the model along the
heuristic trajectory of exercise 5.1 and hands your function `build_qp(step)` that period's
numbers as a `racing_lib.control.mpc.StepQP`: $N = 25$ stages, $n = 6$ states
$x = (v_x, v_y, r, e_\\psi, e_y, \\delta)$ (m/s, m/s, rad/s, rad, m, rad; $\\delta$ is the steering
angle behind the actuator's lag of exercise 5.2) and $m = 2$ inputs $u = (\\delta_\\text{cmd}, a_x)$
(rad, m/s$^2$).

| field | shape | what it is |
| --- | --- | --- |
| `step.x0` | $(n,)$ | the state now, $x_0$ (measured) |
| `step.A`, `step.B`, `step.d` | $(N, n, n)$, $(N, n, m)$, $(N, n)$ | the model $x_{k+1} = A_k x_k + B_k u_k + d_k$, $k = 0, \\dots, N-1$ |
| `step.x_ref` | $(N, n)$ | the reference at stages $1, \\dots, N$ (row $k-1$ is stage $k$) |
| `step.state_weights` | $(N, n)$ | the diagonal of $W$ at stages $1, \\dots, N$ |
| `step.rate_weights` | $(m,)$ | the diagonal of $W_{\\Delta u}$ |
| `step.rate_limits` | $(m,)$ | the largest change of each input per period (`inf`: none) |
| `step.u_prev` | $(m,)$ | the input of the last period, $u_{-1}$ |
| `step.u_min`, `step.u_max` | $(N, m)$ | the bounds of $u_0, \\dots, u_{N-1}$ |
| `step.band_min`, `step.band_max` | $(N,)$ | the track's edges on $e_y$ (state `step.band_index` = 4) at stages $1, \\dots, N$, m |
| `step.slack_linear`, `step.slack_quadratic` | float | $\\rho_1$ (1/m), $\\rho_2$ (1/m$^2$) |

The QP is the library's (`racing_lib.control.mpc.qp_problem`):
$$\\min\\; \\sum_{k=1}^{N} (x_k - x^\\text{ref}_k)^\\top W (x_k - x^\\text{ref}_k) +
\\sum_{k=0}^{N-1} (u_k - u_{k-1})^\\top W_{\\Delta u} (u_k - u_{k-1}) +
\\sum_{k=1}^{N} \\big(\\rho_1 \\varepsilon_k + \\rho_2 \\varepsilon_k^2\\big)$$
subject to the model for $k = 0, \\dots, N-1$; the soft band
$e_{y,\\min,k} - \\varepsilon_k \\le e_{y,k} \\le e_{y,\\max,k} + \\varepsilon_k$ with $\\varepsilon_k \\ge 0$;
the bounds $u_{\\min,k} \\le u_k \\le u_{\\max,k}$; and the steering's slew rate,
$|u_k - u_{k-1}| \\le$ `rate_limits`. The band is soft so that the QP has a solution even when the
car is already beyond it.

Return it in OSQP's form, $\\min \\tfrac12 z^\\top P z + q^\\top z$ subject to $l \\le A z \\le u$, over
$z = (x_1, \\dots, x_N, u_0, \\dots, u_{N-1}, \\varepsilon_1, \\dots, \\varepsilon_N)$ stage by stage:
$x_k$ is `z[(k-1)*n : k*n]`, $u_k$ is `z[N*n + k*m : N*n + (k+1)*m]` and $\\varepsilon_k$ is
`z[N*(n+m) + k-1]`. $P$ is symmetric (a NumPy array or a `scipy.sparse` matrix), the rows of $A$
come in any order, and `np.inf` in $l$ or $u$ means no bound on that side. Two things to think
about first: $x_0$ is not a variable, so where does $A_0 x_0$ go? And OSQP minimizes *half* of
$z^\\top P z$.

The library solves your matrices with OSQP at every period, as it solves its own, applies $u_0$
and drives a flying lap of the figure-eight (808 m between walls, two 270° loops of 60 m radius)
on its centerline plan. The check first solves your QP in three single periods and names what
differs from the library's QP; then it drives the lap and grades it: finished, no wall touched, at
most 1.5 m from the plan and 1.0 m/s off its speed on average (the library's own MPC: 1.09 m and
0.64 m/s). The lap takes a few seconds."""

# The start of exercise 5.5's function (template and solution): the sizes and the blocks of z.
CAPSTONE_START = """    N, n, m = step.B.shape  # 25 stages, 6 states, 2 inputs
    nx, nu = N * n, N * m
    nz = nx + nu + N  # z = [x_1..x_N, u_0..u_{N-1}, eps_1..eps_N], stage by stage
    X, U, E = slice(0, nx), slice(nx, nx + nu), slice(nx + nu, nz)  # the three blocks of z
"""

CAPSTONE_SOLUTION = """
    # Cost 1/2 z'Pz + q'z. w (x - x_ref)^2 = w x^2 - 2 w x_ref x + const: 2 w on P's diagonal.
    P = np.zeros((nz, nz))
    q = np.zeros(nz)
    P[X, X] = np.diag(2.0 * step.state_weights.ravel())
    q[X] = -2.0 * (step.state_weights * step.x_ref).ravel()
    # Input changes: (D u)_k = u_k - u_{k-1}, and u_0 alone at k = 0 (u_prev moves into q).
    D = np.eye(nu) - np.eye(nu, k=-m)
    P[U, U] = 2.0 * D.T @ np.diag(np.tile(step.rate_weights, N)) @ D
    q[nx : nx + m] = -2.0 * step.rate_weights * step.u_prev
    # The band's slack: rho_1 eps + rho_2 eps^2.
    P[E, E] = 2.0 * step.slack_quadratic * np.eye(N)
    q[E] = step.slack_linear

    # Model: x_{k+1} - A_k x_k - B_k u_k = d_k. x_0 is measured, so A_0 x_0 joins d_0.
    model = np.zeros((nx, nz))
    model[:, X] = np.eye(nx)
    for k in range(N):
        rows = slice(k * n, (k + 1) * n)
        if k > 0:
            model[rows, (k - 1) * n : k * n] = -step.A[k]
        model[rows, nx + k * m : nx + (k + 1) * m] = -step.B[k]
    rhs = step.d.copy()
    rhs[0] += step.A[0] @ step.x0
    rhs = rhs.ravel()
    # The soft band: band_min - eps <= e_y <= band_max + eps, and eps >= 0.
    e_y = np.zeros((N, nz))
    e_y[np.arange(N), np.arange(N) * n + step.band_index] = 1.0
    eps = np.zeros((N, nz))
    eps[:, E] = np.eye(N)
    # Inputs: their bounds, and changes of at most rate_limits per period (from u_prev at k = 0).
    inputs = np.zeros((nu, nz))
    inputs[:, U] = np.eye(nu)
    changes = np.zeros((nu, nz))
    changes[:, U] = D
    limit = np.tile(step.rate_limits, N)
    first = np.zeros(nu)
    first[:m] = step.u_prev

    inf = np.full(N, np.inf)
    A = np.vstack([model, e_y + eps, e_y - eps, eps, inputs, changes])
    l = np.concatenate([rhs, step.band_min, -inf, np.zeros(N), step.u_min.ravel(), first - limit])
    u = np.concatenate([rhs, inf, step.band_max, inf, step.u_max.ravel(), first + limit])
    return P, q, A, l, u"""

CAPSTONE_AFTER = """# The gap to the plan along the lap: your QP against the library's (a few seconds).
import matplotlib.pyplot as plt

fig, ax = plt.subplots(figsize=(8, 3))
for label, builder in (("the library's QP", None), ("your QP", build_qp)):
    try:
        run = drive_capstone_lap(builder)
    except NotDone:
        print("(build_qp is not written yet: only the library's lap is shown)")
        continue
    except Wrong as mistake:  # matrices the library cannot read: the check says more
        print(f"{label}: {mistake}")
        continue
    if run.result is None:
        print(f"{label}: the car touched the wall at s = {run.wall[1]:.0f} m")
        continue
    log, m = run.result.log, run.result.metrics
    print(
        f"{label}: lap {m.lap_time_s:.2f} s, |e_y| max {m.ey_max_m:.2f} m, mean "
        f"{m.ey_mae_m:.2f} m, |v_x - v_ref| mean {m.vx_mae_mps:.2f} m/s"
    )
    ax.plot(log.t, log.ey, label=label)
ax.set(xlabel="time since the start [s]", ylabel="e_y [m]")
ax.legend();"""

CH05 = Chapter(
    name="05_mpc",
    title="Exercises 05 · The coupled MPC",
    intro="""Chapter 05 tracks the plan with a model-predictive controller that linearizes the model
along a *heuristic trajectory* and solves one QP per control period. Here you write that trajectory,
the discrete model of the steering actuator the QP carries, and the last step from the planned
acceleration to a pedal position. Then you write a tracking MPC's QP yourself, for the lateral
errors of a car. The checks compare with `racing_lib.control.mpc` and `racing_lib.model`, and
your QP's commands with the optimum found by another method. Last, the capstone: you build the
coupled MPC's own QP from its linearization, and it drives a lap.""",
    imports="""import math

import cvxpy as cp
import numpy as np

import racing_lib.face.notebook
from racing_lib.grading.ch05 import (
    check_heuristic_trajectory,
    check_lateral_mpc,
    check_mpc_lap,
    check_pedal_inversion,
    check_steering_lag,
    drive_capstone_lap,
    lateral_mpc_problem,
)
from racing_lib.grading.grader import NotDone, Wrong""",
    exercises=[
        Exercise(
            markdown="""## Exercise 5.1 · The heuristic trajectory

Linearizing along the plan alone is poor when the car is off the plan: the model is then evaluated
where the car is not. Linearizing at the car's state for the whole horizon ignores that the
controller will bring it back. The paper blends the two: with $\\lambda_k$ falling linearly from 1
at stage $k = 0$ to 0 at stage $N$,
$$\\hat\\xi_k = \\xi^\\text{ref}_k + \\lambda_k\\,(\\xi_0 - \\xi^\\text{ref}_0), \\qquad
\\lambda_k = 1 - k/N .$$
`xi_ref` has one row per stage, $k = 0, \\dots, N$ (shape $(N+1, 6)$), and `xi0` is the car's
state (shape $(6,)$).""",
            header='''def heuristic_trajectory(xi0, xi_ref):
    """xi_hat, shape (N+1, 6): from the car's state xi0 (6,) blended linearly into xi_ref (N+1, 6)."""''',
            solution="""    N = xi_ref.shape[0] - 1
    lam = 1.0 - np.arange(N + 1) / N
    return xi_ref + lam[:, None] * (xi0 - xi_ref[0])[None, :]""",
            check="check_heuristic_trajectory(heuristic_trajectory)",
        ),
        Exercise(
            markdown="""## Exercise 5.2 · The steering actuator in the QP

The simulated car's steering follows the command with a first-order lag,
$\\dot\\delta = (\\delta_\\text{cmd} - \\delta)/\\tau$. Holding the command over one period $\\Delta t$,
the exact solution gives
$$\\delta_{k+1} = a\\,\\delta_k + (1 - a)\\,\\delta_\\text{cmd}, \\qquad a = e^{-\\Delta t/\\tau},$$
and the mean angle over the period, which is what the tyres feel on average, is
$w\\,\\delta_k + (1-w)\\,\\delta_\\text{cmd}$ with $w = \\frac{\\tau}{\\Delta t}(1 - a)$
(integrate the exponential over the period to see why).""",
            header='''def steering_lag(tau, dt):
    """(a, w): one-period decay and mean-angle weight of a first-order lag tau (s) over dt (s)."""''',
            solution="""    a = math.exp(-dt / tau)
    return a, tau / dt * (1.0 - a)""",
            check="check_steering_lag(steering_lag)",
        ),
        Exercise(
            markdown="""## Exercise 5.3 · From acceleration to pedal

The MPC plans the tyre acceleration $a_x$; the car takes a pedal $u_p \\in [-1, 1]$. The pedal map of
the paper's Appendix C (with separate throttle and brake slopes) is
$$a_x = m_0 + m_\\xi \\cdot \\xi + m_\\text{thr} \\max(u_p, 0) + m_\\text{brk} \\min(u_p, 0).$$
Invert it: compare the requested $a_x$ with what the car does with the pedal released,
$m_0 + m_\\xi \\cdot \\xi$, and divide the difference by the throttle or the brake slope. Requests
beyond full throttle or full brake are clipped to $\\pm 1$. The map's coefficients are
`pedal_map.m_0`, `pedal_map.m_xi` (6 values), `pedal_map.m_thr`, `pedal_map.m_brk`.""",
            header='''def pedal_for(pedal_map, a_x, xi):
    """Pedal u_p in [-1, 1] that makes the tyre acceleration a_x (m/s^2) in state xi (6,)."""''',
            solution="""    coasting = pedal_map.m_0 + float(np.dot(pedal_map.m_xi, xi))
    excess = a_x - coasting
    u_p = excess / pedal_map.m_thr if excess >= 0 else excess / pedal_map.m_brk
    return float(np.clip(u_p, -1.0, 1.0))""",
            check="check_pedal_inversion(pedal_for)",
        ),
        Exercise(
            markdown="""## Exercise 5.4 · A tracking QP of your own

The coupled MPC builds one QP per period from a linear model, a tracking cost and bounds. Build one
yourself for the lateral part alone. A car at 20 m/s follows its line with errors
$x = (e_y, e_\\psi)$ and steers with $\\delta$; over one period the kinematic model gives

$$x_{k+1} = A\\, x_k + B\\, \\delta_k + d_k, \\qquad k = 0, \\dots, N-1,$$

where $d_k$ is what the line's curvature does to the errors (`problem.A`, `problem.B`, `problem.d`
with one row per stage, and the measured errors `problem.x0`). Choose the $N$ commands that
minimize

$$\\sum_{k=1}^{N} \\big(q_y\\, e_{y,k}^2 + q_\\psi\\, e_{\\psi,k}^2\\big)
\\;+\\; r \\sum_{k=0}^{N-1} (\\delta_k - \\delta_{k-1})^2
\\quad\\text{s.t.}\\quad |\\delta_k| \\le \\delta_\\max,$$

with $\\delta_{-1}$ the command the car has now (`problem.q`, `problem.r`, `problem.delta_prev`,
`problem.delta_max`). Write it with the states and the commands both as cvxpy variables and the
model as equality constraints, the *sparse* form the library hands to OSQP. The check tries three
situations and compares the cost of your commands, simulated through the model, with the optimum
found by another method.""",
            header='''def mpc_steering(problem):
    """The N optimal steering commands (rad) of the lateral tracking QP `problem`."""''',
            solution="""    n = problem.d.shape[0]
    x = cp.Variable((n + 1, 2))  # predicted errors, stages 0..N
    delta = cp.Variable(n)
    steps = cp.hstack([delta[:1] - problem.delta_prev, delta[1:] - delta[:-1]])
    cost = cp.sum(cp.square(x[1:]) @ problem.q) + problem.r * cp.sum_squares(steps)
    model = [x[0] == problem.x0]
    model += [x[k + 1] == problem.A @ x[k] + problem.B * delta[k] + problem.d[k] for k in range(n)]
    bounds = [cp.abs(delta) <= problem.delta_max]
    cp.Problem(cp.Minimize(cost), model + bounds).solve()
    return delta.value""",
            check="check_lateral_mpc(mpc_steering)",
            after="""# Your MPC's plan when the car is 1 m left of a line that turns left after 0.8 s.
problem = lateral_mpc_problem((1.0, 0.02), 0.0, np.r_[np.zeros(8), np.full(17, 1 / 80)])
try:
    delta = mpc_steering(problem)
except NotImplementedError:
    delta = np.zeros(problem.d.shape[0])
    print("(mpc_steering is not written yet: straight steering is shown instead)")
x = [problem.x0]
for k, u in enumerate(delta):
    x.append(problem.A @ x[-1] + problem.B * u + problem.d[k])
print("first commands [rad]:", np.round(delta[:5], 4))
print("predicted e_y [m]:   ", np.round(np.array(x)[:6, 0], 3))""",
        ),
        Exercise(
            markdown=CAPSTONE_MARKDOWN,
            header='''def build_qp(step):
    """OSQP's (P, q, A, l, u) of the coupled MPC's QP for one control period (a StepQP)."""''',
            template=CAPSTONE_START
            + """    # YOUR CODE HERE: the cost (P, q), then the rows of A with their sides l and u
    raise NotImplementedError""",
            solution=CAPSTONE_START + CAPSTONE_SOLUTION,
            check="check_mpc_lap(build_qp)",
            after=CAPSTONE_AFTER,
        ),
    ],
)

# --------------------------------------------------------------------------------------------------
# Chapter 06

# The default constants of CMA-ES (the start of exercise 6.3's function, in template and solution).
CMA_CONSTANTS = """    rng = np.random.default_rng(seed)
    n = len(x0)
    # The default strategy parameters (Hansen's tutorial): population, weights, learning rates.
    lam = 4 + int(3 * math.log(n))  # candidates per generation
    mu = lam // 2  # how many of them are selected
    w = math.log(mu + 0.5) - np.log(np.arange(1, mu + 1))
    w /= w.sum()  # recombination weights, decreasing, sum 1
    mu_eff = 1.0 / np.sum(w**2)
    c_s = (mu_eff + 2) / (n + mu_eff + 5)  # step-size path
    d_s = 1 + 2 * max(0.0, math.sqrt((mu_eff - 1) / (n + 1)) - 1) + c_s
    c_c = (4 + mu_eff / n) / (n + 4 + 2 * mu_eff / n)  # covariance path
    c_1 = 2 / ((n + 1.3) ** 2 + mu_eff)  # rank-one update
    c_mu = min(1 - c_1, 2 * (mu_eff - 2 + 1 / mu_eff) / ((n + 2) ** 2 + mu_eff))  # rank-mu
    chi_n = math.sqrt(n) * (1 - 1 / (4 * n) + 1 / (21 * n * n))  # E||N(0, I)||
    m, sigma = np.array(x0, dtype=float), float(sigma0)
    C, p_s, p_c = np.eye(n), np.zeros(n), np.zeros(n)
    best_x, best_f = m.copy(), f(m)
    used = 1
"""

TUNING_MARKDOWN = """## Exercise 6.4 · Tuning the MPC with your CMA-ES

Now put the pieces together: your `cma_es` (exercise 6.3) searches the logarithms of two MPC
weights, your `to_params` (exercise 6.2) turns its points into weights, and each candidate is
scored by closed-loop driving. The weights are `w_ey`, the price of the lateral error
(1/m$^2$), and `w_ddelta`, the price of a steering change (1/rad$^2$): tracking against
smoothness. `space = tuning_space()` starts at the MPC's defaults (5 and 100).

`evaluate(weights, seed)` drives the coupled MPC with `weights` (a dict, the other weights at
their defaults) and returns the objective of exercise 6.1 (lower is better). The car's friction and
actuation noise differ from seed to seed, so the objective of a candidate is its mean over all
the `seeds` given (1, 2 and 3), each used once. `budget` counts evaluations of that mean, as
`cma_es` counts evaluations of `f`: 13, the start and two generations of 6 candidates.

To keep the check within seconds the runs are short, and that changes the objective honestly:
each run is 8 s of the figure-eight of exercise 5.5 (from 60 m before the crossing, on the plan,
along the straight and into the right-hand loop) instead of a whole lap of the expressway, and
the objective of exercise 6.1 is taken over that fixed window: 39 runs of 0.07 s each instead of
39 laps of about 0.9 s. Weights tuned on 8 s of one loop are not tuned for a circuit: chapter 06
tunes on whole laps, hundreds of them. The check verifies that your loop scored every candidate
on every seed, spent its budget (not more), and returns weights that score no worse than the
start and than any candidate it scored."""

TUNING_AFTER = """# The objective of the start and of your tuned weights, seed by seed.
space = tuning_space()
start = dict(zip(space.names, space.initial, strict=True))
try:
    tuned = tune_mpc(stretch_objective, space, TUNING_SEEDS, TUNING_BUDGET)
except NotImplementedError:
    tuned = None
    print("(tune_mpc is not written yet)")
if tuned is not None:
    for name, weights in (("start", start), ("tuned", tuned)):
        scores = [stretch_objective(weights, seed) for seed in TUNING_SEEDS]
        shown = ", ".join(f"{k} = {v:.3g}" for k, v in weights.items())
        print(f"{name} ({shown}): J = " + ", ".join(f"{j:.3f}" for j in scores))"""

CH06 = Chapter(
    name="06_tuning",
    title="Exercises 06 · Tuning with CMA-ES",
    intro="""Chapter 06 tunes the MPC's weights with CMA-ES, which only needs a score per closed-loop
lap. Here you write that score, the paper's tuning objective, and the map from CMA-ES's search
space (logarithms of the weights) to the weights themselves. The checks compare with
`racing_lib.experiments.tuning` on laps made up for the exercise (`racing_lib.grading.ch06.synthetic_lap`), so
no simulation is needed. Then you write CMA-ES itself and watch it solve a problem that a search
without its covariance update cannot. Last, your CMA-ES tunes two of the MPC's weights on short
closed-loop runs of the car.""",
    imports="""import math

import numpy as np

import racing_lib.face.notebook
from racing_lib.grading.ch06 import (
    CMA_BUDGET,
    TUNING_BUDGET,
    TUNING_SEEDS,
    check_cma_es,
    check_mpc_tuning,
    check_search_space,
    check_tuning_objective,
    rotated_ellipsoid,
    stretch_objective,
    synthetic_lap,
    tuning_space,
)""",
    exercises=[
        Exercise(
            markdown="""## Exercise 6.1 · The tuning objective

For a completed lap of $N_f$ control steps, the objective (lower is better) is
$$J = \\max_k |e_{y,k}| + \\frac{1}{N_f}\\sum_k |e_{y,k}| + \\frac{1}{N_f}\\sum_k |v_{x,k} -
v^\\text{ref}_{x,k}| + w_t\\,t_c - w_s\\,D,$$
with $t_c$ the time in collision with the track boundary (`metrics.wall_contact_time_s` plus
`metrics.offtrack_time_s`, s) and $D$ the distance travelled along the track during the lap, m.

The log (`log.ey`, `log.vx`, `log.vx_ref`, `log.s_track`, arrays over all logged steps) includes a
run-up before the line and a little after it; `log.in_lap` marks the steps of the lap. $D$ is the sum
of the steps of `log.s_track` between consecutive in-lap samples; `s_track` jumps back by the track
length where the car crosses the line, so undo that jump. Let us look at one lap first:""",
            header='''def objective(log, metrics, track_length, w_t, w_s):
    """The tuning objective J of a completed lap (dimensionless; lower is better)."""''',
            solution="""    lap = np.asarray(log.in_lap, dtype=bool)
    ey = np.abs(log.ey[lap])
    vx_err = np.abs(log.vx[lap] - log.vx_ref[lap])
    # Steps along the track, with the jump at the start/finish line undone.
    steps = np.diff(log.s_track)
    steps = (steps + 0.5 * track_length) % track_length - 0.5 * track_length
    distance = np.sum(steps[lap[:-1] & lap[1:]])
    t_c = metrics.wall_contact_time_s + metrics.offtrack_time_s
    return ey.max() + ey.mean() + vx_err.mean() + w_t * t_c - w_s * distance""",
            check="check_tuning_objective(objective)",
        ),
        Exercise(
            markdown="""## Exercise 6.2 · The search space

MPC weights matter by their ratios, over orders of magnitude, so CMA-ES searches their base-10
logarithms: a step of 0.5 means "about three times larger" for every weight alike. A candidate
$x$ from CMA-ES becomes weights by $w_i = 10^{x_i}$, after clipping $x_i$ into the box
$[\\log_{10} w_{i,\\min}, \\log_{10} w_{i,\\max}]$. The `space` (a `racing_lib.optim.cmaes.SearchSpace`)
has `space.names`, `space.lower` and `space.upper` (in the weights' own units). Return a dict
`{name: weight}`.""",
            header='''def to_params(space, x):
    """{name: weight} of the CMA-ES point x (log10 of the weights), clipped into the box."""''',
            solution="""    lo = np.log10(np.asarray(space.lower, dtype=float))
    hi = np.log10(np.asarray(space.upper, dtype=float))
    x = np.clip(np.asarray(x, dtype=float), lo, hi)
    return {name: float(10.0**v) for name, v in zip(space.names, x, strict=True)}""",
            check="check_search_space(to_params)",
        ),
        Exercise(
            markdown="""## Exercise 6.3 · CMA-ES, written by you

Chapter 06 uses pycma. Write the algorithm's loop yourself, following the five steps of the
chapter: each generation

1. **samples** $\\lambda$ candidates $x_i = m + \\sigma\\, y_i$, $y_i = B D z_i$ with
   $z_i \\sim \\mathcal N(0, I)$ and $C = B D^2 B^\\top$ (`np.linalg.eigh`);
2. **evaluates** them and **sorts** them by cost;
3. **moves the mean** by the weighted average of the $\\mu$ best steps,
   $y_w = \\sum_i w_i\\, y_{i:\\lambda}$, $m' = m + \\sigma\\, y_w$;
4. **updates the two evolution paths**,
   $p_\\sigma' = (1 - c_\\sigma)\\, p_\\sigma + \\sqrt{c_\\sigma (2 - c_\\sigma) \\mu_\\text{eff}}\\;
   C^{-1/2} y_w$ and $p_c' = (1 - c_c)\\, p_c + \\sqrt{c_c (2 - c_c) \\mu_\\text{eff}}\\; y_w$,
   and **reshapes the distribution**,
   $C' = (1 - c_1 - c_\\mu)\\, C + c_1\\, p_c p_c^\\top + c_\\mu \\sum_i w_i\\, y_{i:\\lambda} y_{i:\\lambda}^\\top$;
5. **adapts the step size**,
   $\\sigma' = \\sigma \\exp\\big(\\tfrac{c_\\sigma}{d_\\sigma}
   (\\lVert p_\\sigma \\rVert / \\mathbb E\\lVert \\mathcal N(0, I)\\rVert - 1)\\big)$.

The template sets the default constants; write the loop, spend at most `budget` evaluations of
`f`, and return the best point seen. The test problem, `rotated_ellipsoid()`, is a narrow valley
whose axes differ a hundredfold in length and are tilted against the coordinates: only a search
that learns $C$ solves it on the budget of the check.""",
            header='''def cma_es(f, x0, sigma0, budget, seed):
    """Best point found by CMA-ES minimizing f from x0 with step sigma0, in <= budget evaluations."""''',
            template=CMA_CONSTANTS
            + """    # YOUR CODE HERE: while used + lam <= budget: one generation (steps 1-5)
    raise NotImplementedError""",
            solution=CMA_CONSTANTS
            + """    while used + lam <= budget:
        values, vectors = np.linalg.eigh(C)
        scale = np.sqrt(np.maximum(values, 1e-20))  # D
        y = rng.standard_normal((lam, n)) * scale @ vectors.T  # y_i = B D z_i, one per row
        x = m + sigma * y
        costs = np.array([f(xi) for xi in x])
        used += lam
        order = np.argsort(costs)
        if costs[order[0]] < best_f:
            best_f, best_x = costs[order[0]], x[order[0]].copy()
        y_sel = y[order[:mu]]
        y_w = w @ y_sel
        m = m + sigma * y_w
        c_inv_half = vectors @ np.diag(1.0 / scale) @ vectors.T
        p_s = (1 - c_s) * p_s + math.sqrt(c_s * (2 - c_s) * mu_eff) * (c_inv_half @ y_w)
        p_c = (1 - c_c) * p_c + math.sqrt(c_c * (2 - c_c) * mu_eff) * y_w
        C = (1 - c_1 - c_mu) * C + c_1 * np.outer(p_c, p_c) + c_mu * (y_sel.T * w) @ y_sel
        sigma *= math.exp(c_s / d_s * (np.linalg.norm(p_s) / chi_n - 1))
    return best_x""",
            check="check_cma_es(cma_es)",
            after="""# How your CMA-ES closes in: the best cost against the evaluations spent.
f = rotated_ellipsoid()
for budget in (300, 1000, CMA_BUDGET):
    try:
        x = cma_es(f, np.zeros(6), 1.0, budget, 0)
    except NotImplementedError:
        print("(cma_es is not written yet)")
        break
    print(f"{budget:5d} evaluations: f = {f(x):.2e}")""",
        ),
        Exercise(
            markdown=TUNING_MARKDOWN,
            header='''def tune_mpc(evaluate, space, seeds, budget):
    """Weights {name: weight} tuned by your cma_es on the mean of evaluate over the seeds."""''',
            solution="""
    def f(x):  # the objective of a point of log10 space: the mean over the seeds
        weights = to_params(space, x)
        return float(np.mean([evaluate(weights, seed) for seed in seeds]))

    x_best = cma_es(f, space.x0(), 0.5, budget, 0)  # sigma0 = 0.5: steps of about 3x
    return to_params(space, x_best)""",
            check="check_mpc_tuning(tune_mpc)",
            after=TUNING_AFTER,
        ),
    ],
)

# A look at the lap before exercise 6.1 (inserted after the markdown of 6.1).
CH06_PEEK = """log, metrics, length = synthetic_lap(0)
print(f"{log.t.size} logged steps, {int(log.in_lap.sum())} in the lap, track length {length:.1f} m")
start = int(np.argmax(log.in_lap))  # first step of the lap
print("s_track around the line:", np.round(log.s_track[start - 2 : start + 2], 1))"""

CHAPTERS = [CH01, CH02, CH03, CH04, CH05, CH06]


def _display_math_apart(text: str) -> str:
    """Put every $$...$$ equation in a paragraph of its own.

    MyST (the book) reads display math reliably only as a block of its own; JupyterLab renders it
    either way.
    """
    text = re.sub(r"[ \t]*\n?\$\$(.+?)\$\$[ \t]*\n?", r"\n\n$$\1$$\n\n", text, flags=re.S)
    return re.sub(r"\n{3,}", "\n\n", text).strip("\n")


def build(chapter: Chapter, solved: bool) -> nbformat.NotebookNode:
    """The notebook of one chapter: the template (solved=False) or the solution."""

    def md(text: str) -> nbformat.NotebookNode:
        return nbformat.v4.new_markdown_cell(_display_math_apart(text))

    code = nbformat.v4.new_code_cell
    kind = "Solutions" if solved else "Exercises"
    title = chapter.title.replace("Exercises", kind, 1)
    cells = [md(f"# {title}\n\n{chapter.intro}")]
    if solved:
        cells.append(
            md(
                "*This is the solution notebook: every function is filled in and every check says "
                '"correct". Try the exercises in `exercises/' + chapter.name + ".ipynb` first.*"
            )
        )
    cells.append(code(f"{chapter.imports}\n\n{SETUP}"))
    for ex in chapter.exercises:
        cells.append(md(ex.markdown))
        if chapter is CH06 and ex is CH06.exercises[0]:
            cells.append(code(CH06_PEEK))
        body = ex.solution if solved else (ex.template or TODO)
        cells.append(code(f"{ex.header}\n{body}"))
        cells.append(code(f"{CHECK_MARK}\n{ex.check}"))
        if ex.after:
            cells.append(code(ex.after))
    if chapter.outro:
        cells.append(md(chapter.outro))
    nb = nbformat.v4.new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {
        "display_name": "Python 3",
        "language": "python",
        "name": "python3",
    }
    nb.metadata["language_info"] = {"name": "python"}
    return nb


def paths(chapter: Chapter) -> tuple[Path, Path]:
    """(template, solution) paths of a chapter."""
    return HERE / f"{chapter.name}.ipynb", HERE / "solutions" / f"{chapter.name}.ipynb"


def main(argv: list[str]) -> int:
    (HERE / "solutions").mkdir(exist_ok=True)
    for chapter in CHAPTERS:
        for path, solved in zip(paths(chapter), (False, True), strict=True):
            nb = build(chapter, solved)
            if path.exists():
                old = nbformat.read(path, as_version=4)
                if [(c.cell_type, c.source) for c in old.cells] == [
                    (c.cell_type, c.source) for c in nb.cells
                ]:
                    continue  # unchanged: keep the file and its checked outputs as they are
                # Cell ids are random; keep those of an existing file so diffs stay small.
                if len(old.cells) == len(nb.cells):
                    for new_cell, old_cell in zip(nb.cells, old.cells, strict=True):
                        if "id" in old_cell:
                            new_cell["id"] = old_cell["id"]
            nbformat.write(nb, path)
            print(f"{path.relative_to(HERE.parent)} written; run tools/refresh_notebooks.py on it")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
