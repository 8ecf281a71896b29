"""Runs trep's own scripts — the tutorials, reference snippets and examples of a trep checkout
(https://github.com/MurpheyLab/trep, GPL: read from the checkout, never copied here) — on trep
1.0.2 itself (Python 2.7) and on tree_mech.trep (Python 3: `2to3` plus the import), and
compares what each leaves behind: every float, float array and list of arrays among its
globals, relative to the largest entry. The viewers are stubbed on trep's side (no Qt or
OpenGL here) and headless on ours; plots are not shown.

    python3 tools/reference/trep_examples.py TREP_CHECKOUT TREP_PYTHON [OUR_PYTHON] [SCRIPT …]

TREP_PYTHON is trep's Python 2.7 (README, "Checked against trep"); OUR_PYTHON one with the
package installed (default: this one). Prints one line per script: whether each side ran,
and the largest relative difference over the globals both left with the same shape.
Results of the last run: docs/python.md, "trep's own scripts".
"""
import json
import os
import subprocess
import sys
import tempfile

#: The run inside each interpreter: stubs, the script, then its numeric globals as JSON.
RUNNER = r'''
import sys, os, json, types
script, out = sys.argv[1], sys.argv[2]
os.environ["MPLBACKEND"] = "Agg"
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    plt.show = lambda *a, **k: None
except Exception:
    pass
if sys.version_info[0] == 2:
    visual = types.ModuleType("trep.visual")
    class Item(object):
        def __init__(self, system=None, *a, **k):
            self._system = system
        system = property(lambda self: self._system)
        def setOrientation(self, *a, **k): pass
        def attachDrawing(self, *a, **k): pass
    class Mesh(object):
        def __init__(self, *a, **k): pass
        def draw(self): pass
    visual.VisualItem2D = visual.VisualItem3D = Item
    visual.stlmodel = Mesh
    visual.visualize_2d = visual.visualize_3d = lambda *a, **k: 0
    visual.__all__ = ["VisualItem2D", "VisualItem3D", "stlmodel", "visualize_2d", "visualize_3d"]
    sys.modules["trep.visual"] = visual
    for gl in ("OpenGL", "OpenGL.GL", "OpenGL.GLU", "OpenGL.GLUT"):
        sys.modules[gl] = types.ModuleType(gl)
        sys.modules[gl].__all__ = []
    import trep
    trep.visual = visual
    import trep.puppets
    trep.puppets.PuppetVisual = Item
import numpy as np
sys.argv = [script]
os.chdir(os.path.dirname(os.path.abspath(script)))
sys.path.insert(0, os.getcwd())
ns = {"__name__": "__main__", "__file__": script}
status = "ran"
try:
    exec(compile(open(script).read(), script, "exec", 0, True), ns)
except SystemExit:
    pass
except BaseException as e:
    status = "%s: %s" % (type(e).__name__, (str(e).splitlines() or [""])[0][:70])
dump = {"status": status}
for k, v in list(ns.items()):
    try:
        if isinstance(v, float):
            dump[k] = v
        elif isinstance(v, np.ndarray) and v.dtype.kind == "f" and v.size < 400000:
            dump[k] = v.tolist()
        elif isinstance(v, list) and v and all(isinstance(x, float) for x in v[:50]):
            dump[k] = v
        elif isinstance(v, list) and v and all(isinstance(x, np.ndarray) for x in v[:50]):
            a = np.array(v, dtype=float)
            if a.size < 400000:
                dump[k] = a.tolist()
    except Exception:
        pass
json.dump(dump, open(out, "w"))
'''

#: trep's imports as tree_mech.trep's, after 2to3.
IMPORTS = [
    ("import trep.discopt.dlqr as dlqr", "from tree_mech.trep.discopt import dlqr"),
    ("import trep.discopt as discopt", "from tree_mech.trep import discopt"),
    ("import trep.visual as visual", "from tree_mech.trep import visual"),
    ("import trep.puppets as puppets", "from tree_mech.trep import puppets"),
    ("from trep.", "from tree_mech.trep."),
    ("from trep import", "from tree_mech.trep import"),
]


