// Modbus RTU transactions (drivers/modbus/rtu_transaction.hpp) against a slave played by the test
// on the other end of a socket pair: the reply checked by length, CRC and unit; the inter-frame
// silence kept before every request, and after an unanswered one from its flush; a late reply
// drained or recognised instead of taken for the next answer; the caller's budget never exceeded.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <modbus/modbus.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdint>
#include <thread>
#include <vector>

#include "common/clock.hpp"
#include "drivers/modbus/pdu.hpp"
#include "drivers/modbus/rtu_transaction.hpp"

namespace scp::drivers::modbus {
namespace {

constexpr int kUnit = 17;
constexpr std::int64_t kCharNs = 86'806;  // 10 bits at 115200 Bd
constexpr std::int64_t kSilenceNs = 1'750'000;

// The master's end non-blocking, as libmodbus opens a serial port.
struct Line {
  int master = -1, slave = -1;
  Line() {
    int fds[2];
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) == 0) {
      master = fds[0];
      slave = fds[1];
      fcntl(master, F_SETFL, O_NONBLOCK);
    }
  }
  ~Line() {
    ::close(master);
    ::close(slave);
  }
  // The next request the master sent (waits up to a second), and when it arrived.
  std::vector<std::uint8_t> request(std::int64_t* arrived_ns = nullptr) const {
    pollfd p{slave, POLLIN, 0};
    if (poll(&p, 1, 1000) != 1) return {};
    if (arrived_ns != nullptr) *arrived_ns = clock::monotonic_ns();
    std::array<std::uint8_t, 256> buf{};
    const ssize_t n = ::read(slave, buf.data(), buf.size());
    return {buf.begin(), buf.begin() + (n > 0 ? n : 0)};
  }
  void send(const std::vector<std::uint8_t>& bytes) const {
    ASSERT_EQ(::write(slave, bytes.data(), bytes.size()), static_cast<ssize_t>(bytes.size()));
  }
};

// A frame with its CRC appended (low byte first).
std::vector<std::uint8_t> framed(std::vector<std::uint8_t> bytes) {
  const std::uint16_t crc = rtu_crc16(bytes.data(), static_cast<int>(bytes.size()));
  bytes.push_back(static_cast<std::uint8_t>(crc & 0xFF));
  bytes.push_back(static_cast<std::uint8_t>(crc >> 8));
  return bytes;
}

std::vector<std::uint8_t> read_reply(std::uint16_t value) {
  return framed({kUnit, 0x03, 2, static_cast<std::uint8_t>(value >> 8),
                 static_cast<std::uint8_t>(value & 0xFF)});
}

struct Master {
  explicit Master(const Line& line, std::int64_t silence_ns = kSilenceNs)
      : rtu(kCharNs, silence_ns) {
    EXPECT_TRUE(rtu.attach(line.master));
  }
  RtuTransaction rtu;
  Pdu request{};
  int request_len = 0;
  Pdu reply{};
  int reply_len = 0;
  int read(const Line& line, double timeout_s,
           std::int64_t not_after = std::numeric_limits<std::int64_t>::max()) {
    request_len = read_registers_pdu(false, 1000, 1, request.data());
    (void)line;
    return rtu.transact(kUnit, request.data(), request_len, reply, reply_len, timeout_s, not_after);
  }
  int write(const Line& line, std::uint16_t value, double timeout_s) {
    request_len = write_registers_pdu(6, 1100, 1, &value, request.data());
    (void)line;
    return rtu.transact(kUnit, request.data(), request_len, reply, reply_len, timeout_s);
  }
  std::uint16_t value() const {
    std::uint16_t v = 0;
    return check_read_reply(false, 1, reply.data(), reply_len, &v) == 0 ? v : 0xFFFF;
  }
};

