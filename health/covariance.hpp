#pragma once
// A covariance assembled from approximations (a trend's sandwich of overlapping windows'
// cross-covariances) can come out indefinite; every test downstream (a Wald χ², the fast
// detector's prior precision) needs it positive semi-definite.

#include "health/types.hpp"

namespace scp::health {

// `c` made symmetric positive semi-definite: in units where its diagonal is one (θ spans many
// decades), each eigenvalue λ becomes |λ|. A direction of negative variance is one whose variance
// the approximation got wrong by about |λ|; taking that as its variance keeps it uncertain rather
// than known (clipping to zero would claim it exact). Zero-variance (known) parameters stay known.
// A positive semi-definite `c` comes back unchanged up to rounding.
Matrix6 positive_semidefinite(const Matrix6& c);

}  // namespace scp::health
