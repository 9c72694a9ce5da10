#include "health/innovation.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

#include "health/covariance.hpp"

namespace scp::health {

namespace {

// A parameter the fit held known gets a prior σ of this fraction of |θ_i|: known for every
// purpose here, without an infinite precision in the sums.
constexpr double kKnownRelativeSigma = 1e-10;
// Directions of a block's information below this fraction of its largest are not seen by it.
constexpr double kRankTolerance = 1e-12;

double scale_of(double theta) noexcept {
  return std::abs(theta) > 0.0 ? std::abs(theta) : 1.0;
}

// C⁻¹ of a covariance whose diagonal spans many decades: inverted as a correlation matrix. An
// indefinite C would give an indefinite prior, and the posterior's scores would be meaningless.
Matrix6 precision_of(const Vector6& theta, const Matrix6& reference_covariance) {
  const Matrix6 covariance = positive_semidefinite(reference_covariance);
  Vector6 sigma;
  for (int i = 0; i < kParams; ++i) {
    const double floor = kKnownRelativeSigma * scale_of(theta[i]);
    sigma[i] = std::sqrt(std::max(covariance(i, i), 0.0) + floor * floor);
  }
  const Vector6 inv = sigma.cwiseInverse();
  Matrix6 corr = inv.asDiagonal() * covariance * inv.asDiagonal();
  corr.diagonal().setOnes();
  const Eigen::LDLT<Matrix6> ldlt(corr);
  if (ldlt.info() != Eigen::Success) return inv.cwiseAbs2().asDiagonal();
  return inv.asDiagonal() * ldlt.solve(Matrix6::Identity()) * inv.asDiagonal();
}

using MatrixD = InnovationScores::MatrixD;
using VectorD = InnovationScores::VectorD;

// The block's sums over θ and its segment's nuisance (both outputs).
void block_sums(const ScoreBlock& block, MatrixD& information, VectorD& score) {
  information.setZero();
  score.setZero();
  information.topLeftCorner<kParams, kParams>() = block.information;
  score.head<kParams>() = block.score;
  for (const OutputSums& o : block.outputs) {
    information.bottomRightCorner<kNuisance, kNuisance>() += o.nuisance_information;
    information.topRightCorner<kParams, kNuisance>() += o.cross_information;
    score.tail<kNuisance>() += o.nuisance_score;
  }
  information.bottomLeftCorner<kNuisance, kParams>() =
      information.topRightCorner<kParams, kNuisance>().transpose();
}

// D·M·D with D = diag(1/√M_ii) (0 where M_ii = 0): unit diagonal, whatever θ's scales.
template <int N>
Eigen::Matrix<double, N, 1> unit_scale(const Eigen::Matrix<double, N, N>& m) {
  Eigen::Matrix<double, N, 1> d = Eigen::Matrix<double, N, 1>::Zero();
  for (int i = 0; i < N; ++i)
    if (m(i, i) > 0.0) d[i] = 1.0 / std::sqrt(m(i, i));
  return d;
}

// The pseudo-inverse of a positive semi-definite matrix with a unit (or zero) diagonal.
template <int N>
Eigen::Matrix<double, N, N> pseudo_inverse(const Eigen::Matrix<double, N, N>& m) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(m);
  const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
  Eigen::Matrix<double, N, 1> inv = Eigen::Matrix<double, N, 1>::Zero();
  for (int i = 0; i < N; ++i)
    if (eig.eigenvalues()[i] > kRankTolerance * largest) inv[i] = 1.0 / eig.eigenvalues()[i];
  return eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose();
}

}  // namespace

void InnovationScores::set_reference(const Vector6& theta, const Matrix6& covariance,
                                     double data_end, double from) {
  pending_ = {true, theta, covariance, data_end, from};
}

void InnovationScores::apply(const PendingReference& r) {
  const Vector6 shift = r.theta - theta_;
  std::erase_if(closed_, [&](const Segment& k) { return k.t_begin < r.data_end; });
  if (has_open_ && open_.t_begin < r.data_end) has_open_ = false;
  if (valid_) {
    // E[s] = I·(θ − θ_ref): the same data against the new θ_ref.
    for (Segment& k : closed_) k.score -= k.information.leftCols<kParams>() * shift;
    if (has_open_) open_.score -= open_.information.leftCols<kParams>() * shift;
  }
  theta_ = r.theta;
  prior_precision_ = precision_of(r.theta, r.covariance);
  valid_ = true;
}

