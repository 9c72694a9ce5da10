#pragma once
// The fast detector's building block: a two-sided CUSUM on a stream of standardized block
// statistics z (N(0, 1) and independent while nothing changed), with its threshold designed from
// a false-alarm interval through the average run length (ARL).
//
//   g⁺ ← max(0, g⁺ + z − k),  g⁻ ← max(0, g⁻ − z − k),  alarm when g⁺ > h or g⁻ > h.
//
// k = δ/2 for a design shift δ (in units of z's σ) is Page's optimal choice for that shift.
// Siegmund's approximation (Siegmund 1985; Basseville & Nikiforov 1993, eq. 5.2.44) gives the ARL
// of one side for increments N(μ, 1), with ∆ = μ − k and b = h + 1.166:
//
//   ARL(μ) = (e^{−2∆b} + 2∆b − 1) / (2∆²),   ARL = b² at ∆ = 0;
//
// the two sides together alarm at the rate 1/ARL(μ) + 1/ARL(−μ). Under no change ARL₀ =
// ARL(0) ≈ e^{2kb}/(2k²); after a change of δ = 2k the delay from a zero start is ARL(δ) ≈
// (δb − 1 + e^{−δb})/(δ²/2), Lorden's 2 ln(ARL₀)/δ² for large ARL₀.
//
// The reference the residuals come from is itself an estimate: its error puts a constant bias μ
// into z, the same for every block, drawn once from N(0, v). The false-alarm rate is then the
// mean over μ of 1/ARL(μ) + 1/ARL(−μ) (Gauss–Hermite quadrature), and the design solves h for it,
// so a reference less precise than the design shift asks for a higher h instead of an alarm.

#include <cstdint>

namespace scp::health {

// One side's ARL (in blocks) for increments N(mean, 1).
double siegmund_arl(double mean, double k, double h) noexcept;

// Alarms per block of the two-sided CUSUM whose increments are N(μ, 1), μ ~ N(0, bias_variance).
double cusum_false_alarm_rate(double k, double h, double bias_variance) noexcept;

struct CusumDesign {
  double k = 0.5;  // reference value (half the design shift, capped)
  double h = 5.0;  // threshold
};

// k = min(shift/2, max_k) and the h whose false-alarm rate is 1/arl0_blocks. A CUSUM with a large
// k is a Shewhart chart (one block decides), and there Siegmund's overshoot correction no longer
// holds: simulated, k = 2 runs far shorter than its design while k ≤ 1 keeps it
// (bench/bench_health_calibration.cpp, docs/health.md). Capping k at 1 keeps the design true and
// only lowers the smallest shift seen in one block.
CusumDesign design_cusum(double shift, double arl0_blocks, double bias_variance,
                         double max_k = 1.0) noexcept;

// The expected delay (blocks, from a zero start) for a shift of `shift` standard deviations.
double cusum_delay(const CusumDesign& design, double shift) noexcept;

class TwoSidedCusum {
 public:
  TwoSidedCusum() noexcept = default;
  explicit TwoSidedCusum(const CusumDesign& design) noexcept : design_(design) {}

  // One block that began at `t_begin` (s); returns true while above h. A non-finite z is skipped.
  bool update(double z, double t_begin) noexcept;
  void reset() noexcept;
  void set_design(const CusumDesign& design) noexcept { design_ = design; }

  const CusumDesign& design() const noexcept { return design_; }
  double upper() const noexcept { return upper_; }
  double lower() const noexcept { return lower_; }
  // max(g⁺, g⁻) / h: 1 at the threshold.
  double ratio() const noexcept;
  // +1 (z rose), −1 (z fell) or 0 (no alarm).
  int direction() const noexcept;
  // The change-point estimate of the side that alarmed (or the larger one): the start of the
  // first block after that side last stood at zero (the maximum-likelihood change time for the
  // design shift, Page 1954).
  double onset() const noexcept;
  std::uint64_t blocks() const noexcept { return blocks_; }

 private:
  CusumDesign design_;
  double upper_ = 0.0, lower_ = 0.0;
  double upper_onset_ = 0.0, lower_onset_ = 0.0;
  std::uint64_t blocks_ = 0;
};

}  // namespace scp::health
