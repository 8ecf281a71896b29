"""trep's wrenches on a frame — ``BodyWrench``, ``SpatialWrench``, ``HybridWrench`` — as
forces the runtime calls back, with exact derivatives; an entry may name an input
(``_force_inputs`` gives the step's derivatives with respect to it).

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
    """A wrench ``(fx, fy, fz, τx, τy, τz)`` on ``frame`` in the class's axes: each entry a
    number or the name of an input the wrench creates (trep's), whose value is the entry."""

    #: Called back by the runtime (its force depends on the frame's pose).
    _called_back = True

    def __init__(self, system: System, frame: Any, wrench: Sequence[Any] = (),
                 name: Optional[str] = None):
        self._frame = frame if isinstance(frame, Frame) else system.get_frame(frame)
        values = list(wrench) + [0.0] * (6 - len(wrench))
        if len(values) != 6:
            raise ValueError(f"{type(self).__name__}: a wrench has six entries (fx, fy, fz, "
                             f"τx, τy, τz), got {len(wrench)}")
        constants = []
        for k, x in enumerate(values):
            if isinstance(x, str):
                constants.append(0.0)
                continue
            try:
                finite = np.isfinite(float(x))
            except (TypeError, ValueError):
                finite = False
            if not finite:
                raise ValueError(f"{type(self).__name__}: entry {k} of the wrench is {x!r}; "
                                 "each entry is a finite number or an input's name")
            constants.append(float(x))
        self._wrench = np.array(constants, dtype=float)
        #: (entry, input) for each entry that names an input.
        self._entries: List[Tuple[int, Any]] = []
        super().__init__(system, name)
        system._hold()
        try:
            self._entries = [(k, self._create_input(x)) for k, x in enumerate(values)
                             if isinstance(x, str)]
        finally:
            system._release()

    #: ``X_i`` as a product of factors, with ``("g", (q_i,))`` for ``∂g/∂q_i``.
    _generator: Tuple[Factor, ...] = ()

    @property
    def frame(self) -> Frame:
        """The frame the wrench acts on."""
        return self._frame

    @property
    def wrench(self) -> Tuple[Any, ...]:
        """The wrench's six entries: numbers, and the inputs named."""
        out: List[Any] = list(self._wrench)
        for k, created in self._entries:
            out[k] = created
        return tuple(out)

    @property
    def wrench_val(self) -> List[float]:
        """The wrench's values now (an input's entry its value; trep's name)."""
        return self._values().tolist()

    def _values(self) -> np.ndarray:
        if not self._entries:
            return self._wrench
        w = self._wrench.copy()
        for k, created in self._entries:
            w[k] = created.u
        return w

    def _generator_vee(self, q: Config, *by: Config) -> Optional[np.ndarray]:
        """``(X_q)^∨`` differentiated by ``by``; None where config ``q`` does not move the
        frame (or is kinematic: no force on it)."""
        if q.kinematic or not self._frame.uses_config(q):
            return None
        terms: List[Term] = [(1.0, tuple(("g", (q,)) if f == ("g", ()) else f
                                         for f in self._generator))]
        return _vee(value(self._frame, derivatives(terms, *by)))

    def _force(self, q: Config, *by: Config) -> float:
        x = self._generator_vee(q, *by)
        return 0.0 if x is None else float(self._values() @ x)

    def _entry(self, u1: Any) -> Optional[int]:
        """The entry input ``u1`` is, if it is one of this wrench's."""
        return next((k for k, created in self._entries if created is u1), None)

    def f(self, q: Config) -> float:
        """The generalized force on config ``q``."""
        return self._force(q)

    def f_dq(self, q: Config, q1: Config) -> float:
        """``∂f_q/∂q1``."""
        return self._force(q, q1)

    def f_dqdq(self, q: Config, q1: Config, q2: Config) -> float:
        """``∂²f_q/∂q1∂q2``."""
        return self._force(q, q1, q2)

    def f_du(self, q: Config, u1: Any) -> float:
        """``∂f_q/∂u1``: the generator's entry the input fills."""
        k, x = self._entry(u1), self._generator_vee(q)
        return 0.0 if k is None or x is None else float(x[k])

    def f_dudq(self, q: Config, u1: Any, q2: Config) -> float:
        """``∂²f_q/∂u1∂q2``."""
        k, x = self._entry(u1), self._generator_vee(q, q2)
        return 0.0 if k is None or x is None else float(x[k])

    def f_ddq(self, q: Config, dq1: Config) -> float:
        """Zero: a wrench does not depend on the velocity."""
        return 0.0

    def f_ddqdq(self, q: Config, dq1: Config, q2: Config) -> float:
        """Zero."""
        return 0.0

    def f_ddqddq(self, q: Config, dq1: Config, dq2: Config) -> float:
        """Zero."""
        return 0.0

    def f_duddq(self, q: Config, u1: Any, dq2: Config) -> float:
        """Zero."""
        return 0.0

    def f_dudu(self, q: Config, u1: Any, u2: Any) -> float:
        """Zero: the force is linear in its inputs."""
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
