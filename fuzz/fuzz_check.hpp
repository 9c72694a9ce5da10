#pragma once
// A property check for the fuzz targets that stays active in every build type (assert() vanishes
// under NDEBUG, and the fuzz build is Release): a violated property must crash so that libFuzzer
// saves the input.

#include <cstdio>
#include <cstdlib>

#define FUZZ_CHECK(cond)                                                                 \
  do {                                                                                   \
    if (!(cond)) {                                                                       \
      std::fprintf(stderr, "%s:%d: property violated: %s\n", __FILE__, __LINE__, #cond); \
      std::abort();                                                                      \
    }                                                                                    \
  } while (false)
