#include "daemon/outputs/server/request.hpp"

#include <array>
#include <cmath>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

namespace scp::daemon::server {
namespace {

using nlohmann::json;

constexpr const char* kRequestList =
    "status, estimate, watch, reset, excitation, clear-fault, health, health-ack, "
    "baseline-show, baseline-save, baseline-clear";

struct Entry {
  const char* name;
  RequestKind kind;
};
constexpr std::array<Entry, 11> kRequests{{
    {"status", RequestKind::status},
    {"estimate", RequestKind::estimate},
    {"watch", RequestKind::watch},
    {"reset", RequestKind::reset},
    {"excitation", RequestKind::excitation},
    {"clear-fault", RequestKind::clear_fault},
    {"health", RequestKind::health},
    {"health-ack", RequestKind::health_ack},
    {"baseline-show", RequestKind::baseline_show},
    {"baseline-save", RequestKind::baseline_save},
    {"baseline-clear", RequestKind::baseline_clear},
}};

ParsedRequest fail(std::string message) {
  ParsedRequest out;
  out.error = std::move(message);
  return out;
}

// Keys are echoed back in messages; keep them short and valid UTF-8 (they came through the parser,
// so they are valid already).
std::string quoted(const std::string& key) {
  constexpr std::size_t kMax = 40;
  return "'" + (key.size() > kMax ? key.substr(0, kMax) + "..." : key) + "'";
}

// One top-level member's value, as much of it as the checks below need.
struct Value {
  bool present = false;
  const char* type = "null";  // as an error message names it
  bool boolean = false;
  json number;       // a number keeps its JSON type, so an error quotes it as it was sent
  std::string text;  // a string
};

// The request object read through nlohmann's SAX interface instead of into a DOM: every request
// line passes here, and the DOM's map nodes and strings were most of the parse's cost (perf,
// README "Results"). It keeps what a DOM would answer: the last of duplicated members (the DOM's
// operator[] overwrites), and of the members outside {request, enable, rate_hz} the first in the
// DOM's std::map order, the one check_members reported. Nested arrays and objects are skipped.
class RequestReader {
 public:
  const char* top_level_type() const noexcept { return top_type_; }
  const Value& request() const noexcept { return request_; }
  const Value& enable() const noexcept { return enable_; }
  const Value& rate_hz() const noexcept { return rate_hz_; }
  const std::string& error() const noexcept { return error_; }
  // The first member, in std::map order, that `request` does not take.
  std::optional<std::string> first_unknown(std::initializer_list<const char*> allowed) const {
    std::optional<std::string> first = other_;
    const auto consider = [&](const Value& value, const char* key) {
      if (!value.present) return;
      for (const char* name : allowed)
        if (std::string_view(name) == key) return;
      if (!first || std::string(key) < *first) first = key;
    };
    consider(enable_, "enable");
    consider(rate_hz_, "rate_hz");
    return first;
  }

  // The SAX callbacks (nlohmann::json_sax); returning false stops the parse.
  bool null() { return scalar("null"); }
  bool boolean(bool b) {
    if (Value* v = member(); v != nullptr) v->boolean = b;
    return scalar("a boolean");
  }
  bool number_integer(json::number_integer_t n) { return number(json(n)); }
  bool number_unsigned(json::number_unsigned_t n) { return number(json(n)); }
  bool number_float(json::number_float_t n, const json::string_t& /*raw*/) {
    return number(json(n));
  }
  bool string(json::string_t& text) {
    if (Value* v = member(); v != nullptr) v->text = text;
    return scalar("a string");
  }
  bool binary(json::binary_t& /*binary*/) { return scalar("a binary"); }  // not in JSON text
  bool start_object(std::size_t /*size*/) { return open("an object"); }
  bool end_object() { return close(); }
  bool start_array(std::size_t /*size*/) { return open("an array"); }
  bool end_array() { return close(); }
  bool key(json::string_t& name) {
    if (depth_ != 1) return true;
    current_ = nullptr;
    if (name == "request") {
      current_ = &request_;
    } else if (name == "enable") {
      current_ = &enable_;
    } else if (name == "rate_hz") {
      current_ = &rate_hz_;
    } else if (!other_ || name < *other_) {
      other_ = name;
    }
    return true;
  }
  bool parse_error(std::size_t /*position*/, const std::string& /*last_token*/,
                   const nlohmann::detail::exception& error) {
    error_ = error.what();  // the same text json::parse would have thrown
    return false;
  }

 private:
  // The member whose value the current event is, or nullptr (nested, or not one we keep).
  Value* member() const noexcept { return depth_ == 1 ? current_ : nullptr; }
  bool number(json value) {
    if (Value* v = member(); v != nullptr) v->number = std::move(value);
    return scalar("a number");
  }
  bool scalar(const char* type) {
    if (depth_ == 0) top_type_ = type;
    if (Value* v = member(); v != nullptr) {
      v->present = true;
      v->type = type;
    }
    return true;
  }
  bool open(const char* type) {
    scalar(type);
    ++depth_;
    return true;
  }
  bool close() {
    --depth_;
    return true;
  }

