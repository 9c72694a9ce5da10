#include "estimator/config_check.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "common/checks.hpp"

namespace scp::estimator {
namespace {

// Open lower bound when lo_open, closed upper bound always; hi = inf means unbounded.
void check(const char* field, double v, double lo, bool lo_open, double hi, const char* unit) {
  const bool ok = std::isfinite(v) && (lo_open ? v > lo : v >= lo) && v <= hi;
  if (ok) return;
  const std::string range = std::string(lo_open ? "(" : "[") + checks::num(lo) + ", " +
                            (std::isinf(hi) ? std::string("inf)") : checks::num(hi) + "]");
  throw std::invalid_argument(std::string("estimator config: ") + field + " = " + checks::num(v) +
                              " is out of range; allowed " + range + (*unit ? " " : "") + unit);
}

}  // namespace

void validate_config(const EstimatorConfig& c) {
  constexpr double inf = INFINITY;
  check("beta", c.beta, 0.0, true, 1e4, "rad/s");
  check("forgetting", c.forgetting, 0.0, true, 1e3, "1/s");
  check("forgetting_mechanical", c.forgetting_mechanical, 0.0, false, 1e3,
        "1/s (0: the same as forgetting)");
  check("p_max", c.p_max, 0.0, true, 1e300, "");
  check("p0", c.p0, 0.0, true, c.p_max, "(must not exceed p_max)");
  for (int i = 0; i < 6; ++i) {
    const std::string t0 = "theta0[" + std::to_string(i) + "]";
    check(t0.c_str(), c.theta0(i), -1e300, false, 1e300, "");
    const std::string sc = "scale[" + std::to_string(i) + "]";
    check(sc.c_str(), c.scale(i), 0.0, true, 1e300, "(a typical magnitude of theta_i)");
  }
  if (c.voltage_hold != VoltageHold::zoh && c.voltage_hold != VoltageHold::foh) {
    throw std::invalid_argument("estimator config: voltage_hold must be zoh or foh");
  }
  check("max_gap_periods", c.max_gap_periods, 1.0, false, inf, "periods");
  check("nominal_period", c.nominal_period, 0.0, true, 10.0, "s");
  check("x_abs_max", c.x_abs_max, 0.0, true, inf, "m");
  check("xdot_abs_max", c.xdot_abs_max, 0.0, true, inf, "m/s");
  check("tbar_min", c.tbar_min, -inf, false, 0.0, "degC above ambient");
  check("tbar_max", c.tbar_max, 0.0, true, inf, "degC above ambient");
  check("voltage_max", c.voltage_max, 0.0, true, inf, "V");
  check("converged_rel_sigma", c.converged_rel_sigma, 0.0, true, inf, "");
}

}  // namespace scp::estimator
