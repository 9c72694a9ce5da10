#pragma once
// Block means of a stream of samples, for the residual tests of refine/validation.hpp: a window
// of 300 000 samples kept as a few thousand means, in memory fixed at construction.

#include <Eigen/Core>
#include <cstddef>
#include <limits>
#include <vector>

namespace scp::refine {

// Blocks of fixed duration from the first sample's t, each the sum of `fields` values over its
// samples. At most `max_blocks` closed blocks are kept: when full, adjacent blocks (indices 2i,
// 2i + 1) merge and the duration doubles, so a window longer than planned costs resolution, not
// memory. A block no sample fell into (a gap in the record) is not stored: the series then runs
// on across the gap.
class BlockMeans {
 public:
  BlockMeans(double block_s, int fields, std::size_t max_blocks);

  // The sums of the block that holds t (closing the block before when t enters a new one), to
  // add one sample's `fields` values into; counts the sample. t must not decrease. Never
  // allocates. Inline for the samples inside the open block, all but one per block: the fit's
  // final pass calls it twice per sample.
  double* accumulate(double t) noexcept {
    if (t < open_until_) {
      open_count_ += 1.0;
      return open_sums_.data();
    }
    return enter(t);
  }

  double block_s() const noexcept { return block_s_; }
  int fields() const noexcept { return fields_; }
  // The block means (M × fields) of the closed blocks and the open one, and their sample counts.
  Eigen::MatrixXd means() const;
  Eigen::VectorXd counts() const;
  // Where those rows lie: the first sample's t (t0) and each row's index i, the block
  // [t0 + i·block_s, t0 + (i + 1)·block_s) at the current block_s.
  double t0() const noexcept { return t0_; }
  std::vector<long> indices() const;

 private:
  double* enter(double t) noexcept;
  void set_open_until() noexcept;
  void close_open() noexcept;
  void merge_pairs() noexcept;
  long index_of(double t) const noexcept;

  double block_s_;
  int fields_;
  std::size_t max_blocks_;
  double t0_ = 0.0;
  bool started_ = false;
  long open_index_ = 0;
  // Every t below this belongs to the open block whatever index_of()'s rounding (−∞ before the
  // first sample), so that the samples inside a block skip its division and floor.
  double open_until_ = -std::numeric_limits<double>::infinity();
  double open_count_ = 0.0;
  std::vector<double> open_sums_;
  std::vector<double> sums_;  // closed blocks, row-major (max_blocks × fields)
  std::vector<long> index_;
  std::vector<double> count_;
  std::size_t closed_ = 0;
};

}  // namespace scp::refine
