#include "daemon/analysis/health/baseline.hpp"

#include <cmath>
#include <nlohmann/json.hpp>

namespace scp::daemon::health {

namespace {

using nlohmann::json;
constexpr const char* kFormat = "scp-estimator-baseline";
constexpr int kVersion = 1;

bool read_numbers(const json& j, const char* key, std::size_t n, double* out, std::string& error) {
  if (!j.contains(key) || !j[key].is_array() || j[key].size() != n) {
    error =
        std::string("field '") + key + "' must be an array of " + std::to_string(n) + " numbers";
    return false;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!j[key][i].is_number() || !std::isfinite(j[key][i].get<double>())) {
      error = std::string("field '") + key + "' element " + std::to_string(i) +
              " is not a finite number";
      return false;
    }
    out[i] = j[key][i].get<double>();
  }
  return true;
}

bool covariance_usable(const scp::health::Matrix6& c, std::string& error) {
  for (int i = 0; i < 6; ++i) {
    if (c(i, i) < 0.0) {
      error = "field 'covariance' has a negative variance at " + std::to_string(i);
      return false;
    }
    for (int k = 0; k < i; ++k) {
      const double scale = std::sqrt(c(i, i) * c(k, k));
      if (std::abs(c(i, k) - c(k, i)) > 1e-9 * scale + 1e-300) {
        error = "field 'covariance' is not symmetric";
        return false;
      }
    }
  }
  return true;
}

}  // namespace

std::string to_json(const Baseline& b) {
  json j;
  j["format"] = kFormat;
  j["version"] = kVersion;
  j["actuator"] = b.actuator;
  j["driver"] = b.driver;
  j["verdict"] = b.verdict;
  j["saved_unix_ns"] = b.saved_unix_ns;
  j["t_begin"] = b.window.t_begin;
  j["t_end"] = b.window.t_end;
  j["theta"] = json::array();
  for (int i = 0; i < 6; ++i) j["theta"].push_back(b.window.theta[i]);
  j["covariance"] = json::array();  // row-major
  for (int i = 0; i < 6; ++i)
    for (int k = 0; k < 6; ++k) j["covariance"].push_back(b.window.covariance(i, k));
  return j.dump(2) + "\n";
}

std::optional<Baseline> parse_baseline(const std::string& text, std::string& error) try {
  const json j = json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    error = "not a JSON object";
    return std::nullopt;
  }
  if (j.value("format", "") != kFormat || j.value("version", 0) != kVersion) {
    error = std::string("not a baseline: 'format' must be \"") + kFormat + "\" and 'version' " +
            std::to_string(kVersion);
    return std::nullopt;
  }
  Baseline b;
  double times[2] = {0.0, 0.0};
  double row_major[36] = {};
  const json t = {{"times", {j.value("t_begin", NAN), j.value("t_end", NAN)}}};
  if (!read_numbers(j, "theta", 6, b.window.theta.data(), error) ||
      !read_numbers(j, "covariance", 36, row_major, error) ||
      !read_numbers(t, "times", 2, times, error)) {
    if (error.find("times") != std::string::npos)
      error = "fields 't_begin', 't_end' must be finite";
    return std::nullopt;
  }
  for (int i = 0; i < 6; ++i)
    for (int k = 0; k < 6; ++k) b.window.covariance(i, k) = row_major[6 * i + k];
  if (!covariance_usable(b.window.covariance, error)) return std::nullopt;
  b.window.t_begin = times[0];
  b.window.t_end = times[1];
  b.actuator = j.value("actuator", "");
  b.driver = j.value("driver", "");
  b.verdict = j.value("verdict", "untested");
  b.saved_unix_ns = j.value("saved_unix_ns", std::int64_t{0});
  return b;
} catch (const nlohmann::json::exception& e) {
  error = std::string("a field has the wrong type (") + e.what() + ")";
  return std::nullopt;
}

}  // namespace scp::daemon::health
