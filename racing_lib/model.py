"""The planning and control model: a dynamic bicycle in Frenet coordinates, written once in CasADi.

Taught in notebook 02 ("the race vehicle model"); the planner (``racing_lib.planning``), the MPC
(``racing_lib.control.mpc``), system identification and the tests all use this one definition.

State and input (paper Eq. 1), indexed by :class:`X` and :class:`U`::

    xi = [v_x, v_y, r, e_psi, e_y, s]     (m/s, m/s, rad/s, rad, m, m)
    u  = [delta, a_x]                     (rad, m/s^2)

``a_x`` is the longitudinal acceleration produced by the tyres (drive or brake); drag, rolling
resistance and grade are modelled separately. Two per-point parameters come from the reference
line: its curvature ``kappa`` (1/m, > 0 for a left turn) and the road pitch ``theta`` (rad, > 0
uphill).

Term by term (time domain, ``xi_dot = g(xi, u; kappa, theta)``):

* Frenet kinematics (Eq. 2-4): ``s_dot = (v_x cos e_psi - v_y sin e_psi) / (1 - kappa e_y)``,
  ``e_psi_dot = r - kappa s_dot``, ``e_y_dot = v_x sin e_psi + v_y cos e_psi``.
* Longitudinal dynamics (Eq. 5): ``v_x_dot = a_x - (F_yf sin(delta) + R_x + F_xw)/m - g sin(theta)
  + r v_y`` with drag ``F_xw = C_xw v_x^2`` (Eq. 8; switch ``drag``; written ``C_xw v_x |v_x|``
  so that it always opposes the motion) and rolling resistance
  ``R_x = c_rr (F_zf + F_zr) = c_rr m g cos(theta)``.
* Lateral dynamics (Eq. 6-7): ``v_y_dot = (F_yf cos(delta) + F_yr)/m - r v_x`` and
  ``r_dot = (l_f F_yf cos(delta) - l_r F_yr)/I_zz``.
* Tyres (Eq. 9-10), simplified Pacejka: ``F_y = mu F_z D sin(C arctan(B alpha))`` with slip
  angles (Eq. 11) ``alpha_f = delta - (v_y + l_f r)/v_x`` and ``alpha_r = -(v_y - l_r r)/v_x``. The
  ``v_x`` in the denominator is replaced by a smooth maximum with :data:`VX_GUARD` so that the model
  stays finite at standstill; above about 2 m/s the difference is below 1e-3 m/s.
* Longitudinal load transfer (Eq. 12-14; switch ``longitudinal_weight_transfer``):
  ``Delta W = m v_x_dot h_c / (l_f + l_r)``, ``F_zf = m g cos(theta) l_r / L - Delta W``,
  ``F_zr = m g cos(theta) l_f / L + Delta W``. The vertical acceleration ``a_z`` of Eq. 13-14 is
  taken as zero (no vertical curvature of the road).
* Lateral load transfer (Eq. 15 and Appendix A; switch ``lateral_weight_transfer``, the double-track
  variant): ``Delta W_F = m a_y h_c / l_t * l_r / L`` moves load from the inner to the outer front
  wheel. Both front wheels share one slip angle and the tyre force is proportional to the load, so
  the axle's total force is unchanged; only the yaw moment of the two rotated front forces remains:
  ``r_dot += 0.5 l_t (F_yFL - F_yFR) sin(delta) / I_zz``
  ``= -0.5 l_t mu D_f sin(C_f arctan(B_f alpha_f)) Delta W_F sin(delta) / I_zz``.
  We use the lateral acceleration of the centre of gravity, ``a_y = v_y_dot + r v_x``, where the
  paper writes ``V_y_dot``: in steady cornering ``V_y_dot = 0`` and the literal reading would
  transfer no load at all. (The paper's ``F_zRL = (F_zf - Delta W_R)/2`` is a typo for ``F_zr``;
  the rear split does not change the dynamics either way.) This model keeps the paper's form
  ``F_zFL = (F_zf - Delta W_F)/2`` as printed, which moves only half the load a roll-moment
  balance needs (``Delta W_F/2`` per wheel instead of ``Delta W_F``); with tyres proportional to
  the load it only scales the small yaw term above. The simulated car uses the physical loads
  (:func:`racing_lib.vehicle.wheel_loads`), where load-sensitive tyres make the difference matter.

The algebraic loop of Eq. 5 and 12-13
-------------------------------------
``Delta W`` needs ``v_x_dot``, which needs ``F_yf`` (through ``F_yf sin(delta)``), which needs
``F_zf``, which needs ``Delta W``. Because the simplified Pacejka force is *proportional* to the
load, ``F_yf = phi_f F_zf`` with ``phi_f = mu D_f sin(C_f arctan(B_f alpha_f))`` independent of the
load, the loop is one *linear* scalar equation in ``v_x_dot``::

    v_x_dot = c - k (F_zf0 - m h_c v_x_dot / L) / m,   k = phi_f sin(delta),
    c = a_x - (R_x + F_xw)/m - g sin(theta) + r v_y,   F_zf0 = m g cos(theta) l_r / L

whose solution is ``v_x_dot = (c - k F_zf0 / m) / (1 - k h_c / L)``. We use this closed form: it
is exact (residual at round-off level, checked in ``tests/test_model.py``), explicit, smooth, and
cheaper than unrolled fixed-point iterations. The denominator cannot vanish:
``|k| <= mu D_f |sin(delta)|``, so for the default car ``|k h_c / L| <= 0.3 |sin(delta)|`` (0.14
at the steering limit of 0.5 rad). The closed form relies on the force being proportional to the
load, which holds for the paper's tyre law (``racing_lib.vehicle.pacejka_lateral``, reused here
like every force law of ``racing_lib.vehicle``); a load-sensitive tyre would need an iteration.

Spatial domain (Section "Trajectory Planning"): ``dxi/ds = xi_dot / s_dot``; its ``s`` component is
exactly 1. Neither form guards ``s_dot`` against zero: the car must move forward along the line.

Everything is built with CasADi SX and returned as ``casadi.Function`` objects (cached per parameter
set and options), plus :class:`Model`, a numpy convenience wrapper. Numpy batches hold one state per
*row* (shape ``(N, 6)``); CasADi functions and their ``map`` hold one state per *column*.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import ModelError

# The force laws are defined once, in vehicle.py, for floats, numpy and CasADi alike
from racing_lib.vehicle import (
    VehicleParams,
    axle_cornering_stiffness,
    drag_force,
    lateral_load_transfer,
    longitudinal_load_transfer,
    pacejka_lateral,
    rolling_resistance,
    static_axle_loads,
)

__all__ = [
    "NU",
    "NX",
    "VX_GUARD",
    "U",
    "X",
    "Model",
    "ModelOptions",
    "ModelParams",
    "PedalMap",
    "discrete_dynamics",
    "discrete_linearization",
    "discretize",
    "jacobians",
    "model_terms",
    "spatial_dynamics",
    "time_dynamics",
]


class X(IntEnum):
    """Indices of the state vector ``xi``."""

    VX = 0  #: longitudinal velocity in the body frame, m/s
    VY = 1  #: lateral velocity in the body frame (left positive), m/s
    R = 2  #: yaw rate, rad/s (counter-clockwise positive)
    EPSI = 3  #: heading error to the reference line, rad
    EY = 4  #: lateral offset from the reference line (left positive), m
    S = 5  #: arc length along the reference line, m


class U(IntEnum):
    """Indices of the input vector ``u``."""

    DELTA = 0  #: front steering angle, rad (left positive)
    AX = 1  #: longitudinal acceleration produced by the tyres, m/s^2


NX: int = len(X)
NU: int = len(U)

#: Smooth lower bound (m/s) used for ``v_x`` in the slip-angle denominators.
VX_GUARD: float = 1.0
#: Width (m/s) of the smooth corner of that bound; the error at ``v_x >> VX_GUARD`` is about
#: ``VX_GUARD_WIDTH**2 / (4 (v_x - VX_GUARD))``.
VX_GUARD_WIDTH: float = 0.1

Method = Literal["rk4", "euler"]
Domain = Literal["time", "spatial"]


# --------------------------------------------------------------------------------------------------
# Options and parameters
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelOptions:
    """Which physical effects the model includes (the paper's ablations, Section "Vehicle Model
    Analysis"). Each switch changes exactly the terms it names and nothing else.

    Attributes
    ----------
    drag : bool
        Aerodynamic drag ``F_xw = C_xw v_x^2`` in the longitudinal balance (Eq. 5, 8).
    longitudinal_weight_transfer : bool
        Load transfer ``Delta W = m v_x_dot h_c / L`` between the axles (Eq. 12-14). Off: static
        loads.
    lateral_weight_transfer : bool
        Double-track variant (Appendix A): left/right load transfer ``Delta W_F``, ``Delta W_R``
        (Eq. 15) and the resulting extra yaw moment of the front tyres.
    """

    drag: bool = True
    longitudinal_weight_transfer: bool = True
    lateral_weight_transfer: bool = False

    def label(self) -> str:
        """Short text such as ``"drag+lon"`` for file names and plot legends."""
        parts = [
            name
            for name, on in (
                ("drag", self.drag),
                ("lon", self.longitudinal_weight_transfer),
                ("lat", self.lateral_weight_transfer),
            )
            if on
        ]
        return "+".join(parts) if parts else "plain"


def _as_float(name: str, value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{name} must be a number; got {value!r}.") from None
    if not math.isfinite(out):
        raise ModelError(f"{name} must be finite; got {out}.")
    return out


#: Share of the braking limit ``a_brk_max`` up to which braking stays linear in the pedal
#: (:class:`PedalMap`); the simulated car's stops are linear to about 0.85 of the limit.
BRAKE_KNEE = 0.8


@dataclass(frozen=True)
class PedalMap:
    """Empirical map between the pedal ``u_p`` in [-1, 1] and the tyre acceleration ``a_x``.

    Appendix C of the paper, with separate throttle and brake slopes:

    ``a_x = m_0 + m_xi . xi + g_thr(v_x) * max(u_p, 0) + m_brk * min(u_p, 0)``   (m/s^2)

    with the full-throttle gain ``g_thr(v_x) = min(m_thr, p_thr / v_x)``.

    The paper fits one linear map ``a_x = M [xi; u_p]``. Our simulated car has a nonlinear
    powertrain (torque curve, gears, power limit) and brakes that are far stronger than the engine:
    one slope through both throttle and brake data fits neither (full brake is about three times
    full throttle). So the pedal part has one slope for throttle (``u_p >= 0``) and one for brake
    (``u_p < 0``), while the state part ``m_0 + m_xi . xi`` (what the car does with the pedal
    released: engine braking, speed dependence) is shared, which keeps the map continuous at
    ``u_p = 0`` and monotone, hence invertible. With ``m_thr == m_brk`` (see :meth:`from_linear`)
    it is exactly the paper's single linear map.

    An engine delivers at most its power ``P``, so full throttle cannot add more than
    ``P / (m v_x)`` at speed ``v_x``: a straight line in ``v_x`` overstates the throttle at the
    top of the speed range by up to 2x (1.5 against 1.0 m/s^2 at 50 m/s on the default car), and a
    planner that believes it plans straights the car cannot drive. ``p_thr`` (power per unit
    mass, W/kg) caps the throttle gain by that hyperbola; ``None`` leaves the map linear, as in
    the paper. Likewise the brakes can ask for more than the tyres give: ``a_brk_max`` is the
    deceleration the tyres deliver at full brake in a straight line (the longitudinal tyre limit
    of the paper's Appendix C). The brake part then stays ``m_brk u_p`` down to
    ``BRAKE_KNEE a_brk_max`` and bends linearly from there to ``a_brk_max`` at ``u_p = -1``:
    continuous, monotone and invertible, and close to an anti-lock system that gives less and
    less extra deceleration per unit of pedal as it nears the grip. The defaults are placeholders of
    plausible size for the default car; ``racing_lib.sysid`` fits the real coefficients.

    Attributes
    ----------
    m_0 : float
        Intercept, m/s^2.
    m_xi : tuple of 6 floats
        State coefficients in the order of :class:`X`, m/s^2 per unit of each state (e.g. 1/s for
        ``v_x``).
    m_thr : float
        Acceleration added by full throttle, m/s^2 (> 0).
    m_brk : float
        Deceleration added by full brake, m/s^2 (> 0).
    p_thr : float or None
        Largest throttle power per unit mass, W/kg (m^2/s^3): full throttle adds at most
        ``p_thr / v_x``. None: no power limit (the paper's linear map).
    a_brk_max : float or None
        Tyre deceleration at full brake, m/s^2 (> 0), the tyres' limit (see above). None, or a
        value of ``m_brk`` or more: braking is linear in the pedal to ``-m_brk``.
    """

    m_0: float = 1.0
    m_xi: tuple[float, ...] = (-0.06, 0.0, 0.0, 0.0, 0.0, 0.0)
    m_thr: float = 3.0
    m_brk: float = 9.0
    p_thr: float | None = None
    a_brk_max: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "m_0", _as_float("PedalMap.m_0", self.m_0))
        try:
            m_xi = tuple(_as_float("PedalMap.m_xi", v) for v in np.asarray(self.m_xi).ravel())
        except TypeError:
            raise ModelError(f"PedalMap.m_xi must be {NX} numbers; got {self.m_xi!r}.") from None
        if len(m_xi) != NX:
            raise ModelError(
                f"PedalMap.m_xi must have {NX} entries (one per state {[x.name for x in X]}); "
                f"got {len(m_xi)}."
            )
        object.__setattr__(self, "m_xi", m_xi)
        for name in ("m_thr", "m_brk"):
            value = _as_float(f"PedalMap.{name}", getattr(self, name))
            if value <= 0.0:
                raise ModelError(
                    f"PedalMap.{name} must be > 0 so that the pedal map is invertible; "
                    f"got {value}. Refit the map with data that contain both throttle and brake."
                )
            object.__setattr__(self, name, value)
        for name, unit in (("p_thr", "W/kg"), ("a_brk_max", "m/s^2")):
            if getattr(self, name) is None:
                continue
            value = _as_float(f"PedalMap.{name}", getattr(self, name))
            if value <= 0.0:
                raise ModelError(
                    f"PedalMap.{name} must be > 0 {unit} (or None for no limit); got {value}."
                )
            object.__setattr__(self, name, value)

    # --- construction -----------------------------------------------------------------------------
    @classmethod
    def from_coefficients(cls, coefficients: ArrayLike) -> PedalMap:
        """Build from ``[m_0, m_xi (6 values), m_thr, m_brk]`` (9 numbers, the order of
        :meth:`coefficients`)."""
        c = np.asarray(coefficients, dtype=float).ravel()
        if c.size != NX + 3:
            raise ModelError(
                f"PedalMap coefficients must be {NX + 3} numbers [m_0, m_xi x{NX}, m_thr, m_brk]; "
                f"got {c.size}."
            )
        return cls(m_0=c[0], m_xi=tuple(c[1 : 1 + NX]), m_thr=c[1 + NX], m_brk=c[2 + NX])

    @classmethod
    def from_linear(cls, M: ArrayLike, m_0: float = 0.0) -> PedalMap:
        """The paper's single map ``a_x = m_0 + M [xi; u_p]`` (``M``: 7 numbers)."""
        M = np.asarray(M, dtype=float).ravel()
        if M.size != NX + 1:
            raise ModelError(f"M must have {NX + 1} entries ([xi; u_p]); got {M.size}.")
        return cls(m_0=m_0, m_xi=tuple(M[:NX]), m_thr=M[NX], m_brk=M[NX])

    def coefficients(self) -> np.ndarray:
        """``[m_0, m_xi..., m_thr, m_brk]`` as a float array of shape (9,)."""
        return np.array([self.m_0, *self.m_xi, self.m_thr, self.m_brk])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "m_0": self.m_0,
            "m_xi": list(self.m_xi),
            "m_thr": self.m_thr,
            "m_brk": self.m_brk,
            "p_thr": self.p_thr,
            "a_brk_max": self.a_brk_max,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PedalMap:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`ModelError`."""
        _check_keys("PedalMap", data, {f.name for f in dataclasses.fields(cls)})
        kwargs = dict(data)
        if "m_xi" in kwargs:
            kwargs["m_xi"] = tuple(kwargs["m_xi"])
        return cls(**kwargs)

    # --- evaluation -------------------------------------------------------------------------------
    def _base(self, xi: Any) -> Any:
        """``m_0 + m_xi . xi``: numpy rows ``(N, 6)`` -> ``(N,)``; CasADi columns -> ``1 x N``."""
        if isinstance(xi, ca.SX | ca.MX | ca.DM):
            if xi.size1() != NX:
                raise ModelError(f"symbolic xi must have {NX} rows; got {xi.size1()}.")
            return self.m_0 + ca.mtimes(ca.DM(self.m_xi).T, xi)
        xi = _state_rows(xi)
        out = self.m_0 + xi @ np.asarray(self.m_xi)
        return out

    def throttle_gain(self, v_x: Any) -> Any:
        """Acceleration added by full throttle at speed ``v_x`` (m/s), m/s^2:
        ``min(m_thr, p_thr / v_x)`` (``m_thr`` without a power limit).

        Works on floats, arrays and CasADi expressions. Below 1 m/s the speed is taken as 1 m/s
        (the hyperbola has no meaning at standstill, where ``m_thr`` binds anyway).
        """
        if self.p_thr is None:
            return self.m_thr
        if isinstance(v_x, ca.SX | ca.MX | ca.DM):
            return ca.fmin(self.m_thr, self.p_thr / ca.fmax(v_x, 1.0))
        return np.minimum(self.m_thr, self.p_thr / np.maximum(np.asarray(v_x, dtype=float), 1.0))

    def _brake_knee(self) -> tuple[float, float, float] | None:
        """``(u_k, a_k, slope)``: the pedal and deceleration (m/s^2) where braking bends, and the
        slope below it (m/s^2 per unit pedal); None when braking is linear to full brake."""
        if self.a_brk_max is None or self.a_brk_max >= self.m_brk:
            return None
        a_k = BRAKE_KNEE * self.a_brk_max
        u_k = -a_k / self.m_brk
        return u_k, a_k, (self.a_brk_max - a_k) / (1.0 + u_k)

    def _brake(self, u_p: Any) -> Any:
        """Brake part of ``a_x`` (m/s^2, <= 0) for pedal(s) ``u_p``; numpy or CasADi."""
        sym = isinstance(u_p, ca.SX | ca.MX | ca.DM)
        fmin, fmax = (ca.fmin, ca.fmax) if sym else (np.minimum, np.maximum)
        w = fmin(u_p, 0.0)
        knee = self._brake_knee()
        if knee is None:
            return self.m_brk * w
        u_k, _, slope = knee
        return self.m_brk * fmax(w, u_k) + slope * fmin(w - u_k, 0.0)

    def _speed(self, xi: Any) -> Any:
        """``v_x`` of state(s) ``xi``: CasADi row ``1 x N`` or numpy ``(N,)``."""
        if isinstance(xi, ca.SX | ca.MX | ca.DM):
            return xi[int(X.VX), :]
        return _state_rows(xi)[:, X.VX]

    def ax(self, xi: Any, u_p: Any) -> Any:
        """Tyre acceleration ``a_x`` (m/s^2) for state(s) ``xi`` and pedal ``u_p`` in [-1, 1].

        ``xi``: shape (6,) or (N, 6) (or a CasADi column / 6 x N matrix); ``u_p``: scalar or (N,).
        Returns a float, an array of shape (N,), or a CasADi expression.
        """
        gain = self.throttle_gain(self._speed(xi))
        if isinstance(xi, ca.SX | ca.MX | ca.DM) or isinstance(u_p, ca.SX | ca.MX):
            return self._base(xi) + gain * ca.fmax(u_p, 0) + self._brake(u_p)
        scalar = np.ndim(xi) == 1 and np.ndim(u_p) == 0
        u_p = np.asarray(u_p, dtype=float)
        out = self._base(xi) + gain * np.maximum(u_p, 0.0) + self._brake(u_p)
        return float(out[0]) if scalar else out

    def limits(self, xi: Any) -> tuple[Any, Any]:
        """``(a_min, a_max)`` in m/s^2: ``a_x`` at full brake (``u_p=-1``) and full throttle
        (``u_p=+1``) for state(s) ``xi`` of shape (6,) or (N, 6) (or CasADi columns)."""
        base = self._base(xi)
        gain = self.throttle_gain(self._speed(xi))
        if not isinstance(base, ca.SX | ca.MX | ca.DM) and np.ndim(xi) == 1:
            base, gain = float(base[0]), float(np.ravel(gain)[0])
        return base - self.full_brake(), base + gain

    def full_brake(self) -> float:
        """Deceleration added by full brake, m/s^2: ``a_brk_max`` if the tyres limit it, else
        ``m_brk``."""
        return self.m_brk if self._brake_knee() is None else float(self.a_brk_max)

    def limits_at_speed(self, v_x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(a_min, a_max)`` in m/s^2 at speed(s) ``v_x`` (m/s) with every other state zero
        (straight driving on the line): arrays shaped like ``v_x``, for speed profiles."""
        v = np.asarray(v_x, dtype=float)
        xi = np.zeros((v.size, NX))
        xi[:, X.VX] = v.ravel()
        lo, hi = self.limits(xi)
        return lo.reshape(v.shape), hi.reshape(v.shape)

    def pedal(self, a_x: ArrayLike, xi: ArrayLike) -> Any:
        """Pedal ``u_p`` in [-1, 1] that produces ``a_x`` (m/s^2) in state(s) ``xi``; clipped.

        Shapes as in :meth:`ax`; numpy only (the controller's last step).
        """
        scalar = np.ndim(xi) == 1 and np.ndim(a_x) == 0
        excess = np.asarray(a_x, dtype=float) - self._base(xi)
        gain = self.throttle_gain(self._speed(xi))
        u_brake = excess / self.m_brk
        knee = self._brake_knee()
        if knee is not None:
            u_k, a_k, slope = knee
            u_brake = np.where(excess >= -a_k, u_brake, u_k + (excess + a_k) / slope)
        u_p = np.where(excess >= 0.0, excess / gain, u_brake)
        u_p = np.clip(u_p, -1.0, 1.0)
        return float(u_p[0]) if scalar else u_p


def _check_keys(what: str, data: Mapping[str, Any], allowed: set[str]) -> None:
    if not isinstance(data, Mapping):
        raise ModelError(f"{what} data must be a mapping (JSON object); got {type(data).__name__}.")
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ModelError(
            f"unknown {what} field(s) {unknown}; allowed: {sorted(allowed)}. "
            "Check the JSON file's origin and version."
        )


# Fields that must be > 0, and those that must be >= 0 (zero switches the effect off).
_POSITIVE = ("m", "l_f", "l_r", "l_t", "mu", "I_zz", "B_f", "C_f", "D_f", "B_r", "C_r", "D_r", "g")
_NON_NEGATIVE = ("h_c", "C_xw", "c_rr")


@dataclass(frozen=True)
class ModelParams:
    """Parameters of the planning/control model (a frozen, hashable value object).

    Defaults: the simulated car's true values (``racing_lib.vehicle.VehicleParams``: the paper's
    Mazda Demio table for ``m, l_f, l_r, h_c, mu, C_xw, I_zz``, documented choices for the rest) and
    a placeholder pedal map. Use :meth:`from_vehicle` for another car and :meth:`load` for an
    identified set.

    Attributes
    ----------
    m : float
        Mass, kg.
    l_f : float
        Distance from the centre of gravity (CoG) to the front axle, m.
    l_r : float
        Distance from the CoG to the rear axle, m.
    h_c : float
        Height of the CoG above the ground, m.
    l_t : float
        Track width (distance between the left and right wheels), m; used only with lateral load
        transfer.
    mu : float
        Tyre-road friction coefficient, dimensionless.
    C_xw : float
        Drag coefficient in ``F_xw = C_xw v_x^2``, kg/m (N s^2/m^2).
    I_zz : float
        Yaw moment of inertia, kg m^2.
    c_rr : float
        Rolling-resistance coefficient, ``R_x = c_rr * (F_zf + F_zr)``, dimensionless.
    B_f, C_f, D_f : float
        Front-axle Pacejka stiffness (1/rad), shape and peak factors (dimensionless).
    B_r, C_r, D_r : float
        Rear-axle Pacejka factors, as for the front.
    g : float
        Gravitational acceleration, m/s^2.
    pedal : PedalMap
        Map between pedal and tyre acceleration (Appendix C), also giving the ``a_x`` limits.
    """

    # Defaults: the simulated car's true values, defined once in VehicleParams
    m: float = VehicleParams.m
    l_f: float = VehicleParams.l_f
    l_r: float = VehicleParams.l_r
    h_c: float = VehicleParams.h_c
    l_t: float = VehicleParams.l_t
    mu: float = VehicleParams.mu
    C_xw: float = VehicleParams.C_xw
    I_zz: float = VehicleParams.I_zz
    c_rr: float = VehicleParams.c_rr
    B_f: float = VehicleParams.B_f
    C_f: float = VehicleParams.C_f
    D_f: float = VehicleParams.D_f
    B_r: float = VehicleParams.B_r
    C_r: float = VehicleParams.C_r
    D_r: float = VehicleParams.D_r
    g: float = VehicleParams.g
    pedal: PedalMap = field(default_factory=PedalMap)

    def __post_init__(self) -> None:
        for name in _POSITIVE:
            value = _as_float(f"ModelParams.{name}", getattr(self, name))
            if value <= 0.0:
                raise ModelError(f"ModelParams.{name} must be > 0; got {value}.")
            object.__setattr__(self, name, value)
        for name in _NON_NEGATIVE:
            value = _as_float(f"ModelParams.{name}", getattr(self, name))
            if value < 0.0:
                raise ModelError(
                    f"ModelParams.{name} must be >= 0 (use ModelOptions to switch effects off); "
                    f"got {value}."
                )
            object.__setattr__(self, name, value)
        if not isinstance(self.pedal, PedalMap):
            raise ModelError(f"ModelParams.pedal must be a PedalMap; got {type(self.pedal)}.")
        for axle in ("f", "r"):
            C = getattr(self, f"C_{axle}")
            if C >= 2.0:
                raise ModelError(
                    f"ModelParams.C_{axle} = {C} must be < 2 for a tyre curve with a peak "
                    "(typical lateral values 1.2-1.9)."
                )

    # --- derived quantities -----------------------------------------------------------------------
    @property
    def wheelbase(self) -> float:
        """``L = l_f + l_r``, m."""
        return self.l_f + self.l_r

    def static_loads(self, theta: float = 0.0) -> tuple[float, float]:
        """Static axle loads ``(F_zf0, F_zr0)`` in N on a road of pitch ``theta`` (rad)."""
        F_zf, F_zr = static_axle_loads(self.m, self.l_f, self.l_r, self.g, float(theta))
        return float(F_zf), float(F_zr)

    def cornering_stiffness(self, theta: float = 0.0) -> tuple[float, float]:
        """Linear cornering stiffnesses ``C_alpha = mu F_z0 B C D`` (N/rad) at the static loads: the
        slope of the Pacejka curve at zero slip."""
        F_zf, F_zr = self.static_loads(theta)
        return (
            axle_cornering_stiffness(F_zf, self.mu, self.B_f, self.C_f, self.D_f),
            axle_cornering_stiffness(F_zr, self.mu, self.B_r, self.C_r, self.D_r),
        )

    def peak_slip_angle(self) -> tuple[float, float]:
        """Slip angles (rad) of the front and rear force peaks: ``tan(pi / (2 C)) / B``.

        Bound ``|alpha|`` by these in planning to keep the tyres on the stable side of the curve.
        """
        return (
            math.tan(math.pi / (2.0 * self.C_f)) / self.B_f,
            math.tan(math.pi / (2.0 * self.C_r)) / self.B_r,
        )

    def slip_angle_at(self, share: float) -> tuple[float, float]:
        """Slip angles (rad) where the front and rear forces reach ``share`` of their peak.

        On the rising side of ``sin(C arctan(B alpha))``: ``tan(arcsin(share) / C) / B``;
        ``share = 1`` gives :meth:`peak_slip_angle`. A broad tyre curve (``C`` near 1) reaches
        95 % of its peak at about half the peak's slip angle.
        """
        if not 0.0 < share <= 1.0:
            raise ModelError(f"share must be in (0, 1], got {share!r}.")
        lift = math.asin(share)
        return (
            math.tan(lift / self.C_f) / self.B_f,
            math.tan(lift / self.C_r) / self.B_r,
        )

    def peak_acceleration(self) -> float:
        """Largest acceleration the tyres can give in any direction, m/s^2: ``mu min(D_f, D_r) g``.

        The radius of the friction ellipse (a circle here) that planning and control put around
        ``(a_x, a_y)``: the model's lateral tyre forces know nothing of braking, the car's do.
        """
        return self.mu * min(self.D_f, self.D_r) * self.g

    def replace(self, **changes: Any) -> ModelParams:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    # --- conversion -------------------------------------------------------------------------------
    @classmethod
    def from_vehicle(cls, vehicle: Any, pedal: PedalMap | None = None) -> ModelParams:
        """The simulated car's true values (``racing_lib.vehicle.VehicleParams``).

        The pedal map is not a parameter of the car (its powertrain is nonlinear): pass an
        identified one, or get the placeholder default.
        """
        names = {f.name for f in dataclasses.fields(cls)} - {"pedal"}
        values: dict[str, Any] = {}
        missing = []
        for name in sorted(names):
            if hasattr(vehicle, name):
                values[name] = getattr(vehicle, name)
            elif name != "g":
                missing.append(name)
        if missing:
            raise ModelError(
                f"{type(vehicle).__name__} lacks the model parameter(s) {missing}; pass a "
                "racing_lib.vehicle.VehicleParams or build ModelParams(...) directly."
            )
        return cls(**values, pedal=pedal if pedal is not None else PedalMap())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (the pedal map nested under ``"pedal"``)."""
        out: dict[str, Any] = {
            f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "pedal"
        }
        out["pedal"] = self.pedal.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModelParams:
        """Inverse of :meth:`to_dict`. Missing fields take their defaults; unknown ones raise."""
        _check_keys("ModelParams", data, {f.name for f in dataclasses.fields(cls)})
        kwargs = dict(data)
        if "pedal" in kwargs and not isinstance(kwargs["pedal"], PedalMap):
            kwargs["pedal"] = PedalMap.from_dict(kwargs["pedal"])
        return cls(**kwargs)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write as JSON, atomically (temporary file, then rename)."""
        from racing_lib.io import atomic_write_json

        atomic_write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ModelParams:
        """Read a JSON file written by :meth:`save`."""
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ModelError(f"model parameter file {path} does not exist.") from None
        except json.JSONDecodeError as exc:
            raise ModelError(f"model parameter file {path} is not valid JSON: {exc}.") from None
        return cls.from_dict(data)


# --------------------------------------------------------------------------------------------------
# The equations (the one definition)
# --------------------------------------------------------------------------------------------------


def _smooth_max(x: Any, lower: float, width: float) -> Any:
    """``max(x, lower)`` with a hyperbolic corner of size ``width`` (smooth, exact far away)."""
    return 0.5 * (x + lower + ca.sqrt((x - lower) ** 2 + width**2))


def frenet_kinematics(
    v_x: Any, v_y: Any, r: Any, e_psi: Any, e_y: Any, kappa: Any, ops: Any = ca
) -> tuple[Any, Any, Any]:
    """The Frenet kinematics of the paper's Eq. (2)-(4), for any math backend.

    The one definition of these rows: the model's dynamics use it, and so does any other model
    written in Frenet coordinates (the best-lap planner on the simulated car's equations).

    Parameters
    ----------
    v_x, v_y : float, array or casadi expression
        Body-frame velocities, m/s.
    r : float, array or casadi expression
        Yaw rate, rad/s.
    e_psi, e_y : float, array or casadi expression
        Heading error (rad) and lateral offset (m, left positive) to the reference line.
    kappa : float, array or casadi expression
        Curvature of the reference line at the car's s, 1/m.
    ops : module
        Provides ``sin`` and ``cos``: ``casadi`` (default), ``numpy`` or ``math``.

    Returns
    -------
    s_dot, e_psi_dot, e_y_dot
        Progress along the line (m/s), heading-error rate (rad/s), lateral rate (m/s).
    """
    s_dot = (v_x * ops.cos(e_psi) - v_y * ops.sin(e_psi)) / (1 - kappa * e_y)
    return s_dot, r - kappa * s_dot, v_x * ops.sin(e_psi) + v_y * ops.cos(e_psi)


def _equations(
    xi: ca.SX, u: ca.SX, kappa: ca.SX, theta: ca.SX, p: ModelParams, o: ModelOptions
) -> tuple[ca.SX, dict[str, ca.SX]]:
    """Time-domain right-hand side and the named intermediate terms, symbolically."""
    v_x, v_y, r, e_psi, e_y = (xi[X.VX], xi[X.VY], xi[X.R], xi[X.EPSI], xi[X.EY])
    delta, a_x = u[U.DELTA], u[U.AX]
    L = p.wheelbase

    s_dot, e_psi_dot, e_y_dot = frenet_kinematics(v_x, v_y, r, e_psi, e_y, kappa, ca)

    # Slip angles, Eq. (11), with a guarded v_x so standstill does not divide by zero
    v_x_safe = _smooth_max(v_x, VX_GUARD, VX_GUARD_WIDTH)
    alpha_f = delta - (v_y + p.l_f * r) / v_x_safe
    alpha_r = -(v_y - p.l_r * r) / v_x_safe

    # Tyre force per newton of load: the simplified Pacejka force is proportional to F_z
    phi_f = pacejka_lateral(alpha_f, 1.0, p.mu, p.B_f, p.C_f, p.D_f)
    phi_r = pacejka_lateral(alpha_r, 1.0, p.mu, p.B_r, p.C_r, p.D_r)

    # Static loads, Eq. (13)-(14) with Delta W = 0 and a_z = 0
    F_zf0, F_zr0 = static_axle_loads(p.m, p.l_f, p.l_r, p.g, theta)

    F_xw = drag_force(v_x, p.C_xw) if o.drag else ca.SX(0)  # Eq. (8), C_xw v_x |v_x|
    R_x = rolling_resistance(F_zf0 + F_zr0, p.c_rr)  # total load does not depend on Delta W

    # Longitudinal balance, Eq. (5), without the F_yf sin(delta) coupling
    c = a_x - (R_x + F_xw) / p.m - p.g * ca.sin(theta) + r * v_y
    k = phi_f * ca.sin(delta)  # F_yf sin(delta) = k F_zf
    if o.longitudinal_weight_transfer:
        # Exact solution of the linear loop v_x_dot = c - k (F_zf0 - m h_c v_x_dot / L) / m
        v_x_dot = (c - k * F_zf0 / p.m) / (1 - k * p.h_c / L)
        delta_W = longitudinal_load_transfer(p.m, v_x_dot, p.h_c, p.l_f, p.l_r)  # Eq. (12)
    else:
        v_x_dot = c - k * F_zf0 / p.m
        delta_W = ca.SX(0)
    F_zf = F_zf0 - delta_W
    F_zr = F_zr0 + delta_W
    F_yf = phi_f * F_zf  # Eq. (9)
    F_yr = phi_r * F_zr  # Eq. (10)

    # Lateral dynamics, Eq. (6)-(7)
    a_y = (F_yf * ca.cos(delta) + F_yr) / p.m  # lateral acceleration of the CoG
    v_y_dot = a_y - r * v_x
    r_dot = (p.l_f * F_yf * ca.cos(delta) - p.l_r * F_yr) / p.I_zz
    if o.lateral_weight_transfer:
        # Eq. (15) with a_y (see module docstring); left wheels lose load in a left turn
        delta_W_F, delta_W_R = lateral_load_transfer(p.m, a_y, p.h_c, p.l_t, p.l_f, p.l_r)
        F_yFL = phi_f * (F_zf - delta_W_F) / 2
        F_yFR = phi_f * (F_zf + delta_W_F) / 2
        # Appendix A: the rotated front forces act at +-l_t/2 and add a yaw moment
        r_dot = r_dot + 0.5 * p.l_t * (F_yFL - F_yFR) * ca.sin(delta) / p.I_zz
    else:
        delta_W_F = ca.SX(0)
        delta_W_R = ca.SX(0)

    xi_dot = ca.vertcat(v_x_dot, v_y_dot, r_dot, e_psi_dot, e_y_dot, s_dot)
    terms = {
        "s_dot": s_dot,
        "alpha_f": alpha_f,
        "alpha_r": alpha_r,
        "F_zf": F_zf,
        "F_zr": F_zr,
        "F_yf": F_yf,
        "F_yr": F_yr,
        "F_xw": F_xw,
        "R_x": R_x,
        "delta_W": delta_W,
        "delta_W_F": delta_W_F,
        "delta_W_R": delta_W_R,
        "a_y": a_y,
    }
    return xi_dot, terms


def _symbols() -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    return ca.SX.sym("xi", NX), ca.SX.sym("u", NU), ca.SX.sym("kappa"), ca.SX.sym("theta")


_IN = ["xi", "u", "kappa", "theta"]


def _check_args(params: Any, options: Any) -> None:
    if not isinstance(params, ModelParams):
        raise ModelError(f"params must be a ModelParams; got {type(params).__name__}.")
    if not isinstance(options, ModelOptions):
        raise ModelError(f"options must be a ModelOptions; got {type(options).__name__}.")


def _check_method_domain(method: str, domain: str) -> None:
    if method not in ("rk4", "euler"):
        raise ModelError(f"unknown method {method!r}; use 'rk4' or 'euler'.")
    if domain not in ("time", "spatial"):
        raise ModelError(f"unknown domain {domain!r}; use 'time' or 'spatial'.")


def _cached(fn: Any) -> Any:
    """Cache a Function builder on its full argument tuple (defaults filled in), so that
    ``time_dynamics()`` and ``time_dynamics(ModelParams(), ModelOptions())`` share one build."""
    signature = inspect.signature(fn)
    inner = functools.lru_cache(maxsize=64)(fn)

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        try:
            hash(bound.args)
        except TypeError:
            raise ModelError(
                f"{fn.__name__} takes a ModelParams, a ModelOptions and plain numbers/strings; "
                f"got {[type(a).__name__ for a in bound.args]}."
            ) from None
        return inner(*bound.args)

    wrapper.cache_clear = inner.cache_clear  # type: ignore[attr-defined]
    return wrapper


@_cached
def time_dynamics(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """``f(xi, u, kappa, theta) -> xi_dot``: the time-domain model (Eq. 2-15), a CasADi Function.

    Inputs: ``xi`` (6x1; m/s, m/s, rad/s, rad, m, m), ``u`` (2x1; rad, m/s^2), ``kappa`` (1/m),
    ``theta`` (rad). Output ``xi_dot`` (6x1, time derivatives). Cached per (params, options).
    """
    _check_args(params, options)
    xi, u, kappa, theta = _symbols()
    xi_dot, _ = _equations(xi, u, kappa, theta, params, options)
    return ca.Function("f_time", [xi, u, kappa, theta], [xi_dot], _IN, ["xi_dot"])


@_cached
def spatial_dynamics(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """``f_s(xi, u, kappa, theta) -> dxi/ds = xi_dot / s_dot``: the spatial-domain model.

    Same inputs as :func:`time_dynamics`; the ``s`` component of the output is exactly 1.
    """
    _check_args(params, options)
    xi, u, kappa, theta = _symbols()
    xi_dot, terms = _equations(xi, u, kappa, theta, params, options)
    dxi_ds = xi_dot / terms["s_dot"]
    dxi_ds[X.S] = 1.0
    return ca.Function("f_spatial", [xi, u, kappa, theta], [dxi_ds], _IN, ["dxi_ds"])


@_cached
def model_terms(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """Intermediate quantities (named outputs) for plots, constraints and checks.

    ``(xi, u, kappa, theta) -> s_dot (m/s), alpha_f, alpha_r (rad), F_zf, F_zr, F_yf, F_yr, F_xw,
    R_x, delta_W, delta_W_F, delta_W_R (N), a_y (m/s^2)``. Use ``fn(xi=..., u=..., ...)["F_zf"]``.
    """
    _check_args(params, options)
    xi, u, kappa, theta = _symbols()
    _, terms = _equations(xi, u, kappa, theta, params, options)
    return ca.Function(
        "model_terms", [xi, u, kappa, theta], list(terms.values()), _IN, list(terms.keys())
    )


def _continuous(params: ModelParams, options: ModelOptions, domain: str) -> ca.Function:
    return (time_dynamics if domain == "time" else spatial_dynamics)(params, options)


@_cached
def jacobians(
    params: ModelParams = ModelParams(),
    options: ModelOptions = ModelOptions(),
    domain: Domain = "time",
) -> ca.Function:
    """``(xi, u, kappa, theta) -> (A_c, B_c)``: exact Jacobians of the continuous model.

    ``A_c = d f / d xi`` (6x6) and ``B_c = d f / d u`` (6x2) of :func:`time_dynamics`
    (``domain="time"``) or :func:`spatial_dynamics` (``domain="spatial"``), by CasADi's algorithmic
    differentiation.
    """
    _check_method_domain("rk4", domain)
    f = _continuous(params, options, domain)
    xi, u, kappa, theta = _symbols()
    rhs = f(xi, u, kappa, theta)
    return ca.Function(
        f"jac_{domain}",
        [xi, u, kappa, theta],
        [ca.jacobian(rhs, xi), ca.jacobian(rhs, u)],
        _IN,
        ["A_c", "B_c"],
    )


def _integrate(f: ca.Function, xi: Any, u: Any, kappa: Any, theta: Any, h: Any, method: str) -> Any:
    """One step of length ``h`` with ``u``, ``kappa``, ``theta`` held constant."""
    if method == "euler":
        return xi + h * f(xi, u, kappa, theta)
    k1 = f(xi, u, kappa, theta)
    k2 = f(xi + h / 2 * k1, u, kappa, theta)
    k3 = f(xi + h / 2 * k2, u, kappa, theta)
    k4 = f(xi + h * k3, u, kappa, theta)
    return xi + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _check_step(step: float | None) -> float | None:
    if step is None:
        return None
    step = _as_float("step", step)
    if step <= 0.0:
        raise ModelError(f"step must be > 0 (s in the time domain, m in the spatial); got {step}.")
    return step


@_cached
def discretize(
    params: ModelParams = ModelParams(),
    options: ModelOptions = ModelOptions(),
    step: float | None = 0.1,
    method: Method = "rk4",
    domain: Domain = "time",
) -> ca.Function:
    """Discrete model ``F(xi, u, kappa, theta) -> xi_next`` over one step.

    Parameters
    ----------
    params, options
        Model parameters and switches.
    step : float or None
        ``dt`` in s (``domain="time"``) or ``ds`` in m (``domain="spatial"``). ``None`` adds a fifth
        input ``h`` (the step) to the Function, for non-uniform grids.
    method : {"rk4", "euler"}
        Explicit integrator; ``u``, ``kappa`` and ``theta`` are held constant over the step.
    domain : {"time", "spatial"}
        Integrate ``xi_dot`` over time or ``dxi/ds`` over arc length (then ``s_next = s + ds``).
    """
    _check_method_domain(method, domain)
    step = _check_step(step)
    f = _continuous(params, options, domain)
    xi, u, kappa, theta = _symbols()
    h = ca.SX.sym("h") if step is None else step
    xi_next = _integrate(f, xi, u, kappa, theta, h, method)
    inputs, names = [xi, u, kappa, theta], list(_IN)
    if step is None:
        inputs.append(h)
        names.append("h")
    return ca.Function(f"F_{method}_{domain}", inputs, [xi_next], names, ["xi_next"])


#: Alias of :func:`discretize`.
discrete_dynamics = discretize


@_cached
def discrete_linearization(
    params: ModelParams = ModelParams(),
    options: ModelOptions = ModelOptions(),
    step: float | None = 0.1,
    method: Method = "rk4",
    domain: Domain = "time",
) -> ca.Function:
    """Affine model of one discrete step around ``(xi_bar, u_bar)``.

    ``(xi_bar, u_bar, kappa, theta[, h]) -> (A_d, B_d, d_d)`` with
    ``xi_next ~= A_d xi + B_d u + d_d`` exact to first order: ``A_d = dF/dxi``, ``B_d = dF/du`` at
    the point and ``d_d = F(xi_bar, u_bar) - A_d xi_bar - B_d u_bar`` (the paper's ``A_k, B_k,
    D_k``). Use ``.map(N)`` to linearize N stages in one call (inputs stacked as columns; ``A_d``
    comes back as 6 x 6N), or :meth:`Model.linearize` for numpy arrays. Arguments as in
    :func:`discretize`.
    """
    F = discretize(params, options, step, method, domain)
    xi, u, kappa, theta = _symbols()
    extra = [ca.SX.sym("h")] if step is None else []
    xi_next = F(xi, u, kappa, theta, *extra)
    A = ca.jacobian(xi_next, xi)
    B = ca.jacobian(xi_next, u)
    d = xi_next - ca.mtimes(A, xi) - ca.mtimes(B, u)
    names = ["xi_bar", "u_bar", "kappa", "theta"] + (["h"] if extra else [])
    return ca.Function(
        f"lin_{method}_{domain}",
        [xi, u, kappa, theta, *extra],
        [A, B, d],
        names,
        ["A_d", "B_d", "d_d"],
    )


# --------------------------------------------------------------------------------------------------
# Numpy convenience wrapper
# --------------------------------------------------------------------------------------------------


def _state_rows(xi: ArrayLike, name: str = "xi", width: int = NX) -> np.ndarray:
    """``(width,)`` or ``(N, width)`` -> float array ``(N, width)``; ModelError otherwise."""
    arr = np.asarray(xi, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == width:
        return arr[None, :]
    if arr.ndim == 2 and arr.shape[1] == width:
        return arr
    raise ModelError(
        f"{name} must have shape ({width},) or (N, {width}); got {arr.shape}. "
        f"Order: {[x.name for x in (X if width == NX else U)]}."
    )


def _per_stage(value: ArrayLike, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    arr = arr.ravel()
    if arr.size != n:
        raise ModelError(
            f"{name} must be a scalar or have {n} entries (one per state); got {arr.size}."
        )
    return arr


class Model:
    """The model for numpy users: evaluate, integrate and linearize single states or batches.

    Taught in notebook 02. Batches hold one state per row: ``xi`` of shape ``(N, 6)``, ``u`` of
    shape ``(N, 2)``; ``kappa`` and ``theta`` are scalars or shape ``(N,)``. Single states of shape
    ``(6,)`` give outputs without the batch axis.

    Parameters
    ----------
    params : ModelParams
        Parameter set (default: the paper's car).
    options : ModelOptions
        Physical effects included (default: drag and longitudinal load transfer).

    Examples
    --------
    >>> import numpy as np
    >>> from racing_lib.model import Model, X
    >>> model = Model()
    >>> xi = np.array([20.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    >>> xi_dot = model.xi_dot(xi, [0.0, 0.0])  # coasting on a straight
    >>> bool(xi_dot[X.VX] < 0)  # drag and rolling resistance slow the car
    True
    >>> A, B, d = model.linearize(np.tile(xi, (20, 1)), np.zeros((20, 2)), 0.1)  # 20 MPC stages
    >>> A.shape, B.shape, d.shape
    ((20, 6, 6), (20, 6, 2), (20, 6))
    """

    def __init__(
        self, params: ModelParams | None = None, options: ModelOptions | None = None
    ) -> None:
        self.params = ModelParams() if params is None else params
        self.options = ModelOptions() if options is None else options
        _check_args(self.params, self.options)
        self.f_time = time_dynamics(self.params, self.options)
        self.f_spatial = spatial_dynamics(self.params, self.options)
        self._maps: dict[tuple[Any, ...], ca.Function] = {}

    def __repr__(self) -> str:
        return f"Model(options={self.options})"

    def _prepare(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike, theta: ArrayLike
    ) -> tuple[bool, list[np.ndarray]]:
        single = np.ndim(xi) == 1
        X_ = _state_rows(xi)
        U_ = _state_rows(u, "u", NU)
        n = X_.shape[0]
        if U_.shape[0] != n:
            if U_.shape[0] != 1:
                raise ModelError(f"u has {U_.shape[0]} rows but xi has {n}.")
            U_ = np.repeat(U_, n, axis=0)
        K = _per_stage(kappa, n, "kappa")
        T = _per_stage(theta, n, "theta")
        return single, [X_.T, U_.T, K[None, :], T[None, :]]

    def _call(self, fn: ca.Function, args: list[np.ndarray], single: bool) -> np.ndarray:
        out = np.asarray(fn(*args)).T
        return out[0] if single else out

    def xi_dot(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike = 0.0, theta: ArrayLike = 0.0
    ) -> np.ndarray:
        """Time derivative of the state, shape like ``xi``."""
        single, args = self._prepare(xi, u, kappa, theta)
        return self._call(self.f_time, args, single)

    def dxi_ds(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike = 0.0, theta: ArrayLike = 0.0
    ) -> np.ndarray:
        """Derivative of the state with respect to arc length ``s`` (per m), shape like ``xi``."""
        single, args = self._prepare(xi, u, kappa, theta)
        return self._call(self.f_spatial, args, single)

    def terms(
        self, xi: ArrayLike, u: ArrayLike, kappa: ArrayLike = 0.0, theta: ArrayLike = 0.0
    ) -> dict[str, np.ndarray]:
        """Named intermediate quantities (see :func:`model_terms`): floats or (N,) arrays."""
        single, args = self._prepare(xi, u, kappa, theta)
        fn = model_terms(self.params, self.options)
        res = fn.call(dict(zip(_IN, args, strict=True)))
        out = {}
        for name, value in res.items():
            arr = np.asarray(value).ravel()
            out[name] = float(arr[0]) if single else arr
        return out

    def step(
        self,
        xi: ArrayLike,
        u: ArrayLike,
        h: float,
        kappa: ArrayLike = 0.0,
        theta: ArrayLike = 0.0,
        method: Method = "rk4",
        domain: Domain = "time",
    ) -> np.ndarray:
        """One integration step of length ``h`` (s, or m for ``domain="spatial"``)."""
        single, args = self._prepare(xi, u, kappa, theta)
        F = discretize(self.params, self.options, _check_step(h), method, domain)
        return self._call(F, args, single)

    def linearize(
        self,
        xi_bar: ArrayLike,
        u_bar: ArrayLike,
        h: float,
        kappa: ArrayLike = 0.0,
        theta: ArrayLike = 0.0,
        method: Method = "rk4",
        domain: Domain = "time",
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Affine discrete model(s) ``xi_next ~= A xi + B u + d`` around the point(s).

        For a batch of N points returns ``A`` (N, 6, 6), ``B`` (N, 6, 2), ``d`` (N, 6), computed in
        one call of a mapped CasADi Function (built once per N); for one point (6,) the batch axis
        is dropped.
        """
        single, args = self._prepare(xi_bar, u_bar, kappa, theta)
        n = args[0].shape[1]
        key = (_check_step(h), method, domain, n)
        fn = self._maps.get(key)
        if fn is None:
            lin = discrete_linearization(self.params, self.options, key[0], method, domain)
            fn = lin if n == 1 else lin.map(n)
            self._maps[key] = fn
        A, B, d = fn(*args)
        A = np.asarray(A).reshape(NX, n, NX).transpose(1, 0, 2)
        B = np.asarray(B).reshape(NX, n, NU).transpose(1, 0, 2)
        d = np.asarray(d).T
        if single:
            return A[0], B[0], d[0]
        return A, B, d

    def jacobians(
        self,
        xi: ArrayLike,
        u: ArrayLike,
        kappa: ArrayLike = 0.0,
        theta: ArrayLike = 0.0,
        domain: Domain = "time",
    ) -> tuple[np.ndarray, np.ndarray]:
        """Continuous Jacobians ``A_c`` (6, 6) and ``B_c`` (6, 2) at one point (numpy)."""
        single, args = self._prepare(xi, u, kappa, theta)
        if not single:
            raise ModelError("Model.jacobians takes one state of shape (6,); loop for batches.")
        A, B = jacobians(self.params, self.options, domain)(*args)
        return np.asarray(A), np.asarray(B)
