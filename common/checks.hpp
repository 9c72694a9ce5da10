#pragma once
// Validation of settings that a library checks itself (the simulated plant, the excitation, the
// estimator, a CSV file): numbers quoted back as a user writes them, and one message shape,
// "FIELD must be RULE (got VALUE); REMEDY", thrown as the library's own error type.

#include <cstdio>
#include <stdexcept>
#include <string>
#include <string_view>

namespace scp::checks {

// Short, as written in a YAML file ("%g").
inline std::string num(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

// Every digit ("%.17g"): a value quoted from a data file must read back as the same double.
inline std::string exact_num(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

template <class Error = std::invalid_argument>
void require(bool ok, std::string_view field, std::string_view rule, double got,
             std::string_view remedy) {
  if (ok) return;
  throw Error(std::string(field) + " must be " + std::string(rule) + " (got " + num(got) + "); " +
              std::string(remedy));
}

}  // namespace scp::checks
