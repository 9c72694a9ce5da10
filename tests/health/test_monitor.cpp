// The health monitor (placeholder until its tests land in the next commit).
#include <gtest/gtest.h>
