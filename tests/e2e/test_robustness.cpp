// Issues 3 and 5: hostile and heavy clients must not disturb the real-time loop or each other.

#include <fcntl.h>
#include <sys/socket.h>

#include <atomic>
#include <chrono>
#include <random>
#include <thread>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

using Clock = std::chrono::steady_clock;

// The loop's own counters over a window of wall time.
struct LoopDelta {
  std::uint64_t cycles = 0, overruns = 0, missed = 0;
  double seconds = 0;
};

LoopDelta measure(const DaemonProcess& daemon, const std::function<void()>& during) {
  const json a = daemon.status();
  const auto t0 = Clock::now();
  during();
  const json b = daemon.status();
  LoopDelta d;
  d.seconds = Seconds(Clock::now() - t0).count();
  d.cycles = loop_count(b, "cycles") - loop_count(a, "cycles");
  d.overruns = loop_count(b, "overruns") - loop_count(a, "overruns");
  d.missed = loop_count(b, "missed_periods") - loop_count(a, "missed_periods");
  return d;
}

// The larger per-second rate of two quiet windows, one before and one after the load: a shared
// machine's own hiccups (another test, a hypervisor's steal) come and go, and one quiet window
// alone can catch a calm moment that the load window then is compared against.
LoopDelta busier_of(const LoopDelta& a, const LoopDelta& b) {
  const auto rate = [](const LoopDelta& d) {
    return static_cast<double>(d.overruns + d.missed) / std::max(d.seconds, 1e-3);
  };
  return rate(a) >= rate(b) ? a : b;
}

void expect_loop_unaffected(const DaemonProcess& daemon, const LoopDelta& quiet_before,
                            const LoopDelta& load, const char* what) {
  const LoopDelta quiet_after = measure(daemon, [] { sleep_s(3.0); });
  const LoopDelta quiet = busier_of(quiet_before, quiet_after);
  std::printf(
      "%s: quiet %.1f s: %llu cycles, %llu overruns, %llu missed (before %llu/%llu, after "
      "%llu/%llu); load %.1f s: %llu cycles, %llu overruns, %llu missed\n",
      what, quiet.seconds, static_cast<unsigned long long>(quiet.cycles),
      static_cast<unsigned long long>(quiet.overruns),
      static_cast<unsigned long long>(quiet.missed),
      static_cast<unsigned long long>(quiet_before.overruns),
      static_cast<unsigned long long>(quiet_before.missed),
      static_cast<unsigned long long>(quiet_after.overruns),
      static_cast<unsigned long long>(quiet_after.missed), load.seconds,
      static_cast<unsigned long long>(load.cycles), static_cast<unsigned long long>(load.overruns),
      static_cast<unsigned long long>(load.missed));
  // Loose on purpose: this machine is shared. The loop must keep cycling at ~1 kHz and not lose
  // many more periods than when nobody talks to it. The slack, 50 plus 1 % of the load window's
  // cycles, absorbs a loaded CI machine's bursts (82 overruns in 6000 cycles against 3 in a calm
  // 3 s baseline were seen once); a server that blocked or starved the loop costs thousands.
  EXPECT_GT(static_cast<double>(load.cycles), 0.8 * 1000.0 * load.seconds) << what;
  const double scale = load.seconds / std::max(quiet.seconds, 1e-3);
  const double slack = 50.0 + 0.01 * static_cast<double>(load.cycles);
  EXPECT_LE(static_cast<double>(load.missed),
            3.0 * scale * static_cast<double>(quiet.missed) + slack)
      << what;
  EXPECT_LE(static_cast<double>(load.overruns),
            3.0 * scale * static_cast<double>(quiet.overruns) + slack)
      << what;
}

// The configuration of these tests: the loop at real-time priority (as in production), so what
// is measured is the server's interference, not the test's own CPU hunger.
json rt_config() {
  return {{"loop", {{"realtime", {{"priority", 50}}}}}, {"socket", {{"max_line_bytes", 4096}}}};
}

// Reads until an ERROR line or the peer's close; false on a 5 s silence (a hang).
bool gets_error_or_disconnect(Client& c, std::string& last) {
  for (;;) {
    bool timed_out = false;
    auto line = c.read_line(Seconds(5), &timed_out);
    if (!line) return !timed_out;
    last = *line;
    if (contains(*line, "\"class\":\"ERROR\"")) return true;
  }
}

