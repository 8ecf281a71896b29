"""trep 1.0.2's time to linearise a trajectory of its own Puppet: `DSystem.linearize_trajectory`
over 100 midpoint-VI steps at dt = 0.01 from the Puppet at rest (the start
`tools/reference/trep-puppet.toml` records), best of 10 passes. Prints
`trep_linearize_ms_per_step <t>`, and the three pieces of one iLQR iteration over those 100
steps as the optimal-control issue counts them (simulate, linearize_trajectory,
solve_tv_lqr; seconds, best of 10 each) and their sum.

Run with trep's Python 2.7 (README, "Checked against trep"):
    v27/bin/python tools/reference/trep_linearize.py
tools/reference/trep_linearize_bench.sh puts it beside tree-mech's figure. trep is called, not
copied.
"""
import os
import sys
import time

import numpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from trep_puppet import puppet  # noqa: E402  (also stubs out trep's viewer)

import trep  # noqa: E402
import trep.discopt  # noqa: E402

STEPS = 100
DT = 0.01


def trajectory(s, mvi):
    """The Puppet's 100 steps from rest: configurations, momenta, kinematic velocities and the
    kinematic inputs, as DSystem takes them."""
    mvi.initialize_from_state(0.0, s.q, numpy.zeros(s.nQd))
    k = s.qk
    Q, p, v, rho = [mvi.q2.copy()], [mvi.p2.copy()], [numpy.zeros(s.nQk)], []
    for _ in range(STEPS):
        mvi.step(mvi.t2 + DT, k2=k)
        Q.append(mvi.q2.copy())
        p.append(mvi.p2.copy())
        v.append(numpy.zeros(s.nQk))
        rho.append(numpy.array(k, dtype=float))
    return numpy.array(Q), numpy.array(p), numpy.array(v), numpy.array(rho)


def best_of(passes, f):
    best = float('inf')
    for _ in range(passes):
        start = time.time()
        out = f()
        best = min(best, time.time() - start)
    return best, out


def main():
    s = puppet()
    mvi = trep.MidpointVI(s)
    simulated, (Q, p, v, rho) = best_of(10, lambda: trajectory(s, mvi))
    dsys = trep.discopt.DSystem(mvi, numpy.arange(STEPS + 1) * DT)
    X, U = dsys.build_trajectory(Q=Q, p=p, v=v, rho=rho)
    linearised, (A, B) = best_of(10, lambda: dsys.linearize_trajectory(X, U))
    assert A.shape[0] == STEPS and numpy.isfinite(A).all() and numpy.isfinite(B).all()
    # The time-varying LQR along it (unit weights), the third piece of one iLQR iteration.
    eye_x, eye_u = numpy.eye(dsys.nX), numpy.eye(dsys.nU)
    lqr, _ = best_of(10, lambda: trep.discopt.dlqr.solve_tv_lqr(
        A, B, lambda k: eye_x, lambda k: eye_u))
    print('trep_linearize_ms_per_step %.4f' % (linearised / STEPS * 1e3))
    print('trep_simulate_s %.4f' % simulated)
    print('trep_linearize_s %.4f' % linearised)
    print('trep_tv_lqr_s %.4f' % lqr)
    print('trep_iteration_s %.4f' % (simulated + linearised + lqr))


if __name__ == '__main__':
    main()
