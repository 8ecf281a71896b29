"""Runs python/tests/trep_scripts.py and trep_discopt_scripts.py on trep 1.0.2 itself and
saves what the scripts record as python/tests/fixtures/trep-api.json and trep-discopt.json
(read by python/tests/test_trep.py and test_trep_discopt.py, which run the same scripts on
tree_mech.trep); with --time, times trep's Puppet built by the same script
(1000 VI steps at dt = 0.01) instead; with --time-python, 1000 steps of the system whose
potential, force and constraint are written in Python (trep_scripts.python_elements); with --time-discopt, the pieces of one trajectory-
optimisation iteration on it (trep_discopt_scripts.time_discopt). trep is called, never copied.

Run with trep's Python 2.7 (README, "Checked against trep"):
    v27/bin/python tools/reference/trep_api.py [--time]
"""
from __future__ import print_function

import json
import os
import sys
import types

# trep.puppets imports its OpenGL/Qt viewer at module level; nothing here draws.
visual = types.ModuleType('trep.visual')
visual.VisualItem3D = type('VisualItem3D', (object,), {})
visual.__all__ = ['VisualItem3D']
sys.modules['trep.visual'] = visual
for _gl in ('OpenGL', 'OpenGL.GL', 'OpenGL.GLU', 'OpenGL.GLUT'):
    sys.modules[_gl] = types.ModuleType(_gl)
    sys.modules[_gl].__all__ = []

import trep  # noqa: E402
import trep.discopt  # noqa: E402,F401 (the scripts reach it as trep.discopt)

root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..')
sys.path.insert(0, os.path.join(root, 'python', 'tests'))
import trep_discopt_scripts  # noqa: E402
import trep_scripts  # noqa: E402

with open(os.path.join(root, 'tools', 'reference', 'trep-puppet.json')) as f:
    spec = json.load(f)

if '--time-discopt' in sys.argv:
    print('trep_seconds %.4f %.4f %.4f' % tuple(trep_discopt_scripts.time_discopt(trep, spec)))
    sys.exit(0)

if '--time-python' in sys.argv:
    print('trep_seconds %.4f %.4f' % (trep_scripts.time_python_elements(trep),
                                      trep_scripts.time_python_elements(trep, parts=('potential',))))
    sys.exit(0)

if '--time' in sys.argv:
    print('trep_seconds %.4f' % trep_scripts.time_puppet(trep, spec))
    sys.exit(0)

out = dict((name, trep_scripts.record(trep, build)) for name, build in trep_scripts.SYSTEMS)
s = trep_scripts.puppet_from_frames(trep, spec)
out['puppet'] = {'configs': [c.name for c in s.configs],
                 'q100': [float(x) for x in trep_scripts.step_puppet(trep, s, 100, 0.01)]}
out['energy_pump'] = trep_scripts.energy_pump(trep)
out['puppet_module'] = trep_scripts.puppet_module(trep)
out['puppet_string_forces'] = trep_scripts.puppet_string_forces(trep)
out['splines'] = trep_scripts.splines(trep)
out['tape_measure'] = trep_scripts.tape_measure(trep)
path = os.path.join(root, 'python', 'tests', 'fixtures', 'trep-api.json')
with open(path, 'w') as f:
    json.dump(out, f, indent=1, sort_keys=True)
    f.write('\n')
print('wrote', path)

discopt = dict((name, trep_discopt_scripts.record(trep, build, dt, n))
               for name, build, dt, n in trep_discopt_scripts.SYSTEMS)
# Trajectory files both ways: trep writes one for the layer to read, and reads the one the
# layer wrote (committed beside it) so the test can hold the layer's writer to what trep read.
fixtures = os.path.join(root, 'python', 'tests', 'fixtures')
s, t, Q, p, v, u, rho = trep_discopt_scripts.saved_trajectory(trep)
trep.save_trajectory(os.path.join(fixtures, 'trep-trajectory.mat'), s, t, Q, p, v, u, rho)
loaded = trep.load_trajectory(os.path.join(fixtures, 'tree-mech-trajectory.mat'), s)
discopt['loaded_by_trep'] = trep_discopt_scripts._plain(
    [x if x is not None else 'none' for x in loaded])
path = os.path.join(fixtures, 'trep-discopt.json')
with open(path, 'w') as f:
    json.dump(discopt, f, indent=1, sort_keys=True)
    f.write('\n')
print('wrote', path)