std::vector<std::string> hostile_payloads(std::mt19937& rng) {
  std::vector<std::string> p;
  p.push_back("{\"request\":\n");
  p.push_back("{\"request\":\"status\"\n");
  p.push_back("not json at all\n");
  p.push_back("[1,2,3]\n");
  p.push_back("\"request\"\n");
  p.push_back("{\"request\":42}\n");
  p.push_back("{\"request\":\"watch\",\"rate_hz\":1e999}\n");
  p.push_back("{\"request\":\"watch\",\"rate_hz\":-1e308}\n");
  p.push_back("{\"request\":\"watch\",\"rate_hz\":123456789012345678901234567890123456789}\n");
  p.push_back("{\"request\":\"status\",\"n\":1e400}\n");
  p.push_back("{\"request\":\"stats\"}\n");
  p.push_back("{\"request\":\"excitation\",\"enable\":\"yes\"}\n");
  p.push_back("{\"request\":\"status\",\"extra\":true}\n");
  p.push_back(std::string(2000, '[') + std::string(2000, ']') + "\n");  // deep nesting
  p.push_back("{\"request\":" + std::string(1500, '{') + "\n");
  p.push_back(std::string("{\"request\":\"sta\0tus\"}\n", 22));  // NUL inside
  p.push_back(std::string("\0\0\0\0\n", 5));
  p.push_back("\xff\xfe\xc3\x28 {\"request\":\"status\"}\n");  // invalid UTF-8
  p.push_back(std::string(10000, 'a'));                        // oversized, no newline
  p.push_back(std::string(5000, ' ') + "{\"request\":\"status\"}\n");
  for (int i = 0; i < 8; ++i) {  // random binary, each line newline-terminated
    std::string bytes(static_cast<std::size_t>(rng() % 3000 + 1), '\0');
    for (auto& b : bytes) b = static_cast<char>(rng() & 0xff);
    p.push_back(bytes + "\n");
  }
  return p;
}

// Issue 3, item 7: garbage at the socket. Every hostile line gets an ERROR or a disconnect, the
// daemon keeps answering status, and the loop does not miss more periods than while idle.
TEST(Robustness, FuzzedClientsGetErrorsAndTheLoopIsUnaffected) {
  TempDir dir;
  DaemonProcess daemon(dir, rt_config());
  daemon.start();
  sleep_s(0.5);
  const LoopDelta quiet = measure(daemon, [] { sleep_s(3.0); });

  std::mt19937 rng(7);
  int answered = 0, connections = 0;
  const LoopDelta load = measure(daemon, [&] {
    const auto end = Clock::now() + Seconds(3.0);
    while (Clock::now() < end) {
      for (const std::string& payload : hostile_payloads(rng)) {
        Client c = daemon.connect();
        ++connections;
        (void)c.send_raw(payload);  // the server may close before all of it is sent
        std::string last;
        ASSERT_TRUE(gets_error_or_disconnect(c, last))
            << "no ERROR and no disconnect for payload of " << payload.size() << " bytes";
        ++answered;
      }
      // Half a line, then gone.
      for (int i = 0; i < 5; ++i) {
        Client c = daemon.connect();
        c.send_raw("{\"request\":\"sta");
      }
      // Several at once, interleaved.
      std::vector<Client> many;
      for (int i = 0; i < 20; ++i) many.push_back(daemon.connect());
      for (auto& c : many) c.send_raw("{\"request\":\"status\",\"bogus\":");
      for (auto& c : many) c.send_raw("[]}\n");
      for (auto& c : many) {
        std::string last;
        ASSERT_TRUE(gets_error_or_disconnect(c, last));
      }
    }
  });
  std::printf("%d hostile payloads on %d connections\n", answered, connections);
  EXPECT_GT(answered, 50);
  const json st = daemon.status();
  EXPECT_EQ(st.value("class", ""), "STATUS") << st.dump();
  EXPECT_EQ(st.value("state", ""), "running") << st.dump();
  EXPECT_TRUE(daemon.running());
  expect_loop_unaffected(daemon, quiet, load, "fuzz");
}

