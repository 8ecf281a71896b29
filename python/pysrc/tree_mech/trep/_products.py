"""Derivatives of products of a frame's pose factors by the configs, by the product rule:
one mechanism for the body velocity's derivatives (``Frame.vb_*``), ``g⁻¹``'s and the
wrenches' generalized forces.

A product is a tuple of factors: ``("inv",)`` is ``g⁻¹``; ``("g", S)`` is ``∂^S g``, the pose
differentiated by the configs in ``S`` (``S = ()``: ``g`` itself); ``("K", S)`` is
``[(∂^S R)ᵀ 0; 0 δ]`` built from the rotation's derivative (``δ = 1`` for ``S = ()``, else 0).
``∂_j g⁻¹ = −g⁻¹ ∂_j g g⁻¹``, ``∂_j ∂^S g = ∂^{S+j} g``, ``∂_j K_S = K_{S+j}``; ``∂^S g`` is the
spatial generators of the configs in ``S`` in order from the root, times ``g``
(``Frame._pose_by``).
"""
from __future__ import annotations

from typing import Any, List, Tuple

import numpy as np

Factor = Tuple[Any, ...]
Term = Tuple[float, Tuple[Factor, ...]]


def derivative(terms: List[Term], q: Any) -> List[Term]:
    """``∂/∂q`` of a sum of products of factors."""
    out: List[Term] = []
    for coefficient, factors in terms:
        for k, factor in enumerate(factors):
            before, after = factors[:k], factors[k + 1:]
            if factor[0] == "inv":
                replaced: Tuple[Factor, ...] = (("inv",), ("g", (q,)), ("inv",))
                out.append((-coefficient, before + replaced + after))
            else:
                out.append((coefficient, before + ((factor[0], factor[1] + (q,)),) + after))
    return out


def derivatives(terms: List[Term], *by: Any) -> List[Term]:
    """The terms differentiated by each config of ``by`` in turn."""
    for q in by:
        terms = derivative(terms, q)
    return terms


def value(frame: Any, terms: List[Term]) -> np.ndarray:
    """The sum's 4×4 matrix at the system's state."""
    total = np.zeros((4, 4))
    for coefficient, factors in terms:
        product = np.eye(4)
        for factor in factors:
            product = product @ _factor(frame, factor)
        total += coefficient * product
    return total


def _factor(frame: Any, factor: Factor) -> np.ndarray:
    if factor[0] == "inv":
        return frame.g_inv()
    configs = factor[1]
    g = frame._pose_by(configs)
    if factor[0] == "g":
        return g
    out = np.zeros((4, 4))
    out[:3, :3] = g[:3, :3].T
    if not configs:
        out[3, 3] = 1.0
    return out
