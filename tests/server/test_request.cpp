#include <gtest/gtest.h>

#include <string>

#include "daemon/outputs/server/request.hpp"

namespace scp::daemon::server {
namespace {

void expect_error(std::string_view line, std::string_view fragment) {
  const ParsedRequest r = parse_request(line);
  EXPECT_FALSE(r.ok) << line;
  EXPECT_NE(r.error.find(fragment), std::string::npos)
      << "line: " << line << "\nerror: " << r.error;
}

TEST(Request, SimpleRequests) {
  const std::pair<const char*, RequestKind> cases[] = {
      {R"({"request":"status"})", RequestKind::status},
      {R"({"request":"estimate"})", RequestKind::estimate},
      {R"({"request":"reset"})", RequestKind::reset},
      {R"( {"request" : "clear-fault"} )", RequestKind::clear_fault},
  };
  for (const auto& [line, kind] : cases) {
    const ParsedRequest r = parse_request(line);
    ASSERT_TRUE(r.ok) << line << ": " << r.error;
    EXPECT_EQ(r.kind, kind);
  }
  EXPECT_TRUE(parse_request("{\"request\":\"status\"}\r").ok);  // CRLF clients
}

TEST(Request, Watch) {
  ParsedRequest r = parse_request(R"({"request":"watch","rate_hz":250})");
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.kind, RequestKind::watch);
  EXPECT_DOUBLE_EQ(r.rate_hz, 250.0);
  EXPECT_TRUE(r.enable);
  r = parse_request(R"({"request":"watch"})");
  ASSERT_TRUE(r.ok);
  EXPECT_DOUBLE_EQ(r.rate_hz, 10.0);
  r = parse_request(R"({"request":"watch","enable":false})");
  ASSERT_TRUE(r.ok);
  EXPECT_FALSE(r.enable);
  EXPECT_TRUE(parse_request(R"({"request":"watch","rate_hz":0.1})").ok);
  EXPECT_TRUE(parse_request(R"({"request":"watch","rate_hz":1000})").ok);
  expect_error(R"({"request":"watch","rate_hz":0.05})", "outside the allowed range [0.1, 1000]");
  expect_error(R"({"request":"watch","rate_hz":1000.5})", "outside the allowed range");
  expect_error(R"({"request":"watch","rate_hz":"fast"})",
               "'rate_hz' of request 'watch' must be a number");
  expect_error(R"({"request":"watch","rate_hz":1e999})", "malformed JSON");
  expect_error(R"({"request":"watch","enable":1})",
               "'enable' of request 'watch' must be true or false");
  expect_error(R"({"request":"watch","rate":5})",
               "unknown member 'rate' in request 'watch'; allowed members: rate_hz enable");
}

TEST(Request, Excitation) {
  ParsedRequest r = parse_request(R"({"request":"excitation","enable":false})");
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.kind, RequestKind::excitation);
  EXPECT_FALSE(r.enable);
  r = parse_request(R"({"request":"excitation","enable":true})");
  ASSERT_TRUE(r.ok);
  EXPECT_TRUE(r.enable);
  expect_error(R"({"request":"excitation"})", "needs member 'enable'");
  expect_error(R"({"request":"excitation","enable":"off"})", "must be true or false, got a string");
}

TEST(Request, Malformed) {
  expect_error("", "malformed JSON");
  expect_error("{\"request\":\"status\"", "malformed JSON");
  expect_error("status", "malformed JSON");
  expect_error("[1,2]", "must be a JSON object, got an array");
  expect_error("42", "must be a JSON object, got a number");
  expect_error("{}", "missing member 'request'");
  expect_error(R"({"request":7})", "member 'request' must be a string, got a number");
  expect_error(R"({"request":"stats"})", "unknown request 'stats'; expected one of status");
  expect_error(R"({"request":"status","verbose":true})",
               "unknown member 'verbose' in request 'status'; it takes no members");
  expect_error(R"({"request":"reset","x":1})", "it takes no members");
}

