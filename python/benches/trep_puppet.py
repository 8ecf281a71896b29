"""A trep script on trep's own Puppet (python/tests/trep_scripts.py: the Puppet built through
the trep API, then 1000 midpoint-VI steps at dt = 0.01) run on tree_mech.trep and, side by
side in the same run, on trep 1.0.2 itself when TREP_PYTHON names trep's Python 2.7.
Best of 3 each. Run: TREP_PYTHON=…/v27/bin/python python python/benches/trep_puppet.py
"""
import json
import os
import pathlib
import subprocess
import sys

root = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(root / "python" / "tests"))
import trep_scripts  # noqa: E402
from tree_mech import trep  # noqa: E402

spec = json.loads((root / "tools" / "reference" / "trep-puppet.json").read_text())
best = trep_scripts.time_puppet(trep, spec)
print(f"tree_mech.trep: {best:.3f} s for 1000 steps")
python2 = os.environ.get("TREP_PYTHON")
if python2:
    out = subprocess.run([python2, str(root / "tools" / "reference" / "trep_api.py"), "--time"],
                         check=True, capture_output=True, text=True).stdout
    theirs = float(out.split()[1])
    print(f"trep 1.0.2:     {theirs:.3f} s for 1000 steps — tree_mech.trep is {theirs / best:.1f}x faster")
