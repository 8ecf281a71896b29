"""trep's ``DSystem``: a midpoint variational integrator seen as a first-order discrete
system ``X(k+1) = f(X(k), U(k), k)`` (docs/derivations.md, "trep's discrete optimal
control").

The state is ``X = (q_d, q_k, p, v_k)`` — every config (trep's order: dynamic, then
kinematic), the dynamic momenta and the kinematic configs' discrete velocity
``v_k(k) = (q_k(k) − q_k(k−1))/(t(k) − t(k−1))``; the input is ``U = (u, ρ)``, the force
inputs over the step and the kinematic configs at its end (``q_k(k+1) = ρ(k)``). So

    f = (q2_d, ρ, p2, (ρ − q_k)/Δt),

whose derivatives are the integrator's (``q2_dq1`` …) with the identity blocks of ``ρ``;
``v_k`` enters nothing, and only ``q2_d`` and ``p2`` have second derivatives.
"""
from __future__ import annotations

from collections import namedtuple
from typing import Any, Optional

import numpy as np

from .._core import ConvergenceError, MidpointVI
from .._trajectory import load_trajectory, save_trajectory
from .dlqr import solve_tv_lqr

SplitState = namedtuple("split_state", ["Q", "p", "v"])
SplitInput = namedtuple("split_input", ["u", "rho"])
SplitTrajectory = namedtuple("split_trajectory", ["Q", "p", "v", "u", "rho"])
Trajectory = namedtuple("trajectory", ["X", "U"])
TangentTrajectory = namedtuple("tangent_trajectory", ["dX", "dU"])
Linearization = namedtuple("linearization", ["A", "B"])
Feedback = namedtuple("feedback", ["Kproj", "A", "B"])
DerivativeError = namedtuple("error", ["error", "exact_norm", "approx_norm"])