TEST(RtuTransaction, CrcIsLibmodbussOwn) {
  // A request mbpoll (libmodbus) sent on the serial line emulator: read 10 holding registers
  // from 1000 of unit 17, CRC 0x2D47 sent low byte first.
  const std::array<std::uint8_t, 6> request{0x11, 0x03, 0x03, 0xE8, 0x00, 0x0A};
  EXPECT_EQ(rtu_crc16(request.data(), 6), 0x2D47);
  EXPECT_EQ(rtu_silence_ns(kCharNs, 115200), 1'750'000);
  EXPECT_EQ(rtu_silence_ns(1'145'833, 9600), 4'010'415);  // 3.5 characters of 11 bits
}

TEST(RtuTransaction, RequestIsFramedAndTheReplyCheckedByLengthCrcAndUnit) {
  Line line;
  Master m(line);
  std::thread slave([&] {
    EXPECT_EQ(line.request(), framed({kUnit, 0x03, 0x03, 0xE8, 0x00, 0x01}));
    // The reply in two pieces, as a UART delivers it: complete only with the second.
    const auto reply = read_reply(0x1234);
    line.send({reply.begin(), reply.begin() + 3});
    usleep(500);
    line.send({reply.begin() + 3, reply.end()});
  });
  ASSERT_EQ(m.read(line, 0.5), 0);
  slave.join();
  EXPECT_EQ(m.value(), 0x1234);
  EXPECT_GT(m.rtu.reply_received_ns(), m.rtu.request_sent_ns());

  const auto answer_with = [&](std::vector<std::uint8_t> reply) {
    std::thread s([&] {
      line.request();
      line.send(reply);
    });
    const int err = m.read(line, 0.5);
    s.join();
    return err;
  };
  auto bad_crc = read_reply(7);
  bad_crc.back() ^= 0xFF;
  EXPECT_EQ(answer_with(bad_crc), EMBBADCRC);
  EXPECT_EQ(answer_with(framed({kUnit + 1, 0x03, 2, 0, 7})), EMBBADSLAVE);
  // A byte count no RTU frame can hold (5 + 252 > 256 bytes) is refused at once, not waited
  // for until the timeout.
  const std::int64_t begin = clock::monotonic_ns();
  EXPECT_EQ(answer_with(framed({kUnit, 0x03, 252, 0, 7})), EMBBADDATA);
  EXPECT_LT(clock::monotonic_ns() - begin, 400'000'000);
  EXPECT_EQ(answer_with(framed({kUnit, 0x83, 2})), 0);  // an exception is an answer
  std::uint16_t v = 0;
  EXPECT_EQ(check_read_reply(false, 1, m.reply.data(), m.reply_len, &v), MODBUS_ENOBASE + 2);
}

TEST(RtuTransaction, EveryRequestWaitsForTheInterFrameSilence) {
  Line line;
  Master m(line);
  std::int64_t reply_sent = 0, next_arrived = 0;
  std::thread slave([&] {
    line.request();
    // Taken before the send: no byte of the reply reaches the master sooner, and a slave thread
    // preempted after its send (a loaded machine) would take it late.
    reply_sent = clock::monotonic_ns();
    line.send(read_reply(1));
    line.request(&next_arrived);
    line.send(framed({kUnit, 0x06, 0x04, 0x4C, 0x00, 0x05}));
  });
  ASSERT_EQ(m.read(line, 0.5), 0);
  const std::int64_t read_reply_received = m.rtu.reply_received_ns();
  ASSERT_EQ(m.write(line, 5, 0.5), 0);  // asked at once, sent only after t3.5
  slave.join();
  EXPECT_GE(next_arrived - reply_sent, kSilenceNs);
  EXPECT_GE(m.rtu.request_sent_ns() - read_reply_received, kSilenceNs);
}

