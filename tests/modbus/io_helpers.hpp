#pragma once
// Shared by the I/O tests: temporary config files, scp-simdaq started on a free port, and an
// independent libmodbus client to look at registers behind the driver's back.

#include <gtest/gtest.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "tests/support/child_process.hpp"

namespace scp::test {

inline std::string temp_file(const std::string& text, const std::string& suffix = ".yaml") {
  std::string path = "/tmp/scp-modbus-test-XXXXXX" + suffix;
  const int fd = mkstemps(path.data(), static_cast<int>(suffix.size()));
  if (fd < 0) return {};
  ::close(fd);
  std::ofstream(path) << text;
  return path;
}

// The map every simdaq test serves: x, T, ẋ, V read-back as float32 ab in input registers 0-7,
// the command as float32 ab in holding registers 0-1.
inline const char* kSimdaqConfig = R"(driver:
  type: modbus
  modbus:
    transport: tcp
    signals:
      x: {table: input, address: 0, type: float32, word_order: ab}
      temperature: {table: input, address: 2, type: float32, word_order: ab}
      xdot: {table: input, address: 4, type: float32, word_order: ab}
      voltage: {table: input, address: 6, type: float32, word_order: ab}
    command: {address: 0, type: float32, word_order: ab, min: 0, max: 10}
)";

// A port nothing listens on right now (bound and released).
inline int free_port() {
  const int s = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  getsockname(s, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(s);
  return ntohs(a.sin_port);
}

// Starts scp-simdaq; `port` 0 lets it pick one, returned through `port`.
inline std::unique_ptr<ChildProcess> start_simdaq(const std::string& config, int& port,
                                                  std::vector<std::string> extra = {}) {
  std::vector<std::string> argv = {SCP_SIMDAQ_PATH, "--config", config, "--listen",
                                   "127.0.0.1:" + std::to_string(port)};
  argv.insert(argv.end(), extra.begin(), extra.end());
  auto p = std::make_unique<ChildProcess>(argv);
  const std::string tag = "listening on 127.0.0.1:";
  if (!p->wait_for(tag, 10.0)) {
    ADD_FAILURE() << "scp-simdaq did not start: " << p->output();
    return p;
  }
  const std::string& out = p->output();
  port = std::atoi(out.c_str() + out.find(tag) + tag.size());
  return p;
}

// Reads holding registers with a fresh libmodbus context (not the driver's).
inline bool read_holding(int port, int address, int count, std::uint16_t* out) {
  modbus_t* ctx = modbus_new_tcp("127.0.0.1", port);
  if (ctx == nullptr) return false;
  modbus_set_slave(ctx, 1);
  bool ok = modbus_connect(ctx) == 0 && modbus_read_registers(ctx, address, count, out) == count;
  modbus_close(ctx);
  modbus_free(ctx);
  return ok;
}

}  // namespace scp::test
