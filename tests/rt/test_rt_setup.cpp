#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <string>
#include <thread>

#include "daemon/core/rt/rt_setup.hpp"

namespace scp::rt {
namespace {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitizer = true;
#else
constexpr bool kSanitizer = false;
#endif

bool contains(const std::vector<std::string>& warnings, const std::string& needle) {
  for (const auto& w : warnings) {
    if (w.find(needle) != std::string::npos) return true;
  }
  return false;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& w : v) s += w + "\n";
  return s;
}

TEST(RtSetup, RejectsImpossibleSettings) {
  RtSettings s;
  s.lock_memory = false;
  s.prefault_heap_bytes = 0;
  s.prefault_stack_bytes = 0;
  s.priority = 100;
  EXPECT_THROW(apply_rt_settings(s), std::invalid_argument);
  s.priority = -1;
  EXPECT_THROW(apply_rt_settings(s), std::invalid_argument);
  s.priority = 0;
  s.cpus = {-1};
  EXPECT_THROW(apply_rt_settings(s), std::invalid_argument);
}

TEST(RtSetup, NothingRequestedNothingWarned) {
  RtSettings s;
  s.priority = 0;
  s.lock_memory = false;
  s.prefault_heap_bytes = 1 << 20;
  s.prefault_stack_bytes = 64 << 10;
  EXPECT_TRUE(apply_rt_settings(s).empty());
}

TEST(RtSetup, NonexistentCpuGivesAWarningWithTheRemedy) {
  RtSettings s;
  s.priority = 0;
  s.lock_memory = false;
  s.prefault_heap_bytes = 0;
  s.prefault_stack_bytes = 0;
  s.cpus = {1000};  // in CPU_SETSIZE, but no such CPU here
  std::thread t([&] {
    const auto w = apply_rt_settings(s);
    EXPECT_TRUE(contains(w, "cannot pin the loop thread to CPUs [1000]")) << join(w);
    EXPECT_TRUE(contains(w, "loop.realtime.cpus")) << join(w);
    s.required = true;
    EXPECT_THROW(apply_rt_settings(s), std::runtime_error);
  });
  t.join();
}

TEST(RtSetup, OversizedStackPrefaultIsClampedNotFatal) {
  RtSettings s;
  s.priority = 0;
  s.lock_memory = false;
  s.prefault_heap_bytes = 0;
  s.prefault_stack_bytes = std::size_t{1} << 30;  // far beyond any thread stack
  std::thread t([&] {
    const auto w = apply_rt_settings(s);
    EXPECT_TRUE(contains(w, "prefault_stack_bytes")) << join(w);
  });
  t.join();
}

// Unprivileged: without CAP_SYS_NICE / CAP_IPC_LOCK and with zero rlimits, both steps must fail
// with warnings that name the unit settings that fix them. Run in a child that drops privileges.
TEST(RtSetup, UnprivilegedFailuresNameTheRemedy) {
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(fds[0]);
    rlimit zero{0, 0};
    setrlimit(RLIMIT_RTPRIO, &zero);
    setrlimit(RLIMIT_MEMLOCK, &zero);
    if (getuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0)) _exit(77);
    RtSettings s;
    s.priority = 80;
    s.prefault_heap_bytes = 1 << 20;
    s.prefault_stack_bytes = 64 << 10;
    std::string out = join(apply_rt_settings(s));
    s.required = true;
    try {
      apply_rt_settings(s);
      out += "NO-THROW\n";
    } catch (const std::runtime_error& e) {
      out += std::string("THREW: ") + e.what() + "\n";
    }
    const ssize_t n = write(fds[1], out.data(), out.size());
    _exit(n == static_cast<ssize_t>(out.size()) ? 0 : 1);
  }
  close(fds[1]);
  std::string text;
  char buf[1024];
  ssize_t n;
  while ((n = read(fds[0], buf, sizeof(buf))) > 0) text.append(buf, static_cast<std::size_t>(n));
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (WIFEXITED(status) && WEXITSTATUS(status) == 77) GTEST_SKIP() << "cannot drop root privileges";
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << text;
  EXPECT_NE(text.find("cannot set SCHED_FIFO priority 80"), std::string::npos) << text;
  EXPECT_NE(text.find("LimitRTPRIO="), std::string::npos) << text;
  EXPECT_NE(text.find("loop.realtime.priority: 0"), std::string::npos) << text;
  if (kSanitizer) {
    EXPECT_NE(text.find("sanitizer build"), std::string::npos) << text;
  } else {
    EXPECT_NE(text.find("cannot lock memory"), std::string::npos) << text;
    EXPECT_NE(text.find("LimitMEMLOCK=infinity"), std::string::npos) << text;
  }
  EXPECT_NE(text.find("THREW: "), std::string::npos) << text;
}

