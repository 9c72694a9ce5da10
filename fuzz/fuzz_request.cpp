// Fuzzes the socket request parser (docs/protocol.md, "Requests"): any byte string, including
// invalid UTF-8 and deep JSON nesting, must give a request or an error naming the problem, and the
// ERROR reply built from that message must serialise (invalid UTF-8 echoed back must not throw).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "daemon/outputs/server/render.hpp"
#include "daemon/outputs/server/request.hpp"
#include "fuzz/fuzz_check.hpp"

namespace server = scp::daemon::server;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view line(reinterpret_cast<const char*>(data), size);
  const server::ParsedRequest request = server::parse_request(line);
  if (!request.ok) {
    FUZZ_CHECK(!request.error.empty());
    const std::string reply = server::render_error(request.error);
    FUZZ_CHECK(!reply.empty() && reply.back() == '\n');
    return 0;
  }
  FUZZ_CHECK(request.error.empty());
  if (request.kind == server::RequestKind::watch) {
    FUZZ_CHECK(std::isfinite(request.rate_hz));
    FUZZ_CHECK(request.rate_hz >= server::kMinWatchHz && request.rate_hz <= server::kMaxWatchHz);
  }
  FUZZ_CHECK(server::request_name(request.kind)[0] != '?');
  return 0;
}
