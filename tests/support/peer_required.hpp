#pragma once
// A test whose peer program or package is missing skips on a developer's machine but FAILS under
// CI=true: a CI run must never pass by not running its peer tests (issue 9, part 5).

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>

namespace scp::test {

inline bool in_ci() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::strcmp(ci, "true") == 0;
}

}  // namespace scp::test

// Use as a statement in a TEST body: returns from it either way.
#define SCP_PEER_MISSING(message)                                              \
  do {                                                                         \
    if (::scp::test::in_ci()) {                                                \
      GTEST_FAIL() << "CI=true and a peer is missing (scripts/setup installs " \
                      "it): "                                                  \
                   << message;                                                 \
    } else {                                                                   \
      GTEST_SKIP() << message;                                                 \
    }                                                                          \
  } while (false)
