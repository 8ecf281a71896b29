#!/usr/bin/env bash
# The whole test suite: the Rust tests, then the Python package built into a fresh venv
# (pip builds it with maturin from PyPI; only the Rust toolchain and Python ≥ 3.9 are
# needed) with pytest, Ray (for the sweep example), matplotlib (for trep.visual) and mypy,
# its pytest suite, and mypy's stubtest on its type stubs.
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
# The test tools at the versions last seen to pass, so a new release cannot break CI unseen.
"$venv/bin/pip" install --quiet ./python pytest==9.2.0 ray==2.60.0 mypy==2.4.1 \
  matplotlib==3.11.2
"$venv/bin/python" -m pytest -q python/tests
# The type stubs (`.pyi`) against the module as built: a name, parameter or default that
# differs fails here.
"$venv/bin/python" -m mypy.stubtest tree_mech --concise --ignore-disjoint-bases \
  --mypy-config-file python/pyproject.toml --allowlist python/stubtest-allowlist.txt