// The closed segment keeps what its blocks say about e with its nuisance profiled out (the
// Schur complement), as the nuisance of a new seed is another.
void InnovationScores::close_open_segment() {
  has_open_ = false;
  const auto nn = open_.information.bottomRightCorner<kNuisance, kNuisance>();
  const Eigen::Matrix<double, kNuisance, 1> d = unit_scale<kNuisance>(nn);
  const Eigen::Matrix<double, kNuisance, kNuisance> nn_pinv =
      d.asDiagonal() *
      pseudo_inverse<kNuisance>(d.asDiagonal() * Eigen::Matrix<double, kNuisance, kNuisance>(nn) *
                                d.asDiagonal()) *
      d.asDiagonal();
  const Eigen::Matrix<double, kParams, kNuisance> en =
      open_.information.topRightCorner<kParams, kNuisance>();
  Segment closed;
  closed.id = open_.id;
  closed.t_begin = open_.t_begin;
  closed.information.topLeftCorner<kParams, kParams>() =
      open_.information.topLeftCorner<kParams, kParams>() - en * nn_pinv * en.transpose();
  closed.score.head<kParams>() =
      open_.score.head<kParams>() - en * nn_pinv * open_.score.tail<kNuisance>();
  closed_.push_back(closed);
}

void InnovationScores::totals(MatrixD& information, VectorD& score) const {
  information.setZero();
  score.setZero();
  information.topLeftCorner<kParams, kParams>() = prior_precision_;
  for (const Segment& k : closed_) {
    information += k.information;
    score += k.score;
  }
  if (has_open_) {
    information += open_.information;
    score += open_.score;
  }
}

std::optional<Vector6> InnovationScores::add(const ScoreBlock& block) {
  if (pending_.active && block.t_begin >= pending_.from) {
    apply(pending_);
    pending_.active = false;
  }
  if (!valid_) return std::nullopt;
  if (has_open_ && open_.id != block.segment) close_open_segment();
  if (!has_open_) {
    open_ = Segment{};
    open_.id = block.segment;
    open_.t_begin = block.t_begin;
    has_open_ = true;
  }
  MatrixD a, i;
  VectorD b, s;
  totals(a, b);
  block_sums(block, i, s);
  // In units where A + I has a unit diagonal: the posterior with the block, the block's score
  // at it, and that score's covariance given the past.
  const VectorD d = unit_scale<kDim>(MatrixD(a + i));
  const MatrixD h_pinv = pseudo_inverse<kDim>(MatrixD(d.asDiagonal() * (a + i) * d.asDiagonal()));
  const MatrixD iu = d.asDiagonal() * i * d.asDiagonal();
  const VectorD posterior = h_pinv * (d.asDiagonal() * (b + s));
  const VectorD score = d.asDiagonal() * s - iu * posterior;
  const MatrixD g = iu - iu * h_pinv * iu;
  Vector6 z = Vector6::Zero();
  for (int k = 0; k < kParams; ++k)
    if (iu(k, k) > 0.0 && g(k, k) > kRankTolerance * iu(k, k)) z[k] = score[k] / std::sqrt(g(k, k));
  open_.information += i;
  open_.score += s;
  if (!z.allFinite()) return Vector6::Zero();
  return z;
}

Vector6 InnovationScores::error_estimate() const {
  MatrixD a;
  VectorD b;
  totals(a, b);
  const VectorD d = unit_scale<kDim>(a);
  const VectorD e =
      d.asDiagonal() *
      (pseudo_inverse<kDim>(MatrixD(d.asDiagonal() * a * d.asDiagonal())) * (d.asDiagonal() * b));
  return e.head<kParams>();
}

void InnovationScores::clear() noexcept {
  valid_ = false;
  pending_.active = false;
  has_open_ = false;
  closed_.clear();
}

}  // namespace scp::health
