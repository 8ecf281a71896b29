#!/usr/bin/env bash
# trep 1.0.2 against tree-mech on trep's own Puppet, side by side in one run: 1000
# midpoint-VI steps at dt = 0.01 each — trep's MidpointVI.step (best of 3), the tree-mech
# command line as a whole process recording every step to CSV (best of 5), and run() on the
# model compiled by tree_model! and interpreted, recording every step (best of 7, from
# `cargo bench --bench marionette -- puppet`). Needs trep's Python 2.7 venv: TREP_PYTHON=/path/to/v27/bin/python.
# Regenerates tools/reference/trep-puppet.toml from trep on the way.
set -euo pipefail
cd "$(dirname "$0")/../.."
py=${TREP_PYTHON:?set TREP_PYTHON to trep\'s Python 2.7}
cargo build --release -q
cargo bench --bench marionette --no-run -q 2>/dev/null
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
bench=$(cargo bench -q --bench marionette -- puppet)
compiled=$(echo "$bench" | awk '/compiled_ms/ {print $2 / 1000}')
interpreted=$(echo "$bench" | awk '/interpreted_ms/ {print $2 / 1000}')
python3 -c "
t, o, c, i = $trep, $ours, $compiled, $interpreted
print(f'trep {t:.3f} s')
print(f'tree-mech simulate (process, every step recorded) {o:.3f} s: {t / o:.1f}x')
print(f'compiled run() {c * 1e3:.1f} ms: {t / c:.1f}x; interpreted run() {i * 1e3:.1f} ms: {t / i:.1f}x')"
