#!/usr/bin/env bash
# The whole test suite: the Rust tests, then the Python package built into a fresh venv
# (pip builds it with maturin from PyPI; only the Rust toolchain and Python ≥ 3.9 are
# needed) with pytest and Ray (for the sweep example), and its pytest suite.
set -euo pipefail
cd "$(dirname "$0")/.."

# `tools/test.sh python` runs the Python part alone (`.ci/run` runs the Rust tests itself first).
if [ "${1:-}" != python ]; then
  cargo test --workspace --release
fi

venv=target/python-venv
rm -rf "$venv"
python3 -m venv "$venv"
"$venv/bin/pip" install --quiet --upgrade pip
"$venv/bin/pip" install --quiet ./python pytest ray
"$venv/bin/python" -m pytest -q python/tests
