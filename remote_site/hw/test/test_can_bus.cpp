#include <gtest/gtest.h>
#include <linux/can/error.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <vector>
#include <thread>

#include "foresight/hw/can_bus.hpp"

using namespace foresight::hw;

TEST(SocketCanBus, FailsWithAClearMessageWithoutKernelCan) {
  // This kernel has no PF_CAN; on a machine with CAN, can0 may exist, so the
  // check is on a name that never exists there either.
  try {
    SocketCanBus bus("fsnocan0");
    FAIL() << "opened a CAN interface that should not exist";
  } catch (const CanError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("SocketCAN interface 'fsnocan0'"), std::string::npos) << msg;
    const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (fd < 0 && errno == EAFNOSUPPORT) {
      EXPECT_NE(msg.find("EAFNOSUPPORT"), std::string::npos) << msg;
      EXPECT_NE(msg.find("no CAN support"), std::string::npos) << msg;
    } else {
      if (fd >= 0) ::close(fd);
      EXPECT_NE(msg.find("no such interface"), std::string::npos) << msg;
    }
  }
}

TEST(SocketCanBus, RejectsBadInterfaceNames) {
  EXPECT_THROW(SocketCanBus(""), CanError);
  EXPECT_THROW(SocketCanBus("a_name_much_longer_than_ifnamsiz"), CanError);
}

TEST(MockCanBus, CarriesFramesBothWaysIntact) {
  auto [a, b] = MockCanBus::create_pair("t");
  can_frame f{};
  EXPECT_EQ(b->read(f), CanIo::WouldBlock);
  for (int i = 0; i < 100; ++i) {
    const can_frame out = make_frame(0x180 + (i % 127), {static_cast<std::uint8_t>(i), 1, 2, 3, 4, 5, 6, 7});
    ASSERT_EQ(a->write(out), CanIo::Ok);
  }
  for (int i = 0; i < 100; ++i) {
    ASSERT_EQ(b->read(f), CanIo::Ok);
    EXPECT_EQ(f.can_id, static_cast<canid_t>(0x180 + (i % 127)));
    EXPECT_EQ(f.can_dlc, 8);
    EXPECT_EQ(f.data[0], i);
    EXPECT_EQ(f.data[7], 7);
  }
  EXPECT_EQ(b->read(f), CanIo::WouldBlock);
  ASSERT_EQ(b->write(make_frame(0x080, {})), CanIo::Ok);
  ASSERT_EQ(a->read(f), CanIo::Ok);
  EXPECT_EQ(f.can_id, 0x080u);
  EXPECT_EQ(f.can_dlc, 0);
}

// The read's stamp is when the frame was written, not when it was read: a
// simulated node that reads late still times the bus by the master's clock.
TEST(MockCanBus, ReadStampIsTheWriteTimeOnTheMonotonicClock) {
  auto [a, b] = MockCanBus::create_pair("t");
  auto mono_ns = [] { return std::chrono::steady_clock::now().time_since_epoch() / std::chrono::nanoseconds(1); };
  const std::int64_t before = mono_ns();
  ASSERT_EQ(a->write(make_frame(0x80, {})), CanIo::Ok);
  const std::int64_t after = mono_ns();
  // Read 30 ms later (measured, not assumed: any later read must give the same stamp).
  while (mono_ns() < after + 30'000'000) std::this_thread::yield();
  can_frame f{};
  std::int64_t stamp = 0;
  ASSERT_EQ(b->read(f, stamp), CanIo::Ok);
  EXPECT_EQ(f.can_id, 0x80u);
  // Kernel stamps are CLOCK_REALTIME, converted at the read: a few us of slack.
  EXPECT_GE(stamp, before - 1'000'000);
  EXPECT_LE(stamp, after + 1'000'000);
  EXPECT_EQ(b->read(f, stamp), CanIo::WouldBlock);
}

