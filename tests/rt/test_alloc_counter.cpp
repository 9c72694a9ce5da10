#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <memory>
#include <thread>
#include <vector>

#include "daemon/core/rt/alloc_counter.hpp"

namespace scp::rt::alloc {
namespace {

// Stores pointers where the optimiser cannot see, so new/delete pairs are not elided.
void* volatile g_sink = nullptr;

class AllocCounter : public ::testing::Test {
 protected:
  void SetUp() override { arm(); }
  void TearDown() override { disarm(); }
};

TEST_F(AllocCounter, CatchesScalarArrayAndAlignedAllocations) {
  const ScopedAllocationCount count;
  const auto before_bytes = bytes_allocated_on_this_thread();
  const auto before_frees = deallocations_on_this_thread();
  {
    auto a = std::make_unique<int>(1);
    g_sink = a.get();
    auto b = std::make_unique<double[]>(10);
    g_sink = b.get();
    struct alignas(64) Wide {
      double d[8];
    };
    auto c = std::make_unique<Wide>();
    g_sink = c.get();
  }
  EXPECT_EQ(count.count(), 3U);
  EXPECT_EQ(deallocations_on_this_thread() - before_frees, 3U);
  EXPECT_GE(bytes_allocated_on_this_thread() - before_bytes,
            sizeof(int) + 10 * sizeof(double) + 64);
}

TEST_F(AllocCounter, CountsAVectorGrowing) {
  const ScopedAllocationCount count;
  std::vector<int> v;
  for (int i = 0; i < 100; ++i) v.push_back(i);
  g_sink = v.data();
  EXPECT_GE(count.count(), 2U);  // several reallocations, however the growth factor goes
}

TEST_F(AllocCounter, OtherThreadsDoNotCountHere) {
  const ScopedAllocationCount count;
  const auto total_before = allocations_total();
  std::uint64_t theirs = 0;
  // The std::thread's own state is allocated here, on this thread: measure it before, not inside.
  std::thread t([&] {
    const ScopedAllocationCount mine;
    auto p = std::make_unique<long>(3);
    g_sink = p.get();
    theirs = mine.count();
  });
  const auto after_spawn = count.count();
  t.join();
  EXPECT_EQ(theirs, 1U);
  EXPECT_EQ(count.count(), after_spawn);
  EXPECT_GE(allocations_total() - total_before, 1U + after_spawn);
}

TEST(AllocCounterDisarmed, CountsNothingWhileDisarmed) {
  disarm();
  const ScopedAllocationCount count;
  auto p = std::make_unique<int>(5);
  g_sink = p.get();
  EXPECT_EQ(count.count(), 0U);
}

TEST_F(AllocCounter, FixedSizeEigenComputationAllocatesNothing) {
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  disarm();
  Mat6 a = Mat6::Random();
  Vec6 b = Vec6::Random();
  arm();
  const ScopedAllocationCount count;
  // The estimator's kind of work: form an SPD matrix, factor it, solve, integrate.
  const Mat6 spd = a * a.transpose() + Mat6::Identity();
  const Eigen::LLT<Mat6> llt(spd);
  const Vec6 x = llt.solve(b);
  const Mat6 next = 0.99 * spd + x * x.transpose();
  EXPECT_EQ(count.count(), 0U);
  EXPECT_TRUE((spd * x - b).norm() < 1e-9 * (1.0 + b.norm()));
  EXPECT_TRUE(next.allFinite());
}

TEST_F(AllocCounter, DynamicEigenIsCaught) {
  // Eigen's dynamic matrices call malloc, not operator new.
  if (!counts_malloc()) GTEST_SKIP() << "sanitizer build: malloc is not counted";
  const ScopedAllocationCount count;
  Eigen::MatrixXd m = Eigen::MatrixXd::Identity(6, 6);
  g_sink = m.data();
  EXPECT_GE(count.count(), 1U);
}

}  // namespace
}  // namespace scp::rt::alloc
