"""A trep script whose potential, force and constraint are written in Python
(python/tests/trep_scripts.py: python_elements, 1000 midpoint-VI steps at dt = 0.01, every
evaluation calling the script's methods back), and the same system with its potential alone
written in Python, run on tree_mech.trep and, side by side in the same run, on trep 1.0.2
itself when TREP_PYTHON names trep's Python 2.7. Best of 3 each.
Run: TREP_PYTHON=…/v27/bin/python python python/benches/trep_python_elements.py
"""
import os
import pathlib
import subprocess
import sys

root = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(root / "python" / "tests"))
import trep_scripts  # noqa: E402
from tree_mech import trep  # noqa: E402

ours = (trep_scripts.time_python_elements(trep),
        trep_scripts.time_python_elements(trep, parts=("potential",)))
labels = ("potential, force and constraint", "the potential alone")
python2 = os.environ.get("TREP_PYTHON")
theirs = None
if python2:
    script = str(root / "tools" / "reference" / "trep_api.py")
    out = subprocess.run([python2, script, "--time-python"], check=True, capture_output=True,
                         text=True).stdout
    theirs = [float(x) for x in out.split()[1:3]]
for k, label in enumerate(labels):
    line = f"{label}: tree_mech.trep {ours[k]:.4f} s for 1000 steps"
    if theirs:
        line += f", trep 1.0.2 {theirs[k]:.4f} s — {ours[k] / theirs[k]:.2f}x trep's time"
    print(line)
