# -*- coding: utf-8 -*-
"""trep-style discrete optimal control scripts (``trep.discopt``), run unchanged by trep
1.0.2 itself (Python 2.7, through tools/reference/trep_api.py, which saves what they record
in tests/fixtures/trep-api.json) and by tree_mech.trep (python/tests/test_trep_discopt.py,
which compares). Each takes the `trep` module, with `trep.discopt` imported. Written for this
project (no trep code or examples); Python 2.7 and 3 alike.
"""
from __future__ import division, print_function

import numpy as np

import trep_scripts


def pendulum_on_cart(trep):
    """A pendulum (theta) under a cart whose position x is kinematic; damping, a torque."""
    s = trep.System()
    s.import_frames([
        trep.tx('x', kinematic=True, name='cart', mass=1.0), [
            trep.rx('theta', name='pivot'), [trep.tz(-1.0, name='bob', mass=1.0)]]])
    trep.potentials.Gravity(s, (0, 0, -9.8))
    trep.forces.Damping(s, 0.2)
    trep.forces.ConfigForce(s, 'theta', 'torque')
    s.get_config('theta').q = 0.3
    return s


SYSTEMS = [
    ('pendulum_on_cart', pendulum_on_cart, 0.05, 21),
    ('cart_pendulum_string', trep_scripts.cart_pendulum_string, 0.02, 11),
]


def _plain(x):
    """What JSON can hold: arrays and tuples as lists, numpy scalars as Python's."""
    if isinstance(x, dict):
        return dict((str(k), _plain(v)) for k, v in x.items())
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    return str(x)


class Recorder(object):
    """A silent monitor that keeps the cost after every completed step."""

    def __init__(self, base):
        self.costs = []
        self.methods = []
        self.base = base

    def __getattr__(self, name):
        return lambda *args: None

    def step_completed(self, method, cost, nX, nU):
        self.methods.append(method)
        self.costs.append(float(cost))


def rollout(dsys, x0, U):
    """The trajectory from x0 under U, stepped with set/f."""
    X = np.zeros((len(dsys.time), dsys.nX))
    X[0] = x0
    for k in range(len(U)):
        dsys.set(X[k], U[k], k)
        X[k + 1] = dsys.f()
    return X