TEST(MockCanBus, ReceiveFiltersFollowSocketCanSemantics) {
  auto [a, b] = MockCanBus::create_pair("t");
  const can_filter filters[] = {{0x180, 0x780}, {0x700 | CAN_INV_FILTER, 0x7FF}};
  b->set_filters(filters);
  // 0x185 passes filter 1; 0x701 passes the inverted filter 2 (anything but 0x700);
  // 0x700 passes neither.
  ASSERT_EQ(a->write(make_frame(0x700, {1})), CanIo::Ok);
  ASSERT_EQ(a->write(make_frame(0x185, {2})), CanIo::Ok);
  ASSERT_EQ(a->write(make_frame(0x701, {3})), CanIo::Ok);
  can_frame f{};
  ASSERT_EQ(b->read(f), CanIo::Ok);
  EXPECT_EQ(f.can_id, 0x185u);
  ASSERT_EQ(b->read(f), CanIo::Ok);
  EXPECT_EQ(f.can_id, 0x701u);
  EXPECT_EQ(b->read(f), CanIo::WouldBlock);
  EXPECT_EQ(b->health().filtered, 1u);
}

TEST(MockCanBus, ErrorFramesUpdateHealthAndBusOff) {
  auto [a, b] = MockCanBus::create_pair("t");
  can_frame passive = make_frame(CAN_ERR_FLAG | CAN_ERR_CRTL, {0, CAN_ERR_CRTL_TX_PASSIVE, 0, 0, 0, 0, 0, 0});
  can_frame busoff = make_frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF, {0, 0, 0, 0, 0, 0, 0, 0});
  can_frame restarted = make_frame(CAN_ERR_FLAG | CAN_ERR_RESTARTED, {0, 0, 0, 0, 0, 0, 0, 0});
  ASSERT_EQ(a->write(passive), CanIo::Ok);
  ASSERT_EQ(a->write(busoff), CanIo::Ok);
  can_frame f{};
  EXPECT_EQ(b->read(f), CanIo::ErrorFrame);
  EXPECT_TRUE(b->health().error_passive);
  EXPECT_FALSE(b->health().bus_off);
  EXPECT_EQ(b->read(f), CanIo::ErrorFrame);
  EXPECT_TRUE(b->health().bus_off);
  EXPECT_EQ(b->health().error_frames, 2u);
  ASSERT_EQ(a->write(restarted), CanIo::Ok);
  EXPECT_EQ(b->read(f), CanIo::ErrorFrame);
  EXPECT_FALSE(b->health().bus_off);
}

TEST(MockCanBus, DatagramThatIsNotACanFrameIsMalformed) {
  auto [a, b] = MockCanBus::create_pair("t");
  const char junk[5] = {1, 2, 3, 4, 5};
  ASSERT_EQ(::send(a->fd(), junk, sizeof junk, 0), 5);
  can_frame bad_dlc = make_frame(0x181, {});
  bad_dlc.can_dlc = 12;
  ASSERT_EQ(::send(a->fd(), &bad_dlc, sizeof bad_dlc, 0), static_cast<ssize_t>(sizeof bad_dlc));
  can_frame f{};
  EXPECT_EQ(b->read(f), CanIo::Malformed);
  EXPECT_EQ(b->read(f), CanIo::Malformed);
  EXPECT_EQ(b->health().malformed, 2u);
  EXPECT_EQ(a->write(bad_dlc), CanIo::Malformed);  // never sent
}

TEST(MockCanBus, FullQueueIsWouldBlockNotABlock) {
  auto [a, b] = MockCanBus::create_pair("t");
  const can_frame f = make_frame(0x200, {1, 2, 3, 4, 5, 6});
  int sent = 0;
  CanIo io = CanIo::Ok;
  const auto t0 = std::chrono::steady_clock::now();
  while ((io = a->write(f)) == CanIo::Ok && sent < 1000000) ++sent;
  EXPECT_EQ(io, CanIo::WouldBlock);
  EXPECT_GT(sent, 100);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
}

TEST(MockCanBus, PeerClosedIsReported) {
  auto [a, b] = MockCanBus::create_pair("t");
  b.reset();
  can_frame f{};
  EXPECT_EQ(a->read(f), CanIo::Closed);
  EXPECT_EQ(a->write(make_frame(0x80, {})), CanIo::Closed);
}