// The steps below are hundreds of milliseconds apart (a silence of 400 ms instead of t3.5), so
// that a loaded machine's late wake-ups do not reorder them.
TEST(RtuTransaction, RestOfALateReplyIsDrainedBeforeTheNextRequest) {
  Line line;
  constexpr std::int64_t kLongSilence = 400'000'000;
  Master m(line, kLongSilence);
  usleep(kLongSilence / 1000 + 50'000);  // the silence after attaching has passed
  // A read answered too late, its reply straddling the timeout: the rest arrives while the next
  // transaction (a write) waits for the line to fall silent, is discarded, and restarts the
  // silence.
  std::int64_t rest_sent = 0, write_arrived = 0;
  std::thread slave([&] {
    line.request();
    usleep(30'000);
    const auto late = read_reply(0x0BAD);
    line.send({late.begin(), late.begin() + 4});
    usleep(200'000);
    rest_sent = clock::monotonic_ns();  // before the send, as above
    line.send({late.begin() + 4, late.end()});
    line.request(&write_arrived);
    line.send(framed({kUnit, 0x06, 0x04, 0x4C, 0x00, 0x05}));
  });
  EXPECT_EQ(m.read(line, 0.060), ETIMEDOUT);
  ASSERT_EQ(m.write(line, 5, 2.0), 0);
  slave.join();
  EXPECT_EQ(m.rtu.late_replies(), 1u);
  EXPECT_GE(write_arrived - rest_sent, kLongSilence);
}

// A request that got no answer may still be in the port, and what the flush before the next one
// cannot reach may leave as late as the flush: the next request keeps the silence after that.
TEST(RtuTransaction, AfterAnUnansweredRequestTheSilenceCountsFromItsFlush) {
  Line line;
  constexpr std::int64_t kLongSilence = 400'000'000;
  Master m(line, kLongSilence);
  usleep(kLongSilence / 1000 + 50'000);
  std::thread slave([&] {
    line.request();  // never answered
    line.request();
    line.send(framed({kUnit, 0x06, 0x04, 0x4C, 0x00, 0x05}));
  });
  EXPECT_EQ(m.read(line, 0.060), ETIMEDOUT);
  const std::int64_t timed_out = clock::monotonic_ns();
  ASSERT_EQ(m.write(line, 5, 2.0), 0);
  slave.join();
  // Counted from the unanswered request's own wire time instead, the write would have left
  // 60 ms sooner.
  EXPECT_GE(m.rtu.request_sent_ns() - timed_out, kLongSilence + 8 * kCharNs);
}

TEST(RtuTransaction, LateReplyToTheOtherFunctionIsRecognisedNotTakenForTheAnswer) {
  Line line;
  Master m(line);
  // A command's echo that comes after its timeout, once the next read has been sent: an intact
  // reply to another function, dropped; the read's own reply follows.
  std::thread slave([&] {
    line.request();
    usleep(200'000);
    line.send(framed({kUnit, 0x06, 0x04, 0x4C, 0x00, 0x06}));
    line.request();
    usleep(200);
    line.send(read_reply(0x0042));
  });
  EXPECT_EQ(m.write(line, 6, 0.030), ETIMEDOUT);
  ASSERT_EQ(m.read(line, 2.0), 0);
  slave.join();
  EXPECT_EQ(m.value(), 0x0042);
  EXPECT_EQ(m.rtu.late_replies(), 1u);
}

TEST(RtuTransaction, NeverRunsPastItsBudget) {
  Line line;
  Master m(line);
  // Nobody answers: the budget ends the wait before the response timeout would.
  std::int64_t begin = clock::monotonic_ns();
  EXPECT_EQ(m.read(line, 0.5, begin + 20'000'000), ETIMEDOUT);
  std::int64_t took = clock::monotonic_ns() - begin;
  EXPECT_GE(took, 19'000'000);
  EXPECT_LT(took, 100'000'000);
  line.request();
  // A byte on the line just now, and a silence (here 60 ms) that could then not end within the
  // response timeout (50 ms): no request is sent, and the transaction gives up at once instead of
  // waiting for the silence. Without the byte it would have been sent: attach() counts the line
  // busy from then, and its silence ends 20 ms into the transaction, within the timeout.
  Master quiet_wanted(line, 60'000'000);
  usleep(40'000);
  line.send({0x55});
  begin = clock::monotonic_ns();
  EXPECT_EQ(quiet_wanted.read(line, 0.050), EBUSY);
  took = clock::monotonic_ns() - begin;
  EXPECT_LT(took, 50'000'000);
  EXPECT_EQ(quiet_wanted.rtu.request_sent_ns(), 0);
}

}  // namespace
}  // namespace scp::drivers::modbus
