"""trep's ``DOptimizer``: trajectory optimisation by the projection operator (docs/
derivations.md, "trep's discrete optimal control").

A trajectory ``ξ = (X, U)`` of a ``DSystem`` is improved along a tangent trajectory
``ζ = (dX, dU)`` that minimises a quadratic model of the projected cost ``h(P(ξ + ζ))``
(an LQ problem on the linearisation ``A(k)``, ``B(k)``, solved by ``solve_tv_lq``): the
model's weights are identities (``"steepest"``), the cost's own second derivatives
(``"quasi"``) or the projected cost's true ones (``"newton"``, with the adjoint ``z`` and
the dynamics' second derivatives). An Armijo search along ``ξ + zζ``, each candidate
projected onto the dynamics by the LQR feedback ``Kproj`` (``DSystem.project``), takes the
step. A trajectory is optimal when the model's directional derivative ``Dh·ζ`` falls below
``descent_tolerance``.
"""
from __future__ import annotations

from collections import namedtuple
from typing import Any

import numpy as np

from .._core import ConvergenceError
from .dcost import DCost
from .dlqr import at_step, per_step, solve_tv_lq
from .dsystem import DSystem

DescentModel = namedtuple("descent_model", ["Q", "R", "S"])
DescentDirection = namedtuple("calc_descent_direction", ["Kproj", "dX", "dU", "Q", "R", "S"])
ArmijoSimulation = namedtuple("armijo_simulate", ["success", "nX", "nU"])
ArmijoSearch = namedtuple("armijo_search", ["nX", "nU", "cost1"])
StepResult = namedtuple("step", ["done", "nX", "nU", "dcost0", "cost1"])
OptimizeResult = namedtuple("optimize", ["converged", "X", "U"])
DcostCheck = namedtuple("check_dcost", ["result", "error", "cost1", "cost0", "approx_dcost",
                                        "exact_dcost"])
DdcostCheck = namedtuple("check_ddcost", ["result", "error", "cost1", "cost0", "approx_ddcost",
                                          "exact_ddcost"])

_METHODS = ("steepest", "quasi", "newton")


