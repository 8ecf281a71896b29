"""Inputs that act through a force written in Python (trep's ``Force._create_input``: a
wrench whose entries name inputs, a script's own force with ``f_du``): the step's and the
dynamics' derivatives with respect to them.

Such a force's ``F(q, q̇, u)`` is called back by the runtime at the step's ``u``, so the step
and its derivatives with respect to ``q₁``, ``p₁``, the ConfigForce inputs and ``k₂`` are
the runtime's. For these inputs the model carries one hidden input per dynamic config, a
force ``w_r`` on it, held at zero: ``∂F/∂u`` at the solution says how a change of ``u`` is a
change of ``w`` (docs/derivations.md, "Inputs through a force"). With ``y`` any output of
the step (``q₂``, ``p₂``, ``λ``), ``B = ∂F/∂u`` at the step's quadrature point, ``D_j B`` its
total derivative along direction ``x_j`` of the step's inputs (through ``q_mid = (q₁ + q₂)/2``
and ``v = (q₂ − q₁)/Δt``) and ``C = ∂²F/∂u∂u``:

* ``y_{u_k} = Σ_r B_rk y_{w_r}``;
* ``y_{u_k x_j} = Σ_r B_rk y_{w_r x_j} + Σ_r (D_j B_rk) y_{w_r}``;
* ``y_{u_k u_l} = Σ_s B_sl y_{u_k w_s} + Σ_s (D_{u_k} B_sl + C_skl) y_{w_s}``

— the implicit function theorem on the step's equations, where ``F`` enters the residual
and the end momentum linearly, as ``w`` does. The dynamics' ``∂q̈/∂u`` and ``∂λ/∂u`` are the
first line with ``y = (q̈, λ)``.
"""
from __future__ import annotations

from typing import Dict, Sequence, Tuple

import numpy as np

#: The step's input blocks, in the runtime's order.
BLOCKS = ("q1", "p1", "u1", "k2")
OUTPUTS = ("q2", "p2", "lambda1")


def _offsets(sizes: Dict[str, int]) -> Dict[str, int]:
    out, at = {}, 0
    for b in BLOCKS:
        out[b] = at
        at += sizes[b]
    return out


def _whole(derivs: Dict[str, np.ndarray], of: str, sizes: Dict[str, int], second: bool
           ) -> Tuple[np.ndarray, np.ndarray]:
    """Output ``of``'s first derivatives as one matrix over the whole input ``x`` and (if
    ``second``) its second derivatives as one symmetric rows × x × x array."""
    rows = derivs[f"{of}_dq1"].shape[0]
    jac = np.concatenate([derivs[f"{of}_d{b}"].reshape(rows, sizes[b]) for b in BLOCKS], axis=1)
    if not second:
        return jac, np.zeros((0, 0, 0))
    at, x = _offsets(sizes), jac.shape[1]
    hess = np.zeros((jac.shape[0], x, x))
    for k, a in enumerate(BLOCKS):
        for b in BLOCKS[k:]:
            blk = derivs[f"{of}_d{a}d{b}"]
            if blk.size == 0:
                continue  # no rows (or no such inputs): handed back as (0, 0, 0)
            ra, rb = slice(at[a], at[a] + sizes[a]), slice(at[b], at[b] + sizes[b])
            hess[:, ra, rb] = blk
            hess[:, rb, ra] = blk.transpose(0, 2, 1)
    return jac, hess


def _blocks(of: str, jac: np.ndarray, hess: np.ndarray, sizes: Dict[str, int], second: bool
            ) -> Dict[str, np.ndarray]:
    """:func:`_whole` undone: the runtime's keys (``q2_dq1``, ``q2_dq1dp1`` …)."""
    at = _offsets(sizes)
    cut = {b: slice(at[b], at[b] + sizes[b]) for b in BLOCKS}
    out = {f"{of}_d{b}": jac[:, cut[b]].copy() for b in BLOCKS}
    if second:
        for k, a in enumerate(BLOCKS):
            for b in BLOCKS[k:]:
                out[f"{of}_d{a}d{b}"] = hess[:, cut[a], cut[b]].copy()
    return out


def dynamics_columns(block: np.ndarray, kept: Sequence[int], hidden: Sequence[int],
                     b: np.ndarray) -> np.ndarray:
    """``∂y/∂u`` over the model's inputs ``block`` (its columns ``kept`` the ConfigForce
    inputs', ``hidden`` the per-config forces') as columns ``(kept…, through…)``."""
    return np.hstack([block[:, list(kept)], block[:, list(hidden)] @ b])


