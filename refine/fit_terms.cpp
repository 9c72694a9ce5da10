#include "refine/fit_terms.hpp"

namespace scp::refine {

const char* to_text(VoltageInterval interval) noexcept {
  switch (interval) {
    case VoltageInterval::before:
      return "before";
    case VoltageInterval::after:
      return "after";
    case VoltageInterval::estimate:
      return "estimate";
  }
  return "";
}

const char* to_text(ExtensionMode mode) noexcept {
  switch (mode) {
    case ExtensionMode::off:
      return "off";
    case ExtensionMode::on:
      return "on";
    case ExtensionMode::automatic:
      return "auto";
  }
  return "";
}

const char* to_text(InformationCriterion criterion) noexcept {
  switch (criterion) {
    case InformationCriterion::none:
      return "none";
    case InformationCriterion::bic:
      return "bic";
    case InformationCriterion::yic:
      return "yic";
  }
  return "";
}

}  // namespace scp::refine