class DOptimizer:
    """Optimises trajectories of ``dsys`` for ``cost``: ``first_method_iterations`` steps of
    ``first_method`` (``"quasi"``), then ``second_method`` (``"newton"``); progress goes to
    ``monitor`` (a ``DOptimizerDefaultMonitor`` printing to the console when not given)."""

    def __init__(self, dsys: DSystem, cost: DCost, first_method_iterations: int = 10,
                 monitor: Any = None):
        self.dsys = dsys
        self.cost = cost
        self.optimize_ic = False
        self.monitor = DOptimizerDefaultMonitor() if monitor is None else monitor
        self.Qproj = lambda k: np.eye(dsys.nX)
        self.Rproj = lambda k: np.eye(dsys.nU)
        self.descent_tolerance = 1e-6
        self.first_method_iterations = first_method_iterations
        self.first_method = "quasi"
        self.second_method = "newton"
        self.armijo_beta = 0.7
        self.armijo_alpha = 1e-5
        self.armijo_max_iterations = 30

    # Cost and its derivatives along a tangent trajectory ----------------------------------
    def calc_cost(self, X: Any, U: Any) -> float:
        """``h(ξ) = Σ_{k<k_f} ℓ(X(k), U(k), k) + m(X(k_f))``."""
        c = self.cost
        return float(sum(c.l(X[k], U[k], k) for k in range(len(U))) + c.m(X[-1]))

    def calc_dcost(self, X: Any, U: Any, dX: Any, dU: Any) -> float:
        """``Dh(ξ)·ζ`` for a tangent trajectory ``ζ = (dX, dU)``."""
        c = self.cost
        total = sum(c.l_dx(X[k], U[k], k) @ dX[k] + c.l_du(X[k], U[k], k) @ dU[k]
                    for k in range(len(U)))
        return float(total + c.m_dx(X[-1]) @ dX[-1])

    def calc_ddcost(self, X: Any, U: Any, dX: Any, dU: Any, Q: Any, R: Any, S: Any) -> float:
        """The second derivative ``ζᵀ [[Q, S], [Sᵀ, R]] ζ`` summed over the trajectory, for a
        model's weights (``Q`` with ``k_f + 1`` entries, ``R`` and ``S`` with ``k_f``)."""
        n = len(dU)
        total = sum(dX[k] @ at_step(Q, k) @ dX[k] + 2.0 * dX[k] @ at_step(S, k) @ dU[k]
                    + dU[k] @ at_step(R, k) @ dU[k] for k in range(n))
        return float(total + dX[-1] @ at_step(Q, n) @ dX[-1])

    # Quadratic models ---------------------------------------------------------------------
    def calc_steepest_model(self) -> DescentModel:
        """Identity weights: the steepest descent direction. Each of ``Q``, ``R``, ``S`` is
        called with ``k`` as trep's are (or indexed)."""
        n, nx, nu = len(self.dsys.time), self.dsys.nX, self.dsys.nU
        return DescentModel(per_step([np.eye(nx)] * n), per_step([np.eye(nu)] * (n - 1)),
                            per_step(np.zeros((n - 1, nx, nu))))

    def calc_quasi_model(self, X: Any, U: Any) -> DescentModel:
        """The cost's own second derivatives (no second derivative of the dynamics)."""
        c = self.cost
        n = len(U)
        Q = [c.l_dxdx(X[k], U[k], k) for k in range(n)] + [c.m_dxdx(X[-1])]
        R = [c.l_dudu(X[k], U[k], k) for k in range(n)]
        S = [c.l_dxdu(X[k], U[k], k) for k in range(n)]
        return DescentModel(per_step(Q), per_step(R), per_step(S))

    def calc_newton_model(self, X: Any, U: Any, A: Any, B: Any, K: Any) -> DescentModel:
        """The projected cost's second derivatives: with the adjoint ``z(k_f) = ∂m/∂x`` and
        ``z(k) = ∂ℓ/∂x − Kᵀ∂ℓ/∂u + (A − BK)ᵀ z(k+1)``, ``Q(k) = ℓ_xx + z(k+1)·f_xx``,
        ``S(k) = ℓ_xu + z(k+1)·f_xu``, ``R(k) = ℓ_uu + z(k+1)·f_uu``, ``Q(k_f) = m_xx``."""
        c, d = self.cost, self.dsys
        n = len(U)
        Q, R, S = [None] * (n + 1), [None] * n, [None] * n
        z = c.m_dx(X[-1])
        Q[n] = c.m_dxdx(X[-1])
        for k in range(n - 1, -1, -1):
            d._set(X[k], U[k], k, 2)
            Q[k] = c.l_dxdx(X[k], U[k], k) + d.fdxdx(z)
            S[k] = c.l_dxdu(X[k], U[k], k) + d.fdxdu(z)
            R[k] = c.l_dudu(X[k], U[k], k) + d.fdudu(z)
            z = (c.l_dx(X[k], U[k], k) - K[k].T @ c.l_du(X[k], U[k], k)
                 + (A[k] - B[k] @ K[k]).T @ z)
        return DescentModel(per_step(Q), per_step(R), per_step(S))

    def calc_descent_direction(self, X: Any, U: Any, method: str = "steepest") -> DescentDirection:
        """The tangent trajectory minimising ``Dh·ζ + ½ ζᵀ(model)ζ`` on the linearisation,
        with the projection's feedback and the model: ``(Kproj, dX, dU, Q, R, S)``."""
        if method not in _METHODS:
            raise ValueError(f"unknown descent method {method!r}: use one of {', '.join(_METHODS)}")
        X, U = np.asarray(X, dtype=float), np.asarray(U, dtype=float)
        Kproj, A, B = self.dsys.calc_feedback_controller(X, U, self.Qproj, self.Rproj,
                                                         return_linearization=True)
        if method == "steepest":
            model = self.calc_steepest_model()
        elif method == "quasi":
            model = self.calc_quasi_model(X, U)
        else:
            model = self.calc_newton_model(X, U, A, B, Kproj)
        c = self.cost
        n = len(U)
        q = [c.l_dx(X[k], U[k], k) for k in range(n)] + [c.m_dx(X[-1])]
        r = [c.l_du(X[k], U[k], k) for k in range(n)]
        K, C, P, b = solve_tv_lq(A, B, q, r, model.Q, model.S, model.R)
        dX, dU = np.zeros_like(X), np.zeros_like(U)
        if self.optimize_ic:
            # The start is free too: the LQ value xᵀP(0)x + 2b(0)ᵀx is least at −P(0)⁻¹b(0).
            dX[0] = -np.linalg.solve(P, b)
        for k in range(n):
            dU[k] = -K[k] @ dX[k] - C[k]
            dX[k + 1] = A[k] @ dX[k] + B[k] @ dU[k]
        return DescentDirection(Kproj, dX, dU, model.Q, model.R, model.S)

    # Armijo line search -------------------------------------------------------------------
    def armijo_simulate(self, bX: Any, bU: Any, Kproj: Any) -> ArmijoSimulation:
        """``DSystem.project`` of ``(bX, bU)`` under ``Kproj``, or, when a step fails, the
        trajectory as far as it got (``success`` false, the rest zero)."""
        d = self.dsys
        X, U = np.zeros_like(bX), np.zeros_like(bU)
        X[0] = bX[0]
        try:
            for k in range(len(bU)):
                U[k] = bU[k] - Kproj[k] @ (X[k] - bX[k])
                d._set(X[k], U[k], k, 0)
                X[k + 1] = d.f()
        except ConvergenceError:
            return ArmijoSimulation(False, X, U)
        return ArmijoSimulation(True, X, U)

    def armijo_search(self, X: Any, U: Any, Kproj: Any, dX: Any, dU: Any) -> ArmijoSearch:
        """The first ``z = β^m`` whose projected trajectory ``P(ξ + zζ)`` has a cost below
        ``h(ξ) + α z Dh(ξ)·ζ``: ``(nX, nU, cost1)``. Raises ``ConvergenceError`` after
        ``armijo_max_iterations`` tries."""
        cost0 = self.calc_cost(X, U)
        dcost0 = self.calc_dcost(X, U, dX, dU)
        for m in range(self.armijo_max_iterations):
            z = self.armijo_beta ** m
            bX, bU = X + z * dX, U + z * dU
            success, nX, nU = self.armijo_simulate(bX, bU, Kproj)
            if not success:
                self.monitor.armijo_simulation_failure(m, nX, nU, bX, bU)
                continue
            cost1 = self.calc_cost(nX, nU)
            max_cost = cost0 + self.armijo_alpha * z * dcost0
            self.monitor.armijo_evaluation(m, nX, nU, bX, bU, cost1, max_cost)
            if cost1 < max_cost:
                return ArmijoSearch(nX, nU, cost1)
        self.monitor.armijo_search_failure(X, U, dX, dU, cost0, dcost0, Kproj)
        raise ConvergenceError(
            f"the Armijo search found no sufficient decrease in {self.armijo_max_iterations} tries")

    # Optimising ---------------------------------------------------------------------------
    def select_method(self, iteration: int) -> str:
        """``first_method`` for the first ``first_method_iterations`` steps, then
        ``second_method``."""
        return self.first_method if iteration < self.first_method_iterations else self.second_method

    def select_fallback_method(self, iteration: int, current_method: str) -> str:
        """The method to try when ``current_method`` gave no descent: newton → quasi →
        steepest (steepest always descends unless the trajectory is optimal)."""
        fallback = {"newton": "quasi", "quasi": "steepest"}.get(current_method)
        if fallback is None:
            raise ConvergenceError(f"the {current_method} direction does not descend")
        return fallback

    def step(self, iteration: int, X: Any, U: Any, method: str = "steepest") -> StepResult:
        """One step from ``(X, U)`` by ``method`` (falling back while it gives no descent):
        ``(done, nX, nU, dcost0, cost1)``, ``done`` when ``(X, U)`` is already optimal."""
        X, U = np.asarray(X, dtype=float), np.asarray(U, dtype=float)
        self.monitor.step_begin(iteration)
        Kproj, dX, dU, _, _, _ = self.calc_descent_direction(X, U, method)
        cost0 = self.calc_cost(X, U)
        dcost0 = self.calc_dcost(X, U, dX, dU)
        self.monitor.step_info(method, cost0, dcost0, X, U, dX, dU, Kproj)
        if abs(dcost0) < self.descent_tolerance:
            self.monitor.step_termination(cost0, dcost0)
            return StepResult(True, X, U, dcost0, cost0)
        if dcost0 > 0:
            fallback = self.select_fallback_method(iteration, method)
            self.monitor.step_method_failure(method, cost0, dcost0, fallback)
            return self.step(iteration, X, U, fallback)
        nX, nU, cost1 = self.armijo_search(X, U, Kproj, dX, dU)
        self.monitor.step_completed(method, cost1, nX, nU)
        return StepResult(False, nX, nU, dcost0, cost1)

    def optimize(self, X: Any, U: Any, max_steps: int = 50) -> OptimizeResult:
        """Steps from ``(X, U)`` (a trajectory of the system) until it is optimal or
        ``max_steps`` were taken: ``(converged, X, U)``. A line search that finds no decrease
        ends the optimisation unconverged, with the best trajectory."""
        X, U = np.array(X, dtype=float), np.array(U, dtype=float)
        self.monitor.optimize_begin(X, U)
        converged, cost = False, self.calc_cost(X, U)
        for iteration in range(int(max_steps)):
            try:
                done, X, U, _, cost = self.step(iteration, X, U, self.select_method(iteration))
            except ConvergenceError:
                break
            if done:
                converged = True
                break
        self.monitor.optimize_end(converged, X, U, cost)
        return OptimizeResult(converged, X, U)

    # Checks ---------------------------------------------------------------------------------
    def check_dcost(self, X: Any, U: Any, method: str = "steepest", delta: float = 1e-6,
                    tolerance: float = 1e-5) -> DcostCheck:
        """``Dh·ζ`` along the method's direction against ``(h(P(ξ + δζ)) − h(ξ))/δ``."""
        X, U = np.asarray(X, dtype=float), np.asarray(U, dtype=float)
        Kproj, dX, dU, _, _, _ = self.calc_descent_direction(X, U, method)
        exact = self.calc_dcost(X, U, dX, dU)
        cost0 = self.calc_cost(X, U)
        nX, nU = self.dsys.project(X + delta * dX, U + delta * dU, Kproj)
        cost1 = self.calc_cost(nX, nU)
        approx = (cost1 - cost0) / delta
        error = abs(approx - exact)
        return DcostCheck(error < tolerance, error, cost1, cost0, approx, exact)

    def check_ddcost(self, X: Any, U: Any, method: str = "steepest", delta: float = 1e-6,
                     tolerance: float = 1e-5) -> DdcostCheck:
        """The Newton model's ``D²(h∘P)(ζ, ζ)`` along the method's direction against the
        change of ``D(h∘P)·ζ`` (ζ carried to ``P(ξ + δζ)`` by ``dproject``) over δ."""
        X, U = np.asarray(X, dtype=float), np.asarray(U, dtype=float)
        d = self.dsys
        Kproj, dX, dU, _, _, _ = self.calc_descent_direction(X, U, method)
        A, B = d.linearize_trajectory(X, U)
        Q, R, S = self.calc_newton_model(X, U, A, B, Kproj)
        exact = self.calc_ddcost(X, U, dX, dU, Q, R, S)
        cost0 = self.calc_dcost(X, U, dX, dU)
        nX, nU = d.project(X + delta * dX, U + delta * dU, Kproj)
        nA, nB = d.linearize_trajectory(nX, nU)
        ndX, ndU = d.dproject(nA, nB, dX, dU, Kproj)
        cost1 = self.calc_dcost(nX, nU, ndX, ndU)
        approx = (cost1 - cost0) / delta
        error = abs(approx - exact)
        return DdcostCheck(error < tolerance, error, cost1, cost0, approx, exact)

    def descent_plot(self, X: Any, U: Any, method: str = "steepest", points: int = 40,
                     legend: bool = True) -> None:
        """Plots (matplotlib) the true cost change along the method's direction, its
        quadratic model, the sufficient-decrease line and the Armijo points."""
        import matplotlib.pyplot as plt  # only this debugging aid needs it

        X, U = np.asarray(X, dtype=float), np.asarray(U, dtype=float)
        Kproj, dX, dU, Q, R, S = self.calc_descent_direction(X, U, method)
        cost0 = self.calc_cost(X, U)
        dcost0 = self.calc_dcost(X, U, dX, dU)
        ddcost0 = self.calc_ddcost(X, U, dX, dU, Q, R, S)
        zs = np.linspace(-0.1, 1.0, int(points))
        true = []
        for z in zs:
            ok, nX, nU = self.armijo_simulate(X + z * dX, U + z * dU, Kproj)
            true.append(self.calc_cost(nX, nU) - cost0 if ok else np.nan)
        plt.plot(zs, true, label="cost")
        plt.plot(zs, dcost0 * zs + 0.5 * ddcost0 * zs ** 2, label="model")
        plt.plot(zs, self.armijo_alpha * dcost0 * zs, label="sufficient decrease")
        armijo = self.armijo_beta ** np.arange(self.armijo_max_iterations)
        armijo = armijo[armijo >= zs[0]]
        plt.plot(armijo, np.zeros_like(armijo), "o", label="Armijo points")
        if legend:
            plt.legend()


