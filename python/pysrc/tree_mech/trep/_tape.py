"""``trep.TapeMeasure``: the length of the polyline through a list of frames' origins, its
rate, and their derivatives by the configs — exact, from the frames' position derivatives.

With ``v_k = p_{k+1} − p_k``, ``x_k = |v_k|`` and ``x = Σ x_k``, and for one segment
``a_i = v·v_i``, ``a_ij = v_j·v_i + v·v_ij``, ``a_ijl = v_jl·v_i + v_j·v_il + v_l·v_ij +
v·v_ijl`` (subscripts: derivatives by configs):

* ``∂x/∂q_i = a_i/x``, ``∂²x/∂q_i∂q_j = a_ij/x − a_i a_j/x³``,
* ``∂³x/∂q_i∂q_j∂q_l = a_ijl/x − (a_ij a_l + a_il a_j + a_i a_jl)/x³ + 3 a_i a_j a_l/x⁵``,
* ``ẋ = Σ_i ∂x/∂q_i q̇_i``, so ``∂ẋ/∂q̇_i = ∂x/∂q_i`` and ``∂ẋ/∂q_l = Σ_i ∂²x/∂q_i∂q_l q̇_i``.

A segment of zero length has no derivative: where trep returns NaN or divides by zero, this
raises a ``ValueError`` naming the segment.
"""
from __future__ import annotations

from typing import Any, Callable, List, Sequence, Tuple

import numpy as np

from ._core import Config, Frame, System

__all__ = ["TapeMeasure"]


def _validator(value: str, derivative: str, rank: int, by_velocity: bool):
    """trep's ``validate_<derivative>``: whether every entry of ``derivative`` agrees with
    central differences of ``value``."""
    def validate(self, delta: float = 1e-5, tolerance: float = 1e-7,
                 verbose: bool = False) -> bool:
        return self._validate(getattr(self, value), getattr(self, derivative), rank,
                              by_velocity, delta, tolerance, verbose)
    validate.__name__ = f"validate_{derivative}"
    validate.__doc__ = (f"Whether ``{derivative}`` agrees with central differences (step "
                        f"``delta``) of ``{value}`` to ``tolerance`` relative to its scale; "
                        "``verbose`` prints each entry that does not.")
    return validate


