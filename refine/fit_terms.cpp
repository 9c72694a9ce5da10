#include "refine/fit_terms.hpp"

namespace scp::refine {

const char* to_text(VoltageInterval interval) noexcept {
  return name_of(kVoltageIntervalNames, interval);
}

const char* to_text(ExtensionMode mode) noexcept {
  return name_of(kExtensionModeNames, mode);
}

const char* to_text(InformationCriterion criterion) noexcept {
  return name_of(kInformationCriterionNames, criterion);
}

}  // namespace scp::refine