class DOptimizerMonitor:
    """Hears of an optimisation's progress; this base class does nothing (a silent
    monitor). Save copies of what it is given: the optimiser may reuse its arrays."""

    def optimize_begin(self, X, U):
        """An optimisation begins from the trajectory ``(X, U)``."""

    def optimize_end(self, converged, X, U, cost):
        """An optimisation ended at ``(X, U)`` with ``cost``, converged or not."""

    def step_begin(self, iteration):
        """Step ``iteration`` of the optimisation begins."""

    def step_info(self, method, cost, dcost, X, U, dX, dU, Kproj):
        """The step's descent direction ``(dX, dU)`` by ``method``, at ``cost`` with slope
        ``dcost``."""

    def step_method_failure(self, method, cost, dcost, fallback_method):
        """``method``'s direction does not descend; ``fallback_method`` is tried."""

    def step_termination(self, cost, dcost):
        """The optimisation stops: the slope ``dcost`` is within the tolerance."""

    def step_completed(self, method, cost, nX, nU):
        """The step by ``method`` reached ``(nX, nU)`` with ``cost``."""

    def armijo_simulation_failure(self, armijo_iteration, nX, nU, bX, bU):
        """The simulation of Armijo trial ``armijo_iteration`` failed."""

    def armijo_search_failure(self, X, U, dX, dU, cost0, dcost0, Kproj):
        """The Armijo search found no sufficient decrease along ``(dX, dU)``."""

    def armijo_evaluation(self, armijo_iteration, nX, nU, bX, bU, cost, max_cost):
        """Armijo trial ``armijo_iteration`` cost ``cost``, against at most ``max_cost``."""


