#include "daemon/analysis/refine/sample_window.hpp"

#include <algorithm>

namespace scp::daemon::refine {

SampleWindow::SampleWindow(std::size_t capacity)
    : capacity_(std::max<std::size_t>(capacity, 1)), storage_(capacity_) {}

void SampleWindow::push(const scp::refine::WindowSample& sample) noexcept {
  storage_[head_] = sample;
  head_ = head_ + 1 == capacity_ ? 0 : head_ + 1;
  if (size_ < capacity_) ++size_;
}

std::span<const scp::refine::WindowSample> SampleWindow::samples() noexcept {
  const std::size_t first = oldest();
  if (first + size_ <= capacity_) return {storage_.data() + first, size_};
  // Wrapped: bring the oldest sample to slot 0; the order of the samples is unchanged.
  std::rotate(storage_.begin(), storage_.begin() + static_cast<std::ptrdiff_t>(first),
              storage_.end());
  head_ = size_ == capacity_ ? 0 : size_;
  return {storage_.data(), size_};
}

double SampleWindow::span_s() const noexcept {
  return size_ < 2 ? 0.0 : back().t - front().t;
}

}  // namespace scp::daemon::refine
