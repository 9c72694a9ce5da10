#include "refine/block_means.hpp"

#include <algorithm>
#include <cmath>

namespace scp::refine {

BlockMeans::BlockMeans(double block_s, int fields, std::size_t max_blocks)
    : block_s_(block_s > 0.0 && std::isfinite(block_s) ? block_s : 1.0),
      fields_(std::max(fields, 1)),
      max_blocks_(std::max<std::size_t>(2, max_blocks)),
      open_sums_(static_cast<std::size_t>(fields_), 0.0),
      sums_(max_blocks_ * static_cast<std::size_t>(fields_), 0.0),
      index_(max_blocks_, 0),
      count_(max_blocks_, 0.0) {}

long BlockMeans::index_of(double t) const noexcept {
  // A t that goes back (or is not a number) stays in the open block.
  const double b = std::floor((t - t0_) / block_s_);
  return std::isfinite(b) ? std::max(open_index_, static_cast<long>(b)) : open_index_;
}

void BlockMeans::set_open_until() noexcept {
  // index_of(t) ≤ open_index_ for every t − t0 below the block's end (open_index_ + 1)·block_s
  // less the rounding of t − t0, of the division and of this sum, each within ε of |t0| + the
  // end: 64ε of it leaves room to spare (a clock counting from the epoch included).
  const double end = static_cast<double>(open_index_ + 1) * block_s_;
  const double margin = 64.0 * std::numeric_limits<double>::epsilon() * (std::abs(t0_) + end);
  open_until_ =
      std::isfinite(end) ? t0_ + (end - margin) : -std::numeric_limits<double>::infinity();
}

double* BlockMeans::enter(double t) noexcept {
  if (!started_) {
    started_ = true;
    t0_ = t;
  }
  long index = index_of(t);
  if (index != open_index_) {
    close_open();
    index = index_of(t);  // the duration may have doubled
    if (closed_ > 0 && index_[closed_ - 1] == index) {
      // A merge put the block t belongs to among the closed ones: it is open again.
      --closed_;
      const double* row = &sums_[closed_ * static_cast<std::size_t>(fields_)];
      std::copy(row, row + fields_, open_sums_.begin());
      open_count_ = count_[closed_];
    }
    open_index_ = index;
  }
  set_open_until();
  open_count_ += 1.0;
  return open_sums_.data();
}

void BlockMeans::close_open() noexcept {
  if (open_count_ == 0.0) return;
  // Blocks shorter than the samples' spacing leave every other index empty, and one merge of
  // pairs may then join none: merge until there is room (each halves every index, so they meet).
  while (closed_ == max_blocks_) {
    merge_pairs();
    open_index_ /= 2;
  }
  const auto f = static_cast<std::size_t>(fields_);
  if (closed_ > 0 && index_[closed_ - 1] == open_index_) {
    double* row = &sums_[(closed_ - 1) * f];
    for (std::size_t j = 0; j < f; ++j) row[j] += open_sums_[j];
    count_[closed_ - 1] += open_count_;
  } else {
    std::copy(open_sums_.begin(), open_sums_.end(), &sums_[closed_ * f]);
    index_[closed_] = open_index_;
    count_[closed_] = open_count_;
    ++closed_;
  }
  std::fill(open_sums_.begin(), open_sums_.end(), 0.0);
  open_count_ = 0.0;
}

void BlockMeans::merge_pairs() noexcept {
  const auto f = static_cast<std::size_t>(fields_);
  std::size_t out = 0;
  for (std::size_t i = 0; i < closed_; ++i) {
    const long merged = index_[i] / 2;
    if (out > 0 && index_[out - 1] == merged) {
      for (std::size_t j = 0; j < f; ++j) sums_[(out - 1) * f + j] += sums_[i * f + j];
      count_[out - 1] += count_[i];
      continue;
    }
    if (out != i) std::copy(&sums_[i * f], &sums_[i * f] + f, &sums_[out * f]);
    index_[out] = merged;
    count_[out] = count_[i];
    ++out;
  }
  closed_ = out;
  block_s_ *= 2.0;
}

Eigen::MatrixXd BlockMeans::means() const {
  const auto rows = static_cast<Eigen::Index>(closed_ + (open_count_ > 0.0 ? 1 : 0));
  Eigen::MatrixXd m(rows, fields_);
  const auto f = static_cast<std::size_t>(fields_);
  for (std::size_t i = 0; i < closed_; ++i)
    for (std::size_t j = 0; j < f; ++j)
      m(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = sums_[i * f + j] / count_[i];
  if (open_count_ > 0.0)
    for (std::size_t j = 0; j < f; ++j)
      m(rows - 1, static_cast<Eigen::Index>(j)) = open_sums_[j] / open_count_;
  return m;
}

Eigen::VectorXd BlockMeans::counts() const {
  const auto rows = static_cast<Eigen::Index>(closed_ + (open_count_ > 0.0 ? 1 : 0));
  Eigen::VectorXd c(rows);
  for (std::size_t i = 0; i < closed_; ++i) c[static_cast<Eigen::Index>(i)] = count_[i];
  if (open_count_ > 0.0) c[rows - 1] = open_count_;
  return c;
}

std::vector<long> BlockMeans::indices() const {
  std::vector<long> out(index_.begin(), index_.begin() + static_cast<long>(closed_));
  if (open_count_ > 0.0) out.push_back(open_index_);
  return out;
}

}  // namespace scp::refine
