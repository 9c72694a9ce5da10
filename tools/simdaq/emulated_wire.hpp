#pragma once
// The serial line scp-simdaq puts between the daemon and its wall-clock plant (--wire): a pty or
// a loopback socket delivers a frame at once, a 115200 Bd RTU line takes ~95 µs per character.
//
// One transaction, as the Modbus serial line specification (§2.5.1) times it: the request's
// characters are on the line from when it arrives here (plus jitter: a USB adapter, an OS),
// the slave acts (samples or applies the command) once the line has been silent for t3.5 after
// the last character, and the reply's characters follow (plus jitter), after which the line is
// silent for t3.5 again before the next frame may start. Times are CLOCK_MONOTONIC ns.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>

namespace scp::drivers::simdaq {

struct WireSettings {
  double char_s = 0.0;    // one character on the line: (1 + data + parity + stop bits) / baud
  double gap_s = 0.0;     // inter-frame silence (3.5 characters)
  double jitter_s = 0.0;  // each frame is delayed by a uniform [0, jitter_s] more
  std::uint64_t seed = 1;
};

struct WireTransaction {
  std::int64_t event_ns = 0;  // the slave samples its inputs / applies the command
  std::int64_t reply_ns = 0;  // the reply's last character has reached the master
};

class EmulatedWire {
 public:
  explicit EmulatedWire(const WireSettings& s) : s_(s), rng_(s.seed), jitter_(0.0, 1.0) {}

  // A request of `request_chars` characters handed over at `arrived_ns`, answered with
  // `reply_chars` characters.
  WireTransaction schedule(std::int64_t arrived_ns, int request_chars, int reply_chars) {
    // A frame cannot start while the previous one (and its trailing silence) holds the line.
    const std::int64_t start = std::max(arrived_ns, line_free_ns_) + jitter_ns();
    WireTransaction t;
    t.event_ns = start + ns(request_chars * s_.char_s + s_.gap_s);
    t.reply_ns = t.event_ns + jitter_ns() + ns(reply_chars * s_.char_s);
    line_free_ns_ = t.reply_ns + ns(s_.gap_s);
    return t;
  }

 private:
  static std::int64_t ns(double s) { return static_cast<std::int64_t>(std::llround(s * 1e9)); }
  std::int64_t jitter_ns() { return s_.jitter_s > 0.0 ? ns(s_.jitter_s * jitter_(rng_)) : 0; }

  WireSettings s_;
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> jitter_;
  std::int64_t line_free_ns_ = 0;
};

}  // namespace scp::drivers::simdaq
