"""trep's wrenches on a frame — ``BodyWrench``, ``SpatialWrench``, ``HybridWrench`` — as
forces the runtime calls back, with exact derivatives.

A wrench ``w = (f, τ)`` held in some axes does the generalized force ``F_i = w · (X_i)^∨`` on
config ``q_i``, where ``X_i`` is the frame's velocity generator for ``q̇_i`` in those axes
(docs/python.md, "Wrenches"):

* body axes: ``X_i = g⁻¹ ∂g/∂q_i``;
* spatial (world) axes: ``X_i = ∂g/∂q_i g⁻¹``;
* hybrid (world axes at the frame's origin): ``X_i = ∂g/∂q_i K`` with ``K = [Rᵀ 0; 0 1]``
  (``∂R/∂q_i Rᵀ`` and ``∂p/∂q_i``);

and ``(X)^∨ = (v, ω)`` of ``X = [ω̂ v; 0 0]``. Each ``X_i`` is a product of the factors
``g⁻¹``, ``∂^S g`` and ``K_S`` (``K`` built from ``∂^S R``); its derivatives come from the
product rule — ``_products``, written once for these three and the frames' body velocities.
"""
from __future__ import annotations

from typing import Any, List, Optional, Sequence, Tuple

import numpy as np

from ._core import Config, Force, Frame, System
from ._products import Factor, Term, derivatives, value

__all__ = ["BodyWrench", "HybridWrench", "SpatialWrench"]


def _vee(x: np.ndarray) -> np.ndarray:
    """``(v, ω)`` of ``[ω̂ v; 0 0]``."""
    return np.array([x[0, 3], x[1, 3], x[2, 3], x[2, 1], x[0, 2], x[1, 0]])


class _Wrench(Force):
    """A constant wrench ``(fx, fy, fz, τx, τy, τz)`` on ``frame`` in the class's axes."""

    #: Called back by the runtime (its force depends on the frame's pose).
    _called_back = True

    def __init__(self, system: System, frame: Any, wrench: Sequence[Any] = (),
                 name: Optional[str] = None):
        self._frame = frame if isinstance(frame, Frame) else system.get_frame(frame)
        values = list(wrench) + [0.0] * (6 - len(wrench))
        if len(values) != 6:
            raise ValueError(f"{type(self).__name__}: a wrench has six entries (fx, fy, fz, "
                             f"τx, τy, τz), got {len(wrench)}")
        for k, x in enumerate(values):
            if isinstance(x, str):
                raise NotImplementedError(
                    f"{type(self).__name__}: entry {k} of the wrench names an input ({x!r}); "
                    "tree_mech.trep takes a wrench of numbers only — its integrators take "
                    "each input on one config (forces.ConfigForce), and a wrench's input "
                    "acts through the frame's Jacobian, which they do not take yet")
            try:
                finite = np.isfinite(float(x))
            except (TypeError, ValueError):
                finite = False
            if not finite:
                raise ValueError(f"{type(self).__name__}: entry {k} of the wrench is {x!r}; "
                                 "each entry is a finite number")
        self._wrench = np.array(values, dtype=float)
        super().__init__(system, name)

    #: ``X_i`` as a product of factors, with ``("g", (q_i,))`` for ``∂g/∂q_i``.
    _generator: Tuple[Factor, ...] = ()

    @property
    def frame(self) -> Frame:
        """The frame the wrench acts on."""
        return self._frame

    @property
    def wrench(self) -> Tuple[float, ...]:
        """The wrench's six entries."""
        return tuple(self._wrench)

    @property
    def wrench_val(self) -> List[float]:
        """The wrench's values (trep's name)."""
        return self._wrench.tolist()

    def _force(self, q: Config, *by: Config) -> float:
        if q.kinematic or not self._frame.uses_config(q):
            return 0.0
        terms: List[Term] = [(1.0, tuple(("g", (q,)) if f == ("g", ()) else f
                                         for f in self._generator))]
        total = value(self._frame, derivatives(terms, *by))
        return float(self._wrench @ _vee(total))

    def f(self, q: Config) -> float:
        """The generalized force on config ``q``."""
        return self._force(q)

    def f_dq(self, q: Config, q1: Config) -> float:
        """``∂f_q/∂q1``."""
        return self._force(q, q1)

    def f_dqdq(self, q: Config, q1: Config, q2: Config) -> float:
        """``∂²f_q/∂q1∂q2``."""
        return self._force(q, q1, q2)

    def f_ddq(self, q: Config, dq1: Config) -> float:
        """Zero: a wrench does not depend on the velocity."""
        return 0.0

    def f_ddqdq(self, q: Config, dq1: Config, q2: Config) -> float:
        """Zero."""
        return 0.0

    def f_ddqddq(self, q: Config, dq1: Config, dq2: Config) -> float:
        """Zero."""
        return 0.0


class BodyWrench(_Wrench):
    """A constant wrench in the frame's own axes (trep's ``BodyWrench``)."""

    _generator = (("inv",), ("g", ()))


class SpatialWrench(_Wrench):
    """A constant wrench in world axes about the world's origin (trep's ``SpatialWrench``)."""

    _generator = (("g", ()), ("inv",))


class HybridWrench(_Wrench):
    """A constant wrench in world axes at the frame's origin (trep's ``HybridWrench``)."""

    _generator = (("g", ()), ("K", ()))
