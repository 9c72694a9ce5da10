#pragma once
// The daemon's log lines, for the journal and for a terminal. Under systemd, stderr is a stream
// to journald: each line then starts with an sd-daemon(3) priority prefix ("<3>" err ... "<7>"
// debug) so that `journalctl -p err` finds faults, and carries no time stamp (the journal adds
// its own). In the foreground each line starts with a UTC time stamp instead.
//
// spdlog has no "notice" level; state changes and recoveries go through notice(), a second logger
// on the same sink whose info lines are written at priority 5.

#include <spdlog/spdlog.h>

#include <memory>
#include <optional>
#include <string>

namespace scp::daemon::log {

// syslog(3) priorities, as sd-daemon(3) spells them in its prefixes.
enum class Priority : int { crit = 2, err = 3, warning = 4, notice = 5, info = 6, debug = 7 };

// The priority of a line logged at `level`; `notice` marks a line logged through notice().
Priority journal_priority(spdlog::level::level_enum level, bool notice) noexcept;

// systemd sets JOURNAL_STREAM="<dev>:<ino>" for the stream it connected to stdout/stderr. A
// process whose stderr was redirected elsewhere inherits the variable, so it counts only when
// `fd` is that very stream (systemd.exec(5), "$JOURNAL_STREAM").
bool stream_is_journal(const char* journal_stream, int fd) noexcept;

// Parses "trace", "debug", "info", "warn", "error"; nullopt for anything else.
std::optional<spdlog::level::level_enum> parse_level(const std::string& name) noexcept;

// Installs the default logger and the notice logger on stderr, with priority prefixes when
// `journal` is true and UTC time stamps when it is false.
void setup(spdlog::level::level_enum level, bool journal);

// Changes the level of both loggers (SIGHUP reload, --log-level).
void set_level(spdlog::level::level_enum level);

// The logger behind notice(); the default logger until setup() ran.
std::shared_ptr<spdlog::logger> notice_logger();

// A state change or a recovery: priority 5 in the journal, "notice:" in the foreground.
template <typename... Args>
void notice(spdlog::format_string_t<Args...> format, Args&&... args) {
  notice_logger()->info(format, std::forward<Args>(args)...);
}

}  // namespace scp::daemon::log
