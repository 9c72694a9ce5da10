// The fast detector's innovations (health/innovation.hpp) on synthetic score blocks whose
// reference is off by an error drawn from a covariance far larger than one block can resolve:
// the plain efficient scores carry that error as a bias in every block; the innovations must be
// N(0, 1) whatever it is, and still carry a step's shift in the blocks right after it.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <random>

#include "health/innovation.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

constexpr double kReferenceSeconds = 30.0;  // a new reference per refit
constexpr int kReferences = 200;

// Blocks that each carry a tenth of a 300 s window's information (the daemon's blocks see the
// mechanical θ far more sharply than a window's marginal σ says, their common scale aside), and
// a reference 100 times less certain than that window (a trend extrapolated from a few
// overlapping windows): the plain scores' bias then has a variance of about 3.
struct Plant {
  Vector6 theta = test::paper_theta();
  Matrix6 window = test::window_covariance_300s();
  Matrix6 information = window.inverse() / 30.0;
  Matrix6 reference_covariance = 100.0 * window;
};

TEST(Innovation, ScoresAreStandardWhateverTheReferenceError) {
  const Plant s;
  test::ScoreStream stream(s.information, 11);
  std::mt19937_64 rng(12);
  std::normal_distribution<double> normal;
  const Matrix6 lower = s.reference_covariance.llt().matrixL();
  InnovationScores innovation;
  Vector6 sum = Vector6::Zero(), square = Vector6::Zero(), plain_square = Vector6::Zero();
  long n = 0;
  Vector6 reference = s.theta;
  for (int r = 0; r < kReferences; ++r) {
    const double t0 = r * kReferenceSeconds;
    // Each reference has its own error; the blocks kept from before are re-expressed against it.
    Vector6 e;
    for (int i = 0; i < kParams; ++i) e[i] = normal(rng);
    reference = s.theta + lower * e;
    innovation.set_reference(reference, s.reference_covariance, t0 - 120.0, t0);
    for (int b = 0; b < static_cast<int>(kReferenceSeconds); ++b) {
      const ScoreBlock block = stream.block(t0 + b, t0 + b + 1.0, s.theta, reference);
      const Vector6 z = innovation.add(block).value();
      const Vector6 plain = block.z();
      sum += z;
      square += z.cwiseAbs2();
      plain_square += plain.cwiseAbs2();
      ++n;
    }
  }
  for (int i = 0; i < kParams; ++i) {
    const double mean = sum[i] / n, variance = square[i] / n - mean * mean;
    SCOPED_TRACE(i);
    // 6000 blocks: σ of the mean 0.013, of the variance ~0.02 (the blocks are independent).
    EXPECT_NEAR(mean, 0.0, 0.06);
    EXPECT_NEAR(variance, 1.0, 0.1);
    // The plain scores carry the reference's error: their mean square is far from 1.
    EXPECT_GT(plain_square[i] / n, 2.0);
  }
}

TEST(Innovation, AStepShowsInTheBlocksAfterIt) {
  // b/m +10 % after 100 s against a reference that is exact but uncertain: the innovations of
  // θ1 over the 10 blocks after the step keep most of the plain score's shift ∆·√I_11 (the
  // posterior of 100 blocks absorbs a few % of it by then; σ of the mean 0.32).
  const Plant s;
  test::ScoreStream stream(s.information, 21);
  InnovationScores innovation;
  innovation.set_reference(s.theta, s.reference_covariance, -120.0, 0.0);
  Vector6 moved = s.theta;
  moved[0] *= 1.1;
  const double shift = 0.1 * s.theta[0] * std::sqrt(s.information(0, 0));
  double after = 0.0;
  for (int b = 0; b < 110; ++b) {
    const Vector6 truth = b < 100 ? s.theta : moved;
    const Vector6 z = innovation.add(stream.block(b, b + 1.0, truth, s.theta)).value();
    if (b >= 100) after += z[0] / 10.0;
  }
  EXPECT_GT(shift, 2.0);  // the step is worth detecting within a few blocks
  EXPECT_GT(after, 0.8 * shift);
  EXPECT_LT(after, 1.1 * shift);
}

}  // namespace
}  // namespace scp::health
