#pragma once
// The whole content of a gzip file, for tests of compressed recordings (link ZLIB::ZLIB).

#include <gtest/gtest.h>
#include <zlib.h>

#include <string>

namespace scp::test {

inline std::string gunzip(const std::string& path) {
  gzFile f = gzopen(path.c_str(), "rb");
  EXPECT_NE(f, nullptr) << path;
  if (f == nullptr) return {};
  std::string out;
  char buf[65536];
  int n = 0;
  while ((n = gzread(f, buf, sizeof buf)) > 0) out.append(buf, static_cast<std::size_t>(n));
  int code = Z_OK;
  gzerror(f, &code);
  EXPECT_EQ(code, Z_OK) << path;
  gzclose(f);
  return out;
}

}  // namespace scp::test
