"""trep 1.0.2's own Puppet (trep.puppets.Puppet with string constraints, 40 variables) as a
tree-mech model, and trep's time for 1000 midpoint-VI steps of it.

Run with trep's Python 2.7 (README, "Checked against trep"):
    v27/bin/python tools/reference/trep_puppet.py tools/reference/trep-puppet.toml \
        tests/fixtures/trep-puppet.json
writes the model (every frame, mass, damping and string of trep's Puppet, the strings'
control points projected above their hooks, some joints bent so it moves) and prints
`trep_seconds <t>` for 1000 steps at dt = 0.01 from rest; with a second path, also trep's
configuration every 10 of 100 steps from rest (the fixture tests/trep.rs reads). trep is
called, not copied.
"""
import math
import sys
import time
import types

# trep.puppets imports its OpenGL/Qt viewer at module level; nothing here draws.
visual = types.ModuleType('trep.visual')
class VisualItem3D(object):
    pass
visual.VisualItem3D = VisualItem3D
visual.__all__ = ['VisualItem3D']
sys.modules['trep.visual'] = visual

import trep
import trep.puppets

BENT = {'lshoulder_rx': 0.4, 'relbow_rx': -0.5, 'lhip_rx': 0.3, 'rknee_rx': 0.4, 'torso_rz': 0.2}


def puppet():
    s = trep.puppets.Puppet(string_constraints=True)
    for name, q in BENT.items():
        s.get_config(name).q = q
    s.project_string_controls()
    return s


def fmt(x):
    return repr(float(x))


def rpy_of(r):
    """ZYX angles (yaw, pitch, roll) of a rotation matrix."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2][0])))
    roll = math.atan2(r[2][1], r[2][2])
    yaw = math.atan2(r[1][0], r[0][0])
    return yaw, pitch, roll


def write_toml(s, path):
    out = ['# trep 1.0.2\'s Puppet (trep.puppets.Puppet(string_constraints=True)), written by',
           '# tools/reference/trep_puppet.py from the system trep builds: a fixture, regenerate',
           '# it with trep rather than editing it.',
           'name = "trep-puppet"',
           'gravity = [0.0, 0.0, -9.8]', '']
    kinds = {trep.TX: 'tx', trep.TY: 'ty', trep.TZ: 'tz', trep.RX: 'rx', trep.RY: 'ry', trep.RZ: 'rz'}

    def frame(name, parent, kind, value, mass=None):
        out.append('[[frame]]')
        out.append('name = "%s"' % name)
        if parent is not None:
            out.append('parent = "%s"' % parent)
        out.append('%s = %s' % (kind, value))
        if mass is not None:
            out.extend(mass)
        out.append('')

    names = {}

    def name_of(f):
        # trep leaves most frames unnamed: name them by their position in trep's list.
        if f not in names:
            names[f] = f.name if f.name else 'frame_%d' % s.frames.index(f)
        return names[f]

    def walk(f, parent):
        mass = None
        if f.mass > 0 or f.Ixx > 0 or f.Iyy > 0 or f.Izz > 0:
            mass = ['mass = %s' % fmt(f.mass),
                    'inertia = [%s, %s, %s]' % (fmt(f.Ixx), fmt(f.Iyy), fmt(f.Izz))]
        if f.transform_type == trep.CONST_SE3:
            g = f.lg()
            r = [[g[i][j] for j in range(3)] for i in range(3)]
            chain = [('tx', g[0][3]), ('ty', g[1][3]), ('tz', g[2][3])]
            yaw, pitch, roll = rpy_of(r)
            chain += [('rz', yaw), ('ry', pitch), ('rx', roll)]
            chain = [c for c in chain if c[1] != 0.0] or [('tx', 0.0)]
            for i, (kind, x) in enumerate(chain):
                last = i == len(chain) - 1
                name = name_of(f) if last else '%s_%d' % (name_of(f), i)
                frame(name, parent, kind, fmt(x), mass if last else None)
                parent = name
        else:
            value = '"%s"' % f.config.name if f.config is not None else fmt(f.transform_value)
            frame(name_of(f), parent, kinds[f.transform_type], value, mass)
        for c in f.children:
            walk(c, name_of(f))

    for c in s.world_frame.children:
        walk(c, None)
    default_damping = None
    for force in s.forces:
        if isinstance(force, trep.forces.Damping):
            default_damping = force
    for q in s.configs:
        out.append('[variables."%s"]' % q.name)
        out.append('q0 = %s' % fmt(q.q))
        if q.kinematic:
            out.append('kinematic = true')
        elif default_damping is not None:
            out.append('damping = %s' % fmt(default_damping.get_damping_coefficient(q)))
        out.append('')
    for c in s.constraints:
        out.append('[[constraint]]')
        out.append('name = "%s"' % c.name)
        out.append('kind = "distance"')
        out.append('frames = ["%s", "%s"]' % (name_of(c.frame1), name_of(c.frame2)))
        out.append('length = "%s"' % c.config.name)
        out.append('')
    open(path, 'w').write('\n'.join(out))


def trep_seconds(steps=1000, dt=0.01):
    s = puppet()
    mvi = trep.MidpointVI(s)
    q0 = s.q
    mvi.initialize_from_configs(0.0, q0, dt, q0)
    k = s.qk
    start = time.time()
    for _ in range(steps - 1):
        mvi.step(mvi.t2 + dt, k2=k)
    return time.time() - start


def fixture(path, steps=100, dt=0.01):
    """trep's configuration every 10 steps from rest (p = 0), for tests/trep.rs."""
    import json
    import numpy
    s = puppet()
    mvi = trep.MidpointVI(s)
    mvi.initialize_from_state(0.0, s.q, numpy.zeros(s.nQd))
    k = s.qk
    samples = []
    for n in range(1, steps + 1):
        mvi.step(mvi.t2 + dt, k2=k)
        if n % 10 == 0:
            samples.append({'step': n, 't': mvi.t2, 'q': [float(x) for x in mvi.q2]})
    json.dump({'source': 'trep 1.0.2 MidpointVI on trep.puppets.Puppet(string_constraints=True), '
                         'tools/reference/trep_puppet.py',
               'dt': dt, 'variables': [q.name for q in s.configs], 'samples': samples},
              open(path, 'w'), indent=1)


if __name__ == '__main__':
    write_toml(puppet(), sys.argv[1])
    if len(sys.argv) > 2:
        fixture(sys.argv[2])
    print('trep_seconds %.4f' % trep_seconds())