def scripts(checkout):
    """trep's scripts in a checkout: the tutorial and reference snippets, the examples."""
    out = []
    for top in ("doc", "examples"):
        for root, dirs, files in os.walk(os.path.join(checkout, top)):
            dirs[:] = [d for d in dirs if d not in ("piston", "puppet-interactive")]
            out += [os.path.join(root, f) for f in files
                    if f.endswith(".py") and f != "conf.py" and not f.startswith("__")]
    return sorted(out)


def to_python3(source_path, target_path):
    """The script through 2to3, importing tree_mech.trep where it imported trep."""
    with open(source_path) as f, open(target_path, "w") as g:
        g.write(f.read())
    subprocess.run([sys.executable, "-m", "lib2to3", "-w", "-n", target_path],
                   capture_output=True, check=False)
    lines = []
    for line in open(target_path):
        stripped, indent = line.lstrip(), line[: len(line) - len(line.lstrip())]
        for theirs, ours in IMPORTS:
            if stripped.startswith(theirs):
                stripped = ours + stripped[len(theirs):]
                break
        else:
            if stripped.rstrip() == "import trep":
                stripped = "from tree_mech import trep\n"
            elif stripped.startswith("import trep."):
                module = stripped.split()[1].strip()
                stripped = "from tree_mech import trep; import tree_mech.%s\n" % module
        lines.append(indent + stripped)
    with open(target_path, "w") as g:
        g.writelines(lines)


def run(python, runner, script, out):
    try:
        subprocess.run([python, runner, script, out], capture_output=True, timeout=900,
                       check=False)
        with open(out) as f:
            return json.load(f)
    except (subprocess.TimeoutExpired, OSError, ValueError):
        return {"status": "no result (timed out or crashed)"}


def _flat(x):
    """A nested list of numbers flattened, with its shape (None where ragged or not numbers)."""
    if isinstance(x, (int, float)):
        return [float(x)], ()
    if not isinstance(x, list):
        return None, None
    parts = [_flat(v) for v in x]
    if any(p[0] is None for p in parts) or len({p[1] for p in parts}) > 1:
        return None, None
    inner = parts[0][1] if parts else ()
    return [v for p in parts for v in p[0]], (len(x),) + inner


def difference(a, b):
    """The largest relative difference over the globals both left with one shape."""
    worst, compared = 0.0, 0
    for k, v in a.items():
        if k == "status" or k not in b:
            continue
        (x, sx), (y, sy) = _flat(v), _flat(b[k])
        if x is None or y is None or sx != sy or not x:
            continue
        compared += 1
        scale = max(max(abs(e) for e in x), 1e-300)
        worst = max(worst, max(abs(p - q) for p, q in zip(x, y)) / scale)
    return worst, compared


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    try:
        import lib2to3  # noqa: F401 (the conversion runs it as a module)
    except ImportError:
        sys.exit("trep_examples.py converts trep's scripts with lib2to3, which Python 3.13 "
                 "removed: run it with Python 3.12 or older")
    checkout, trep_python = sys.argv[1], sys.argv[2]
    if not os.path.isdir(os.path.join(checkout, "examples")):
        sys.exit("%s is no trep checkout (it has no examples/ folder)" % checkout)
    ours = sys.argv[3] if len(sys.argv) > 3 else sys.executable
    chosen = sys.argv[4:] or scripts(checkout)
    work = tempfile.mkdtemp()
    runner = os.path.join(work, "runner.py")
    with open(runner, "w") as f:
        f.write(RUNNER)
    for path in chosen:
        name = os.path.relpath(path, checkout)
        here = os.path.dirname(path)
        theirs_copy = os.path.join(here, "__trep_" + os.path.basename(path))
        ours_copy = os.path.join(here, "__tree_mech_" + os.path.basename(path))
        with open(path) as f, open(theirs_copy, "w") as g:
            g.write(f.read())
        to_python3(path, ours_copy)
        try:
            a = run(trep_python, runner, theirs_copy, os.path.join(work, "a.json"))
            b = run(ours, runner, ours_copy, os.path.join(work, "b.json"))
        finally:
            os.remove(theirs_copy)
            os.remove(ours_copy)
        worst, compared = difference(a, b)
        print("%-52s trep: %-28s tree_mech.trep: %-40s %3d globals, worst %.1e"
              % (name, a["status"][:28], b["status"][:40], compared, worst))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
