#pragma once
// Runs a program through the shell and collects what it printed: the tests of the command-line
// tools (scp-benchsim, scp-crb) check their output and exit status this way.

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace scp::test {

// Runs `command` (a shell command line) with stderr joined to stdout; returns the output, and in
// `status` the exit status (−1 if it could not run or did not exit).
inline std::string run_command(const std::string& command, int& status) {
  const std::string cmd = command + " 2>&1";
  FILE* pipe = ::popen(cmd.c_str(), "r");
  std::string out;
  char buf[4096];
  while (pipe && std::fgets(buf, sizeof buf, pipe)) out += buf;
  status = pipe ? ::pclose(pipe) : -1;
  status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

}  // namespace scp::test
