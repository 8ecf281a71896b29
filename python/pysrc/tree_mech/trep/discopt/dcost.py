"""trep's ``DCost``: the tracking cost of a discrete trajectory,

    h = Σ_{k<k_f} ℓ(x(k), u(k), k) + m(x(k_f)),
    ℓ = ½ (x − x_d(k))ᵀ Q (x − x_d(k)) + ½ (u − u_d(k))ᵀ R (u − u_d(k)),
    m = ½ (x − x_d(k_f))ᵀ Q_f (x − x_d(k_f))       (Q_f = Q unless given),

with its first and second derivatives (the second are the weights themselves).
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np


def _square(m: Any, n: int, what: str) -> np.ndarray:
    a = np.asarray(m, dtype=float)
    if a.shape != (n, n):
        raise ValueError(f"{what} has shape {a.shape}; it must be {(n, n)}")
    return a


class DCost:
    """The cost of tracking the states ``xd`` (N × nX) and inputs ``ud`` ((N−1) × nU) with
    weights ``Q``, ``R`` and, on the final state, ``Qf`` (``Q`` unless given)."""

    def __init__(self, xd: Any, ud: Any, Q: Any, R: Any, Qf: Optional[Any] = None):
        self.xd = np.atleast_2d(np.asarray(xd, dtype=float))
        self.ud = np.atleast_2d(np.asarray(ud, dtype=float))
        nx, nu = self.xd.shape[1], self.ud.shape[1]
        self.Q = _square(Q, nx, "Q")
        self.R = _square(R, nu, "R")
        self.Qf = self.Q if Qf is None else _square(Qf, nx, "Qf")

    def _dx(self, xk: Any, k: int) -> np.ndarray:
        return np.asarray(xk, dtype=float) - self.xd[k]

    def _du(self, uk: Any, k: int) -> np.ndarray:
        return np.asarray(uk, dtype=float) - self.ud[k]

    def l(self, xk: Any, uk: Any, k: int) -> float:  # noqa: E743 (trep's name)
        """The running cost ``ℓ(x, u, k)``."""
        dx, du = self._dx(xk, k), self._du(uk, k)
        return float(0.5 * (dx @ self.Q @ dx + du @ self.R @ du))

    def m(self, xkf: Any) -> float:
        """The terminal cost ``m(x)``."""
        dx = self._dx(xkf, -1)
        return float(0.5 * dx @ self.Qf @ dx)

    def l_dx(self, xk: Any, uk: Any, k: int) -> np.ndarray:
        """``∂ℓ/∂x = Q (x − x_d)``."""
        return self.Q @ self._dx(xk, k)

    def l_du(self, xk: Any, uk: Any, k: int) -> np.ndarray:
        """``∂ℓ/∂u = R (u − u_d)``."""
        return self.R @ self._du(uk, k)

    def m_dx(self, xkf: Any) -> np.ndarray:
        """``∂m/∂x = Q_f (x − x_d(k_f))``."""
        return self.Qf @ self._dx(xkf, -1)

    def l_dxdx(self, xk: Any, uk: Any, k: int) -> np.ndarray:
        """``∂²ℓ/∂x² = Q``."""
        return self.Q

    def l_dudu(self, xk: Any, uk: Any, k: int) -> np.ndarray:
        """``∂²ℓ/∂u² = R``."""
        return self.R

    def l_dxdu(self, xk: Any, uk: Any, k: int) -> np.ndarray:
        """``∂²ℓ/∂x∂u = 0``."""
        return np.zeros((self.Q.shape[0], self.R.shape[0]))

    def m_dxdx(self, xkf: Any) -> np.ndarray:
        """``∂²m/∂x² = Q_f``."""
        return self.Qf
