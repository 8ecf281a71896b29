#!/usr/bin/env bash
# trep 1.0.2 against the tree-mech command line on trep's own Puppet, side by side in one run:
# 1000 midpoint-VI steps at dt = 0.01 each, tree-mech as a whole process recording every
# step to CSV (best of 5 each). Needs trep's Python 2.7 venv: TREP_PYTHON=/path/to/v27/bin/python.
# Regenerates tools/reference/trep-puppet.toml from trep on the way.
set -euo pipefail
cd "$(dirname "$0")/../.."
py=${TREP_PYTHON:?set TREP_PYTHON to trep\'s Python 2.7}
cargo build --release -q
best() { sort -g | head -n 1; }
trep=$(for _ in 1 2 3; do "$py" tools/reference/trep_puppet.py tools/reference/trep-puppet.toml | awk '{print $2}'; done | best)
out=$(mktemp -d)
ours=$(for _ in 1 2 3 4 5; do
  python3 - "$out" <<'PY'
import subprocess, sys, time
start = time.time()
subprocess.run(["target/release/tree-mech", "simulate", "tools/reference/trep-puppet.toml",
                "--duration", "10", "--dt", "0.01", "--out", sys.argv[1] + "/p.csv"],
               check=True, stdout=subprocess.DEVNULL)
print(time.time() - start)
PY
done | best)
rm -rf "$out"
python3 -c "t, o = $trep, $ours; print(f'trep {t:.3f} s, tree-mech simulate (process, every step recorded) {o:.3f} s: {t / o:.1f}x')"