  int depth_ = 0;
  const char* top_type_ = "null";
  Value* current_ = nullptr;
  Value request_, enable_, rate_hz_;
  std::optional<std::string> other_;
  std::string error_;
};

// Unknown members are rejected so that a typo ("rate" for "rate_hz") is reported, not ignored.
std::string check_members(const RequestReader& reader, const char* request,
                          std::initializer_list<const char*> allowed) {
  const std::optional<std::string> unknown = reader.first_unknown(allowed);
  if (!unknown) return {};
  std::string message = "unknown member " + quoted(*unknown) + " in request '" + request + "'";
  if (allowed.size() == 0) return message + "; it takes no members";
  message += "; allowed members:";
  for (const char* name : allowed) message += std::string(" ") + name;
  return message;
}

}  // namespace

const char* request_name(RequestKind kind) noexcept {
  for (const Entry& entry : kRequests)
    if (entry.kind == kind) return entry.name;
  return "?";
}

bool is_mutating(RequestKind kind) noexcept {
  return kind == RequestKind::reset || kind == RequestKind::excitation ||
         kind == RequestKind::clear_fault || is_health_command(kind);
}

bool is_health_command(RequestKind kind) noexcept {
  return kind == RequestKind::health_ack || kind == RequestKind::baseline_save ||
         kind == RequestKind::baseline_clear;
}

ParsedRequest parse_request(std::string_view line) {
  // A NUL would end the text for a C-string reader; no valid JSON request contains one.
  if (const auto nul = line.find('\0'); nul != std::string_view::npos)
    return fail("malformed request: NUL byte at offset " + std::to_string(nul) +
                "; send one JSON object per line, e.g. {\"request\":\"status\"}");
  // The framing layer strips '\n'; a CRLF client leaves '\r', which JSON treats as whitespace.
  RequestReader reader;
  if (!json::sax_parse(line.begin(), line.end(), &reader))  // parse_error, or 1e999's overflow
    // The parser's text names the byte offset and what it expected; that is the useful part.
    return fail("malformed JSON: " + reader.error() +
                "; send one JSON object per line, e.g. {\"request\":\"status\"}");
  if (std::string_view(reader.top_level_type()) != "an object")
    return fail(std::string("a request must be a JSON object, got ") + reader.top_level_type() +
                "; e.g. {\"request\":\"status\"}");
  const Value& request = reader.request();
  if (!request.present)
    return fail(std::string("missing member 'request'; expected one of ") + kRequestList);
  if (request.type != std::string_view("a string"))
    return fail(std::string("member 'request' must be a string, got ") + request.type +
                "; expected one of " + kRequestList);
  const std::string& name = request.text;

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
    case RequestKind::health:
    case RequestKind::health_ack:
    case RequestKind::baseline_show:
    case RequestKind::baseline_save:
    case RequestKind::baseline_clear:
      problem = check_members(reader, request_name(out.kind), {});
      break;
    case RequestKind::watch:
      problem = check_members(reader, "watch", {"rate_hz", "enable"});
      break;
    case RequestKind::excitation:
      problem = check_members(reader, "excitation", {"enable"});
      break;
  }
  if (!problem.empty()) return fail(problem);

  if (out.kind == RequestKind::watch || out.kind == RequestKind::excitation) {
    const Value& enable = reader.enable();
    if (!enable.present) {
      if (out.kind == RequestKind::excitation)
        return fail(
            "request 'excitation' needs member 'enable' (true or false), e.g. "
            "{\"request\":\"excitation\",\"enable\":false}");
    } else if (enable.type != std::string_view("a boolean")) {
      return fail(std::string("member 'enable' of request '") + request_name(out.kind) +
                  "' must be true or false, got " + enable.type);
    } else {
      out.enable = enable.boolean;
    }
  }

  if (out.kind == RequestKind::watch) {
    const Value& rate_hz = reader.rate_hz();
    if (rate_hz.present) {
      if (rate_hz.type != std::string_view("a number"))
        return fail(std::string("member 'rate_hz' of request 'watch' must be a number in [0.1, "
                                "1000], got ") +
                    rate_hz.type);
      const double rate = rate_hz.number.get<double>();
      if (!std::isfinite(rate) || rate < kMinWatchHz || rate > kMaxWatchHz)
        return fail("member 'rate_hz' of request 'watch' is " + rate_hz.number.dump() +
                    ", outside the allowed range [0.1, 1000] Hz");
      out.rate_hz = rate;
    }
  }
  out.ok = true;
  return out;
}

}  // namespace scp::daemon::server
