#pragma once
// A recorded (or externally produced) run of the actuator, as CSV, for offline replay.
//
// Format: a header line naming the columns, then one sample per line, comma-separated, SI units,
// T in °C. Required columns: t, x, xdot, T, V (any order; names are case-sensitive, so `t` is time
// and `T` temperature). Other columns are ignored (the daemon's recordings also carry
// theta_hat1..6, eps1, eps2). Blank lines and lines starting with '#' are skipped.
//
// Values are parsed with std::from_chars (no locale: the decimal separator is always '.').
// A blank xdot field or `nan` means "not measured" (NaN). NaN or ±inf in x, T or V are loaded
// as-is on purpose: replaying a faulty recording must exercise the loop's safety checks and the
// estimator's input checks exactly as the live run did. t must be finite and strictly increasing
// with a uniform step (each step within 1e-6 relative of the median step), so recordings must
// write t with enough digits (%.17g, or ≥ 10 significant digits for runs of hours at 1 ms).

#include <istream>
#include <stdexcept>
#include <string>
#include <vector>

#include "drivers/sample.hpp"

namespace scp::drivers::replay {

// Every problem with a trace file; what() names the file, the line, the column and the remedy.
class TraceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Trace {
  std::vector<Sample> rows;
  double period = 0.0;  // s, the median step of t
};

inline constexpr double kPeriodTolerance = 1e-6;  // relative to the median step

Trace load_trace(const std::string& path);
// The same from an already open stream (tests, fuzzing); `name` stands for the file in messages.
Trace parse_trace(std::istream& in, const std::string& name);

}  // namespace scp::drivers::replay
