// daemon/programs/cli: the conventions, the man page and the completion generated from a CLI11 App.

#include <gtest/gtest.h>

#include "daemon/programs/cli/conventions.hpp"
#include "daemon/programs/cli/roff.hpp"

namespace scp::cli {
namespace {

ProgramInfo toy_info() {
  ProgramInfo info;
  info.name = "toyctl";
  info.section = 1;
  info.summary = "a toy";
  info.synopsis = {"[--socket PATH] COMMAND"};
  info.description = {".starts with a dot", "back\\slash"};
  info.exit_codes = {{"0", "fine"}, {"64", "usage"}};
  info.see_also = {"scp-estimatord(8)"};
  info.completion_words = {{"switch", "on off"}};
  return info;
}

struct Toy {
  CLI::App app{"toy"};
  std::string socket;
  double rate = 1;
  std::string state;
  CLI::App* status = nullptr;
  CLI::App* watch = nullptr;
  CLI::App* sw = nullptr;
  explicit Toy(const ProgramInfo& info) {
    prepare(app, info);
    app.add_option("--socket", socket, "the socket")->type_name("PATH");
    status = app.add_subcommand("status", "show status");
    watch = app.add_subcommand("watch", "stream");
    watch->add_option("--rate", rate, "per second");
    sw = app.add_subcommand("switch", "on or off");
    sw->add_option("state", state, "on or off")->required();
  }
};

std::optional<int> run(Toy& toy, std::vector<const char*> args, const ProgramInfo& info) {
  args.insert(args.begin(), "toyctl");
  return parse(toy.app, static_cast<int>(args.size()), args.data(), info);
}

TEST(Cli, ClosestNamesLikelyTyposOnly) {
  const std::vector<std::string> commands{"status", "get", "watch", "clear-fault"};
  EXPECT_EQ(closest("stauts", commands), "status");
  EXPECT_EQ(closest("wacth", commands), "watch");
  EXPECT_EQ(closest("clearfault", commands), "clear-fault");
  EXPECT_EQ(closest("frobnicate", commands), "");
}

TEST(Cli, OptionsAfterTheCommandAndUsageErrors) {
  const ProgramInfo info = toy_info();
  {
    Toy toy(info);
    EXPECT_EQ(run(toy, {"status", "--socket", "/x"}, info), std::nullopt);
    EXPECT_TRUE(toy.status->parsed());
    EXPECT_EQ(toy.socket, "/x");
  }
  {
    Toy toy(info);
    EXPECT_EQ(run(toy, {"--socket", "/x", "watch", "--rate", "5"}, info), std::nullopt);
    EXPECT_EQ(toy.rate, 5);
  }
  for (const std::vector<const char*>& bad : {std::vector<const char*>{"stauts"},
                                              {},
                                              {"--bogus", "status"},
                                              {"watch", "--rate", "x"},
                                              {"switch"}}) {
    Toy toy(info);
    testing::internal::CaptureStderr();
    EXPECT_EQ(run(toy, bad, info), kExitUsage);
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_NE(err.find("toyctl: "), std::string::npos) << err;
    EXPECT_NE(err.find("Run 'toyctl --help'"), std::string::npos) << err;
  }
}

TEST(Cli, VersionAndHelpExitZero) {
  const ProgramInfo info = toy_info();
  Toy toy(info);
  testing::internal::CaptureStdout();
  EXPECT_EQ(run(toy, {"--version"}, info), 0);
  EXPECT_EQ(testing::internal::GetCapturedStdout(), std::string("toyctl ") + version() + "\n");
  Toy helped(info);
  testing::internal::CaptureStdout();
  EXPECT_EQ(run(helped, {"watch", "--help"}, info), 0);
  const std::string help = testing::internal::GetCapturedStdout();
  EXPECT_NE(help.find("Exit status:\n  0   fine\n  64  usage\n"), std::string::npos) << help;
}

TEST(Cli, ManPageHasEveryOptionAndEscapesText) {
  const ProgramInfo info = toy_info();
  Toy toy(info);
  const std::string page = man_page(toy.app, info);
  EXPECT_EQ(page.rfind(".TH TOYCTL 1 ", 0), 0U) << page.substr(0, 40);
  for (const char* part : {"\\fB\\-\\-socket\\fR \\fIPATH\\fR", "\\fBstatus\\fR",
                           "\\fB\\-\\-rate\\fR", "\\fBswitch\\fR \\fIstate\\fR", ".SH EXIT STATUS",
                           "\\&.starts with a dot", "back\\eslash", ".BR scp\\-estimatord (8)"}) {
    EXPECT_NE(page.find(part), std::string::npos) << part << " missing in\n" << page;
  }
}

TEST(Cli, CompletionListsCommandsOptionsAndWords) {
  const ProgramInfo info = toy_info();
  Toy toy(info);
  const std::string script = bash_completion(toy.app, info);
  for (const char* part : {"complete -F _toyctl toyctl", "commands=\"status watch switch\"",
                           "watch) words+=\" --help --rate\"", "on off", "--socket)"}) {
    EXPECT_NE(script.find(part), std::string::npos) << part << " missing in\n" << script;
  }
}

TEST(Cli, RoffEscape) {
  EXPECT_EQ(roff_escape("a-b\\c\n.d\n'e"), "a\\-b\\ec\n\\&.d\n\\&'e");
}

}  // namespace
}  // namespace scp::cli
