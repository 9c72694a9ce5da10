// Measures how ẋ estimated from x (daemon/core/velocity) changes θ̂, against the true ẋ: the paper's
// experiment (simulated plant, paper excitation, 1 kHz) run through the estimator. Not a test:
// a program whose output is quoted in docs/velocity.md.
//
//   velocity_theta_harness [duration_s=400] [noise_x_m=0] [bandwidth_hz ...=5 20 100]

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "daemon/core/velocity/velocity_estimator.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "estimator/estimator.hpp"
#include "excitation/excitation.hpp"
#include "excitation/excitation_settings.hpp"

namespace {

using scp::daemon::velocity::VelocityEstimator;
using scp::daemon::velocity::VelocitySettings;

struct Run {
  const char* label;  // the rms column always compares the run's filter with the true ẋ
  bool estimated;
  double bandwidth_hz;
};

void run(const Run& r, double duration, double noise_x) {
  scp::drivers::sim::SimSettings sim;
  sim.noise_x = noise_x;
  sim.noise_xdot = 0.0;
  sim.seed = 3;
  scp::drivers::sim::SimDriver driver(sim);
  driver.open();
  const scp::excitation::Excitation exc(scp::excitation::paper_excitation());
  scp::estimator::EstimatorConfig cfg;
  std::array<double, 6> truth{};
  driver.true_theta(0.0, truth);
  for (int i = 0; i < 6; ++i) cfg.scale[i] = truth[static_cast<std::size_t>(i)];
  scp::estimator::Estimator est(cfg);
  VelocityEstimator vel(VelocitySettings{r.bandwidth_hz, 0.707});
  const double h = 1e-3;
  double v_err2 = 0.0;
  long n = 0;
  for (long k = 0; k * h <= duration; ++k) {
    const double t = static_cast<double>(k) * h;
    scp::drivers::Sample s;
    if (driver.read({t, h}, s).status != scp::drivers::IoStatus::ok) continue;
    const double xdot_hat = vel.update(s.x, k == 0 ? 0.0 : h);
    if (t > 1.0) {
      v_err2 += (xdot_hat - s.xdot) * (xdot_hat - s.xdot);
      ++n;
    }
    const double xdot = r.estimated ? xdot_hat : s.xdot;
    est.update({t, s.x, xdot, s.temperature - sim.ambient_c, s.voltage});
    (void)driver.write_voltage(exc.voltage(t));
  }
  const auto& e = est.estimate();
  std::printf("%-26s rms(xdot_hat - xdot) = %.2e m/s  rel. error of theta_hat:", r.label,
              std::sqrt(v_err2 / static_cast<double>(n)));
  for (int i = 0; i < 6; ++i) {
    std::printf(" %+.1e", (e.theta_hat(i) - truth[static_cast<std::size_t>(i)]) /
                              truth[static_cast<std::size_t>(i)]);
  }
  // What the mechanical data pin down are ratios (b/k, α2/k): report them too.
  const auto ratio_err = [&](int i) {
    const double est_ratio = e.theta_hat(i) / e.theta_hat(2);
    const double true_ratio = truth[static_cast<std::size_t>(i)] / truth[2];
    return (est_ratio - true_ratio) / true_ratio;
  };
  std::printf("  | b/k %+.1e  a1/k %+.1e  a2/k %+.1e\n", ratio_err(0), ratio_err(1), ratio_err(3));
}

}  // namespace

int main(int argc, char** argv) {
  const double duration = argc > 1 ? std::atof(argv[1]) : 400.0;
  const double noise_x = argc > 2 ? std::atof(argv[2]) : 0.0;
  std::printf("duration %.0f s, noise on x %.1e m (true xdot noise free)\n", duration, noise_x);
  run({"true xdot", false, 20.0}, duration, noise_x);
  std::array<double, 8> bands{5.0, 20.0, 100.0};
  int n_bands = 3;
  if (argc > 3) n_bands = 0;
  for (int i = 3; i < argc && n_bands < 8; ++i)
    bands[static_cast<std::size_t>(n_bands++)] = std::atof(argv[i]);
  for (int i = 0; i < n_bands; ++i) {
    char label[64];
    std::snprintf(label, sizeof label, "estimated, %g Hz", bands[static_cast<std::size_t>(i)]);
    run({label, true, bands[static_cast<std::size_t>(i)]}, duration, noise_x);
  }
  return 0;
}