class StepPoint:
    """Where a step's forces were evaluated and how that point moves with the step's inputs:
    ``perm``/``dperm``/``kperm`` place trep's configs among the model's (``trep = model[perm]``),
    ``dt`` the step."""

    def __init__(self, perm: np.ndarray, dperm: np.ndarray, kperm: np.ndarray, dt: float):
        self.perm, self.dperm, self.kperm, self.dt = perm, dperm, kperm, dt

    def tangents(self, dq2: np.ndarray, sizes: Dict[str, int]) -> Tuple[np.ndarray, np.ndarray]:
        """``∂q_mid/∂x`` and ``∂v/∂x`` (trep's configs × directions) from ``dq2 = ∂q₂_d/∂x``
        (the model's dynamic rows × directions: x's, then any more)."""
        at = _offsets(sizes)
        n, nd = len(self.perm), len(self.dperm)
        q1 = np.zeros((n, dq2.shape[1]))
        q2 = np.zeros((n, dq2.shape[1]))
        q1[np.arange(n), at["q1"] + self.perm] = 1.0
        q2[:nd] = dq2[self.dperm]
        q2[np.arange(nd, n), at["k2"] + self.kperm] = 1.0
        return 0.5 * (q1 + q2), (q2 - q1) / self.dt


def complete(derivs: Dict[str, np.ndarray], second: bool, kept: Sequence[int],
             hidden: Sequence[int], point: StepPoint, b: np.ndarray,
             b_dq: np.ndarray, b_dv: np.ndarray, b_du: np.ndarray) -> Dict[str, np.ndarray]:
    """The runtime's step derivatives ``derivs`` (its ``u1`` block over the model's inputs)
    with the ``u1`` block made ``(kept…, through…)``: the ConfigForce inputs' columns
    ``kept``, then one column per input through a force, from the hidden forces' columns
    ``hidden`` (trep's dynamic configs' order) and, at the step's point, ``b = ∂F/∂u``
    (configs × inputs), ``b_dq``, ``b_dv`` (``∂B/∂q``, ``∂B/∂q̇``: configs × inputs × every
    config) and ``b_du = ∂²F/∂u∂u`` (the module's formulas)."""
    sizes = {bk: derivs[f"q2_d{bk}"].shape[1] for bk in BLOCKS}
    at = _offsets(sizes)
    x = sum(sizes.values())
    nt = b.shape[1]
    w = at["u1"] + np.asarray(hidden, dtype=int)
    keep = np.concatenate([np.arange(at["u1"]),
                           at["u1"] + np.asarray(kept, dtype=int),
                           x + np.arange(nt),
                           np.arange(at["k2"], x)]).astype(int)
    new_sizes = dict(sizes, u1=len(kept) + nt)
    # The step's point along every direction, the inputs through forces included.
    dq2 = np.concatenate([derivs[f"q2_d{bk}"] for bk in BLOCKS], axis=1)
    mid, vel = point.tangents(np.hstack([dq2, dq2[:, w] @ b]), sizes)
    # D_j B_rk along every direction j of the extended x.
    d_b = (np.einsum("rka,aj->rkj", b_dq, mid) + np.einsum("rka,aj->rkj", b_dv, vel)
           if second else None)
    out: Dict[str, np.ndarray] = {}
    for of in OUTPUTS:
        jac, hess = _whole(derivs, of, sizes, second)
        y_w = jac[:, w]
        jac_e = np.hstack([jac, y_w @ b])
        hess_e = np.zeros((0, 0, 0))
        if second:
            rows = jac.shape[0]
            hess_e = np.zeros((rows, x + nt, x + nt))
            hess_e[:, :x, :x] = hess
            h_u = (np.einsum("ck,rcj->rkj", b, hess[:, w, :])
                   + np.einsum("ckj,rc->rkj", d_b[:, :, :x], y_w))
            h_uu = (np.einsum("sl,rks->rkl", b, h_u[:, :, w])
                    + np.einsum("slk,rs->rkl", d_b[:, :, x:], y_w)
                    + np.einsum("skl,rs->rkl", b_du, y_w))
            hess_e[:, x:, :x] = h_u
            hess_e[:, :x, x:] = h_u.transpose(0, 2, 1)
            hess_e[:, x:, x:] = h_uu
            hess_e = hess_e[:, keep][:, :, keep]
        out.update(_blocks(of, jac_e[:, keep], hess_e, new_sizes, second))
    return out
