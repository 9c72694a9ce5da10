// Fuzzes the replay CSV reader (drivers/replay/csv_trace.hpp): any text must either load into a
// trace that keeps the documented guarantees or throw TraceError naming the source.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "drivers/replay/csv_trace.hpp"
#include "fuzz/fuzz_check.hpp"

namespace replay = scp::drivers::replay;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const replay::Trace trace = replay::parse_trace(in, "fuzz.csv");
    // Guarantees of the format: ≥ 2 rows, finite strictly increasing t, a positive period.
    FUZZ_CHECK(trace.rows.size() >= 2);
    FUZZ_CHECK(trace.period > 0.0);
    for (std::size_t i = 0; i < trace.rows.size(); ++i) {
      FUZZ_CHECK(std::isfinite(trace.rows[i].t));
      if (i > 0) FUZZ_CHECK(trace.rows[i].t > trace.rows[i - 1].t);
    }
  } catch (const replay::TraceError& error) {
    const std::string message = error.what();
    FUZZ_CHECK(message.rfind("fuzz.csv", 0) == 0);
  }
  return 0;
}
