#pragma once
// Thresholds for tests repeated on overlapping data: a refined window of length L refitted every
// Δ ≪ L gives test statistics that are nearly the same from one fit to the next, so a per-test
// significance α does not say how often the repeated test raises a false alarm (α/Δ counts every
// overlapping test as new; α/L, one test per window length, undercounts by the factor b below).
//
// Model: the statistic is a χ²_p process, the squared norm of p Gaussian processes each with
// correlation 1 − β|s| near s = 0 (a moving average of white information over L has β = 1/L),
// observed every Δ. Its expected upcrossings of a high level b per unit time are (Pickands'
// constant H₁ = 1; Siegmund's discrete-grid correction ν, Siegmund & Yakir 2007, ch. 4)
//
//   rate(b) = β · b · 2 f_p(b) · ν(√(2 β Δ b)),
//   ν(x) = (2/x)(Φ(x/2) − ½) / ((x/2) Φ(x/2) + φ(x/2))       (≈ e^{−0.583 x} for small x),
//
// f_p the χ²_p density (2 b f_p(b) → b·P(χ²_p > b) for large b: β b per unit time independent
// looks). The rate can never exceed P(χ²_p > b)/Δ (every test independent); that bound is taken
// where it is smaller. The thresholds are solved from this rate and measured against simulated
// moving windows in bench/bench_health_calibration.cpp (docs/health.md).

namespace scp::health {

double siegmund_nu(double x) noexcept;

// Expected upcrossings of level b per unit time (units of 1/β and Δ).
double chi_square_scan_rate(double b, int dof, double beta, double spacing) noexcept;

// The level b whose rate is `rate` (per unit time), rate·spacing < 1.
double chi_square_scan_threshold(double rate, int dof, double beta, double spacing) noexcept;

}  // namespace scp::health