// Issue 3, item 8: 64 clients polling `estimate` as fast as they can plus four 100 Hz watch
// streams. Everyone is served and the loop keeps its 1 kHz.
TEST(Robustness, SixtyFourClientsAreServedAndTheLoopKeepsCycling) {
  TempDir dir;
  DaemonProcess daemon(dir, rt_config());
  daemon.start();
  sleep_s(0.5);
  const LoopDelta quiet = measure(daemon, [] { sleep_s(3.0); });

  constexpr int kClients = 64;
  std::atomic<bool> stop{false};
  std::vector<int> replies(kClients, 0), bad(kClients, 0);
  std::vector<int> streamed(4, 0);
  const LoopDelta load = measure(daemon, [&] {
    std::vector<std::thread> threads;
    for (int i = 0; i < kClients; ++i) {
      threads.emplace_back([&, i] {
        try {
          Client c = daemon.connect();
          while (!stop.load()) {
            const json e = c.request({{"request", "estimate"}});
            (e.value("class", "") == "ESTIMATE" ? replies[i] : bad[i])++;
          }
        } catch (const std::exception&) {
          bad[i]++;
        }
      });
    }
    for (int i = 0; i < 4; ++i) {
      threads.emplace_back([&, i] {
        try {
          Client c = daemon.connect();
          c.request({{"request", "watch"}, {"rate_hz", 100}});
          while (!stop.load()) {
            auto line = c.read_line(Seconds(1));
            if (line && contains(*line, "\"class\":\"ESTIMATE\"")) streamed[i]++;
          }
        } catch (const std::exception&) {
        }
      });
    }
    sleep_s(4.0);
    stop = true;
    for (auto& t : threads) t.join();
  });
  int total = 0;
  for (int i = 0; i < kClients; ++i) {
    EXPECT_GT(replies[i], 10) << "client " << i << " starved";
    EXPECT_EQ(bad[i], 0) << "client " << i << " got a wrong reply or lost its connection";
    total += replies[i];
  }
  // 64 clients polling flat out saturate the server thread, so the streams need not keep 100 Hz;
  // they must keep flowing: at least 5 Hz (measured: ~400 per stream unloaded, ~160 under ASan
  // on a busy machine, 79-80 under ASan in a clean-clone CI run).
  for (int i = 0; i < 4; ++i)
    EXPECT_GE(streamed[i], 20) << "watch stream " << i << " (100 Hz × 4 s) starved";
  std::printf("%d estimates served in %.1f s\n", total, load.seconds);
  expect_loop_unaffected(daemon, quiet, load, "64 clients");
  EXPECT_TRUE(daemon.running());
}

// Issue 5, item 14: one client floods requests without reading, one watches at 1 kHz without
// reading. The server drops both once their unread output passes its limit, and meanwhile a
// normal client is answered promptly and the loop does not notice.
TEST(Robustness, NonReadingClientsAreDroppedOthersServed) {
  TempDir dir;
  DaemonProcess daemon(dir, rt_config());
  daemon.start();
  sleep_s(0.5);
  const LoopDelta quiet = measure(daemon, [] { sleep_s(3.0); });

  Client flooder = daemon.connect();
  Client watcher = daemon.connect();
  ASSERT_TRUE(watcher.send_raw("{\"request\":\"watch\",\"rate_hz\":1000}\n"));
  ::fcntl(flooder.fd(), F_SETFL, ::fcntl(flooder.fd(), F_GETFL) | O_NONBLOCK);
  bool flooder_dropped = false;
  int normal_replies = 0;
  double worst_reply_s = 0;
  const LoopDelta load = measure(daemon, [&] {
    const std::string burst = [] {
      std::string s;
      for (int i = 0; i < 50; ++i) s += "{\"request\":\"status\"}\n";
      return s;
    }();
    Client normal = daemon.connect();
    const auto end = Clock::now() + Seconds(6.0);
    while (Clock::now() < end) {
      // Flood without ever reading; EPIPE/ECONNRESET means the server dropped us.
      if (!flooder_dropped) {
        const ssize_t n = ::send(flooder.fd(), burst.data(), burst.size(), MSG_NOSIGNAL);
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) flooder_dropped = true;
      }
      const auto t0 = Clock::now();
      const json s = normal.request({{"request", "status"}});
      worst_reply_s = std::max(worst_reply_s, Seconds(Clock::now() - t0).count());
      normal_replies += s.value("class", "") == "STATUS";
      sleep_s(0.002);
    }
  });
  // The watcher: drain what the kernel still holds; a dropped client then sees end-of-file.
  bool watcher_dropped = false;
  const auto end = Clock::now() + Seconds(5);
  while (Clock::now() < end) {
    bool timed_out = false;
    if (!watcher.read_line(Seconds(1), &timed_out)) {
      watcher_dropped = !timed_out;
      break;
    }
  }
  // The flooder: a dropped client reads its pending replies, then end-of-file.
  if (!flooder_dropped) {
    ::fcntl(flooder.fd(), F_SETFL, ::fcntl(flooder.fd(), F_GETFL) & ~O_NONBLOCK);
    const auto end2 = Clock::now() + Seconds(5);
    while (Clock::now() < end2) {
      bool timed_out = false;
      if (!flooder.read_line(Seconds(1), &timed_out)) {
        flooder_dropped = !timed_out;
        break;
      }
    }
  }
  EXPECT_TRUE(watcher_dropped) << "a watcher that never reads must be dropped";
  EXPECT_TRUE(flooder_dropped) << "a flooder that never reads must be dropped";
  EXPECT_GT(normal_replies, 200) << "the normal client was starved";
  EXPECT_LT(worst_reply_s, 1.0) << "a status reply took " << worst_reply_s << " s";
  expect_loop_unaffected(daemon, quiet, load, "non-readers");
  EXPECT_EQ(daemon.status().value("state", ""), "running");
}

}  // namespace
}  // namespace scp::test
