// Issue 10, audit trail: every mutating request is logged with the peer's uid, gid and pid (the
// kernel's SO_PEERCRED) and its outcome, refused ones included, and STATUS shows the last one.

#include <unistd.h>

#include <regex>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

constexpr int kNobody = 65534;

// The log lines that mention `command 'name'`.
std::vector<std::string> audit_lines(const std::string& log, const std::string& name) {
  std::vector<std::string> out;
  const std::string needle = "command '" + name + "' from ";
  std::size_t start = 0;
  for (std::size_t nl; (nl = log.find('\n', start)) != std::string::npos; start = nl + 1) {
    const std::string line = log.substr(start, nl - start);
    if (contains(line, needle)) out.push_back(line);
  }
  return out;
}

TEST(Audit, MutatingRequestsAreLoggedWithTheirCallerAndOutcome) {
  TempDir dir;
  DaemonProcess daemon(dir, {{"socket", {{"mode", "0666"}}}});
  daemon.start();

  // Root (privileged): carried out, at notice, with uid 0 and the client's pid.
  const ProcessResult off = daemon.run_ctl({"excitation", "off"});
  ASSERT_EQ(off.exit_code, 0) << off.out << off.err;
  const ProcessResult on = daemon.run_ctl({"excitation", "on"});
  ASSERT_EQ(on.exit_code, 0) << on.out << on.err;
  const ProcessResult clear = daemon.run_ctl({"clear-fault"});
  ASSERT_EQ(clear.exit_code, 0) << clear.out << clear.err;  // "no fault to clear" is not an error
  // Nobody (unprivileged): refused, still logged with its uid.
  const ProcessResult reset = daemon.run_ctl({"reset"}, /*as_nobody=*/true);
  ASSERT_EQ(reset.exit_code, 1) << reset.out << reset.err;

  const json st = daemon.status();
  ASSERT_TRUE(st.contains("last_command")) << st.dump();
  const json& last = st["last_command"];
  EXPECT_EQ(last.value("name", ""), "reset") << st.dump();
  EXPECT_EQ(last.value("outcome", ""), "refused") << st.dump();
  EXPECT_EQ(last.value("uid", -1), kNobody) << st.dump();
  EXPECT_EQ(last.value("gid", -1), kNobody) << st.dump();
  EXPECT_GT(last.value("pid", 0), 0) << st.dump();
  EXPECT_TRUE(last.contains("utc")) << st.dump();

  sleep_s(0.1);
  const std::string log = daemon.stderr_text();
  const std::regex done_by_root(
      R"(.*notice: command '[a-z -]+' from uid 0 gid 0 pid [0-9]+: done.*)");
  for (const char* name : {"excitation off", "excitation on", "clear-fault"}) {
    const auto lines = audit_lines(log, name);
    ASSERT_EQ(lines.size(), 1u) << name << " logged " << lines.size() << " times:\n" << log;
    EXPECT_TRUE(std::regex_match(lines[0], done_by_root)) << lines[0];
  }
  EXPECT_TRUE(contains(audit_lines(log, "excitation off")[0], "output held at 0 V"));
  EXPECT_TRUE(contains(audit_lines(log, "clear-fault")[0], "no fault to clear"));
  const auto refused = audit_lines(log, "reset");
  ASSERT_EQ(refused.size(), 1u) << log;
  EXPECT_TRUE(std::regex_match(
      refused[0],
      std::regex(R"(.*warning: command 'reset' from uid 65534 gid 65534 pid [0-9]+: refused.*)")))
      << refused[0];
}

// A refused clear-fault (the cause persists) is logged as failed, with the loop's reason.
TEST(Audit, ClearFaultRefusedByTheLoopIsLoggedAsFailed) {
  TempDir dir;
  DaemonProcess daemon(
      dir,
      {{"driver",
        {{"sim",
          {{"fault", {{"kind", "nan_temperature"}, {"start_s", 0.5}, {"duration_s", 30.0}}}}}}}});
  daemon.start();
  ASSERT_TRUE(daemon.wait_status([](const json& s) { return s.value("state", "") == "fault"; },
                                 Seconds(10)));
  const ProcessResult clear = daemon.run_ctl({"clear-fault"});
  EXPECT_EQ(clear.exit_code, 1) << clear.out << clear.err;
  const json st = daemon.status();
  EXPECT_EQ(st["last_command"].value("outcome", ""), "failed") << st.dump();
  EXPECT_EQ(st["last_command"].value("uid", -1), 0) << st.dump();
  sleep_s(0.1);
  const auto lines = audit_lines(daemon.stderr_text(), "clear-fault");
  ASSERT_EQ(lines.size(), 1u) << daemon.stderr_text();
  EXPECT_TRUE(contains(lines[0], "warning: ")) << lines[0];
  EXPECT_TRUE(contains(lines[0], ": failed (")) << lines[0];
  EXPECT_TRUE(contains(lines[0], "temperature")) << lines[0];
}

}  // namespace
}  // namespace scp::test
