#include "health/innovation.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

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

// C⁻¹ of a covariance whose diagonal spans many decades: inverted as a correlation matrix.
Matrix6 precision_of(const Vector6& theta, const Matrix6& covariance) {
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
// [u, v]: the reference's error at its anchor and θ's rate; the nuisance follows.
constexpr int kErrorDim = 2 * kParams;
constexpr int kRate = kParams;  // v's first index

// The block's sums over [u, v] and its segment's nuisance (both outputs). The block is short
// against a drift: its samples are all taken at its midpoint, τ from the anchor, where the
// error is u + v·τ.
void block_sums(const ScoreBlock& block, double anchor, MatrixD& information, VectorD& score) {
  const double tau = 0.5 * (block.t_begin + block.t_end) - anchor;
  Matrix6N cross = Matrix6N::Zero();
  NuisanceMatrix nuisance_information = NuisanceMatrix::Zero();
  NuisanceVector nuisance_score = NuisanceVector::Zero();
  for (const OutputSums& o : block.outputs) {
    nuisance_information += o.nuisance_information;
    cross += o.cross_information;
    nuisance_score += o.nuisance_score;
  }
  information.setZero();
  score.setZero();
  information.block<kParams, kParams>(0, 0) = block.information;
  information.block<kParams, kParams>(0, kRate) = tau * block.information;
  information.block<kParams, kParams>(kRate, 0) = tau * block.information;
  information.block<kParams, kParams>(kRate, kRate) = tau * tau * block.information;
  information.block<kParams, kNuisance>(0, kErrorDim) = cross;
  information.block<kParams, kNuisance>(kRate, kErrorDim) = tau * cross;
  information.bottomRightCorner<kNuisance, kNuisance>() = nuisance_information;
  information.bottomLeftCorner<kNuisance, kErrorDim>() =
      information.topRightCorner<kErrorDim, kNuisance>().transpose();
  score.head<kParams>() = block.score;
  score.segment<kParams>(kRate) = tau * block.score;
  score.tail<kNuisance>() = nuisance_score;
}

// The same data with the error at anchor T' instead of T: u_T = u_T' + (T − T')·v, so
// A' = MᵀAM, b' = Mᵀb with M the identity but for (T − T')·I from v into u.
void reanchor(MatrixD& information, VectorD& score, double from_anchor, double to_anchor) {
  const double d = from_anchor - to_anchor;
  information.middleCols<kParams>(kRate) += d * information.leftCols<kParams>();
  information.middleRows<kParams>(kRate) += d * information.topRows<kParams>();
  score.segment<kParams>(kRate) += d * score.head<kParams>();
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

void InnovationScores::set_reference(const ReferencePrior& prior, double data_end, double from) {
  pending_ = {true, prior, data_end, from};
}

void InnovationScores::set_reference(const Vector6& theta, const Matrix6& covariance,
                                     double data_end, double from) {
  ReferencePrior prior;
  prior.theta = theta;
  prior.covariance = covariance;
  prior.anchor = from;
  set_reference(prior, data_end, from);
}

void InnovationScores::apply(const PendingReference& r) {
  const ReferencePrior& p = r.prior;
  const Vector6 shift = p.theta - theta_;
  std::erase_if(closed_, [&](const Segment& k) { return k.t_begin < r.data_end; });
  if (has_open_ && open_.t_begin < r.data_end) has_open_ = false;
  if (valid_) {
    // E[s] = I·(θ − θ_ref): the same data about the error at the new anchor, against the new θ_ref.
    for (Segment& k : closed_) {
      reanchor(k.information, k.score, anchor_, p.anchor);
      k.score -= k.information.leftCols<kParams>() * shift;
    }
    if (has_open_) {
      reanchor(open_.information, open_.score, anchor_, p.anchor);
      open_.score -= open_.information.leftCols<kParams>() * shift;
    }
  }
  theta_ = p.theta;
  anchor_ = p.anchor;
  prior_precision_.setZero();
  prior_score_.setZero();
  prior_precision_.topLeftCorner<kParams, kParams>() = precision_of(p.theta, p.covariance);
  for (int i = 0; i < kParams; ++i) {
    // θ units per second; a known rate gets the same tiny σ as a known θ.
    const double floor = kKnownRelativeSigma * scale_of(p.theta[i]);
    const double sigma = std::isfinite(p.rate_sigma[i]) ? std::abs(p.rate_sigma[i]) : 0.0;
    const double precision = 1.0 / (sigma * sigma + floor * floor);
    const double rate = std::isfinite(p.rate[i]) ? p.rate[i] : 0.0;
    prior_precision_(kRate + i, kRate + i) = precision;
    prior_score_[kRate + i] = precision * rate;
  }
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
  const Eigen::Matrix<double, kErrorDim, kNuisance> en =
      open_.information.topRightCorner<kErrorDim, kNuisance>();
  Segment closed;
  closed.id = open_.id;
  closed.t_begin = open_.t_begin;
  closed.information.topLeftCorner<kErrorDim, kErrorDim>() =
      open_.information.topLeftCorner<kErrorDim, kErrorDim>() - en * nn_pinv * en.transpose();
  closed.score.head<kErrorDim>() =
      open_.score.head<kErrorDim>() - en * nn_pinv * open_.score.tail<kNuisance>();
  closed_.push_back(closed);
}

void InnovationScores::totals(MatrixD& information, VectorD& score) const {
  information = prior_precision_;
  score = prior_score_;
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
  block_sums(block, anchor_, i, s);
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

InnovationScores::VectorD InnovationScores::posterior_mean() const {
  MatrixD a;
  VectorD b;
  totals(a, b);
  const VectorD d = unit_scale<kDim>(a);
  return d.asDiagonal() * (pseudo_inverse<kDim>(MatrixD(d.asDiagonal() * a * d.asDiagonal())) *
                           (d.asDiagonal() * b));
}

Vector6 InnovationScores::error_estimate() const {
  return posterior_mean().head<kParams>();
}

Vector6 InnovationScores::rate_estimate() const {
  return posterior_mean().segment<kParams>(kRate);
}

void InnovationScores::clear() noexcept {
  valid_ = false;
  pending_.active = false;
  has_open_ = false;
  closed_.clear();
}

}  // namespace scp::health