class TapeMeasure:
    """The polyline through ``frames``' origins (trep's ``TapeMeasure(system, frames)``)."""

    def __init__(self, system: System, frames: Sequence[Any]):
        self._system = system
        self._frames = tuple(f if isinstance(f, Frame) else system.get_frame(f) for f in frames)
        if len(self._frames) < 2:
            raise ValueError("TapeMeasure: give at least two frames")

    @property
    def system(self) -> System:
        """The system the frames belong to."""
        return self._system

    @property
    def frames(self) -> Tuple[Frame, ...]:
        """The frames, in order along the line."""
        return self._frames

    # One segment's pieces ----------------------------------------------------------------
    def _segments(self):
        return zip(self._frames, self._frames[1:])

    @staticmethod
    def _v(a: Frame, b: Frame, *by: Config) -> np.ndarray:
        """``v`` of segment ``a → b``, or its derivative by the configs ``by``."""
        if not by:
            return (b.p() - a.p())[:3]
        name = {1: "p_dq", 2: "p_dqdq", 3: "p_dqdqdq"}[len(by)]
        return (getattr(b, name)(*by) - getattr(a, name)(*by))[:3]

    def _length_of(self, a: Frame, b: Frame) -> Tuple[np.ndarray, float]:
        v = self._v(a, b)
        x = float(np.sqrt(v @ v))
        if x == 0.0:
            raise ValueError(f"TapeMeasure: the segment from {a.name!r} to {b.name!r} has zero "
                             "length, where the length has no derivative")
        return v, x

    def _sum(self, each: Callable[[Frame, Frame], float]) -> float:
        return float(sum(each(a, b) for a, b in self._segments()))

    # The length and its derivatives ------------------------------------------------------
    def length(self) -> float:
        """``x``: the sum of the segments' lengths."""
        return self._sum(lambda a, b: float(np.linalg.norm(self._v(a, b))))

    def length_dq(self, q1: Config) -> float:
        """``∂x/∂q1``."""
        def each(a, b):
            v, x = self._length_of(a, b)
            return v @ self._v(a, b, q1) / x
        return self._sum(each)

    def length_dqdq(self, q1: Config, q2: Config) -> float:
        """``∂²x/∂q1∂q2``."""
        def each(a, b):
            v, x = self._length_of(a, b)
            v1, v2, v12 = self._v(a, b, q1), self._v(a, b, q2), self._v(a, b, q1, q2)
            return (v2 @ v1 + v @ v12) / x - (v @ v1) * (v @ v2) / x ** 3
        return self._sum(each)

    def length_dqdqdq(self, q1: Config, q2: Config, q3: Config) -> float:
        """``∂³x/∂q1∂q2∂q3``."""
        def each(a, b):
            v, x = self._length_of(a, b)
            d = lambda *by: self._v(a, b, *by)  # noqa: E731
            v1, v2, v3 = d(q1), d(q2), d(q3)
            a1, a2, a3 = v @ v1, v @ v2, v @ v3
            a12, a13, a23 = v2 @ v1 + v @ d(q1, q2), v3 @ v1 + v @ d(q1, q3), v3 @ v2 + v @ d(q2, q3)
            a123 = (d(q2, q3) @ v1 + v2 @ d(q1, q3) + v3 @ d(q1, q2) + v @ d(q1, q2, q3))
            return (a123 / x - (a12 * a3 + a13 * a2 + a1 * a23) / x ** 3
                    + 3.0 * a1 * a2 * a3 / x ** 5)
        return self._sum(each)

    # The rate and its derivatives --------------------------------------------------------
    def _configs(self) -> List[Config]:
        return list(self._system.configs)

    def velocity(self) -> float:
        """``ẋ = Σ_i ∂x/∂q_i q̇_i``."""
        return float(sum(self.length_dq(c) * c.dq for c in self._configs()))

    def velocity_ddq(self, dq1: Config) -> float:
        """``∂ẋ/∂q̇1 = ∂x/∂q1``."""
        return self.length_dq(dq1)

    def velocity_dq(self, q1: Config) -> float:
        """``∂ẋ/∂q1 = Σ_i ∂²x/∂q_i∂q1 q̇_i``."""
        return float(sum(self.length_dqdq(c, q1) * c.dq for c in self._configs()))

    def velocity_ddqdq(self, dq1: Config, q2: Config) -> float:
        """``∂²ẋ/∂q̇1∂q2 = ∂²x/∂q1∂q2``."""
        return self.length_dqdq(dq1, q2)

    def velocity_dqdq(self, q1: Config, q2: Config) -> float:
        """``∂²ẋ/∂q1∂q2 = Σ_i ∂³x/∂q_i∂q1∂q2 q̇_i``."""
        return float(sum(self.length_dqdqdq(c, q1, q2) * c.dq for c in self._configs()))

    # Checks against central differences (trep's validate_*) -------------------------------
    def _validate(self, value: Callable[..., float], derivative: Callable[..., float],
                  rank: int, by_velocity: bool, delta: float, tolerance: float,
                  verbose: bool) -> bool:
        """Every derivative of rank ``rank`` against central differences of ``value``'s lower
        one in the last config (in ``q̇`` where ``by_velocity``), relative to its scale."""
        configs = self._configs()
        ok = True
        grids = [[]]
        for _ in range(rank - 1):
            grids = [g + [c] for g in grids for c in configs]
        for lower in grids:
            for c in configs:
                exact = derivative(*(lower + [c]))
                attr = "dq" if by_velocity else "q"
                kept = getattr(c, attr)
                setattr(c, attr, kept + delta)
                plus = value(*lower)
                setattr(c, attr, kept - delta)
                minus = value(*lower)
                setattr(c, attr, kept)
                approx = (plus - minus) / (2.0 * delta)
                error = abs(exact - approx) / max(1.0, abs(exact))
                if error > tolerance:
                    ok = False
                    if verbose:
                        print(f"{derivative.__name__}{tuple(x.name for x in lower + [c])}: "
                              f"{exact!r} against {approx!r}")
        return ok

    validate_length_dq = _validator("length", "length_dq", 1, False)
    validate_length_dqdq = _validator("length_dq", "length_dqdq", 2, False)
    validate_length_dqdqdq = _validator("length_dqdq", "length_dqdqdq", 3, False)
    validate_velocity_dq = _validator("velocity", "velocity_dq", 1, False)
    validate_velocity_ddq = _validator("velocity", "velocity_ddq", 1, True)
    validate_velocity_dqdq = _validator("velocity_dq", "velocity_dqdq", 2, False)
    validate_velocity_ddqdq = _validator("velocity_ddq", "velocity_ddqdq", 2, False)
