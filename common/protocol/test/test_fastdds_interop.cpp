// Interoperability over RTPS on loopback: this Cyclone DDS process against
// foresight_fastdds_peer, an eProsima Fast DDS participant whose types
// fastddsgen generated from the same IDL. JointState goes to Fast DDS and
// comes back field by field; pings are answered with four-timestamp pongs.
// Each TEST runs in its own process with its own domain and its own peer.

#include <gtest/gtest.h>

#include "foresight/test/child_process.hpp"
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <thread>
#include <vector>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/loopback.hpp"


namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

constexpr auto kDiscovery = 30s;

class FastDdsInterop : public ::testing::Test {
 protected:
  void SetUp() override {
    fp::use_loopback_if_unconfigured();
    domain_ = fp::unique_test_domain();
    foresight::test::ChildProcess::Options o;
    o.stop_grace_s = 5.0;
    peer_ = std::make_unique<foresight::test::ChildProcess>(
        std::vector<std::string>{std::string(FORESIGHT_BIN_DIR) + "/foresight_fastdds_peer", "--domain",
                                 std::to_string(domain_), "--lifetime-s", "110"},
        o);
    participant_ = std::make_unique<fp::Participant>(domain_);
  }
  void TearDown() override {
    participant_.reset();
    if (peer_) {
      EXPECT_TRUE(peer_->running()) << "the Fast DDS peer exited early";
    }
    peer_.reset();
  }
  dds_domainid_t domain_ = 0;
  std::unique_ptr<foresight::test::ChildProcess> peer_;
  std::unique_ptr<fp::Participant> participant_;
};

}  // namespace

TEST_F(FastDdsInterop, FastDdsReadsJointStateFieldByField) {
  fp::Writer<msg::JointState> writer(*participant_);
  fp::Reader<msg::JointState> echo(*participant_, std::string(fp::topics::kJointState) + "/echo");
  ASSERT_TRUE(writer.wait_for_readers(1, kDiscovery)) << "Fast DDS's reader did not match";
  ASSERT_TRUE(echo.wait_for_writers(1, kDiscovery)) << "Fast DDS's echo writer did not match";
  fp::Sample<msg::JointState> sent;
  sent->stamp_ns = 1'234'567'890'123'456'789;
  sent->cycle = 42;
  const std::vector<double> q{0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7};
  const std::vector<double> dq{1, 2, 3, 4, 5, 6, 7};
  const std::vector<double> tau{-1.5, 2.5, -3.5};
  fp::assign(sent->q_rad, std::span<const double>(q), msg::kMaxJoints, "q");
  fp::assign(sent->dq_rad_s, std::span<const double>(dq), msg::kMaxJoints, "dq");
  fp::assign(sent->torque_nm, std::span<const double>(tau), msg::kMaxJoints, "tau");
  fp::Sample<msg::JointState> got;
  bool back = false;
  // Best effort: re-send until the echo comes (a sample written before the
  // far reader finished matching is legitimately lost).
  const auto deadline = Clock::now() + kDiscovery;
  while (!back && Clock::now() < deadline) {
    writer.write(sent);
    back = echo.wait_take(got, 250ms);
  }
  ASSERT_TRUE(back) << "no JointState came back from Fast DDS";
  EXPECT_EQ(got->stamp_ns, sent->stamp_ns);
  EXPECT_EQ(got->cycle, 42u);
  const auto gq = fp::view(got->q_rad), gdq = fp::view(got->dq_rad_s), gt = fp::view(got->torque_nm);
  EXPECT_EQ(std::vector<double>(gq.begin(), gq.end()), q);
  EXPECT_EQ(std::vector<double>(gdq.begin(), gdq.end()), dq);
  EXPECT_EQ(std::vector<double>(gt.begin(), gt.end()), tau);
}

TEST_F(FastDdsInterop, FastDdsAnswersPingsWithFourTimestamps) {
  fp::Writer<msg::Ping> ping(*participant_);
  fp::Reader<msg::Pong> pong(*participant_);
  ASSERT_TRUE(ping.wait_for_readers(1, kDiscovery));
  ASSERT_TRUE(pong.wait_for_writers(1, kDiscovery));
  fp::Sample<msg::Pong> got;
  int answered = 0;
  std::uint64_t id = 0;
  const auto deadline = Clock::now() + kDiscovery;
  while (answered < 100 && Clock::now() < deadline) {
    msg::Ping p{};
    p.ping_id = ++id;
    p.ground_send_ns = fp::now_ns();
    ping.write(p);
    while (pong.wait_take(got, 250ms)) {
      if (got->ping_id != id) continue;
      const std::int64_t t4 = fp::now_ns();
      EXPECT_EQ(got->ground_send_ns, p.ground_send_ns);
      EXPECT_LE(got->remote_receive_ns, got->remote_send_ns);
      const auto d = fp::delay_from_pong(*got, t4);
      EXPECT_GT(d.rtt_ns, 0);
      // One clock: t1 <= t2 <= t3 <= t4, so the offset is within half the round trip.
      EXPECT_LE(std::abs(d.offset_ns), d.rtt_ns / 2 + 1000);
      ++answered;
      break;
    }
  }
  EXPECT_EQ(answered, 100);
}
