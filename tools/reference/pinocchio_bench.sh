#!/usr/bin/env bash
# Builds tools/reference/pinocchio_bench.cpp against the `pin` wheel's C++ headers and
# libraries (plus `cmeel-eigen` for Eigen's headers) and writes target/pinocchio-timing.json,
# which `cargo bench --bench robots` puts beside tree-mech's numbers.
#   pip install pin==4.1.0 cmeel-eigen==3.4.1 cmeel-urdfdom-headers
#   bash tools/reference/pinocchio_bench.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
prefix="$(python3 -c 'import site; print(site.getsitepackages()[0])')/cmeel.prefix"
mkdir -p target
g++ -O3 -DNDEBUG -std=c++17 -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 \
  tools/reference/pinocchio_bench.cpp \
  -I"$prefix/include" -I"$prefix/include/eigen3" -I"$prefix/include/urdfdom" -I"$prefix/include/urdfdom_headers" \
  -L"$prefix/lib" -Wl,-rpath,"$prefix/lib" \
  -lpinocchio_default -lpinocchio_parsers -lurdfdom_model -lboost_serialization \
  -o target/pinocchio_bench
robots=tests/robots/example-robot-data
target/pinocchio_bench ur5 models/ur5.urdf 0 panda models/panda.urdf 0 solo12 models/solo12.urdf 1 \
  talos "$robots/talos_data/robots/talos_reduced.urdf" 1 \
  g1 "$robots/g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf" 1 \
  | tee target/pinocchio-timing.json
