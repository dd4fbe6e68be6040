"""A learned correction of the model's accelerations, fitted on logged laps (chapter 09).

The identified model (chapter 02) has the structure of the paper's bicycle; the car it stands
for has more (load-sensitive tyres, combined slip, a powertrain with gears). What the structure
cannot express shows up as *residual accelerations*: the measured change of ``v_x``, ``v_y`` and
``r`` over one control period, less the model's prediction, divided by the period. A
:class:`ModelCorrection` holds one sparse Gaussian process (:mod:`racing_lib.model.gp`) per
residual, each a function of the body-frame state and the inputs::

    features  z = (v_x, alpha_f, alpha_r, a_x)     (m/s, rad, rad, m/s^2)
    correction    (dv_x, dv_y, dr)(z)              (m/s^2, m/s^2, rad/s^2)

and the model's equations add the posterior mean to ``(v_x_dot, v_y_dot, r_dot)``
(:func:`racing_lib.model.equations.time_dynamics`). The correction is a field of
:class:`~racing_lib.model.params.ModelParams`, so it travels with the plan and its file to the
MPC like every other parameter: the planner and the controller see the same corrected model.
Away from the data the mean returns to zero (the model as identified) and the posterior standard
deviation grows: :meth:`ModelCorrection.std` says where the learned model is unsure.

The GPs' data (a few thousand numbers) are not written into the compiled code of the NLP and the
MPC as constants: that code takes them as an input (:class:`CorrectionTemplate`), so it is built
once per layout (inducing inputs per GP) and every later correction of a learning run reuses the
build. With the data as constants, each iteration spent about 50 s in the C compiler.

The features say what the tyres and the powertrain are asked for: the slip angles (which the
tyre forces depend on), the speed and the tyre acceleration (load transfer, combined slip,
gears). They are frame-free, so the correction does not depend on where on which track the car
is, and they are far less correlated along a lap than ``v_y``, ``r`` and ``delta``, whose
combinations off the recorded laps made a GP over them extrapolate wildly inside the MPC.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from racing_lib.errors import ModelError
from racing_lib.model.gp import (
    CasadiGP,
    SparseGP,
    casadi_arrays,
    casadi_mean,
    casadi_std,
    packed_size,
)
from racing_lib.model.states import X

__all__ = ["CORRECTED", "FEATURES", "CorrectionTemplate", "ModelCorrection", "correction_template"]

#: The inputs of the correction, in order: the speed, the two slip angles and the tyre
#: acceleration (m/s, rad, rad, m/s^2), as the model computes them (``model_terms``).
FEATURES: tuple[str, ...] = ("v_x", "alpha_f", "alpha_r", "a_x")
#: The state derivatives the correction adds to, in order (indices of :class:`X`).
CORRECTED: tuple[int, ...] = (int(X.VX), int(X.VY), int(X.R))


class ModelCorrection:
    """Additive corrections of ``(v_x_dot, v_y_dot, r_dot)``, one sparse GP each (or none).

    Immutable and hashable by its content (:attr:`digest`), so that the model's cached CasADi
    functions are built once per correction and two equal corrections share them.

    Parameters
    ----------
    gps : sequence of three SparseGP or None
        The GP of each corrected derivative, in the order of :data:`CORRECTED`; None leaves that
        derivative as the model has it.
    label : str
        A name for people (e.g. ``"learned from 3 laps, iteration 2"``).
    """

    __slots__ = ("_digest", "gps", "label")

    def __init__(self, gps: Sequence[SparseGP | None], label: str = "") -> None:
        gps = tuple(gps)
        if len(gps) != len(CORRECTED):
            raise ModelError(
                f"a ModelCorrection has {len(CORRECTED)} entries (v_x, v_y, r), got {len(gps)}."
            )
        for gp in gps:
            if gp is not None and not isinstance(gp, SparseGP):
                raise ModelError(f"a ModelCorrection holds SparseGP or None, got {type(gp)}.")
            if gp is not None and gp.z.shape[1] != len(FEATURES):
                raise ModelError(
                    f"a correction's GP takes the {len(FEATURES)} features {FEATURES}, this one "
                    f"takes {gp.z.shape[1]}."
                )
        object.__setattr__(self, "gps", gps)
        object.__setattr__(self, "label", str(label))
        text = json.dumps(self._arrays(), sort_keys=True)
        object.__setattr__(self, "_digest", hashlib.sha256(text.encode()).hexdigest()[:16])

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("a ModelCorrection is immutable")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ModelCorrection) and other._digest == self._digest

    def __hash__(self) -> int:
        return hash(self._digest)

    def __repr__(self) -> str:
        return f"ModelCorrection({self.label or 'learned'}, {self._digest})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (ModelCorrection.from_dict, (self.to_dict(),))

    @property
    def digest(self) -> str:
        """A 16-hex-digit fingerprint of the GPs' arrays (the label is not part of it)."""
        return self._digest

    # --- evaluation -------------------------------------------------------------------------------
    def mean(self, z: np.ndarray) -> np.ndarray:
        """The correction at features ``z`` (N, 4): shape (N, 3), in m/s^2, m/s^2, rad/s^2."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        return np.column_stack(
            [np.zeros(z.shape[0]) if gp is None else gp.mean(z) for gp in self.gps]
        )

    def std(self, z: np.ndarray) -> np.ndarray:
        """Posterior standard deviation of the correction at features ``z``: shape (N, 3)."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        return np.column_stack(
            [np.zeros(z.shape[0]) if gp is None else gp.std(z) for gp in self.gps]
        )

    def casadi(self, z: Any) -> list[Any]:
        """The three corrections as CasADi expressions of the feature column ``z`` (4 x 1)."""
        return [0 if g is None else casadi_mean(z, g) for g in self._casadi_gps()]

    def casadi_std(self, z: Any) -> list[Any]:
        """The three posterior standard deviations as CasADi expressions of ``z`` (4 x 1)."""
        return [0 if g is None else casadi_std(z, g) for g in self._casadi_gps()]

    def _casadi_gps(self) -> list[CasadiGP | None]:
        return [None if gp is None else gp.casadi_data() for gp in self.gps]

    # --- the data as an input of compiled code ----------------------------------------------------
    @property
    def layout(self) -> tuple[tuple[int, int] | None, ...]:
        """``(M, d)`` of each GP (None where there is none): the shape of :meth:`packed`."""
        return tuple(None if gp is None else gp.layout for gp in self.gps)

    def packed(self) -> np.ndarray:
        """Every GP's :meth:`~racing_lib.model.gp.SparseGP.packed` data, in one vector.

        The value of the :class:`CorrectionTemplate` input of code built for this layout.
        """
        parts = [gp.packed() for gp in self.gps if gp is not None]
        return np.concatenate(parts) if parts else np.zeros(0)

    # --- files ------------------------------------------------------------------------------------
    def _arrays(self) -> list[dict[str, Any] | None]:
        return [None if gp is None else gp.to_dict() for gp in self.gps]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {"features": list(FEATURES), "label": self.label, "gps": self._arrays()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModelCorrection:
        """Inverse of :meth:`to_dict`; a malformed dictionary raises :class:`ModelError`."""
        if not isinstance(data, Mapping) or "gps" not in data:
            raise ModelError(
                "a model correction must be a JSON object with 'gps'; the file was not written "
                "by racing_lib, or is damaged: learn it again (racing-lib learn)."
            )
        if list(data.get("features", FEATURES)) != list(FEATURES):
            raise ModelError(
                f"a model correction over the features {data.get('features')} cannot be used; "
                f"this racing_lib's corrections take {list(FEATURES)}. Learn it again."
            )
        gps = data["gps"]
        if not isinstance(gps, Sequence):
            raise ModelError("a model correction's 'gps' must be a list of three entries.")
        return cls(
            [None if g is None else SparseGP.from_dict(g) for g in gps],
            label=str(data.get("label", "")),
        )


class CorrectionTemplate(ModelCorrection):
    """A correction whose GPs' data are CasADi symbols: one build serves every correction alike.

    A correction's GPs are a few thousand numbers; written into the generated C code as
    constants, they made every learned correction a new build (the time-optimal NLP's
    derivatives and the MPC's linearization: about 50 s of compiling per learning iteration).
    Code built from a model whose correction is this template takes the data as an input
    instead (:attr:`data`, laid out as :meth:`ModelCorrection.packed`), so it is compiled once per
    :attr:`layout` and called with each correction's numbers.

    Get one with :func:`correction_template` (cached: equal layouts share their symbols, and
    with them the model's cached functions). Model functions built from it have :attr:`data` as
    a free symbol, which the code that builds them turns into an input.
    """

    __slots__ = ("data", "template_layout")

    def __init__(self, layout: tuple[tuple[int, int] | None, ...]) -> None:
        import casadi as ca

        layout = tuple(
            None if shape is None else (int(shape[0]), int(shape[1])) for shape in layout
        )
        if len(layout) != len(CORRECTED):
            raise ModelError(f"a correction's layout has {len(CORRECTED)} entries, got {layout}.")
        size = sum(packed_size(*shape) for shape in layout if shape is not None)
        object.__setattr__(self, "gps", (None,) * len(CORRECTED))
        object.__setattr__(self, "label", f"template {layout}")
        object.__setattr__(self, "template_layout", layout)
        object.__setattr__(self, "data", ca.SX.sym("correction_data", size))
        text = json.dumps(["template", layout])
        object.__setattr__(self, "_digest", hashlib.sha256(text.encode()).hexdigest()[:16])

    def __reduce__(self) -> tuple[Any, ...]:
        return (correction_template, (self.template_layout,))

    # Equal only to itself: the cached model functions built from a template hold its symbol,
    # so two templates of one layout (made directly, or by two threads at once) must not share
    # them. The compiled code is still shared: it is cached by the text it is generated as.
    def __eq__(self, other: object) -> bool:
        return other is self

    def __hash__(self) -> int:
        return id(self)

    @property
    def layout(self) -> tuple[tuple[int, int] | None, ...]:
        """The layout of the corrections this template stands for."""
        return self.template_layout

    def _casadi_gps(self) -> list[CasadiGP | None]:
        out: list[CasadiGP | None] = []
        start = 0
        for shape in self.template_layout:
            if shape is None:
                out.append(None)
                continue
            size = packed_size(*shape)
            out.append(casadi_arrays(self.data[start : start + size], *shape))
            start += size
        return out

    def _no_data(self, *args: Any, **kwargs: Any) -> Any:
        raise ModelError(
            "a CorrectionTemplate holds symbols, not a learned correction: it cannot be "
            "evaluated or saved; use the ModelCorrection it stands for."
        )

    mean = std = to_dict = packed = _no_data  # type: ignore[assignment]


@functools.cache
def correction_template(layout: tuple[tuple[int, int] | None, ...]) -> CorrectionTemplate:
    """The :class:`CorrectionTemplate` of ``layout`` (one per layout and process)."""
    return CorrectionTemplate(layout)
