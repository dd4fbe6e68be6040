"""The planning model's parameters: which effects it models, its pedal map and its numbers.

* :class:`ModelOptions`: the switches of the paper's ablations (drag, longitudinal and lateral
  weight transfer).
* :class:`PedalMap`: how the one pedal u_p in [-1, 1] maps to the longitudinal tyre acceleration.
* :class:`ModelParams`: the paper's table plus what identification adds; the defaults are the
  paper's values, the identified set is :func:`racing_lib.model.identified.identified_params`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import ModelError
from racing_lib.io import JSONObject, atomic_write_json
from racing_lib.model.correction import ModelCorrection
from racing_lib.model.states import NX, X, as_float, state_rows

# The force laws are defined once, in racing_lib/vehicle/forces.py, for floats, numpy and CasADi
from racing_lib.vehicle import (
    Numeric,
    VehicleParams,
    axle_cornering_stiffness,
    static_axle_loads,
)

__all__ = ["BRAKE_KNEE", "ModelOptions", "ModelParams", "PedalMap"]


@dataclass(frozen=True)
class ModelOptions:
    """Which physical effects the model includes (the paper's ablations).

    Which physical effects the model includes (the paper's ablations, Section "Vehicle Model
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

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, bool | np.bool_):
                raise ModelError(f"ModelOptions.{f.name} must be True or False; got {value!r}.")
            object.__setattr__(self, f.name, bool(value))

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


#: Share of the braking limit ``a_brk_max`` up to which braking stays linear in the pedal
#: (:class:`PedalMap`); the simulated car's stops are linear to about 0.85 of the limit.
BRAKE_KNEE = 0.8


#: The forms of :attr:`PedalMap.throttle`.
THROTTLE_FORMS = ("share", "demand")


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
    plausible size for the default car; ``racing_lib.experiments.sysid`` fits the real coefficients.

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
        value of ``m_brk`` or more: braking is linear in the pedal to ``-m_brk``. The knee's
        bend always ends at ``u_p = -1``: with ``brake_max < 1`` the map stops before it, and
        full brake gives less than ``a_brk_max`` (identification sets one or the other).
    throttle : {"share", "demand"}
        How a partial throttle relates to full throttle. ``"share"`` (default, the form above):
        the pedal is a share of what full throttle gives at that speed,
        ``g_thr(v_x) max(u_p, 0)``, as for an engine whose pedal scales its torque.
        ``"demand"``: the pedal asks for an acceleration, which the power caps,
        ``min(m_thr max(u_p, 0), g_thr(v_x))``, as for CommonRoad's cars (``a = u_p a_max``,
        cut at ``a_max v_switch / v``). Full throttle, hence :meth:`limits`, is the same in
        both; partial throttle and its inverse :meth:`pedal` differ. Identification fits both
        and keeps the better.
    brake_max : float
        The deepest brake pedal the car holds, in (0, 1] (1: the full pedal). A car without
        anti-lock brakes locks its wheels beyond some pedal, and a locked wheel steers nothing:
        the map then ends there, so full brake (:meth:`full_brake`, :meth:`limits`) means
        ``u_p = -brake_max`` and :meth:`pedal` never asks for more. Identification sets it from
        the pedal its full stops held without locking.
    """

    m_0: float = 1.0
    m_xi: tuple[float, ...] = (-0.06, 0.0, 0.0, 0.0, 0.0, 0.0)
    m_thr: float = 3.0
    m_brk: float = 9.0
    p_thr: float | None = None
    a_brk_max: float | None = None
    brake_max: float = 1.0
    throttle: str = "share"

    def __post_init__(self) -> None:
        if self.throttle not in THROTTLE_FORMS:
            raise ModelError(
                f"PedalMap.throttle must be one of {THROTTLE_FORMS}, got {self.throttle!r}."
            )
        object.__setattr__(self, "m_0", as_float("PedalMap.m_0", self.m_0))
        try:
            m_xi = tuple(as_float("PedalMap.m_xi", v) for v in np.asarray(self.m_xi).ravel())
        except TypeError:
            raise ModelError(f"PedalMap.m_xi must be {NX} numbers; got {self.m_xi!r}.") from None
        if len(m_xi) != NX:
            raise ModelError(
                f"PedalMap.m_xi must have {NX} entries (one per state {[x.name for x in X]}); "
                f"got {len(m_xi)}."
            )
        object.__setattr__(self, "m_xi", m_xi)
        for name in ("m_thr", "m_brk"):
            value = as_float(f"PedalMap.{name}", getattr(self, name))
            if value <= 0.0:
                raise ModelError(
                    f"PedalMap.{name} must be > 0 so that the pedal map is invertible; "
                    f"got {value}. Refit the map with data that contain both throttle and brake."
                )
            object.__setattr__(self, name, value)
        for name, unit in (("p_thr", "W/kg"), ("a_brk_max", "m/s^2")):
            if getattr(self, name) is None:
                continue
            value = as_float(f"PedalMap.{name}", getattr(self, name))
            if value <= 0.0:
                raise ModelError(
                    f"PedalMap.{name} must be > 0 {unit} (or None for no limit); got {value}."
                )
            object.__setattr__(self, name, value)
        brake_max = as_float("PedalMap.brake_max", self.brake_max)
        if not 0.0 < brake_max <= 1.0:
            raise ModelError(
                f"PedalMap.brake_max must be in (0, 1] (the deepest brake pedal the car holds); "
                f"got {brake_max}."
            )
        object.__setattr__(self, "brake_max", brake_max)

    # --- construction -----------------------------------------------------------------------------
    @classmethod
    def from_coefficients(cls, coefficients: ArrayLike) -> PedalMap:
        """Build from the 9 coefficients of :meth:`coefficients`.

        Build from ``[m_0, m_xi (6 values), m_thr, m_brk]`` (9 numbers, the order of
        :meth:`coefficients`).
        """
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

    def to_dict(self) -> JSONObject:
        """JSON-ready dictionary."""
        return {
            "m_0": self.m_0,
            "m_xi": list(self.m_xi),
            "m_thr": self.m_thr,
            "m_brk": self.m_brk,
            "p_thr": self.p_thr,
            "a_brk_max": self.a_brk_max,
            "brake_max": self.brake_max,
            "throttle": self.throttle,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> PedalMap:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`ModelError`."""
        _check_keys("PedalMap", data, {f.name for f in dataclasses.fields(cls)})
        kwargs = dict(data)
        if "m_xi" in kwargs:
            kwargs["m_xi"] = tuple(kwargs["m_xi"])
        return cls(**kwargs)

    # --- evaluation -------------------------------------------------------------------------------
    def _base(self, xi: ArrayLike | ca.SX | ca.MX | ca.DM) -> Numeric:
        """``m_0 + m_xi . xi``: numpy rows ``(N, 6)`` -> ``(N,)``; CasADi columns -> ``1 x N``."""
        if isinstance(xi, ca.SX | ca.MX | ca.DM):
            if xi.size1() != NX:
                raise ModelError(f"symbolic xi must have {NX} rows; got {xi.size1()}.")
            return self.m_0 + ca.mtimes(ca.DM(self.m_xi).T, xi)
        xi = state_rows(xi)
        # A sum over the six states in a fixed order, not a matrix product: a BLAS kernel adds the
        # products in an order of its own, which on some processors (AVX-512) differs between one
        # row and many, and the controller's one-value pedal must equal the array path to the bit.
        acc = xi[:, 0] * self.m_xi[0]
        for j in range(1, NX):
            acc = acc + xi[:, j] * self.m_xi[j]
        return self.m_0 + acc

    def throttle_gain(self, v_x: Numeric) -> Numeric:
        """Acceleration added by full throttle at speed ``v_x`` (m/s), m/s^2.

        ``min(m_thr, p_thr / v_x)`` (``m_thr`` without a power limit).

        Works on floats, arrays and CasADi expressions. Below 1 m/s the speed is taken as 1 m/s
        (the hyperbola has no meaning at standstill, where ``m_thr`` binds anyway).
        """
        if self.p_thr is None:
            return self.m_thr
        if isinstance(v_x, float):
            # Written so that NaN propagates as through np.minimum and np.maximum.
            return min(self.p_thr / max(v_x, 1.0), self.m_thr)
        if isinstance(v_x, ca.SX | ca.MX | ca.DM):
            return ca.fmin(self.m_thr, self.p_thr / ca.fmax(v_x, 1.0))
        return np.minimum(self.m_thr, self.p_thr / np.maximum(np.asarray(v_x, dtype=float), 1.0))

    def _brake_knee(self) -> tuple[float, float, float] | None:
        """Where braking bends: ``(u_k, a_k, slope)``, or None.

        ``(u_k, a_k, slope)``: the pedal and deceleration (m/s^2) where braking bends, and the
        slope below it (m/s^2 per unit pedal); None when braking is linear to full brake.
        """
        if self.a_brk_max is None or self.a_brk_max >= self.m_brk:
            return None
        a_k = BRAKE_KNEE * self.a_brk_max
        u_k = -a_k / self.m_brk
        return u_k, a_k, (self.a_brk_max - a_k) / (1.0 + u_k)

    def _brake(self, u_p: Numeric) -> Numeric:
        """Brake part of ``a_x`` (m/s^2, <= 0) for pedal(s) ``u_p``; numpy or CasADi."""
        sym = isinstance(u_p, ca.SX | ca.MX | ca.DM)
        fmin, fmax = (ca.fmin, ca.fmax) if sym else (np.minimum, np.maximum)
        w = fmin(u_p, 0.0)
        knee = self._brake_knee()
        if knee is None:
            return self.m_brk * w
        u_k, _, slope = knee
        return self.m_brk * fmax(w, u_k) + slope * fmin(w - u_k, 0.0)

    def _speed(self, xi: ArrayLike | ca.SX | ca.MX | ca.DM) -> Numeric:
        """``v_x`` of state(s) ``xi``: CasADi row ``1 x N`` or numpy ``(N,)``."""
        if isinstance(xi, ca.SX | ca.MX | ca.DM):
            return xi[int(X.VX), :]
        return state_rows(xi)[:, X.VX]

    def ax(self, xi: ArrayLike | ca.SX | ca.MX | ca.DM, u_p: Numeric | ArrayLike) -> Numeric:
        """Tyre acceleration ``a_x`` (m/s^2) for state(s) ``xi`` and pedal ``u_p`` in [-1, 1].

        ``xi``: shape (6,) or (N, 6) (or a CasADi column / 6 x N matrix); ``u_p``: scalar or (N,).
        Returns a float, an array of shape (N,), or a CasADi expression.
        """
        gain = self.throttle_gain(self._speed(xi))
        if isinstance(xi, ca.SX | ca.MX | ca.DM) or isinstance(u_p, ca.SX | ca.MX):
            return self._base(xi) + self._throttle(gain, u_p, ca.fmin, ca.fmax) + self._brake(u_p)
        scalar = np.ndim(xi) == 1 and np.ndim(u_p) == 0
        u_p = np.asarray(u_p, dtype=float)
        out = self._base(xi) + self._throttle(gain, u_p, np.minimum, np.maximum) + self._brake(u_p)
        return float(out[0]) if scalar else out

    def _throttle(self, gain: Any, u_p: Any, fmin: Any, fmax: Any) -> Any:
        """Throttle part of ``a_x`` (m/s^2, >= 0): full throttle's ``gain`` (m/s^2), pedal(s)."""
        if self.throttle == "share":
            return gain * fmax(u_p, 0.0)
        return fmin(self.m_thr * fmax(u_p, 0.0), gain)

    def limits(self, xi: ArrayLike | ca.SX | ca.MX | ca.DM) -> tuple[Numeric, Numeric]:
        """``(a_min, a_max)`` in m/s^2 at full brake and full throttle for state(s) ``xi``.

        ``(a_min, a_max)`` in m/s^2: ``a_x`` at full brake (``u_p = -brake_max``, the deepest
        pedal the car holds) and full throttle (``u_p=+1``) for state(s) ``xi`` of shape (6,) or
        (N, 6) (or CasADi columns).
        """
        base = self._base(xi)
        gain = self.throttle_gain(self._speed(xi))
        if not isinstance(base, ca.SX | ca.MX | ca.DM) and np.ndim(xi) == 1:
            base, gain = float(base[0]), float(np.ravel(gain)[0])
        return base - self.full_brake(), base + gain

    def full_brake(self) -> float:
        """Deceleration added by full brake, m/s^2.

        ``a_brk_max`` if the tyres limit it, else ``m_brk``; for a car whose wheels lock, the
        deceleration at its deepest pedal ``-brake_max``.
        """
        if self.brake_max < 1.0:
            return -float(self._brake(np.float64(-self.brake_max)))
        return self.m_brk if self._brake_knee() is None else float(self.a_brk_max)

    def limits_at_speed(self, v_x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(a_min, a_max)`` in m/s^2 at speed(s) ``v_x`` (m/s), driving straight on the line.

        ``(a_min, a_max)`` in m/s^2 at speed(s) ``v_x`` (m/s) with every other state zero
        (straight driving on the line): arrays shaped like ``v_x``, for speed profiles.
        """
        v = np.asarray(v_x, dtype=float)
        xi = np.zeros((v.size, NX))
        xi[:, X.VX] = v.ravel()
        lo, hi = self.limits(xi)
        return lo.reshape(v.shape), hi.reshape(v.shape)

    def pedal(self, a_x: ArrayLike, xi: ArrayLike) -> float | np.ndarray:
        """Pedal ``u_p`` in [-brake_max, 1] giving ``a_x`` (m/s^2) in state(s) ``xi``; clipped.

        Shapes as in :meth:`ax`; numpy only (the controller's last step).
        """
        scalar = np.ndim(xi) == 1 and np.ndim(a_x) == 0
        if scalar:
            # The controller's case, once a step: the same IEEE arithmetic on Python floats costs
            # a quarter of numpy's on one-element arrays.
            row = state_rows(xi)[0].tolist()
            # _base's sum, in the same order, on Python floats.
            acc = row[0] * self.m_xi[0]
            for j in range(1, NX):
                acc = acc + row[j] * self.m_xi[j]
            excess = float(a_x) - (self.m_0 + acc)
            gain = self.throttle_gain(row[X.VX])
            if gain > 0.0:  # else an infinite (or NaN) speed: Python floats raise on x / 0
                return self._invert(excess, gain, _select, min, max)
        excess = np.asarray(a_x, dtype=float) - self._base(xi)
        gain = self.throttle_gain(self._speed(xi))
        u_p = self._invert(excess, gain, np.where, np.minimum, np.maximum)
        return float(u_p[0]) if scalar else u_p

    def _invert(self, excess: Any, gain: Any, select: Any, fmin: Any, fmax: Any) -> Any:
        """Pedal for the acceleration ``excess`` (m/s^2) over the pedal-free part; clipped.

        ``gain`` is full throttle's acceleration (m/s^2). ``select(cond, a, b)``, ``fmin`` and
        ``fmax`` are ``np.where``, ``np.minimum`` and ``np.maximum`` for arrays, or their Python
        forms for floats (with ``u_p`` as the first argument, so that NaN passes through ``min``
        and ``max`` as it does through numpy).
        """
        u_brake = excess / self.m_brk
        knee = self._brake_knee()
        if knee is not None:
            u_k, a_k, slope = knee
            u_brake = select(excess >= -a_k, u_brake, u_k + (excess + a_k) / slope)
        if self.throttle == "share":
            u_throttle = excess / gain
        else:  # the pedal that asks for it, or full throttle where the power caps it
            u_throttle = select(excess >= gain, 1.0, excess / self.m_thr)
        u_p = select(excess >= 0.0, u_throttle, u_brake)
        # Not np.clip: its Python wrapper costs more than the rest on a single value.
        return fmin(fmax(u_p, -self.brake_max), 1.0)


def _select(cond: bool, a: float, b: float) -> float:
    """``np.where`` for one value."""
    return a if cond else b


def _check_keys(what: str, data: Mapping[str, object], allowed: set[str]) -> None:
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
    correction : ModelCorrection or None
        Learned additions to the accelerations ``(v_x_dot, v_y_dot, r_dot)``, fitted on logged
        laps (:mod:`racing_lib.model.correction`, chapter 09); None: the equations as written.
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
    correction: ModelCorrection | None = None

    def __post_init__(self) -> None:
        for name in _POSITIVE:
            value = as_float(f"ModelParams.{name}", getattr(self, name))
            if value <= 0.0:
                raise ModelError(f"ModelParams.{name} must be > 0; got {value}.")
            object.__setattr__(self, name, value)
        for name in _NON_NEGATIVE:
            value = as_float(f"ModelParams.{name}", getattr(self, name))
            if value < 0.0:
                raise ModelError(
                    f"ModelParams.{name} must be >= 0 (use ModelOptions to switch effects off); "
                    f"got {value}."
                )
            object.__setattr__(self, name, value)
        if not isinstance(self.pedal, PedalMap):
            raise ModelError(f"ModelParams.pedal must be a PedalMap; got {type(self.pedal)}.")
        if self.correction is not None and not isinstance(self.correction, ModelCorrection):
            raise ModelError(
                "ModelParams.correction must be a racing_lib.model.ModelCorrection (learned by "
                f"racing_lib.experiments.learning) or None; got {type(self.correction)}."
            )
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
        """Linear cornering stiffnesses ``C_alpha = mu F_z0 B C D`` (N/rad) at the static loads.

        The slope of the Pacejka curve at zero slip.
        """
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

    def replace(self, **changes: float | PedalMap | ModelCorrection | None) -> ModelParams:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    # --- conversion -------------------------------------------------------------------------------
    @classmethod
    def from_vehicle(cls, vehicle: VehicleParams, pedal: PedalMap | None = None) -> ModelParams:
        """The simulated car's true values (``racing_lib.vehicle.VehicleParams``).

        The pedal map is not a parameter of the car (its powertrain is nonlinear): pass an
        identified one, or get the placeholder default.
        """
        names = {f.name for f in dataclasses.fields(cls)} - {"pedal", "correction"}
        values: dict[str, float] = {}
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

    def to_dict(self) -> JSONObject:
        """JSON-ready dictionary (nested: ``"pedal"``, and ``"correction"`` when there is one)."""
        nested = ("pedal", "correction")
        out: JSONObject = {
            f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in nested
        }
        out["pedal"] = self.pedal.to_dict()
        if self.correction is not None:
            out["correction"] = self.correction.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> ModelParams:
        """Inverse of :meth:`to_dict`. Missing fields take their defaults; unknown ones raise."""
        _check_keys("ModelParams", data, {f.name for f in dataclasses.fields(cls)})
        kwargs = dict(data)
        if "pedal" in kwargs and not isinstance(kwargs["pedal"], PedalMap):
            kwargs["pedal"] = PedalMap.from_dict(kwargs["pedal"])
        if kwargs.get("correction") is not None and not isinstance(
            kwargs["correction"], ModelCorrection
        ):
            kwargs["correction"] = ModelCorrection.from_dict(kwargs["correction"])
        return cls(**kwargs)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write as JSON, atomically (temporary file, then rename)."""
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
