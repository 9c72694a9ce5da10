#pragma once
// scp-estimator.yaml(5), generated from the key declarations (like docs/configuration.md).

#include <string>
#include <string_view>

namespace scp::config {

// The man page (roff) of every key: `scp-estimatord --print-config-reference=man`.
std::string config_reference_man(std::string_view version);

}  // namespace scp::config
