#include "daemon/server/request.hpp"

#include <array>
#include <cmath>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <string>

namespace scp::daemon::server {
namespace {

using nlohmann::json;

constexpr const char* kRequestList = "status, estimate, watch, reset, excitation, clear-fault";

struct Entry {
  const char* name;
  RequestKind kind;
};
constexpr std::array<Entry, 6> kRequests{{
    {"status", RequestKind::status},
    {"estimate", RequestKind::estimate},
    {"watch", RequestKind::watch},
    {"reset", RequestKind::reset},
    {"excitation", RequestKind::excitation},
    {"clear-fault", RequestKind::clear_fault},
}};

ParsedRequest fail(std::string message) {
  ParsedRequest out;
  out.error = std::move(message);
  return out;
}

const char* type_name(const json& value) {
  if (value.is_null()) return "null";
  if (value.is_boolean()) return "a boolean";
  if (value.is_number()) return "a number";
  if (value.is_string()) return "a string";
  if (value.is_array()) return "an array";
  return "an object";
}

// Keys are echoed back in messages; keep them short and valid UTF-8 (they came through the parser,
// so they are valid already).
std::string quoted(const std::string& key) {
  constexpr std::size_t kMax = 40;
  return "'" + (key.size() > kMax ? key.substr(0, kMax) + "..." : key) + "'";
}

// Unknown members are rejected so that a typo ("rate" for "rate_hz") is reported, not ignored.
std::string check_members(const json& object, const char* request,
                          std::initializer_list<const char*> allowed) {
  for (const auto& item : object.items()) {
    if (item.key() == "request") continue;
    bool known = false;
    for (const char* name : allowed) known = known || item.key() == name;
    if (known) continue;
    std::string message = "unknown member " + quoted(item.key()) + " in request '" + request + "'";
    if (allowed.size() == 0) return message + "; it takes no members";
    message += "; allowed members:";
    for (const char* name : allowed) message += std::string(" ") + name;
    return message;
  }
  return {};
}

}  // namespace

const char* request_name(RequestKind kind) noexcept {
  for (const Entry& entry : kRequests)
    if (entry.kind == kind) return entry.name;
  return "?";
}

bool is_mutating(RequestKind kind) noexcept {
  return kind == RequestKind::reset || kind == RequestKind::excitation ||
         kind == RequestKind::clear_fault;
}

ParsedRequest parse_request(std::string_view line) {
  // A NUL would end the text for a C-string reader; no valid JSON request contains one.
  if (const auto nul = line.find('\0'); nul != std::string_view::npos)
    return fail("malformed request: NUL byte at offset " + std::to_string(nul) +
                "; send one JSON object per line, e.g. {\"request\":\"status\"}");
  // The framing layer strips '\n'; a CRLF client leaves '\r', which JSON treats as whitespace.
  json doc;
  try {
    doc = json::parse(line.begin(), line.end());
  } catch (const json::exception& error) {  // parse_error, or out_of_range for 1e999
    // The parser's text names the byte offset and what it expected; that is the useful part.
    return fail(std::string("malformed JSON: ") + error.what() +
                "; send one JSON object per line, e.g. {\"request\":\"status\"}");
  }
  if (!doc.is_object())
    return fail(std::string("a request must be a JSON object, got ") + type_name(doc) +
                "; e.g. {\"request\":\"status\"}");
  const auto request_it = doc.find("request");
  if (request_it == doc.end())
    return fail(std::string("missing member 'request'; expected one of ") + kRequestList);
  if (!request_it->is_string())
    return fail(std::string("member 'request' must be a string, got ") + type_name(*request_it) +
                "; expected one of " + kRequestList);
  const std::string& name = request_it->get_ref<const std::string&>();

  ParsedRequest out;
  bool found = false;
  for (const Entry& entry : kRequests) {
    if (name == entry.name) {
      out.kind = entry.kind;
      found = true;
    }
  }
  if (!found) return fail("unknown request " + quoted(name) + "; expected one of " + kRequestList);

  std::string problem;
  switch (out.kind) {
    case RequestKind::status:
    case RequestKind::estimate:
    case RequestKind::reset:
    case RequestKind::clear_fault:
      problem = check_members(doc, request_name(out.kind), {});
      break;
    case RequestKind::watch:
      problem = check_members(doc, "watch", {"rate_hz", "enable"});
      break;
    case RequestKind::excitation:
      problem = check_members(doc, "excitation", {"enable"});
      break;
  }
  if (!problem.empty()) return fail(problem);

  if (out.kind == RequestKind::watch || out.kind == RequestKind::excitation) {
    const auto enable_it = doc.find("enable");
    if (enable_it == doc.end()) {
      if (out.kind == RequestKind::excitation)
        return fail(
            "request 'excitation' needs member 'enable' (true or false), e.g. "
            "{\"request\":\"excitation\",\"enable\":false}");
    } else if (!enable_it->is_boolean()) {
      return fail(std::string("member 'enable' of request '") + request_name(out.kind) +
                  "' must be true or false, got " + type_name(*enable_it));
    } else {
      out.enable = enable_it->get<bool>();
    }
  }

  if (out.kind == RequestKind::watch) {
    const auto rate_it = doc.find("rate_hz");
    if (rate_it != doc.end()) {
      if (!rate_it->is_number())
        return fail(std::string("member 'rate_hz' of request 'watch' must be a number in [0.1, "
                                "1000], got ") +
                    type_name(*rate_it));
      const double rate = rate_it->get<double>();
      if (!std::isfinite(rate) || rate < kMinWatchHz || rate > kMaxWatchHz)
        return fail("member 'rate_hz' of request 'watch' is " + rate_it->dump() +
                    ", outside the allowed range [0.1, 1000] Hz");
      out.rate_hz = rate;
    }
  }
  out.ok = true;
  return out;
}

}  // namespace scp::daemon::server
