#pragma once
// A recorded (or externally produced) run of the actuator, as CSV, for offline replay.
//
// Format: a header line naming the columns, then one sample per line, comma-separated, SI units,
// T in °C. Required columns: t, x, xdot, T, V (any order; names are case-sensitive, so `t` is time
// and `T` temperature). Other columns are ignored, text or empty (the daemon's recordings also
// carry theta_hat1..6, eps1, eps2, state, refined_theta_hat1..6, best, ...). Blank lines and lines
// starting with '#' are skipped. Optional column V_since: when the row's V took effect (s, same
// clock as t, not after t), blank for "over the whole interval" (Sample::voltage_since). Optional
// column I: the heater's current in A (Sample::current), blank or nan for "not measured".
//
// Values are parsed with std::from_chars (no locale: the decimal separator is always '.').
// A blank xdot field or `nan` means "not measured" (NaN). NaN or ±inf in x, T or V are loaded
// as-is on purpose: replaying a faulty recording must exercise the loop's safety checks and the
// estimator's input checks exactly as the live run did. t must be finite and strictly increasing;
// it is fed to the estimator as it is. Steps need not be uniform: a real-time recording has a gap
// wherever the loop missed periods or was not running (a fault), and jitter where a driver stamps
// its samples, and the live estimator took those steps too (a gap longer than
// estimator.max_gap_periods restarts its filters, docs/numerics.md). Recordings should write t
// with enough digits (the daemon writes the shortest text that reads back bit for bit).
//
// Several files (a rotated recording) are one trace: load_traces() takes files and directories
// (a directory's *.csv and *.csv.gz in name order, which is time order for the daemon's
// recordings) and requires t to keep increasing from one file to the next. A file whose name
// ends in .gz is read through zlib (recording.compress: gzip); line numbers in messages are
// those of the decompressed text (`zcat -n`).

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
  double period = 0.0;             // s, the median step of t
  std::size_t gaps = 0;            // steps longer than 1.5 periods (missed periods, faults)
  double max_step = 0.0;           // s, the longest step
  std::vector<std::string> files;  // the files read, in order
  // A file had a V_since column: it says which interval each row's voltage was applied over (the
  // daemon's own recordings); without it the refinement estimates that (refine.voltage_interval).
  bool voltage_since_column = false;
};

Trace load_trace(const std::string& path);
// Files and directories, in the order given; a directory stands for its *.csv and *.csv.gz files
// sorted by name (A.csv.gz as A.csv; when both exist, A.csv). Throws TraceError when a file's first
// time is not after the previous file's last.
Trace load_traces(const std::vector<std::string>& paths);
// The same from an already open stream (tests, fuzzing); `name` stands for the file in messages.
Trace parse_trace(std::istream& in, const std::string& name);

}  // namespace scp::drivers::replay
