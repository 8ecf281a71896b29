"""Time-varying discrete LQ problems, trep's ``solve_tv_lqr`` and ``solve_tv_lq``: the
backward Riccati recursion for ``x(k+1) = A(k) x(k) + B(k) u(k)`` (docs/derivations.md,
"trep's discrete optimal control").

trep writes these costs without the factor ½ (``xᵀQx + uᵀRu``, and ``2qᵀx`` for the linear
terms); the minimisers are those of the halved costs, so the gains are the usual ones.
"""
from __future__ import annotations

from collections import namedtuple
from typing import Callable, Sequence

import numpy as np

Matrices = Callable[[int], np.ndarray]

LqrSolution = namedtuple("solve_tv_lqr", ["K", "P"])
LqSolution = namedtuple("solve_tv_lq", ["K", "C", "P", "b"])


class PerStep(np.ndarray):
    """Matrices by discrete time, as trep hands them out: call it (``Q(k)``, trep's
    functions of ``k``) or index it (``Q[k]``)."""

    def __call__(self, k: int) -> np.ndarray:
        return np.asarray(self[k])


def per_step(matrices) -> PerStep:
    """A stack of matrices as a :class:`PerStep`."""
    return np.asarray(matrices, dtype=float).view(PerStep)


def at_step(w, k: int) -> np.ndarray:
    """``w(k)`` for trep's functions of ``k``; a stack of matrices is indexed by ``k``, one
    matrix is the same at every ``k``."""
    if callable(w):
        return np.asarray(w(k), dtype=float)
    a = np.asarray(w, dtype=float)
    return a[k] if a.ndim == 3 else a


def solve_tv_lqr(A: Sequence[np.ndarray], B: Sequence[np.ndarray], Q, R) -> LqrSolution:
    """The feedback ``u(k) = −K(k) x(k)`` minimising ``Σ xᵀQ(k)x + uᵀR(k)u + xᵀQ(k_f)x``
    over the ``N = len(A)`` steps, and ``P(0)``: with ``Γ = R + BᵀP'B``,
    ``K = Γ⁻¹BᵀP'A`` and ``P = Q + AᵀP'A − KᵀΓK`` from ``P(N) = Q(N)``. ``Q`` and ``R`` are
    functions of ``k`` (or fixed arrays)."""
    n = len(A)
    P = at_step(Q, n)
    K = [None] * n
    for k in range(n - 1, -1, -1):
        a, b = np.asarray(A[k], dtype=float), np.asarray(B[k], dtype=float)
        pa, pb = P @ a, P @ b
        gamma = at_step(R, k) + b.T @ pb
        bpa = pb.T @ a
        K[k] = np.linalg.solve(gamma, bpa)
        # KᵀΓK = (BᵀP'A)ᵀK, since ΓK = BᵀP'A.
        P = at_step(Q, k) + a.T @ pa - bpa.T @ K[k]
        P = 0.5 * (P + P.T)
    return LqrSolution(K, P)  # a list of gains, as trep returns them


def solve_tv_lq(A, B, q, r, Q, S, R) -> LqSolution:
    """The affine feedback ``u(k) = −K(k) x(k) − C(k)`` minimising
    ``Σ 2qᵀx + 2rᵀu + xᵀQx + 2xᵀSu + uᵀRu + 2q(k_f)ᵀx + xᵀQ(k_f)x``: with
    ``Γ = R + BᵀP'B``, ``K = Γ⁻¹(BᵀP'A + Sᵀ)``, ``C = Γ⁻¹(Bᵀb' + r)``,
    ``P = Q + AᵀP'A − KᵀΓK``, ``b = (Aᵀ − KᵀBᵀ)b' + q − Kᵀr`` from ``P(N) = Q(N)``,
    ``b(N) = q(N)``. ``q`` has ``N + 1`` entries, ``r`` ``N``; ``Q``, ``S``, ``R`` are
    functions of ``k`` (or fixed arrays). Returns ``K``, ``C``, ``P(0)`` and ``b(0)``."""
    n = len(A)
    P = at_step(Q, n)
    b_next = np.asarray(q[n], dtype=float)
    K, C = [None] * n, [None] * n
    for k in range(n - 1, -1, -1):
        a, bk = np.asarray(A[k], dtype=float), np.asarray(B[k], dtype=float)
        rk = np.asarray(r[k], dtype=float)
        pa, pb = P @ a, P @ bk
        gamma = at_step(R, k) + bk.T @ pb
        K[k] = np.linalg.solve(gamma, pb.T @ a + at_step(S, k).T)
        C[k] = np.linalg.solve(gamma, bk.T @ b_next + rk)
        b_next = (a.T - K[k].T @ bk.T) @ b_next + np.asarray(q[k], dtype=float) - K[k].T @ rk
        P = at_step(Q, k) + a.T @ pa - K[k].T @ gamma @ K[k]
        P = 0.5 * (P + P.T)
    return LqSolution(K, C, P, b_next)  # lists, as trep returns them