// Privileged: the settings must really take effect. Runs in a child so that SCHED_FIFO and
// mlockall do not leak into the other tests.
TEST(RtSetup, PrivilegedSettingsTakeEffect) {
  if (kSanitizer) GTEST_SKIP() << "mlockall is skipped in sanitizer builds";
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(fds[0]);
    std::string out;
    std::thread t([&] {
      RtSettings s;
      s.priority = 5;
      s.cpus = {0};
      s.prefault_heap_bytes = 4 << 20;
      s.prefault_stack_bytes = 128 << 10;
      const auto w = apply_rt_settings(s);
      if (!w.empty()) {
        out = "WARN " + join(w);
        return;
      }
      int policy = -1;
      sched_param param{};
      pthread_getschedparam(pthread_self(), &policy, &param);
      cpu_set_t set;
      CPU_ZERO(&set);
      pthread_getaffinity_np(pthread_self(), sizeof(set), &set);
      std::ifstream status("/proc/self/status");
      std::string line;
      long vmlck_kb = -1;
      while (std::getline(status, line)) {
        if (line.rfind("VmLck:", 0) == 0) vmlck_kb = std::stol(line.substr(6));
      }
      out = "policy=" + std::to_string(policy) + " prio=" + std::to_string(param.sched_priority) +
            " cpus=" + std::to_string(CPU_COUNT(&set)) +
            " cpu0=" + std::to_string(CPU_ISSET(0, &set)) +
            " vmlck_mb=" + std::to_string(vmlck_kb / 1024);
    });
    t.join();
    const ssize_t n = write(fds[1], out.data(), out.size());
    _exit(n == static_cast<ssize_t>(out.size()) ? 0 : 1);
  }
  close(fds[1]);
  std::string text;
  char buf[1024];
  ssize_t n;
  while ((n = read(fds[0], buf, sizeof(buf))) > 0) text.append(buf, static_cast<std::size_t>(n));
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << text;
  if (text.rfind("WARN ", 0) == 0) GTEST_SKIP() << "no real-time privileges here: " << text;
  EXPECT_NE(text.find("policy=" + std::to_string(SCHED_FIFO) + " prio=5 cpus=1 cpu0=1"),
            std::string::npos)
      << text;
  // The 4 MiB heap prefault stays mapped and locked (M_TRIM_THRESHOLD = -1, MCL_FUTURE).
  const auto pos = text.find("vmlck_mb=");
  ASSERT_NE(pos, std::string::npos);
  EXPECT_GE(std::stol(text.substr(pos + 9)), 4) << text;
}

}  // namespace
}  // namespace scp::rt

namespace scp::rt {
namespace {

std::size_t new_thread_stack_size() {
  std::size_t size = 0;
  std::thread t([&size] {
    pthread_attr_t attr;
    ASSERT_EQ(pthread_getattr_np(pthread_self(), &attr), 0);
    void* addr = nullptr;
    pthread_attr_getstack(&attr, &addr, &size);
    pthread_attr_destroy(&attr);
  });
  t.join();
  return size;
}

// Threads started after set_default_thread_stack get that stack (under mlockall every byte of it
// is locked RAM): the loop's, in which its stack prefault still fits in three quarters, and the
// smaller one of every other thread. The small one first: glibc hands a new thread a cached stack
// of an exited one up to 4× the size asked for.
TEST(RtSetup, DefaultThreadStackIsSmall) {
  pthread_attr_t saved;
  ASSERT_EQ(pthread_getattr_default_np(&saved), 0);
  for (const std::size_t bytes : {kThreadStackBytes, kLoopThreadStackBytes}) {
    ASSERT_TRUE(set_default_thread_stack(bytes));
    const std::size_t size = new_thread_stack_size();
    EXPECT_GE(size, bytes);
    EXPECT_LT(size, bytes + (std::size_t{64} << 10));
  }
  EXPECT_GE(kLoopThreadStackBytes / 4 * 3, RtSettings{}.prefault_stack_bytes);
  EXPECT_LT(kThreadStackBytes, kLoopThreadStackBytes);
  ASSERT_EQ(pthread_setattr_default_np(&saved), 0);
  pthread_attr_destroy(&saved);
}

}  // namespace
}  // namespace scp::rt