class DOptimizerDefaultMonitor(DOptimizerMonitor):
    """Prints each step to the console and records ``cost_history`` and ``dcost_history``
    (iteration → value; reset when an optimisation begins)."""

    def __init__(self):
        self.iteration = 0
        self.cost_history = {}
        self.dcost_history = {}

    def optimize_begin(self, X, U):
        self.cost_history, self.dcost_history = {}, {}

    def optimize_end(self, converged, X, U, cost):
        print("Optimization", "converged" if converged else "did not converge",
              f"(cost {cost:.10g})")

    def step_begin(self, iteration):
        self.iteration = iteration

    def step_info(self, method, cost, dcost, X, U, dX, dU, Kproj):
        self.cost_history[self.iteration] = cost
        self.dcost_history[self.iteration] = dcost

    def step_method_failure(self, method, cost, dcost, fallback_method):
        print(f"  {method} direction does not descend (dcost = {dcost:.3e}); "
              f"trying {fallback_method}")

    def step_termination(self, cost, dcost):
        print(f"{self.iteration:4d}: cost {cost:.10g}, dcost {dcost:.3e}: optimal")

    def step_completed(self, method, cost, nX, nU):
        print(f"{self.iteration:4d}: {method:8s} cost {self.cost_history[self.iteration]:.10g}"
              f" -> {cost:.10g}, dcost {self.dcost_history[self.iteration]:.3e}")

    def armijo_search_failure(self, X, U, dX, dU, cost0, dcost0, Kproj):
        print(f"  the Armijo search found no decrease from cost {cost0:.10g} "
              f"(dcost {dcost0:.3e})")

    def get_costs(self):
        """The cost at each step, in the order of the steps."""
        return [self.cost_history[k] for k in sorted(self.cost_history)]

    def get_dcosts(self):
        """The cost's directional derivative at each step, in the order of the steps."""
        return [self.dcost_history[k] for k in sorted(self.dcost_history)]


class DOptimizerVerboseMonitor(DOptimizerDefaultMonitor):
    """The default monitor, and every Armijo evaluation and simulation failure too."""

    def armijo_simulation_failure(self, armijo_iteration, nX, nU, bX, bU):
        print(f"    Armijo {armijo_iteration}: the simulation failed")

    def armijo_evaluation(self, armijo_iteration, nX, nU, bX, bU, cost, max_cost):
        print(f"    Armijo {armijo_iteration}: cost {cost:.10g} (at most {max_cost:.10g})")
