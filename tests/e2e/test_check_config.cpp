// Issue 3, item 10: `scp-estimatord --check-config FILE`, what an operator runs before a restart.

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

ProcessResult check(const std::string& path) {
  return run_process({estimatord_path(), "--check-config", path}, Seconds(20));
}

TEST(CheckConfig, ShippedAndGeneratedConfigsAreValid) {
  for (const char* name : {"sim.yaml", "paper.yaml", "modbus-tcp.yaml", "can.yaml"}) {
    const ProcessResult r = check(std::string(SCP_E2E_SOURCE_DIR) + "/config/" + name);
    EXPECT_EQ(r.exit_code, 0) << name << ":\n" << r.out << r.err;
    EXPECT_TRUE(contains(r.out, "valid")) << r.out;
  }
  TempDir dir;
  write_config(dir.file("c.yaml"), base_config(dir.path()));
  EXPECT_EQ(check(dir.file("c.yaml")).exit_code, 0);
}

struct BadFile {
  const char* name;
  const char* yaml;
  std::vector<const char*> must_mention;
};

// Each bad file: exit code 78 (EX_CONFIG, so systemd does not restart-loop) and a message that
// names the key and its line (FILE:LINE: key: problem), so the operator knows where to look.
TEST(CheckConfig, BadFilesNameTheKeyAndLine) {
  const std::vector<BadFile> cases = {
      {"out of range", "loop:\n  period_s: 5\n", {"period_s", "bad.yaml:2:"}},
      {"unknown key",
       "safety:\n  voltage_max_v: 3.0\n  volage_min_v: 1\n",
       {"volage_min_v", "bad.yaml:3:"}},
      {"wrong type",
       "log_level: info\nsocket:\n  max_clients: many\n",
       {"max_clients", "bad.yaml:3:"}},
      {"bad choice",
       "driver:\n  type: sim\n  sim:\n    fault:\n      kind: melted\n",
       {"kind", "bad.yaml:5:", "nan_temperature"}},
      {"bad stuck timeout", "safety:\n  stuck_timeout_s: -1\n", {"stuck_timeout_s", "bad.yaml:2:"}},
      {"not YAML", "loop: {period_s: [\n", {"bad.yaml:"}},
  };
  TempDir dir;
  for (const auto& c : cases) {
    write_text(dir.file("bad.yaml"), c.yaml);
    const ProcessResult r = check(dir.file("bad.yaml"));
    EXPECT_EQ(r.exit_code, 78) << c.name << ":\n" << r.out << r.err;
    for (const char* part : c.must_mention) {
      EXPECT_TRUE(contains(r.err, part)) << c.name << ": '" << part << "' missing in:\n" << r.err;
    }
  }
  const ProcessResult missing = check(dir.file("does-not-exist.yaml"));
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_TRUE(contains(missing.err, "does-not-exist.yaml")) << missing.err;
}

}  // namespace
}  // namespace scp::test
