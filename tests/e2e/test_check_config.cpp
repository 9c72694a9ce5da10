// Issue 3, item 10: `scp-estimatord --check-config FILE`, what an operator runs before a restart.

#include <unistd.h>

#include <sstream>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

ProcessResult check(const std::string& path) {
  return run_process({estimatord_path(), "--check-config", path}, Seconds(20));
}

// The shipped files name the service's group and /var/lib/scp-estimator, which exist only once
// the package (or sysusers/tmpfiles) made them: on a machine without them, the only errors
// allowed are those two facts, never a key.
TEST(CheckConfig, ShippedAndGeneratedConfigsAreValid) {
  for (const char* name : {"sim.yaml", "paper.yaml", "prbs.yaml", "modbus-tcp.yaml", "can.yaml",
                           "actuators/light-stiff.yaml", "actuators/heavy-slow.yaml"}) {
    const ProcessResult r = check(std::string(SCP_E2E_SOURCE_DIR) + "/config/" + name);
    if (r.exit_code == 0) {
      EXPECT_TRUE(contains(r.out, "valid")) << r.out;
      continue;
    }
    EXPECT_EQ(r.exit_code, 78) << name << ":\n" << r.out << r.err;
    EXPECT_FALSE(contains(r.err, "configuration error")) << name << ":\n" << r.err;
    std::istringstream lines(r.err);
    for (std::string line; std::getline(lines, line);) {
      if (!contains(line, ": error: ")) continue;
      EXPECT_TRUE(contains(line, "socket.group: group 'scp-estimator'") ||
                  contains(line, "state.directory: '/var/lib/scp-estimator'"))
          << name << ": " << line;
    }
  }
  TempDir dir;
  std::filesystem::create_directories(dir.file("state"));
  write_config(dir.file("c.yaml"), base_config(dir.path()));
  const ProcessResult r = check(dir.file("c.yaml"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");  // no warning on a sound file
}

// Issue 11: yaml-cpp keeps both entries of a duplicated key and the first won silently
// ("loop: {period_s: 0.001}" then "loop: {period_s: 0.01}" was "valid ... period 0.001 s").
TEST(CheckConfig, DuplicateKeysNameBothLines) {
  TempDir dir;
  write_text(dir.file("bad.yaml"), "loop:\n  period_s: 0.001\nloop:\n  period_s: 0.01\n");
  ProcessResult r = check(dir.file("bad.yaml"));
  EXPECT_EQ(r.exit_code, 78) << r.out << r.err;
  EXPECT_TRUE(contains(r.err, "bad.yaml:3: duplicate key 'loop' (first at line 1)")) << r.err;
  write_text(dir.file("bad.yaml"),
             "safety:\n  voltage_max_v: 3.3\n  temperature_max_c: 90\n  voltage_max_v: 5\n");
  r = check(dir.file("bad.yaml"));
  EXPECT_EQ(r.exit_code, 78) << r.out << r.err;
  EXPECT_TRUE(contains(r.err, "bad.yaml:4: duplicate key 'safety.voltage_max_v' (first at line 2)"))
      << r.err;
  write_text(dir.file("bad.yaml"),
             "excitation:\n  profile: custom\n  sines:\n    - {amplitude_v: 1, amplitude_v: 2}\n");
  r = check(dir.file("bad.yaml"));
  EXPECT_EQ(r.exit_code, 78) << r.out << r.err;
  EXPECT_TRUE(contains(r.err, "duplicate key 'excitation.sines[0].amplitude_v'")) << r.err;
}

// Issue 11: --check-config passed files the daemon cannot start with.
TEST(CheckConfig, ReportsWhatWouldStopTheDaemon) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("state"));
  struct Case {
    const char* name;
    json overrides;
    std::vector<std::string> must_mention;
  };
  const std::vector<Case> cases = {
      {"missing group",
       {{"socket", {{"group", "no-such-group-scp"}}}},
       {"socket.group: group 'no-such-group-scp' does not exist", "groupadd"}},
      {"missing replay file",
       {{"driver", {{"type", "replay"}, {"replay", {{"file", dir.file("none.csv")}}}}}},
       {"driver.replay.file: cannot read", "none.csv"}},
      {"missing state directory",
       {{"state", {{"directory", dir.file("no-state")}}}},
       {"state.directory:", "no-state' does not exist"}},
      {"missing socket directory",
       {{"socket", {{"path", dir.file("no-dir/d.sock")}}}},
       {"socket.path:", "no-dir' does not exist"}},
      {"state directory is a file",
       {{"state", {{"directory", dir.file("c.yaml")}}}},
       {"state.directory:", "is not a directory"}},
  };
  for (const auto& c : cases) {
    write_config(dir.file("c.yaml"), merge_config(base_config(dir.path()), c.overrides));
    const ProcessResult r = check(dir.file("c.yaml"));
    EXPECT_EQ(r.exit_code, 78) << c.name << ":\n" << r.out << r.err;
    for (const auto& part : c.must_mention)
      EXPECT_TRUE(contains(r.err, part)) << c.name << ": '" << part << "' missing in:\n" << r.err;
    EXPECT_TRUE(contains(r.err, "c.yaml:")) << c.name << ": no file:line in " << r.err;
  }
  if (::geteuid() != 0) {  // root may write anywhere
    std::filesystem::create_directories(dir.file("ro"));
    std::filesystem::permissions(
        dir.file("ro"), std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
    write_config(dir.file("c.yaml"), merge_config(base_config(dir.path()),
                                                  {{"state", {{"directory", dir.file("ro")}}}}));
    const ProcessResult r = check(dir.file("c.yaml"));
    EXPECT_EQ(r.exit_code, 78) << r.err;
    EXPECT_TRUE(contains(r.err, "is not writable")) << r.err;
  }
}

// Issue 11: a limit in kelvin and an excitation above the voltage limit passed without a word.
TEST(CheckConfig, WarnsAboutSuspiciousValues) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("state"));
  write_config(dir.file("c.yaml"),
               merge_config(base_config(dir.path()), {{"safety", {{"temperature_max_c", 373}}}}));
  ProcessResult r = check(dir.file("c.yaml"));
  EXPECT_EQ(r.exit_code, 0) << r.err;  // valid, but said
  EXPECT_TRUE(contains(r.err, "warning")) << r.err;
  EXPECT_TRUE(contains(r.err, "safety.temperature_max_c")) << r.err;
  EXPECT_TRUE(contains(r.err, "kelvin")) << r.err;
  EXPECT_TRUE(contains(r.err, "99.85 °C")) << r.err;
  write_config(
      dir.file("c.yaml"),
      merge_config(base_config(dir.path()), {{"excitation", {{"profile", "custom"}, {"v_max", 5}}},
                                             {"safety", {{"voltage_max_v", 3.3}}}}));
  r = check(dir.file("c.yaml"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.err, "warning")) << r.err;
  EXPECT_TRUE(contains(r.err, "excitation.v_max: 5 V is above safety.voltage_max_v 3.3 V"))
      << r.err;
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