class DSystem:
    """A ``MidpointVI`` as the discrete system ``X(k+1) = f(X(k), U(k), k)`` on the times
    ``t`` (one per state of a trajectory)."""

    def __init__(self, varint: MidpointVI, t: Any):
        self.varint = varint
        self.time = np.asarray(t, dtype=float).reshape(-1)
        if len(self.time) < 2 or not np.all(np.diff(self.time) > 0):
            raise ValueError("t must hold at least two increasing times")
        s = varint.system
        self._nQ, self._nd, self._nk, self._nu = s.nQ, s.nQd, s.nQk, s.nu
        self._nX = self._nQ + self._nd + self._nk
        self._nU = self._nu + self._nk
        self._xk = np.zeros(self._nX)
        self._uk = np.zeros(self._nU)
        self._k = 0

    # Sizes and the current point ----------------------------------------------------------
    nX = property(lambda self: self._nX, doc="Number of states.")
    nU = property(lambda self: self._nU, doc="Number of inputs.")
    system = property(lambda self: self.varint.system, doc="The mechanical system.")
    xk = property(lambda self: self._xk.copy(), doc="The current state.")
    uk = property(lambda self: self._uk.copy(), doc="The current input.")
    k = property(lambda self: self._k, doc="The current discrete time.")
    #: trep's private name of the time base, which its own examples read.
    _time = property(lambda self: self.time, doc="The time base (trep's ``_time``).")

    def kf(self) -> int:
        """The last discrete time a state can be set to (``len(time) − 1``)."""
        return len(self.time) - 1

    # Building and splitting ---------------------------------------------------------------
    def _part(self, value: Any, n: int, what: str, shape=()) -> np.ndarray:
        if value is None:
            return np.zeros(shape + (n,))
        v = np.asarray(value, dtype=float)
        want = shape + (n,)
        # A vector of one-entry states (or a number for one entry) is taken as meant.
        if v.shape != want and v.ndim < len(want) and v.size == int(np.prod(want)):
            v = v.reshape(want)
        if v.shape != want:
            # What numpy broadcasts into the part, as trep assigns it (a system without
            # kinematic configs takes rho of shape (N − 1, 1) into its (N − 1, 0) part).
            try:
                v = np.broadcast_to(v, want).copy()
            except ValueError:
                raise ValueError(f"{what} has shape {v.shape}; this system needs {want}") from None
        return v

    def build_state(self, Q: Any = None, p: Any = None, v: Any = None) -> np.ndarray:
        """``X = (Q, p, v)``; a part not given is zero."""
        return np.concatenate([self._part(Q, self._nQ, "Q"), self._part(p, self._nd, "p"),
                               self._part(v, self._nk, "v")])

    def build_input(self, u: Any = None, rho: Any = None) -> np.ndarray:
        """``U = (u, ρ)``; a part not given is zero."""
        return np.concatenate([self._part(u, self._nu, "u"), self._part(rho, self._nk, "rho")])

    def build_trajectory(self, Q=None, p=None, v=None, u=None, rho=None) -> Trajectory:
        """State and input trajectories from their parts (``N`` states on the time base,
        ``N − 1`` inputs); a part not given is zero."""
        n = len(self.time)
        X = np.concatenate([self._part(Q, self._nQ, "Q", (n,)),
                            self._part(p, self._nd, "p", (n,)),
                            self._part(v, self._nk, "v", (n,))], axis=1)
        U = np.concatenate([self._part(u, self._nu, "u", (n - 1,)),
                            self._part(rho, self._nk, "rho", (n - 1,))], axis=1)
        return Trajectory(X, U)

    def split_state(self, X: Any = None) -> SplitState:
        """``(Q, p, v)`` of a state (zeros for ``None``)."""
        x = self._part(X, self._nX, "X")
        a, b = self._nQ, self._nQ + self._nd
        return SplitState(x[:a].copy(), x[a:b].copy(), x[b:].copy())

    def split_input(self, U: Any = None) -> SplitInput:
        """``(u, ρ)`` of an input (zeros for ``None``)."""
        u = self._part(U, self._nU, "U")
        return SplitInput(u[: self._nu].copy(), u[self._nu:].copy())

    def split_trajectory(self, X: Any = None, U: Any = None) -> SplitTrajectory:
        """``(Q, p, v, u, ρ)`` of a trajectory (zeros for a part not given)."""
        n = len(self.time)
        X = self._part(X, self._nX, "X", (n,))
        U = self._part(U, self._nU, "U", (n - 1,))
        a, b = self._nQ, self._nQ + self._nd
        return SplitTrajectory(X[:, :a].copy(), X[:, a:b].copy(), X[:, b:].copy(),
                               U[:, : self._nu].copy(), U[:, self._nu:].copy())

    def convert_trajectory(self, dsys_a: "DSystem", X: Any, U: Any) -> Trajectory:
        """``(X, U)`` of ``dsys_a`` reordered for this system by config and input names;
        what this system has and ``dsys_a`` lacks is zero. Only reorders: the result need not
        be a trajectory of this system."""
        Qa, pa, va, ua, rhoa = dsys_a.split_trajectory(X, U)
        a, b = dsys_a.system, self.system
        n = len(self.time)
        if len(Qa) != n:
            raise ValueError(f"the trajectory has {len(Qa)} states; this system's time base has {n}")

        def move(src, names_a, names_b, width):
            out = np.zeros((src.shape[0], width))
            where = {name: i for i, name in enumerate(names_a)}
            for j, name in enumerate(names_b):
                if name in where:
                    out[:, j] = src[:, where[name]]
            return out

        configs = lambda s: [c.name for c in s.configs]  # noqa: E731
        dyn = lambda s: [c.name for c in s.dyn_configs]  # noqa: E731
        kin = lambda s: [c.name for c in s.kin_configs]  # noqa: E731
        inputs = lambda s: [i.name for i in s.inputs]  # noqa: E731
        return self.build_trajectory(
            move(Qa, configs(a), configs(b), self._nQ), move(pa, dyn(a), dyn(b), self._nd),
            move(va, kin(a), kin(b), self._nk), move(ua, inputs(a), inputs(b), self._nu),
            move(rhoa, kin(a), kin(b), self._nk))

    def save_state_trajectory(self, filename: str, X: Any = None, U: Any = None) -> None:
        """Saves ``(X, U)`` (zeros for one not given) split into its parts, as
        ``trep.save_trajectory`` does, on this system's time base."""
        Q, p, v, u, rho = self.split_trajectory(X, U)
        save_trajectory(filename, self.system, self.time, Q, p, v, u, rho)

    def load_state_trajectory(self, filename: str) -> Trajectory:
        """``(X, U)`` from a file of :meth:`save_state_trajectory` or ``save_trajectory``;
        what the file lacks (another system's parts, inputs not saved) is zero."""
        t, Q, p, v, u, rho = load_trajectory(filename, self.system)
        if len(t) != len(self.time):
            raise ValueError(f"{filename} holds {len(t)} times; this system's time base has "
                             f"{len(self.time)}")
        return self.build_trajectory(Q, p, v, u, rho)

    # Dynamics -----------------------------------------------------------------------------
    def set(self, xk: Any, uk: Any, k: int, xk_hint: Any = None, lambda_hint: Any = None) -> None:
        """Sets the state, input and discrete time, and steps the integrator to ``k + 1``
        (when ``k`` is not the last time), so that :meth:`f` and its derivatives refer to
        them. A step that does not converge raises ``ConvergenceError``. (The hints are
        accepted for trep's scripts; tree-mech's Newton starts from its own predictor.)"""
        self._set(xk, uk, k, 0)

    def _set(self, xk: Any, uk: Any, k: int, order: int) -> None:
        """:meth:`set`, the step's derivatives up to ``order`` solved for with it."""
        k = int(k)
        if not 0 <= k <= self.kf():
            raise ValueError(f"k = {k} is outside the time base (0 … {self.kf()})")
        x = self._part(xk, self._nX, "xk")
        u = self._part(uk, self._nU, "uk")
        Q, p, _ = self.split_state(x)
        self.varint.initialize_from_state(self.time[k], Q, p)
        self._xk, self._uk, self._k = x.copy(), u.copy(), k
        if k < self.kf():
            force, rho = self.split_input(u)
            self.varint._step(self.time[k + 1], force, rho, order)

    def step(self, uk: Any, xk_hint: Any = None, lambda_hint: Any = None) -> None:
        """``set(f(), uk, k + 1)``: advances to the next discrete time under ``uk``."""
        self._set(self.f(), uk, self._k + 1, 0)

    def _dt(self) -> float:
        if self._k >= self.kf():
            raise ValueError(f"k = {self._k} is the last time: there is no next state")
        return self.time[self._k + 1] - self.time[self._k]

    def f(self) -> np.ndarray:
        """The next state ``X(k+1)``."""
        dt = self._dt()
        vi = self.varint
        q1k = self.split_state(self._xk).Q[self._nd:]
        rho = self.split_input(self._uk).rho
        return self.build_state(vi.q2, vi.p2, (rho - q1k) / dt)

    # First derivatives ------------------------------------------------------------------
    def _slices(self):
        nQ, nd = self._nQ, self._nd
        return (slice(0, nd), slice(nd, nQ), slice(nQ, nQ + nd), slice(nQ + nd, self._nX))

    def fdx(self) -> np.ndarray:
        """``∂f/∂X`` (nX × nX)."""
        dt = self._dt()
        vi = self.varint
        qd, qk, p, v = self._slices()
        q_all = slice(0, self._nQ)
        out = np.zeros((self._nX, self._nX))
        out[qd, q_all] = vi.q2_dq1()
        out[qd, p] = vi.q2_dp1()
        out[p, q_all] = vi.p2_dq1()
        out[p, p] = vi.p2_dp1()
        out[v, qk] = -np.eye(self._nk) / dt
        return out

    def fdu(self) -> np.ndarray:
        """``∂f/∂U`` (nX × nU)."""
        dt = self._dt()
        vi = self.varint
        qd, qk, p, v = self._slices()
        u, rho = slice(0, self._nu), slice(self._nu, self._nU)
        out = np.zeros((self._nX, self._nU))
        out[qd, u] = vi.q2_du1()
        out[qd, rho] = vi.q2_dk2()
        out[qk, rho] = np.eye(self._nk)
        out[p, u] = vi.p2_du1()
        out[p, rho] = vi.p2_dk2()
        out[v, rho] = np.eye(self._nk) / dt
        return out

    # Second derivatives, contracted with an adjoint z ------------------------------------
    def _contract(self, z: Any, a: str, b: str) -> np.ndarray:
        """``Σ_i z_i ∂²f_i/∂a∂b`` over the rows with second derivatives (``q2_d``, ``p2``)
        for the integrator's inputs ``a``, ``b`` (``q1``, ``p1``, ``u1``, ``k2``)."""
        z = np.asarray(z, dtype=float)
        if z.ndim != 1 or len(z) < self._nX:
            raise ValueError(f"z has shape {z.shape}; this system needs at least ({self._nX},)")
        z = z[: self._nX]  # trep reads the rows it needs and leaves the rest
        qd, _, p, _ = self._slices()
        vi = self.varint
        # trep's layout is (input₁, input₂, output).
        return (getattr(vi, f"q2_d{a}d{b}")() @ z[qd]) + (getattr(vi, f"p2_d{a}d{b}")() @ z[p])

    def fdxdx(self, z: Any) -> np.ndarray:
        """``zᵀ ∂²f/∂X∂X`` (nX × nX)."""
        self._dt()
        nQ, nd = self._nQ, self._nd
        q, p = slice(0, nQ), slice(nQ, nQ + nd)
        out = np.zeros((self._nX, self._nX))
        out[q, q] = self._contract(z, "q1", "q1")
        out[q, p] = self._contract(z, "q1", "p1")
        out[p, q] = out[q, p].T
        out[p, p] = self._contract(z, "p1", "p1")
        return out

    def fdxdu(self, z: Any) -> np.ndarray:
        """``zᵀ ∂²f/∂X∂U`` (nX × nU)."""
        self._dt()
        nQ, nd = self._nQ, self._nd
        q, p = slice(0, nQ), slice(nQ, nQ + nd)
        u, rho = slice(0, self._nu), slice(self._nu, self._nU)
        out = np.zeros((self._nX, self._nU))
        out[q, u] = self._contract(z, "q1", "u1")
        out[q, rho] = self._contract(z, "q1", "k2")
        out[p, u] = self._contract(z, "p1", "u1")
        out[p, rho] = self._contract(z, "p1", "k2")
        return out

    def fdudu(self, z: Any) -> np.ndarray:
        """``zᵀ ∂²f/∂U∂U`` (nU × nU)."""
        self._dt()
        u, rho = slice(0, self._nu), slice(self._nu, self._nU)
        out = np.zeros((self._nU, self._nU))
        out[u, u] = self._contract(z, "u1", "u1")
        out[u, rho] = self._contract(z, "u1", "k2")
        out[rho, u] = out[u, rho].T
        out[rho, rho] = self._contract(z, "k2", "k2")
        return out

    # Trajectories -------------------------------------------------------------------------
    def _trajectory(self, X: Any, U: Any):
        n = len(self.time)
        X = self._part(X, self._nX, "X", (n,))
        U = self._part(U, self._nU, "U", (n - 1,))
        return X, U

    def linearize_trajectory(self, X: Any, U: Any) -> Linearization:
        """``A(k) = ∂f/∂X``, ``B(k) = ∂f/∂U`` at each ``(X(k), U(k))`` (need not be a
        trajectory), ``k < k_f``."""
        X, U = self._trajectory(X, U)
        A, B = [], []
        for k in range(len(U)):
            self._set(X[k], U[k], k, 1)
            A.append(self.fdx())
            B.append(self.fdu())
        return Linearization(np.array(A), np.array(B))

    def calc_feedback_controller(self, X: Any, U: Any, Q: Any = None, R: Any = None,
                                 return_linearization: bool = False):
        """The time-varying LQR gains ``K(k)`` for the linearisation about ``(X, U)`` with
        weights ``Q(k)``, ``R(k)`` (functions of ``k`` or fixed arrays; identities when not
        given); with ``return_linearization``, ``(K, A, B)``."""
        A, B = self.linearize_trajectory(X, U)
        Q = (lambda k: np.eye(self._nX)) if Q is None else Q
        R = (lambda k: np.eye(self._nU)) if R is None else R
        K = solve_tv_lqr(A, B, Q, R).K
        return Feedback(K, A, B) if return_linearization else K

    def project(self, bX: Any, bU: Any, Kproj: Any = None) -> Trajectory:
        """The trajectory near ``(bX, bU)`` under the feedback ``Kproj`` (the LQR gains about
        ``(bX, bU)`` when not given): ``X(0) = bX(0)``, ``U(k) = bU(k) − K(k)(X(k) − bX(k))``,
        ``X(k+1) = f(X(k), U(k), k)``."""
        bX, bU = self._trajectory(bX, bU)
        K = self.calc_feedback_controller(bX, bU) if Kproj is None else np.asarray(Kproj)
        X, U = np.zeros_like(bX), np.zeros_like(bU)
        X[0] = bX[0]
        for k in range(len(bU)):
            U[k] = bU[k] - K[k] @ (X[k] - bX[k])
            self._set(X[k], U[k], k, 0)
            X[k + 1] = self.f()
        return Trajectory(X, U)

    def dproject(self, A: Any, B: Any, bdX: Any, bdU: Any, K: Any) -> TangentTrajectory:
        """The tangent trajectory near ``(bdX, bdU)``: ``dX(0) = bdX(0)``,
        ``dU(k) = bdU(k) − K(k)(dX(k) − bdX(k))``, ``dX(k+1) = A(k)dX(k) + B(k)dU(k)``."""
        bdX, bdU = self._trajectory(bdX, bdU)
        dX, dU = np.zeros_like(bdX), np.zeros_like(bdU)
        dX[0] = bdX[0]
        for k in range(len(bdU)):
            dU[k] = bdU[k] - K[k] @ (dX[k] - bdX[k])
            dX[k + 1] = A[k] @ dX[k] + B[k] @ dU[k]
        return TangentTrajectory(dX, dU)

    # Checking the derivatives ------------------------------------------------------------
    def _check(self, xk, uk, k, delta, exact_of, value_of, by_x: bool) -> DerivativeError:
        """Central differences of ``value_of()`` against ``exact_of()``, by X or by U."""
        xk, uk = self._part(xk, self._nX, "xk"), self._part(uk, self._nU, "uk")
        self.set(xk, uk, k)
        exact = exact_of()
        columns = []
        for j in range(self._nX if by_x else self._nU):
            e = np.zeros(self._nX if by_x else self._nU)
            e[j] = delta
            sides = []
            for sign in (1.0, -1.0):
                if by_x:
                    self.set(xk + sign * e, uk, k)
                else:
                    self.set(xk, uk + sign * e, k)
                sides.append(value_of())
            columns.append((sides[0] - sides[1]) / (2 * delta))
        self.set(xk, uk, k)
        approx = np.moveaxis(np.array(columns), 0, -1)
        return DerivativeError(float(np.linalg.norm(exact - approx)),
                               float(np.linalg.norm(exact)), float(np.linalg.norm(approx)))

    def _adjoint(self) -> np.ndarray:
        return np.linspace(1.0, 2.0, self._nX)

    def check_fdx(self, xk, uk, k, delta=1e-5) -> DerivativeError:
        """``fdx()`` against central differences of ``f()``."""
        return self._check(xk, uk, k, delta, self.fdx, self.f, True)

    def check_fdu(self, xk, uk, k, delta=1e-5) -> DerivativeError:
        """``fdu()`` against central differences of ``f()``."""
        return self._check(xk, uk, k, delta, self.fdu, self.f, False)

    def check_fdxdx(self, xk, uk, k, delta=1e-5) -> DerivativeError:
        """``fdxdx(z)`` against central differences of ``zᵀfdx()`` (a fixed z)."""
        z = self._adjoint()
        return self._check(xk, uk, k, delta, lambda: self.fdxdx(z), lambda: z @ self.fdx(), True)

    def check_fdxdu(self, xk, uk, k, delta=1e-5) -> DerivativeError:
        """``fdxdu(z)`` against central differences of ``zᵀfdx()`` by U."""
        z = self._adjoint()
        return self._check(xk, uk, k, delta, lambda: self.fdxdu(z), lambda: z @ self.fdx(), False)

    def check_fdudu(self, xk, uk, k, delta=1e-5) -> DerivativeError:
        """``fdudu(z)`` against central differences of ``zᵀfdu()`` by U."""
        z = self._adjoint()
        return self._check(xk, uk, k, delta, lambda: self.fdudu(z), lambda: z @ self.fdu(), False)


__all__ = ["DSystem", "ConvergenceError"]
