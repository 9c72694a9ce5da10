#pragma once
// What the health monitor publishes (a Seqlock written by the refinement's worker thread, or by a
// batch run inline) and what STATUS, ESTIMATE, the metrics and the recorder read. Plain data:
// the monitor's report is trivially copyable, and so is everything beside it.

#include <array>
#include <cstdint>

#include "health/monitor.hpp"

namespace scp::daemon::health {

inline constexpr std::size_t kSourceChars = 256;

struct HealthView {
  // A baseline is loaded: the monitor runs. Without one the state is `blind`.
  bool baseline_present = false;
  std::array<double, 6> baseline_theta{};
  std::array<double, 6> baseline_sigma{};
  double baseline_t_begin = 0.0;  // loop times of the run it was saved in
  double baseline_t_end = 0.0;
  std::int64_t baseline_saved_unix_ns = 0;
  std::array<char, kSourceChars> baseline_file{};  // where it was read from

  // The latest converged refined window: what `baseline save` stores.
  bool fit_present = false;
  double fit_t_begin = 0.0, fit_t_end = 0.0;
  std::array<double, 6> fit_theta{};
  std::array<double, 36> fit_covariance{};  // row-major
  bool fit_validated = false;               // the fit ran its model validation
  std::array<char, 32> fit_verdict{};       // its verdict ("adequate", ...)

  scp::health::HealthReport report{};
  std::int64_t last_window_unix_ns = 0;  // wall clock of the last window given; 0 none
  std::uint64_t residual_samples = 0;    // fed to the fast detector
  std::uint64_t reseeds = 0;             // times its simulator was seeded at a fitted state
  // x's and T̄'s long-run variance ratio at the block length, from the last seed's window
  // (health/block_variance.hpp; 1 where not significant): the scores' σ is widened by its root.
  std::array<double, 2> residual_variance_ratio{1.0, 1.0};
};

static_assert(std::is_trivially_copyable_v<HealthView>, "published through a Seqlock");

}  // namespace scp::daemon::health
