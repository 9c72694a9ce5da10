#include "daemon/outputs/log/journal_log.hpp"

#include <spdlog/formatter.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cinttypes>
#include <cstdio>
#include <ctime>
#include <mutex>

namespace scp::daemon::log {
namespace {

constexpr const char* kNoticeLogger = "scp-estimatord-notice";

std::mutex notice_mutex;
std::shared_ptr<spdlog::logger> notice_instance;

const char* level_word(spdlog::level::level_enum level, bool notice) noexcept {
  if (notice && level == spdlog::level::info) return "notice";
  switch (level) {
    case spdlog::level::trace:
      return "trace";
    case spdlog::level::debug:
      return "debug";
    case spdlog::level::info:
      return "info";
    case spdlog::level::warn:
      return "warning";
    case spdlog::level::err:
      return "error";
    case spdlog::level::critical:
      return "critical";
    default:
      return "log";
  }
}

// One line per message: "<N>level: text" for the journal, "2026-11-23T08:30:00.123Z level: text"
// for a terminal. No colours: journald would store the escape codes.
class LineFormatter final : public spdlog::formatter {
 public:
  explicit LineFormatter(bool journal) : journal_(journal) {}

  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override {
    const bool notice = msg.logger_name == kNoticeLogger;
    char head[64];
    int n = 0;
    if (journal_) {
      n = std::snprintf(head, sizeof head, "<%d>",
                        static_cast<int>(journal_priority(msg.level, notice)));
    } else {
      const auto since_epoch = msg.time.time_since_epoch();
      const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(since_epoch).count();
      const std::time_t seconds = static_cast<std::time_t>(ms / 1000);
      std::tm tm{};
      gmtime_r(&seconds, &tm);
      const std::size_t len = std::strftime(head, sizeof head, "%Y-%m-%dT%H:%M:%S", &tm);
      n = static_cast<int>(len) +
          std::snprintf(head + len, sizeof head - len, ".%03dZ ", static_cast<int>(ms % 1000));
    }
    dest.append(head, head + n);
    const char* word = level_word(msg.level, notice);
    dest.append(word, word + std::strlen(word));
    dest.push_back(':');
    dest.push_back(' ');
    // A line break inside a message would start a new journal entry at priority info.
    for (const char c : msg.payload) dest.push_back(c == '\n' ? ' ' : c);
    dest.push_back('\n');
  }

  std::unique_ptr<spdlog::formatter> clone() const override {
    return std::make_unique<LineFormatter>(journal_);
  }

 private:
  bool journal_;
};

}  // namespace

Priority journal_priority(spdlog::level::level_enum level, bool notice) noexcept {
  switch (level) {
    case spdlog::level::trace:
    case spdlog::level::debug:
      return Priority::debug;
    case spdlog::level::info:
      return notice ? Priority::notice : Priority::info;
    case spdlog::level::warn:
      return Priority::warning;
    case spdlog::level::err:
      return Priority::err;
    case spdlog::level::critical:
      return Priority::crit;
    default:
      return Priority::info;
  }
}

bool stream_is_journal(const char* journal_stream, int fd) noexcept {
  if (journal_stream == nullptr) return false;
  std::uintmax_t dev = 0;
  std::uintmax_t ino = 0;
  char tail = '\0';
  if (std::sscanf(journal_stream, "%" SCNuMAX ":%" SCNuMAX "%c", &dev, &ino, &tail) != 2)
    return false;
  struct stat st {};
  if (::fstat(fd, &st) != 0) return false;
  return static_cast<std::uintmax_t>(st.st_dev) == dev &&
         static_cast<std::uintmax_t>(st.st_ino) == ino;
}

std::optional<spdlog::level::level_enum> parse_level(const std::string& name) noexcept {
  if (name == "trace") return spdlog::level::trace;
  if (name == "debug") return spdlog::level::debug;
  if (name == "info") return spdlog::level::info;
  if (name == "warn") return spdlog::level::warn;
  if (name == "error") return spdlog::level::err;
  return std::nullopt;
}

void setup(spdlog::level::level_enum level, bool journal) {
  auto sink = std::make_shared<spdlog::sinks::stderr_sink_mt>();
  sink->set_formatter(std::make_unique<LineFormatter>(journal));
  auto main_logger = std::make_shared<spdlog::logger>("scp-estimatord", sink);
  auto notice = std::make_shared<spdlog::logger>(kNoticeLogger, sink);
  main_logger->set_level(level);
  notice->set_level(level);
  // Errors and warnings must reach the journal even if the process dies right after.
  main_logger->flush_on(spdlog::level::trace);
  notice->flush_on(spdlog::level::trace);
  spdlog::set_default_logger(main_logger);
  const std::lock_guard<std::mutex> lock(notice_mutex);
  notice_instance = std::move(notice);
}

void set_level(spdlog::level::level_enum level) {
  spdlog::set_level(level);
  notice_logger()->set_level(level);
}

std::shared_ptr<spdlog::logger> notice_logger() {
  const std::lock_guard<std::mutex> lock(notice_mutex);
  return notice_instance ? notice_instance : spdlog::default_logger();
}

}  // namespace scp::daemon::log
