#pragma once
// Types shared by the health library: θ of the paper's model (estimator/types.hpp) with its
// covariance, and the refined fit of one window as the health monitor sees it.

#include <Eigen/Core>
#include <array>
#include <cstddef>

namespace scp::health {

inline constexpr int kParams = 6;
using Vector2 = Eigen::Vector2d;
using Vector6 = Eigen::Matrix<double, kParams, 1>;
using Matrix6 = Eigen::Matrix<double, kParams, kParams>;
// ∂(y/σ)/∂θ of the two standardized outputs (x, T̄) at one sample.
using Matrix26 = Eigen::Matrix<double, 2, kParams>;
using ParameterMask = std::array<bool, kParams>;

// Names as the protocol and the metrics spell them (docs/protocol.md).
inline constexpr std::array<const char*, kParams> kParameterNames = {"b/m",  "a1/m",  "k/m",
                                                                     "a2/m", "l/Cth", "1/(R Cth)"};

// The two blocks of θ that the model separates: mechanical θ1..θ4 and thermal θ5, θ6.
inline constexpr int kBlocks = 2;
inline constexpr std::array<int, kBlocks> kBlockFirst = {0, 4};
inline constexpr std::array<int, kBlocks> kBlockEnd = {4, 6};
inline constexpr std::array<const char*, kBlocks> kBlockNames = {"mechanical", "thermal"};

inline int block_of(int parameter) noexcept {
  return parameter < kBlockEnd[0] ? 0 : 1;
}

// One refined window: θ̂ with its covariance (refine::FitResult::covariance, the Newey–West one
// checked by batch means) and the loop times of its first and last samples. A parameter the fit
// held known has zero variance and leaves every test.
struct WindowEstimate {
  double t_begin = 0.0;  // s
  double t_end = 0.0;    // s
  Vector6 theta = Vector6::Zero();
  Matrix6 covariance = Matrix6::Zero();
  // Per block: the fit's validation found structure or colour left in that output's residuals
  // (a verdict other than adequate). Such a θ̂ is the best constant θ for a window the model does
  // not describe (a plant drifting within it), and names no change.
  std::array<bool, kBlocks> misfit{};

  double length() const noexcept { return t_end - t_begin; }
  double midpoint() const noexcept { return 0.5 * (t_begin + t_end); }
};

// A parameter with zero (or non-finite) variance was held known by the fit.
inline ParameterMask known_parameters(const Matrix6& covariance) noexcept {
  ParameterMask known{};
  for (int i = 0; i < kParams; ++i) known[i] = !(covariance(i, i) > 0.0);
  return known;
}

}  // namespace scp::health
