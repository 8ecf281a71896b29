#!/usr/bin/env bash
# Linearising a trajectory of trep's own Puppet, trep 1.0.2 against tree-mech side by side in
# one run: trep's DSystem.linearize_trajectory over 100 steps at dt = 0.01 from rest (best of
# 10 passes, tools/reference/trep_linearize.py) and tree-mech's first derivatives of the same steps,
# compiled by tree_model! and interpreted (best of 30 passes, `cargo bench --bench marionette --
# linearise`), step by step and through batch::StepLinearizer on one thread and on two. Needs
# trep's Python 2.7 venv: TREP_PYTHON=/path/to/v27/bin/python.
set -euo pipefail
cd "$(dirname "$0")/../.."
py=${TREP_PYTHON:?set TREP_PYTHON to trep\'s Python 2.7}
cargo bench --bench marionette --no-run -q 2>/dev/null
times=$("$py" tools/reference/trep_linearize.py)
echo "$times"
trep=$(echo "$times" | awk '/trep_linearize_ms_per_step/ {print $2}')
bench=$(cargo bench -q --bench marionette -- linearize)
field() { echo "$bench" | awk -v k="$1" '$1 == k {print $2}'; }
python3 -c "
t = $trep * 1e3
print(f'trep linearize_trajectory {t:.0f} us a step')
for what, us in [('compiled', $(field compiled_us)), ('interpreted', $(field interpreted_us)),
                 ('compiled, StepLinearizer on 1 thread', $(field compiled_batch_1_us)),
                 ('interpreted, StepLinearizer on 1 thread', $(field interpreted_batch_1_us)),
                 ('compiled, StepLinearizer on 2 threads', $(field compiled_batch_2_us)),
                 ('interpreted, StepLinearizer on 2 threads', $(field interpreted_batch_2_us))]:
    print(f'tree-mech {what} {us:.1f} us: {t / us:.1f}x')"
