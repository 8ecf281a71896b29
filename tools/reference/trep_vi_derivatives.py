# -*- coding: utf-8 -*-
"""trep 1.0.2's midpoint-VI step and its first and second derivatives on the model of
tests/models/trep-vi.toml (built here in trep: keep the two the same), for tests/trep_vi.rs.

Run with trep's Python 2.7 (README, "Checked against trep"):
    v27/bin/python tools/reference/trep_vi_derivatives.py tests/fixtures/trep-vi-derivatives.json

The model: a slider (`slide`, damped) carrying a double pendulum (`theta1` pushed by the input
`torque`, `theta2` damped and sprung) whose tip hangs from a kinematic hand (`hand_y`) by a
string of fixed length. For three steps from a configuration on the constraint it writes the
step's inputs (t1, t2, q1, p1, u1, k2), trep's result (q2, p2, lambda1), the constraint's
`h_dq` at q1 (the multipliers differ by the ratio of the two libraries' constraint rows:
1 for a distance, d·d − ℓ² in both) and every derivative trep has: the 12 first ones as
[output][input] and the 30 second ones as [output][input1][input2]. Names are trep's configs,
in trep's order (dynamic, then kinematic). trep is called, not copied.
"""
import json
import sys

import numpy as np
import trep
import trep.constraints
import trep.forces
import trep.potentials

DT = 0.01


def system():
    s = trep.System()
    w = s.world_frame
    cart = trep.Frame(w, trep.TY, 'slide', name='cart')
    cart.set_mass(2.0, 0.1, 0.1, 0.1)
    shoulder = trep.Frame(cart, trep.RX, 'theta1', name='shoulder')
    upper = trep.Frame(shoulder, trep.TZ, -0.6, name='upper')
    upper.set_mass(1.0, 0.03, 0.02, 0.01)
    elbow = trep.Frame(upper, trep.RX, 'theta2', name='elbow')
    tip = trep.Frame(elbow, trep.TZ, -0.5, name='tip')
    tip.set_mass(0.5, 0.01, 0.012, 0.005)
    hand = trep.Frame(w, trep.TY, 'hand_y', kinematic=True, name='hand')
    trep.Frame(hand, trep.TZ, -0.2, name='hand_point')
    trep.potentials.Gravity(s, (0.0, 0.0, -9.8))
    trep.potentials.ConfigSpring(s, 'theta2', k=3.0, q0=0.2)
    trep.forces.Damping(s, 0.0, {'slide': 0.3, 'theta2': 0.2})
    trep.forces.ConfigForce(s, 'theta1', 'torque')
    trep.constraints.Distance(s, 'tip', 'hand_point', 0.6, name='string')
    return s


def listed(a):
    return np.asarray(a, dtype=float).tolist()


def main(path):
    s = system()
    names = [c.name for c in s.configs]
    s.get_config('theta1').q = 0.4
    s.get_config('theta2').q = 0.7
    s.get_config('hand_y').q = 0.1
    s.satisfy_constraints()
    mvi = trep.MidpointVI(s, tolerance=1e-13)
    rng = np.random.RandomState(20261201)
    q1 = s.q.copy()
    p1 = rng.uniform(-0.5, 0.5, s.nQd)
    mvi.initialize_from_state(0.0, q1, p1)
    steps = []
    for k in range(3):
        u1 = rng.uniform(-2.0, 2.0, s.nu)
        t1, q1, p1 = mvi.t2, mvi.q2.copy(), mvi.p2.copy()
        s.q = q1
        h_dq = listed([[c.h_dq(cfg) for cfg in s.configs] for c in s.constraints])
        k2 = q1[s.nQd:] + 0.002 * (k + 1)
        mvi.step(t1 + DT, u1, k2)
        step = {
            't1': t1, 't2': mvi.t2, 'q1': listed(q1), 'p1': listed(p1), 'u1': listed(u1),
            'k2': listed(k2), 'q2': listed(mvi.q2), 'p2': listed(mvi.p2),
            'lambda1': listed(mvi.lambda1), 'h_dq': h_dq,
        }
        for out in ('q2', 'p2', 'lambda1'):
            for a in ('q1', 'p1', 'u1', 'k2'):
                step['%s_d%s' % (out, a)] = listed(getattr(mvi, '%s_d%s' % (out, a))())
            blocks = ('q1', 'p1', 'u1', 'k2')
            for i, a in enumerate(blocks):
                for b in blocks[i:]:
                    name = '%s_d%sd%s' % (out, a, b)
                    # trep orders a second derivative [input1][input2][output].
                    t = np.asarray(getattr(mvi, name)())
                    step[name] = listed(np.transpose(t, (2, 0, 1)))
        steps.append(step)
    out = {'trep': trep.__version__, 'dt': DT, 'configs': names,
           'dynamic': [c.name for c in s.dyn_configs], 'kinematic': [c.name for c in s.kin_configs],
           'inputs': [u.name for u in s.inputs], 'forcing': 'left', 'steps': steps}
    with open(path, 'w') as f:
        json.dump(out, f, indent=1)
        f.write('\n')
    print('wrote %s: %d steps, %d configs' % (path, len(steps), len(names)))


if __name__ == '__main__':
    main(sys.argv[1])
