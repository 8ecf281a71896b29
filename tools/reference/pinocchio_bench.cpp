// Times Pinocchio (C++, the headers and libraries the `pin` wheel ships) on tree-mech's URDFs:
// CRBA, RNEA (nonlinear effects), ABA, and ABA's derivatives. Built and run by
// tools/reference/pinocchio_bench.sh, which writes target/pinocchio-timing.json for
// `cargo bench --bench robots`. Same seeded-style state for every algorithm; best of 5
// batches, mean per call, in nanoseconds.
#include <chrono>
#include <cstdio>
#include <string>

#include <pinocchio/algorithm/aba-derivatives.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody/joint.hpp>
#include <pinocchio/parsers/urdf.hpp>

namespace pin = pinocchio;

template <class F>
double time_ns(F f) {
  double best = 1e30;
  const int calls = 20000;
  for (int batch = 0; batch < 5; ++batch) {
    auto start = std::chrono::steady_clock::now();
    for (int i = 0; i < calls; ++i) f();
    auto end = std::chrono::steady_clock::now();
    double ns = std::chrono::duration<double, std::nano>(end - start).count() / calls;
    if (ns < best) best = ns;
  }
  return best;
}

int main(int argc, char** argv) {
  std::printf("{\n");
  for (int k = 1; k + 2 < argc + 1 && k < argc; k += 3) {
    std::string label = argv[k], path = argv[k + 1];
    bool floating = std::string(argv[k + 2]) == "1";
    pin::Model model;
    if (floating) {
      pin::JointModelComposite base;
      base.addJoint(pin::JointModelPX());
      base.addJoint(pin::JointModelPY());
      base.addJoint(pin::JointModelPZ());
      base.addJoint(pin::JointModelRZ());
      base.addJoint(pin::JointModelRY());
      base.addJoint(pin::JointModelRX());
      pin::urdf::buildModel(path, base, model);
    } else {
      pin::urdf::buildModel(path, model);
    }
    pin::Data data(model);
    Eigen::VectorXd q(model.nq), v(model.nv), tau(model.nv);
    for (int i = 0; i < model.nq; ++i) q[i] = 0.3 * std::sin(0.7 * i);
    for (int i = 0; i < model.nv; ++i) {
      v[i] = 0.5 * std::cos(1.3 * i);
      tau[i] = std::sin(2.1 * i);
    }
    volatile double sink = 0;
    double crba = time_ns([&] { sink += pin::crba(model, data, q)(0, 0); });
    double nle = time_ns([&] { sink += pin::nonLinearEffects(model, data, q, v)[0]; });
    double aba = time_ns([&] { sink += pin::aba(model, data, q, v, tau)[0]; });
    double aba_d = time_ns([&] {
      pin::computeABADerivatives(model, data, q, v, tau);
      sink += data.ddq[0];
    });
    std::printf("%s  \"%s\": {\"nv\": %d, \"crba_ns\": %.1f, \"nle_ns\": %.1f, \"aba_ns\": %.1f, \"aba_derivatives_ns\": %.1f}\n",
                k > 1 ? "," : "", label.c_str(), model.nv, crba, nle, aba, aba_d);
  }
  std::printf("}\n");
  return 0;
}