def record(trep, build, dt, n):
    discopt = trep.discopt
    s = build(trep)
    t = np.arange(n) * dt
    mvi = trep.MidpointVI(s)
    q0 = np.array(s.q)
    mvi.initialize_from_configs(0.0, q0, dt, q0)
    d = discopt.DSystem(mvi, t)
    nk, nu = s.nQk, s.nu
    out = {'nX': d.nX, 'nU': d.nU, 'kf': d.kf()}
    x0 = d.build_state(mvi.q2, mvi.p2, np.zeros(nk))
    u = 0.3 * np.sin(np.outer(t[:-1], np.arange(1, nu + 1)))
    # The kinematic configs start from rest: smooth, small motions.
    rho = q0[s.nQd:] + 0.5 * np.outer(t[1:] ** 2, 1.0 / np.arange(1, nk + 1))
    X, U = d.build_trajectory(u=u, rho=rho)
    X = rollout(d, x0, U)
    out['X'], out['U'] = X, U
    split = d.split_trajectory(X, U)
    out['split_p'] = split[1]
    # One step's map and its derivatives.
    z = np.linspace(0.5, 1.5, d.nX)
    d.set(X[3], U[3], 3)
    out['f'] = d.f()
    out['fdx'], out['fdu'] = d.fdx(), d.fdu()
    out['fdxdx'], out['fdxdu'], out['fdudu'] = d.fdxdx(z), d.fdxdu(z), d.fdudu(z)
    # Linearisation, feedback, projections.
    A, B = d.linearize_trajectory(X, U)
    out['A'], out['B'] = A, B
    out['K'] = d.calc_feedback_controller(X, U)
    out['K_weighted'] = d.calc_feedback_controller(
        X, U, Q=lambda k: (1.0 + k) * np.eye(d.nX), R=lambda k: 0.5 * np.eye(d.nU))
    # Off the trajectory after the start (which stays on the constraints).
    bX, bU = X.copy(), U + 0.002
    bX[1:] += 0.001
    pX, pU = d.project(bX, bU, out['K'])
    out['project_X'], out['project_U'] = pX, pU
    bdX = np.cos(np.arange(X.size)).reshape(X.shape)
    bdU = np.sin(np.arange(U.size)).reshape(U.shape)
    out['dproject_dX'], out['dproject_dU'] = d.dproject(A, B, bdX, bdU, out['K'])
    # The LQ solvers on the linearisation.
    q = [0.1 * np.arange(d.nX) + k for k in range(len(X))]
    r = [0.2 * np.arange(d.nU) - k for k in range(len(U))]
    S = 0.01 * np.ones((d.nX, d.nU))
    lq = discopt.solve_tv_lq(A, B, q, r, lambda k: np.eye(d.nX), lambda k: S,
                             lambda k: 2.0 * np.eye(d.nU))
    out['lq_K'], out['lq_C'], out['lq_P'], out['lq_b'] = lq
    out['lqr_P'] = discopt.solve_tv_lqr(A, B, lambda k: np.eye(d.nX), lambda k: np.eye(d.nU))[1]
    # A tracking cost: the first config to 0.2, everything else to rest at the start.
    xd = np.tile(x0, (len(X), 1))
    xd[:, 0] = 0.2
    ud = np.zeros(U.shape)
    Q = np.diag(np.linspace(1.0, 2.0, d.nX))
    R = 0.1 * np.eye(d.nU)
    cost = discopt.DCost(xd, ud, Q, R, Qf=10.0 * Q)
    out['l'] = cost.l(X[2], U[2], 2)
    out['l_dx'], out['l_du'] = cost.l_dx(X[2], U[2], 2), cost.l_du(X[2], U[2], 2)
    out['m'], out['m_dx'] = cost.m(X[-1]), cost.m_dx(X[-1])
    monitor = Recorder(None)
    opt = discopt.DOptimizer(d, cost, monitor=monitor)
    out['cost'] = opt.calc_cost(X, U)
    for method in ('steepest', 'quasi', 'newton'):
        Kp, dX, dU, Qm, Rm, Sm = opt.calc_descent_direction(X, U, method)
        # trep's model weights are functions of k.
        out[method] = {'dX': dX, 'dU': dU, 'Q': [Qm(k) for k in range(len(X))],
                       'R': [Rm(k) for k in range(len(U))], 'S': [Sm(k) for k in range(len(U))],
                       'dcost': opt.calc_dcost(X, U, dX, dU),
                       'ddcost': opt.calc_ddcost(X, U, dX, dU, Qm, Rm, Sm)}
    Kp, dX, dU = opt.calc_descent_direction(X, U, 'quasi')[:3]
    nX, nU, cost1 = opt.armijo_search(X, U, Kp, dX, dU)
    out['armijo'] = {'X': nX, 'U': nU, 'cost1': cost1}
    step = opt.step(0, X, U, 'quasi')
    out['step'] = {'done': step[0], 'X': step[1], 'U': step[2], 'dcost0': step[3],
                   'cost1': step[4]}
    opt.first_method_iterations = 3
    converged, oX, oU = opt.optimize(X, U, max_steps=40)
    out['optimize'] = {'converged': bool(converged), 'X': oX, 'U': oU,
                       'costs': monitor.costs, 'methods': monitor.methods}
    return _plain(out)


def time_discopt(trep, spec, runs=3, knots=100, dt=0.01):
    """The best of `runs` wall times (s) of the pieces of one trajectory-optimisation
    iteration on trep's Puppet over `knots` steps (building it is not timed): a rollout
    through DSystem with the strings held, `linearize_trajectory` along it, and
    `solve_tv_lqr` on that linearisation. Returns (rollout, linearize, lqr)."""
    import time
    discopt = trep.discopt
    best = [float("inf")] * 3
    for _ in range(runs):
        s = trep_scripts.puppet_from_frames(trep, spec)
        mvi = trep.MidpointVI(s)
        q0 = np.array(s.q)
        mvi.initialize_from_configs(0.0, q0, dt, q0)
        d = discopt.DSystem(mvi, np.arange(knots + 1) * dt)
        U = np.tile(d.build_input(rho=q0[s.nQd:]), (knots, 1))
        start = time.time()
        X = rollout(d, d.build_state(mvi.q2, mvi.p2), U)
        rolled = time.time()
        A, B = d.linearize_trajectory(X, U)
        linearized = time.time()
        discopt.solve_tv_lqr(A, B, lambda k: np.eye(d.nX), lambda k: np.eye(d.nU))
        solved = time.time()
        times = [rolled - start, linearized - rolled, solved - linearized]
        best = [min(b, t) for b, t in zip(best, times)]
    return best


def saved_trajectory(trep):
    """A system and a trajectory of it, parts (t, Q, p, v, u, rho), for the trajectory-file
    round trips between trep and tree_mech.trep (v and u left out: a file may lack parts)."""
    s = pendulum_on_cart(trep)
    t = np.arange(6) * 0.1
    Q = np.column_stack([0.3 + t ** 2, -0.5 * t])
    p = (1.0 + t).reshape(-1, 1)
    rho = np.sin(t[1:]).reshape(-1, 1)
    return s, t, Q, p, None, None, rho
