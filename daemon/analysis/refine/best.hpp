#pragma once
// The estimate the daemon recommends (ESTIMATE "best", docs/protocol.md): one whose validation
// passed, or none, with the reason and what to do (issue 28).

#include <string>

#include "daemon/analysis/refine/refined_view.hpp"

namespace scp::daemon::refine {

enum class Best : std::uint8_t { refined, paper, none };
const char* best_name(Best best) noexcept;  // "refined", "paper", "none"

struct BestChoice {
  Best best = Best::paper;
  std::string reason;  // why not a better one; empty when `refined`
};

// A block passes when its verdict is adequate or noise_colored (θ̂ fine).
bool block_passed(const scp::refine::BlockReport& block) noexcept;
bool passed(const scp::refine::ValidationReport& report) noexcept;

// The choice alone, without allocating (the recorder's thread writes it on every row).
Best best_of(const RefinedView* v, double now_t) noexcept;

// `refined` when refined_is_best, its validation passed for both blocks and its voltage interval
// is not in doubt (interval_in_doubt: undetermined, or contradicted by the data); else `paper`
// when the
// paper law's prediction passed on the same window; else `none`. Before any fit (v null or not
// valid) the paper law is all there is and nothing has tested it: `paper`, with that reason.
BestChoice best_estimate(const RefinedView* v, double now_t);

// Why an undetermined or contradicted interval keeps `best` off the refined estimate, and the
// remedy.
std::string interval_advice(const RefinedView& v);

// One line on a failed validation: the block, its decisive test with its effect, and the remedy.
std::string failure_advice(const scp::refine::ValidationReport& report);

}  // namespace scp::daemon::refine