// The request is read without a DOM (request.cpp, RequestReader); these are the answers a DOM
// gave: the last of duplicated members wins, nested values are skipped whatever their keys, the
// unknown member named is the first in key order, and a number out of range is quoted as sent.
TEST(Request, ReadsLikeADocument) {
  ParsedRequest r = parse_request(R"({"request":"status","request":"estimate"})");
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.kind, RequestKind::estimate);
  expect_error(R"({"request":"status","request":{"request":"status"}})",
               "member 'request' must be a string, got an object");
  r = parse_request(R"({"request":{"x":[1,{"request":"watch"}]},"request":"watch","rate_hz":5})");
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.kind, RequestKind::watch);
  EXPECT_DOUBLE_EQ(r.rate_hz, 5.0);
  expect_error(R"({"nested":{"request":"status"}})", "missing member 'request'");
  expect_error(R"({"zeta":1,"request":"status","alpha":2})", "unknown member 'alpha'");
  expect_error(R"({"request":"excitation","enable":true,"rate_hz":3,"beta":1})",
               "unknown member 'beta'");
  expect_error(R"({"request":"excitation","enable":true,"rate_hz":3})",
               "unknown member 'rate_hz' in request 'excitation'; allowed members: enable");
  expect_error(R"({"request":"watch","rate_hz":2000})", "is 2000, outside the allowed range");
  expect_error(R"({"request":"watch","rate_hz":0.05})", "is 0.05, outside the allowed range");
  expect_error(R"({"request":"watch","rate_hz":[1]})",
               "must be a number in [0.1, 1000], got an array");
  expect_error(R"({"request":"watch","rate_hz":1e999})", "number overflow");
  expect_error(R"({"request":"watch","enable":null})", "must be true or false, got null");
  expect_error(R"({"request":"status"} {"request":"status"})", "malformed JSON");
  r = parse_request(R"({"request":"watch","enable":true,"enable":false})");
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_FALSE(r.enable);
}

// Bytes after a NUL used to be ignored by the parser ("status\0garbage" answered as status).
TEST(Request, NulAnywhereIsAnError) {
  expect_error(std::string("{\"request\":\"status\"}\0garbage", 28), "NUL byte at offset 20");
  expect_error(std::string("{\"request\":\"sta\0tus\"}", 21), "NUL byte at offset 15");
}

TEST(Request, BinaryAndInvalidUtf8NeverCrash) {
  expect_error(std::string("{\"request\":\"st\xff\xfe\"}"), "malformed JSON");
  std::string garbage;
  for (int i = 0; i < 256; ++i) garbage.push_back(static_cast<char>(i));
  expect_error(garbage, "malformed request: NUL byte at offset 0");
  // Deterministic pseudo-random bytes, including a few that start valid JSON.
  std::uint32_t x = 12345;
  for (int round = 0; round < 2000; ++round) {
    std::string line = round % 3 == 0 ? "{\"request\":" : "";
    const int length = static_cast<int>(x % 64);
    for (int i = 0; i < length; ++i) {
      x = x * 1664525U + 1013904223U;
      line.push_back(static_cast<char>(x >> 24));
    }
    const ParsedRequest r = parse_request(line);
    if (!r.ok) {
      EXPECT_FALSE(r.error.empty());
    }
  }
}

TEST(Request, Names) {
  EXPECT_STREQ(request_name(RequestKind::clear_fault), "clear-fault");
  EXPECT_TRUE(is_mutating(RequestKind::reset));
  EXPECT_TRUE(is_mutating(RequestKind::excitation));
  EXPECT_TRUE(is_mutating(RequestKind::clear_fault));
  EXPECT_FALSE(is_mutating(RequestKind::watch));
  EXPECT_FALSE(is_mutating(RequestKind::status));
  EXPECT_FALSE(is_mutating(RequestKind::estimate));
}

}  // namespace
}  // namespace scp::daemon::server
