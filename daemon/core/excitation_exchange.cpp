#include "daemon/core/excitation_exchange.hpp"

#include <algorithm>

namespace scp::daemon {

bool ExcitationExchange::offer(std::unique_ptr<excitation::Excitation> next, std::int8_t enabled) {
  collect();
  if (next && owned_.size() >= kMaxOwned) return false;
  ExcitationUpdate update{next.get(), enabled};
  if (!incoming_.try_push(update)) return false;
  if (next) owned_.push_back(std::move(next));
  return true;
}

void ExcitationExchange::collect() {
  const excitation::Excitation* old = nullptr;
  while (retired_.try_pop(old)) {
    owned_.erase(std::remove_if(owned_.begin(), owned_.end(),
                                [old](const auto& owned) { return owned.get() == old; }),
                 owned_.end());
  }
}

}  // namespace scp::daemon
