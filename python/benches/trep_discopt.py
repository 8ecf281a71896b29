"""The pieces of one trajectory-optimisation iteration on trep's Puppet through
`trep.discopt` (python/tests/trep_discopt_scripts.py: the Puppet built through the trep API,
a 100-knot rollout through DSystem at dt = 0.01, `linearize_trajectory` along it,
`solve_tv_lqr` on that) run on tree_mech.trep and, side by side in the same run, on trep
1.0.2 itself when TREP_PYTHON names trep's Python 2.7. Best of 3 each.
Run: TREP_PYTHON=…/v27/bin/python python python/benches/trep_discopt.py
"""
import json
import os
import pathlib
import subprocess
import sys

root = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(root / "python" / "tests"))
import trep_discopt_scripts  # noqa: E402
from tree_mech import trep  # noqa: E402

spec = json.loads((root / "tools" / "reference" / "trep-puppet.json").read_text())
names = ("rollout", "linearize_trajectory", "solve_tv_lqr")
ours = trep_discopt_scripts.time_discopt(trep, spec)
theirs = None
python2 = os.environ.get("TREP_PYTHON")
if python2:
    out = subprocess.run([python2, str(root / "tools" / "reference" / "trep_api.py"),
                          "--time-discopt"], check=True, capture_output=True, text=True).stdout
    theirs = [float(x) for x in out.split()[1:]]
print("| piece (100 knots) | tree_mech.trep | trep 1.0.2 | ratio |")
print("|---|---:|---:|---:|")
rows = list(zip(names, ours, theirs or [None] * 3)) + [("total", sum(ours), theirs and sum(theirs))]
for name, a, b in rows:
    ratio = f"{b / a:.1f}×" if b else "—"
    print(f"| {name} | {a * 1e3:.1f} ms | {b * 1e3:.1f} ms | {ratio} |" if b else
          f"| {name} | {a * 1e3:.1f} ms | — | — |")
