// The journal's priority prefixes (daemon/outputs/log/journal_log.hpp).

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <string>

#include "daemon/outputs/log/journal_log.hpp"

namespace scp::daemon::log {
namespace {

TEST(JournalLog, PrioritiesFollowSdDaemon) {
  EXPECT_EQ(journal_priority(spdlog::level::critical, false), Priority::crit);
  EXPECT_EQ(journal_priority(spdlog::level::err, false), Priority::err);
  EXPECT_EQ(journal_priority(spdlog::level::warn, false), Priority::warning);
  EXPECT_EQ(journal_priority(spdlog::level::info, true), Priority::notice);
  EXPECT_EQ(journal_priority(spdlog::level::info, false), Priority::info);
  EXPECT_EQ(journal_priority(spdlog::level::debug, false), Priority::debug);
  EXPECT_EQ(journal_priority(spdlog::level::trace, false), Priority::debug);
  // A notice logger's error is still an error.
  EXPECT_EQ(journal_priority(spdlog::level::err, true), Priority::err);
}

TEST(JournalLog, StreamMustBeTheVeryFileDescriptor) {
  char path[] = "/tmp/scp-journal-XXXXXX";
  const int fd = ::mkstemp(path);
  ASSERT_GE(fd, 0);
  struct stat st {};
  ASSERT_EQ(::fstat(fd, &st), 0);
  const std::string mine = std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
  EXPECT_TRUE(stream_is_journal(mine.c_str(), fd));
  const std::string other_ino = std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino + 1);
  EXPECT_FALSE(stream_is_journal(other_ino.c_str(), fd));
  EXPECT_FALSE(stream_is_journal(nullptr, fd));
  EXPECT_FALSE(stream_is_journal("", fd));
  EXPECT_FALSE(stream_is_journal((mine + "x").c_str(), fd));
  EXPECT_FALSE(stream_is_journal("garbage", fd));
  EXPECT_FALSE(stream_is_journal(mine.c_str(), -1));
  ::close(fd);
  ::unlink(path);
}

TEST(JournalLog, LevelNamesAreTheConfigurationsChoices) {
  EXPECT_EQ(parse_level("warn"), spdlog::level::warn);
  EXPECT_EQ(parse_level("error"), spdlog::level::err);
  EXPECT_FALSE(parse_level("warning").has_value());
  EXPECT_FALSE(parse_level("").has_value());
}

}  // namespace
}  // namespace scp::daemon::log
