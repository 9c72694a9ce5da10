#pragma once
// exp, φ1 and φ2 of a real 2×2 matrix in closed form, and the scalar φ1, φ2 the thermal block
// needs.
//
//   φ0(z) = e^z,  φ1(z) = (e^z − 1)/z,  φ2(z) = (e^z − 1 − z)/z²   (φk(0) = 1/k!)
//
// A linear system dy/dσ = (M y + w0 + w1·σ/τ)/τ over one interval σ ∈ [0, τ] ends at
// y(τ) = e^M y(0) + φ1(M) w0 + φ2(M) w1: the whole discretization (refine/model_simulator.hpp).
//
// Every 2×2 matrix satisfies (M − cI)² = δ²I with c = tr(M)/2, δ² = c² − det(M), so for any entire
// f
//   f(M) = g0·I + g1·(M − cI),  g0 = (f(c+δ) + f(c−δ))/2,  g1 = (f(c+δ) − f(c−δ))/(2δ).
// δ² > 0: real distinct eigenvalues (an overdamped actuator: the paper's, poles −1.455 and
// −1245.5 rad/s); δ² < 0: complex pair (underdamped), inside the unit disc φ2's series on the
// pairs (g0, g1) themselves (no eigenvalue needed); |δ| small: a repeated pair, where the divided
// difference would cancel and a Taylor series in δ² takes over. All three are exercised by
// tests/refine/test_matrix_functions.cpp against a scaling-and-squaring reference.

#include <Eigen/Core>
#include <array>

namespace scp::refine {

using Matrix2 = Eigen::Matrix2d;

struct ExpPhi {
  Matrix2 exp;   // e^M
  Matrix2 phi1;  // φ1(M)
  Matrix2 phi2;  // φ2(M)
};

ExpPhi exp_phi(const Matrix2& m) noexcept;

// Scalar φ1(z), φ2(z) for real z, accurate to a few ulps also near z = 0.
struct Phi12 {
  double phi1;
  double phi2;
};
Phi12 phi12(double z) noexcept;

// φ0..φ5 at real z (φ0 = e^z, φ_{k+1}(z) = (φ_k(z) − 1/k!)/z), accurate near 0 too.
std::array<double, 6> phi_functions(double z) noexcept;

}  // namespace scp::refine
