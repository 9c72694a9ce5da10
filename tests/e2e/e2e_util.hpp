#pragma once
// Shared helpers of the end-to-end tests.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <string>
#include <thread>

#include "tests/support/daemon_process.hpp"

namespace scp::test {

// Table I of the paper: θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)], computed here from the
// physical parameters, independently of the daemon.
inline std::array<double, 6> theta_true() {
  const double m = 0.1, R = 1.0, Cth = 0.9090, lambda = 0.0540, b = 124.7, k = 181.3, alpha1 = 0.08,
               alpha2 = 0.01;
  return {b / m, alpha1 / m, k / m, alpha2 / m, lambda / Cth, 1.0 / (R * Cth)};
}

inline double rel_error(const json& estimate, int i) {
  const double truth = theta_true()[static_cast<std::size_t>(i)];
  const json& v = estimate.at("theta_hat").at(static_cast<std::size_t>(i));
  if (!v.is_number()) return INFINITY;
  return std::fabs(v.get<double>() - truth) / std::fabs(truth);
}

inline double num(const json& j, const char* key, double otherwise = NAN) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : otherwise;
}

inline std::uint64_t loop_count(const json& status, const char* key) {
  return status.at("loop").at(key).get<std::uint64_t>();
}

// The last line a batch run prints is its JSON summary.
inline json summary_of(const ProcessResult& r) {
  std::istringstream lines(r.out);
  std::string line, last;
  while (std::getline(lines, line)) {
    if (!line.empty()) last = line;
  }
  return json::parse(last);
}

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// The last line a batch run (--offline, --replay) prints is its JSON summary.
inline json batch_summary(const ProcessResult& r) {
  std::istringstream lines(r.out);
  std::string line, last;
  while (std::getline(lines, line)) {
    if (!line.empty()) last = line;
  }
  return json::parse(last);
}

}  // namespace scp::test
