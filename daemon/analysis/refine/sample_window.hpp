#pragma once
// The sliding window of the refinement: the newest `capacity` samples in a ring preallocated once,
// each stored once. samples() hands the fit one contiguous span: when the ring has wrapped it
// first rotates the storage in place so that the oldest sample is at slot 0 (one memmove of the
// window, once per fit on the worker thread). Storing each sample twice would avoid the rotation
// but double the largest block of the daemon's locked memory. No allocation after construction.

#include <cstddef>
#include <span>
#include <vector>

#include "refine/fit.hpp"

namespace scp::daemon::refine {

class SampleWindow {
 public:
  explicit SampleWindow(std::size_t capacity);

  void clear() noexcept { size_ = 0; }
  // Drops the oldest sample when full.
  void push(const scp::refine::WindowSample& sample) noexcept;
  void drop_oldest() noexcept {
    if (size_ > 0) --size_;
  }

  // Oldest first. Not const: may rotate the storage (the samples and their order stay the same).
  std::span<const scp::refine::WindowSample> samples() noexcept;
  std::size_t size() const noexcept { return size_; }
  std::size_t capacity() const noexcept { return capacity_; }
  bool empty() const noexcept { return size_ == 0; }
  // Callers check !empty().
  const scp::refine::WindowSample& front() const noexcept { return storage_[oldest()]; }
  // The i-th oldest sample (front() is the 0th); callers check i < size().
  const scp::refine::WindowSample& at(std::size_t i) const noexcept {
    const std::size_t slot = oldest() + i;
    return storage_[slot < capacity_ ? slot : slot - capacity_];
  }
  const scp::refine::WindowSample& back() const noexcept {
    return storage_[head_ == 0 ? capacity_ - 1 : head_ - 1];
  }
  // Loop time between the oldest and the newest sample; 0 when fewer than 2.
  double span_s() const noexcept;

 private:
  std::size_t capacity_;
  std::size_t oldest() const noexcept {
    return head_ >= size_ ? head_ - size_ : head_ + capacity_ - size_;
  }

  std::vector<scp::refine::WindowSample> storage_;  // capacity
  std::size_t head_ = 0;                            // next slot, in [0, capacity)
  std::size_t size_ = 0;
};

}  // namespace scp::daemon::refine
