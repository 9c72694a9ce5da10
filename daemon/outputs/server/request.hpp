#pragma once
// Parsing and validation of one request line (docs/protocol.md, "Requests"). A pure function with
// no I/O so that it can be unit-tested and fuzzed: any byte string gives either a request or an
// error message that names what was wrong and what to send instead.

#include <string>
#include <string_view>

namespace scp::daemon::server {

enum class RequestKind {
  status,
  estimate,
  watch,
  reset,
  excitation,
  clear_fault,
  health,
  health_ack,
  baseline_show,
  baseline_save,
  baseline_clear
};

struct ParsedRequest {
  bool ok = false;
  RequestKind kind = RequestKind::status;
  std::string error;      // when !ok: the text of the ERROR reply
  double rate_hz = 10.0;  // watch
  bool enable = true;     // watch, excitation
};

inline constexpr double kMinWatchHz = 0.1;
inline constexpr double kMaxWatchHz = 1000.0;

// Throws only std::bad_alloc.
ParsedRequest parse_request(std::string_view line);

// Mutating requests need privilege; those of the loop go through it.
bool is_mutating(RequestKind kind) noexcept;
// The mutating requests about the actuator's health, carried out by the server itself.
bool is_health_command(RequestKind kind) noexcept;
const char* request_name(RequestKind kind) noexcept;

}  // namespace scp::daemon::server