TEST(MockCanBus, FarEndInAnotherProcess) {
  auto [a, b] = MockCanBus::create_pair("t");
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    // child: echo 50 frames back with id + 1, then exit
    a.reset();
    int echoed = 0;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (echoed < 50 && std::chrono::steady_clock::now() < end) {
      can_frame f{};
      if (b->read(f) == CanIo::Ok) {
        f.can_id += 1;
        while (b->write(f) == CanIo::WouldBlock) {
        }
        ++echoed;
      } else {
        std::this_thread::sleep_for(std::chrono::microseconds(100));
      }
    }
    ::_exit(echoed == 50 ? 0 : 1);
  }
  b.reset();
  int got = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  for (int i = 0; i < 50; ++i) ASSERT_EQ(a->write(make_frame(0x300, {static_cast<std::uint8_t>(i)})), CanIo::Ok);
  while (got < 50 && std::chrono::steady_clock::now() < end) {
    can_frame f{};
    if (a->read(f) == CanIo::Ok) {
      EXPECT_EQ(f.can_id, 0x301u);
      EXPECT_EQ(f.data[0], got);
      ++got;
    } else {
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
  }
  EXPECT_EQ(got, 50);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

// Issue 12: SocketCanBus::set_filters({}) gave the kernel an empty list, and
// an empty CAN_RAW_FILTER list delivers no data frame at all. "Empty means
// everything" must reach the kernel as one pass-all filter.
TEST(SocketCanBus, EmptyFilterListReachesTheKernelAsPassAll) {
  const std::vector<can_filter> k = detail::kernel_filters({});
  ASSERT_EQ(k.size(), 1u);
  for (canid_t id : {0x000u, 0x080u, 0x181u, 0x7FFu, 0x1FFFFFFFu})
    EXPECT_EQ(id & k[0].can_mask, k[0].can_id & k[0].can_mask) << id;
  const can_filter two[] = {{0x180, 0x780}, {0x700, 0x7FF}};
  const std::vector<can_filter> same = detail::kernel_filters(two);
  ASSERT_EQ(same.size(), 2u);
  EXPECT_EQ(same[1].can_id, 0x700u);
  // The mock bus agrees: an empty list passes everything.
  auto [a, b] = MockCanBus::create_pair("t");
  b->set_filters({});
  ASSERT_EQ(a->write(make_frame(0x555, {1})), CanIo::Ok);
  can_frame f{};
  EXPECT_EQ(b->read(f), CanIo::Ok);
}

// Issue 12: ENETDOWN is "interface not up", not bus-off; bus-off is learned
// only from a CAN_ERR_BUSOFF error frame.
TEST(CanBus, EnetdownIsInterfaceDownNotBusOff) {
  BusHealth healthy;
  EXPECT_EQ(detail::io_from_errno(ENETDOWN, healthy), CanIo::NetDown);
  EXPECT_STREQ(to_string(CanIo::NetDown), "interface down (ENETDOWN)");
  EXPECT_EQ(detail::io_from_errno(ENOBUFS, healthy), CanIo::WouldBlock);
  EXPECT_EQ(detail::io_from_errno(EAGAIN, healthy), CanIo::WouldBlock);
  BusHealth off;
  off.bus_off = true;
  EXPECT_EQ(detail::io_from_errno(ENETDOWN, off), CanIo::NetDown);
  EXPECT_EQ(detail::io_from_errno(ENOBUFS, off), CanIo::BusOff);  // queue full because the controller is off
  EXPECT_EQ(detail::io_from_errno(EPIPE, healthy), CanIo::Closed);
  EXPECT_EQ(detail::io_from_errno(EIO, healthy), CanIo::SysError);
  // On a bus whose controller reported bus-off, a full queue is BusOff.
  auto [a, b] = MockCanBus::create_pair("t");
  ASSERT_EQ(b->write(make_frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF, {0, 0, 0, 0, 0, 0, 0, 0})), CanIo::Ok);
  can_frame f{};
  ASSERT_EQ(a->read(f), CanIo::ErrorFrame);
  ASSERT_TRUE(a->health().bus_off);
  CanIo io = CanIo::Ok;
  for (int i = 0; i < 100000 && io == CanIo::Ok; ++i) io = a->write(make_frame(0x181, {1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(io, CanIo::BusOff);
}
