#pragma once
// Recorded windows for the refine tests: the project's simulated plant (drivers/sim, RK4 at
// 20 sub-steps per ms, voltage held over each step as the daemon's DAC holds it) driven by an
// excitation, sampled like the daemon samples, with optional sensor noise.

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <random>
#include <span>
#include <vector>

#include "drivers/sim/plant.hpp"
#include "excitation/excitation.hpp"
#include "refine/fit.hpp"
#include "refine/model_simulator.hpp"

namespace scp::refine::test {

inline Vector6 theta_of(const drivers::sim::PlantParams& p) {
  const auto a = drivers::sim::theta_of(p);
  Vector6 t;
  for (int i = 0; i < 6; ++i) t[i] = a[i];
  return t;
}

// Table I.
inline drivers::sim::PlantParams paper_actuator() {
  return {};
}

// An underdamped, thermally faster actuator: a thinner, lighter coil (m = 20 g, Cth = 0.12 Ws/°C,
// λ = 0.012 W/°C: τ_th = 10 s, 1.7× faster than the paper's), stiffer and lightly damped
// (k = 400 N/m, b = 2 Ns/m: poles −60 ± 129j rad/s, ζ ≈ 0.42 at room temperature, less when hot
// since α1 > 0 adds damping), R = 5 Ω; its peak rise at 3.2 V is V²/(Rλ) ≈ 170 °C.
inline drivers::sim::PlantParams underdamped_actuator() {
  drivers::sim::PlantParams p;
  p.m = 0.02;
  p.R = 5.0;
  p.Cth = 0.12;
  p.lambda = 0.012;
  p.b = 2.0;
  p.k = 400.0;
  p.alpha1 = 0.005;
  p.alpha2 = 0.004;
  return p;
}

struct Noise {
  double x = 0.0;     // m, standard deviation
  double tbar = 0.0;  // °C
  // Correlation time in samples of a first-order low-pass the x noise goes through (0: white);
  // its output is rescaled to keep the standard deviation `x`.
  double x_correlation_samples = 0.0;
  // A second, slow component of the x noise: standard deviation (m) and correlation time in
  // samples (a drift, a thermal creep of the sensor's mount).
  double x_slow = 0.0;
  double x_slow_correlation_samples = 0.0;
  unsigned seed = 1;
};

// The sensors' white noise at PAPER-NOTES' levels N1 (1e-7 m, 1e-3 °C) and N3 (1e-6 m, 0.1 °C).
inline constexpr Noise kN1{.x = 1e-7, .tbar = 1e-3};
inline constexpr Noise kN3{.x = 1e-6, .tbar = 0.1};
// `noise` drawn from `seed`.
constexpr Noise seeded(Noise noise, unsigned seed) {
  noise.seed = seed;
  return noise;
}

// `seconds` of the plant at period `dt`, voltage from `voltage(t)` written at each sample and held
// until the next: window sample k+1 carries the voltage set at sample k (voltage_since = t_k).
inline std::vector<WindowSample> record(const drivers::sim::PlantParams& params, double seconds,
                                        double dt, const std::function<double(double)>& voltage,
                                        const Noise& noise = {}) {
  drivers::sim::Plant plant(params);
  const auto n = static_cast<std::size_t>(std::llround(seconds / dt)) + 1;
  std::vector<WindowSample> w;
  w.reserve(n);
  std::mt19937_64 rng(noise.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double rho =
      noise.x_correlation_samples > 0.0 ? std::exp(-1.0 / noise.x_correlation_samples) : 0.0;
  const double gain = std::sqrt(1.0 - rho * rho);
  double coloured = gauss(rng);
  double v_prev = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * dt;
    coloured = rho * coloured + gain * gauss(rng);
    WindowSample s;
    s.t = t;
    s.x = plant.x() + noise.x * (rho > 0.0 ? coloured : gauss(rng));
    s.tbar = plant.tbar() + noise.tbar * gauss(rng);
    s.voltage = v_prev;
    s.voltage_since = t - dt;
    w.push_back(s);
    v_prev = voltage(t);
    plant.step(v_prev, dt);
  }
  return w;
}

// A copy of a noise-free window with sensor noise added (the plant is simulated once, the noise
// drawn per seed).
inline std::vector<WindowSample> with_noise(std::vector<WindowSample> w, const Noise& noise) {
  std::mt19937_64 rng(noise.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double rho =
      noise.x_correlation_samples > 0.0 ? std::exp(-1.0 / noise.x_correlation_samples) : 0.0;
  const double gain = std::sqrt(1.0 - rho * rho);
  const double rho_slow = noise.x_slow_correlation_samples > 0.0
                              ? std::exp(-1.0 / noise.x_slow_correlation_samples)
                              : 0.0;
  const double gain_slow = std::sqrt(1.0 - rho_slow * rho_slow);
  double coloured = gauss(rng);
  double slow = noise.x_slow > 0.0 ? gauss(rng) : 0.0;
  for (WindowSample& s : w) {
    coloured = rho * coloured + gain * gauss(rng);
    s.x += noise.x * coloured;
    if (noise.x_slow > 0.0) {
      slow = rho_slow * slow + gain_slow * gauss(rng);
      s.x += noise.x_slow * slow;
    }
    s.tbar += noise.tbar * gauss(rng);
  }
  return w;
}

inline std::function<double(double)> paper_voltage() {
  auto ex = std::make_shared<excitation::Excitation>(excitation::paper_excitation());
  return [ex](double t) { return ex->voltage(t); };
}

inline std::vector<WindowSample> paper_record(double seconds, const Noise& noise = {},
                                              const drivers::sim::PlantParams& p = {}) {
  return record(p, seconds, 1e-3, paper_voltage(), noise);
}

// A record through a link: samples every 10 ms ± 2 ms (uniform jitter), each new voltage landing
// 3.6 ms after the sample it was computed from (voltage_since inside the interval).
inline std::vector<WindowSample> link_record(const drivers::sim::PlantParams& params,
                                             double seconds) {
  drivers::sim::Plant plant(params);
  excitation::Excitation ex(excitation::paper_excitation());
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> jitter(-2e-3, 2e-3);
  std::vector<WindowSample> w;
  double t = 0.0, v_cur = 0.0;
  w.push_back({0.0, 0.0, 0.0, 0.0, -1e300});
  while (t < seconds) {
    const double next = t + 10e-3 + jitter(rng);
    const double lands = t + 3.6e-3;
    const double v_prev = v_cur;
    v_cur = ex.voltage(t);
    plant.step(v_prev, lands - t);
    plant.step(v_cur, next - lands);
    t = next;
    w.push_back({t, plant.x(), plant.tbar(), v_cur, lands});
  }
  return w;
}

// The same link with an output latency nobody configured: each switch recorded `latency` s
// earlier than it landed.
inline std::vector<WindowSample> late_link_record(const drivers::sim::PlantParams& params,
                                                  double seconds, double latency) {
  auto w = link_record(params, seconds);
  for (auto& s : w) s.voltage_since -= latency;
  return w;
}

// What a link's landing stamps get wrong beyond their per-stamp jitter: a constant delay (the
// voltage switches `delay` s after its stamp) and a slow wander about it, a new offset drawn
// uniformly from [−wander, wander] every `wander_block_s` (a live link's landing stamps' 10 s
// means wander by ±10 µs: docs/numerics.md, "σ on a real link").
struct LandingStampErrors {
  double delay = 0.0;
  double wander = 0.0;
  double wander_block_s = 10.0;
};

// The same link with its stamps' error: each sample's stamp and each landing's stamp off by an
// independent Gaussian error of `jitter` (s) RMS, as transaction midpoints on a link are (the
// plant saw the true instants), and the landing stamps' `errors` besides.
inline std::vector<WindowSample> jittered_link_record(const drivers::sim::PlantParams& params,
                                                      double seconds, double jitter, unsigned seed,
                                                      const LandingStampErrors& errors = {}) {
  drivers::sim::Plant plant(params);
  excitation::Excitation ex(excitation::paper_excitation());
  std::mt19937_64 rng(seed);
  std::mt19937_64 wander_rng(seed + 0x9e3779b9u);  // its own: the jitter's draws stay as they were
  std::uniform_real_distribution<double> period_jitter(-2e-3, 2e-3);
  std::uniform_real_distribution<double> wander(-errors.wander, errors.wander);
  std::normal_distribution<double> stamp_error(0.0, jitter);
  std::vector<WindowSample> w;
  double t = 0.0, v_cur = 0.0;
  double offset = errors.wander > 0.0 ? wander(wander_rng) : 0.0;
  double next_offset_at = errors.wander_block_s;
  w.push_back({0.0, 0.0, 0.0, 0.0, -1e300});
  while (t < seconds) {
    if (errors.wander > 0.0 && t >= next_offset_at) {
      offset = wander(wander_rng);
      next_offset_at += errors.wander_block_s;
    }
    const double next = t + 10e-3 + period_jitter(rng);
    const double lands = t + 3.6e-3 + stamp_error(rng);
    const double v_prev = v_cur;
    v_cur = ex.voltage(t);
    plant.step(v_prev, lands - t);
    plant.step(v_cur, next - lands);
    t = next;
    const double sample_stamp = t + stamp_error(rng);
    const double landing_stamp = lands - errors.delay + offset + stamp_error(rng);
    w.push_back({sample_stamp, plant.x(), plant.tbar(), v_cur, landing_stamp});
  }
  return w;
}

// The noise-free paper record of `seconds`, simulated once per test program.
inline const std::vector<WindowSample>& cached_paper_record(double seconds) {
  static std::vector<std::pair<double, std::vector<WindowSample>>> cache;
  for (const auto& [s, w] : cache)
    if (s == seconds) return w;
  cache.emplace_back(seconds, paper_record(seconds));
  return cache.back().second;
}

// θ of the paper's actuator (Table I).
inline const Vector6& paper_theta() {
  static const Vector6 t = test::theta_of(paper_actuator());
  return t;
}

// The paper record of `seconds` with N1 noise drawn from `seed`, simulated once per program (the
// benches' window).
inline const std::vector<WindowSample>& cached_paper_record_n1(double seconds, unsigned seed) {
  struct Entry {
    double seconds;
    unsigned seed;
    std::vector<WindowSample> window;
  };
  static std::vector<Entry> cache;
  for (const Entry& e : cache)
    if (e.seconds == seconds && e.seed == seed) return e.window;
  cache.push_back({seconds, seed, paper_record(seconds, seeded(kN1, seed))});
  return cache.back().window;
}

// max |model − record| / max |record| per output (x, T̄): refine::simulate at θ and the
// extensions' coefficients `tc`, from the record's first sample at rest.
inline Eigen::Vector2d model_misfit(std::span<const WindowSample> w, const Vector6& theta,
                                    const Tempcos& tc = {}) {
  std::vector<ModelState> out(w.size());
  simulate(w, theta, InitialState(w[0].x, 0.0, w[0].tbar), out, 0.0, tc);
  double dx = 0.0, dt = 0.0, mx = 0.0, mt = 0.0;
  for (std::size_t k = 0; k < w.size(); ++k) {
    dx = std::max(dx, std::abs(out[k].x - w[k].x));
    dt = std::max(dt, std::abs(out[k].tbar - w[k].tbar));
    mx = std::max(mx, std::abs(w[k].x));
    mt = std::max(mt, std::abs(w[k].tbar));
  }
  return {dx / mx, dt / mt};
}

// For one slot: max |∂y/∂p − central difference| over the record, relative to the difference's
// largest value (absolute where that is 0), per output (x, T̄). `up`, `down`: the model at p ± h;
// dx, dt: the sensitivities at each sample.
inline Eigen::Vector2d difference_error(const std::vector<ModelState>& up,
                                        const std::vector<ModelState>& down, double h,
                                        const std::vector<ParamVector>& dx,
                                        const std::vector<ParamVector>& dt, int slot) {
  double ex = 0.0, et = 0.0, mx = 0.0, mt = 0.0;
  for (std::size_t k = 0; k < up.size(); ++k) {
    const double fx = (up[k].x - down[k].x) / (2.0 * h);
    const double ft = (up[k].tbar - down[k].tbar) / (2.0 * h);
    ex = std::max(ex, std::abs(dx[k][slot] - fx));
    et = std::max(et, std::abs(dt[k][slot] - ft));
    mx = std::max(mx, std::abs(fx));
    mt = std::max(mt, std::abs(ft));
  }
  return {mx > 0.0 ? ex / mx : ex, mt > 0.0 ? et / mt : et};
}

}  // namespace scp::refine::test
