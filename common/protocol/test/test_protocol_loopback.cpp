// Two real processes on loopback: this test and foresight_protocol_peer
// (built beside it; FORESIGHT_BIN_DIR). Every message type goes to the peer
// and comes back (the peer echoes topic X on "X/echo"); every field is
// checked. The peer also answers like a minimal remote (pongs, acks, upload
// status), which checks the flows: a chunked 2000x7 trajectory upload ->
// assembled -> verified -> committed -> run -> completed with final joint
// angles, and rejections with their reasons.
//
// Each TEST runs in its own process (gtest_discover_tests) with its own DDS
// domain derived from the pid, its own peer, and bounded waits; the peer is
// killed in TearDown whatever happened (and dies with us: PR_SET_PDEATHSIG).

#include <dds/ddsi/ddsi_cdrstream.h>
#include <gtest/gtest.h>

#include "foresight/test/child_process.hpp"
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <span>
#include <thread>
#include <vector>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/command.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/trajectory_upload.hpp"


namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

constexpr auto kDiscoveryTimeout = 10s;
constexpr auto kReplyTimeout = 10s;

/// The peer process; killed (SIGTERM, then SIGKILL) on destruction.
class PeerProcess {
 public:
  explicit PeerProcess(dds_domainid_t domain)
      : process_({std::string(FORESIGHT_BIN_DIR) + "/foresight_protocol_peer", "--domain", std::to_string(domain),
                  "--lifetime-s", "110"},
                 options()) {}
  /// True while the peer runs (it exits early only on a failure of its own).
  bool running() { return process_.running(); }
  void stop() { process_.stop(SIGTERM, 3.0); }

 private:
  static foresight::test::ChildProcess::Options options() {
    foresight::test::ChildProcess::Options o;
    o.stop_grace_s = 3.0;
    return o;
  }
  foresight::test::ChildProcess process_;
};

std::string echo_topic(const char* topic) { return std::string(topic) + "/echo"; }

class ProtocolLoopback : public ::testing::Test {
 protected:
  void SetUp() override {
    fp::use_loopback_if_unconfigured();
    domain_ = fp::unique_test_domain();
    peer_ = std::make_unique<PeerProcess>(domain_);
    participant_ = std::make_unique<fp::Participant>(domain_);
  }
  void TearDown() override {
    if (peer_ != nullptr) {
      EXPECT_TRUE(peer_->running()) << "the peer exited early (see its stderr above)";
      peer_.reset();
    }  // kill before the participant goes: no half-matched endpoints linger
    participant_.reset();
  }

  /// Writes `sent` on its topic and returns what the peer echoed back.
  /// Re-sends every 250 ms until the echo arrives: a best-effort sample (and
  /// on a fresh match even a volatile reliable one) written before the peer's
  /// reader has matched our writer is legitimately lost.
  template <fp::Message T>
  fp::Sample<T> round_trip(const T& sent, std::uint32_t peer_readers = 1) {
    const char* topic = fp::MessageTraits<T>::topic;
    fp::Writer<T> writer(*participant_, topic);
    fp::Reader<T> echo(*participant_, echo_topic(topic), fp::MessageTraits<T>::qos());
    EXPECT_TRUE(writer.wait_for_readers(peer_readers, kDiscoveryTimeout)) << topic;
    EXPECT_TRUE(echo.wait_for_writers(1, kDiscoveryTimeout)) << topic;
    fp::Sample<T> got;
    const auto deadline = Clock::now() + kReplyTimeout;
    while (Clock::now() < deadline && peer_->running()) {
      writer.write(sent);
      if (echo.wait_take(got, 250ms)) return got;
    }
    ADD_FAILURE() << "no echo on " << echo_topic(topic);
    return got;
  }

  dds_domainid_t domain_ = 0;
  std::unique_ptr<PeerProcess> peer_;
  std::unique_ptr<fp::Participant> participant_;
};

/// The ground side of the command/ack and upload flows.
struct GroundLink {
  explicit GroundLink(const fp::Participant& p) : command(p), ack(p), chunk(p), status(p) {}

  /// Waits for discovery and proves the command path with REQUEST commands
  /// (re-sent until the first RECEIVED ack: see round_trip()).
  void connect() {
    ASSERT_TRUE(command.wait_for_readers(2, kDiscoveryTimeout));  // the peer's echo + its mini remote
    ASSERT_TRUE(ack.wait_for_writers(1, kDiscoveryTimeout));
    ASSERT_TRUE(chunk.wait_for_readers(2, kDiscoveryTimeout));
    ASSERT_TRUE(status.wait_for_writers(1, kDiscoveryTimeout));
    const auto deadline = Clock::now() + kReplyTimeout;
    fp::Sample<msg::CommandAck> a;
    while (Clock::now() < deadline) {
      fp::Sample<msg::Command> c = make(foresight_msg_CMD_REQUEST);
      c->payload._u.request.what = foresight_msg_REQUEST_STATUS;
      command.write(c);
      if (ack.wait_take(a, 250ms)) {
        // Drain the rest of this and any earlier warm-up command's acks.
        while (ack.wait_take(a, 100ms)) {
        }
        return;
      }
    }
    FAIL() << "the peer never acknowledged a command";
  }

  fp::Sample<msg::Command> make(msg::CommandKind kind) { return sequencer.next(kind); }

  /// Collects acks of `command_id` until a terminal state (or timeout).
  std::vector<fp::Sample<msg::CommandAck>> acks_until_done(std::uint64_t command_id) {
    std::vector<fp::Sample<msg::CommandAck>> out;
    const auto deadline = Clock::now() + kReplyTimeout;
    fp::Sample<msg::CommandAck> a;
    while (Clock::now() < deadline && ack.wait_take(a, deadline - Clock::now())) {
      if (a->command_id != command_id) continue;
      const msg::AckState s = a->state;
      out.push_back(std::move(a));
      if (fp::is_terminal(s)) break;
    }
    return out;
  }

  /// Waits for the status of `id` to leave UPLOAD_ASSEMBLING.
  fp::Sample<msg::TrajectoryStatus> final_status(std::uint64_t id) {
    fp::Sample<msg::TrajectoryStatus> s;
    const auto deadline = Clock::now() + kReplyTimeout;
    while (Clock::now() < deadline && status.wait_take(s, deadline - Clock::now())) {
      if (s->trajectory_id == id && s->state != foresight_msg_UPLOAD_ASSEMBLING) return s;
    }
    ADD_FAILURE() << "no final status for trajectory " << id;
    return s;
  }

  fp::Writer<msg::Command> command;
  fp::Reader<msg::CommandAck> ack;
  fp::Writer<msg::TrajectoryChunk> chunk;
  fp::Reader<msg::TrajectoryStatus> status;
  fp::CommandSequencer sequencer;
};

foresight::Trajectory make_trajectory(int samples, int joints) {
  foresight::Trajectory t;
  t.time_s.resize(static_cast<std::size_t>(samples));
  t.positions_rad.resize(samples, joints);
  for (int s = 0; s < samples; ++s) {
    const double time = 0.01 * s;
    t.time_s[static_cast<std::size_t>(s)] = time;
    for (int j = 0; j < joints; ++j) t.positions_rad(s, j) = 0.4 * std::sin(0.5 * time + 0.7 * j) + 1e-3 * j;
  }
  return t;
}

std::vector<double> seq(const dds_sequence_double& s) { return {s._buffer, s._buffer + s._length}; }

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
}

}  // namespace

// ------------------------------------------------------------- telemetry etc.

TEST_F(ProtocolLoopback, JointStateRoundTrip) {
  fp::Sample<msg::JointState> js;
  js->stamp_ns = 1'700'000'000'123'456'789;
  js->cycle = 987654321;
  const std::vector<double> q{0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7};
  const std::vector<double> dq{1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3, -7e-3};
  const std::vector<double> tau{10.5, 20.25, -30.125, 4.0, 5.0, 6.0, 0.0};
  fp::assign(js->q_rad, std::span<const double>(q), msg::kMaxJoints, "q");
  fp::assign(js->dq_rad_s, std::span<const double>(dq), msg::kMaxJoints, "dq");
  fp::assign(js->torque_nm, std::span<const double>(tau), msg::kMaxJoints, "tau");
  const auto got = round_trip(*js);
  EXPECT_EQ(got->stamp_ns, js->stamp_ns);
  EXPECT_EQ(got->cycle, js->cycle);
  EXPECT_EQ(seq(got->q_rad), q);
  EXPECT_EQ(seq(got->dq_rad_s), dq);
  EXPECT_EQ(seq(got->torque_nm), tau);
}

TEST_F(ProtocolLoopback, WrenchRoundTrip) {
  msg::Wrench w{};
  w.stamp_ns = -5;  // signed stamps survive
  const double f[3] = {1.5, -2.5, 30.0}, t[3] = {0.1, -0.2, 0.3};
  std::copy(f, f + 3, w.force_tool_n);
  std::copy(t, t + 3, w.torque_tool_nm);
  w.saturated = true;
  const auto got = round_trip(w);
  EXPECT_EQ(got->stamp_ns, -5);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(got->force_tool_n[i], f[i]);
    EXPECT_EQ(got->torque_tool_nm[i], t[i]);
  }
  EXPECT_TRUE(got->saturated);
}

TEST_F(ProtocolLoopback, ToolStateRoundTrip) {
  msg::ToolState s{};
  s.stamp_ns = 42;
  s.latched = true;
  s.running = true;
  s.direction = foresight_msg_TOOL_LOOSEN;
  s.turns = 3.25;
  s.torque_nm = 12.5;
  s.fault_bits = 0x80000005u;
  const auto got = round_trip(s);
  EXPECT_EQ(got->stamp_ns, 42);
  EXPECT_TRUE(got->latched);
  EXPECT_TRUE(got->running);
  EXPECT_EQ(got->direction, foresight_msg_TOOL_LOOSEN);
  EXPECT_EQ(got->turns, 3.25);
  EXPECT_EQ(got->torque_nm, 12.5);
  EXPECT_EQ(got->fault_bits, 0x80000005u);
}

TEST_F(ProtocolLoopback, ControllerStatusAndHeartbeatRoundTrip) {
  msg::ControllerStatus s{};
  s.stamp_ns = 123;
  s.mode = foresight_msg_MODE_STOPPED;
  s.active_command_id = 77;
  s.active_trajectory_id = 88;
  s.last_sequence = 99;
  s.stop_category = foresight_msg_STOP_CAT1;
  fp::set_text(s.stop_reason, "wrench |f| 152.0 N over the 150 N limit at cycle 4711", "stop_reason");
  s.fault_bits = 0x10;
  fp::set_text(s.fault_text, "drive 3: following error", "fault_text");
  const auto got = round_trip(s);
  EXPECT_EQ(got->stamp_ns, 123);
  EXPECT_EQ(got->mode, foresight_msg_MODE_STOPPED);
  EXPECT_EQ(got->active_command_id, 77u);
  EXPECT_EQ(got->active_trajectory_id, 88u);
  EXPECT_EQ(got->last_sequence, 99u);
  EXPECT_EQ(got->stop_category, foresight_msg_STOP_CAT1);
  EXPECT_EQ(fp::text(got->stop_reason), "wrench |f| 152.0 N over the 150 N limit at cycle 4711");
  EXPECT_EQ(got->fault_bits, 0x10u);
  EXPECT_EQ(fp::text(got->fault_text), "drive 3: following error");

  msg::Heartbeat hb{};
  hb.side = foresight_msg_SIDE_GROUND;
  hb.boot_id = 0xdeadbeefcafef00dull;
  hb.counter = 12345;
  hb.stamp_ns = 1'700'000'000'000'000'000;
  const auto beat = round_trip(hb);
  EXPECT_EQ(beat->side, foresight_msg_SIDE_GROUND);
  EXPECT_EQ(beat->boot_id, 0xdeadbeefcafef00dull);
  EXPECT_EQ(beat->counter, 12345u);
  EXPECT_EQ(beat->stamp_ns, hb.stamp_ns);
}

TEST_F(ProtocolLoopback, AckStatusPingPongRoundTrip) {
  fp::Sample<msg::CommandAck> a;
  a->session_id = 3;
  a->command_id = 44;
  a->sequence_number = 5;
  a->kind = foresight_msg_CMD_GOTO_CART;
  a->state = foresight_msg_ACK_FAILED;
  a->code = foresight_msg_REASON_FORCE_LIMIT;
  fp::set_text(a->reason, "force limit 150 N exceeded", "reason");
  a->stamp_ns = 66;
  const std::vector<double> q{0.25, 0.5, 0.75};
  fp::assign(a->final_q_rad, std::span<const double>(q), msg::kMaxJoints, "final_q");
  const auto ack = round_trip(*a);
  EXPECT_EQ(ack->session_id, 3u);
  EXPECT_EQ(ack->command_id, 44u);
  EXPECT_EQ(ack->sequence_number, 5u);
  EXPECT_EQ(ack->kind, foresight_msg_CMD_GOTO_CART);
  EXPECT_EQ(ack->state, foresight_msg_ACK_FAILED);
  EXPECT_EQ(ack->code, foresight_msg_REASON_FORCE_LIMIT);
  EXPECT_EQ(fp::text(ack->reason), "force limit 150 N exceeded");
  EXPECT_EQ(ack->stamp_ns, 66);
  EXPECT_EQ(seq(ack->final_q_rad), q);

  msg::TrajectoryStatus s{};
  s.trajectory_id = 9;
  s.state = foresight_msg_UPLOAD_REJECTED;
  s.chunks_received = 3;
  s.chunk_count = 4;
  for (int i = 0; i < 32; ++i) s.content_hash[i] = static_cast<std::uint8_t>(255 - i);
  s.code = foresight_msg_REASON_VALIDATION_FAILED;
  fp::set_text(s.reason, "row 17 joint 3: velocity 2.1 rad/s over 2.0", "reason");
  s.stamp_ns = 77;
  const auto st = round_trip(s);
  EXPECT_EQ(st->trajectory_id, 9u);
  EXPECT_EQ(st->state, foresight_msg_UPLOAD_REJECTED);
  EXPECT_EQ(st->chunks_received, 3u);
  EXPECT_EQ(st->chunk_count, 4u);
  EXPECT_EQ(0, std::memcmp(st->content_hash, s.content_hash, 32));
  EXPECT_EQ(st->code, foresight_msg_REASON_VALIDATION_FAILED);
  EXPECT_EQ(fp::text(st->reason), "row 17 joint 3: velocity 2.1 rad/s over 2.0");
  EXPECT_EQ(st->stamp_ns, 77);

  msg::Ping ping{};
  ping.ping_id = 31;
  ping.ground_send_ns = 1234567;
  const auto pg = round_trip(ping, 2);  // the peer's echo and its pong responder
  EXPECT_EQ(pg->ping_id, 31u);
  EXPECT_EQ(pg->ground_send_ns, 1234567);

  msg::Pong pong{};
  pong.ping_id = 32;
  pong.ground_send_ns = 1;
  pong.remote_receive_ns = 2;
  pong.remote_send_ns = 3;
  const auto po = round_trip(pong);
  EXPECT_EQ(po->ping_id, 32u);
  EXPECT_EQ(po->ground_send_ns, 1);
  EXPECT_EQ(po->remote_receive_ns, 2);
  EXPECT_EQ(po->remote_send_ns, 3);
}

// ------------------------------------------------------------------ commands

TEST_F(ProtocolLoopback, EveryCommandKindRoundTrips) {
  std::uint64_t sequence = 500;
  auto envelope = [&](fp::Sample<msg::Command>& c, msg::CommandKind kind) {
    c->protocol_version = msg::kProtocolVersion;
    c->session_id = 0xabcdef;
    c->sequence_number = ++sequence;
    c->command_id = 9000 + sequence;
    c->issued_ns = 1'700'000'000'000'000'000 + static_cast<std::int64_t>(sequence);
    c->expires_ns = c->issued_ns + 5'000'000'000;
    c->payload._d = kind;
  };
  auto check_envelope = [&](const msg::Command& got, const msg::Command& sent) {
    EXPECT_EQ(got.protocol_version, sent.protocol_version);
    EXPECT_EQ(got.session_id, sent.session_id);
    EXPECT_EQ(got.sequence_number, sent.sequence_number);
    EXPECT_EQ(got.command_id, sent.command_id);
    EXPECT_EQ(got.issued_ns, sent.issued_ns);
    EXPECT_EQ(got.expires_ns, sent.expires_ns);
    EXPECT_EQ(got.payload._d, sent.payload._d);
  };
  {
    SCOPED_TRACE("TRAJECTORY");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_TRAJECTORY);
    auto& p = c->payload._u.trajectory;
    p.trajectory_id = 0x0123456789abcdefull;
    for (int i = 0; i < 32; ++i) p.content_hash[i] = static_cast<std::uint8_t>(i * 7);
    p.compliant = true;
    p.start_tolerance_rad = 0.01;
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    const auto& g = got->payload._u.trajectory;
    EXPECT_EQ(g.trajectory_id, p.trajectory_id);
    EXPECT_EQ(0, std::memcmp(g.content_hash, p.content_hash, 32));
    EXPECT_TRUE(g.compliant);
    EXPECT_EQ(g.start_tolerance_rad, 0.01);
  }
  {
    SCOPED_TRACE("INVOKE_ALGORITHM");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_INVOKE_ALGORITHM);
    auto& p = c->payload._u.algorithm;
    fp::set_text(p.name, "guarded_insert", "name");
    std::vector<msg::NamedValue> params(2);
    fp::set_text(params[0].name, "depth_m", "param");
    params[0].value = 0.05;
    fp::set_text(params[1].name, "force_limit_n", "param");
    params[1].value = 40.0;
    fp::assign(p.params, std::span<const msg::NamedValue>(params), msg::kMaxParams, "params");
    p.timeout_s = 30.0;
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    const auto& g = got->payload._u.algorithm;
    EXPECT_EQ(fp::text(g.name), "guarded_insert");
    ASSERT_EQ(g.params._length, 2u);
    EXPECT_EQ(fp::text(g.params._buffer[0].name), "depth_m");
    EXPECT_EQ(g.params._buffer[0].value, 0.05);
    EXPECT_EQ(fp::text(g.params._buffer[1].name), "force_limit_n");
    EXPECT_EQ(g.params._buffer[1].value, 40.0);
    EXPECT_EQ(g.timeout_s, 30.0);
  }
  {
    SCOPED_TRACE("REQUEST");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_REQUEST);
    c->payload._u.request.what = foresight_msg_REQUEST_TRAJECTORIES;
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    EXPECT_EQ(got->payload._u.request.what, foresight_msg_REQUEST_TRAJECTORIES);
  }
  {
    SCOPED_TRACE("CAMERA");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_CAMERA);
    auto& p = c->payload._u.camera;
    fp::set_text(p.camera, "overhead", "camera");
    p.action = foresight_msg_CAMERA_POINT;
    p.pan_rad = 0.3;
    p.tilt_rad = -0.2;
    p.focal_px = 800.0;
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    const auto& g = got->payload._u.camera;
    EXPECT_EQ(fp::text(g.camera), "overhead");
    EXPECT_EQ(g.action, foresight_msg_CAMERA_POINT);
    EXPECT_EQ(g.pan_rad, 0.3);
    EXPECT_EQ(g.tilt_rad, -0.2);
    EXPECT_EQ(g.focal_px, 800.0);
  }
  {
    SCOPED_TRACE("GOTO_JOINT");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_GOTO_JOINT);
    const std::vector<double> q{0.0, 0.5, 0.0, -1.2, 0.0, 0.7, 0.1};
    fp::assign(c->payload._u.goto_joint.q_rad, std::span<const double>(q), msg::kMaxJoints, "q");
    c->payload._u.goto_joint.speed_fraction = 0.25;
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    EXPECT_EQ(seq(got->payload._u.goto_joint.q_rad), q);
    EXPECT_EQ(got->payload._u.goto_joint.speed_fraction, 0.25);
  }
  {
    SCOPED_TRACE("GOTO_CART");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_GOTO_CART);
    auto& p = c->payload._u.goto_cart;
    fp::set_text(p.frame, "lst_tip", "frame");
    const double pos[3] = {0.8, -0.1, 0.45}, quat[4] = {0.0, 0.7071067811865476, 0.0, 0.7071067811865476};
    std::copy(pos, pos + 3, p.position_m);
    std::copy(quat, quat + 4, p.orientation_xyzw);
    p.speed_fraction = 0.5;
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    const auto& g = got->payload._u.goto_cart;
    EXPECT_EQ(fp::text(g.frame), "lst_tip");
    for (int i = 0; i < 3; ++i) EXPECT_EQ(g.position_m[i], pos[i]);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(g.orientation_xyzw[i], quat[i]);
    EXPECT_EQ(g.speed_fraction, 0.5);
  }
  {
    SCOPED_TRACE("ABORT");
    fp::Sample<msg::Command> c;
    envelope(c, foresight_msg_CMD_ABORT);
    auto& p = c->payload._u.abort;
    p.target_command_id = 9503;
    p.category = foresight_msg_STOP_CAT2;
    fp::set_text(p.reason, "operator pressed stop", "reason");
    const auto got = round_trip(*c, 2);
    check_envelope(*got, *c);
    const auto& g = got->payload._u.abort;
    EXPECT_EQ(g.target_command_id, 9503u);
    EXPECT_EQ(g.category, foresight_msg_STOP_CAT2);
    EXPECT_EQ(fp::text(g.reason), "operator pressed stop");
  }
}

TEST_F(ProtocolLoopback, GotoJointIsAcknowledgedThroughCompletionWithFinalJointAngles) {
  GroundLink link(*participant_);
  ASSERT_NO_FATAL_FAILURE(link.connect());
  fp::Sample<msg::Command> c = link.make(foresight_msg_CMD_GOTO_JOINT);
  const std::vector<double> q{0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7};
  fp::assign(c->payload._u.goto_joint.q_rad, std::span<const double>(q), msg::kMaxJoints, "q");
  c->payload._u.goto_joint.speed_fraction = 0.5;
  link.command.write(c);
  const auto acks = link.acks_until_done(c->command_id);
  ASSERT_EQ(acks.size(), 4u);
  const msg::AckState expected[] = {foresight_msg_ACK_RECEIVED, foresight_msg_ACK_QUEUED, foresight_msg_ACK_EXECUTING,
                                    foresight_msg_ACK_COMPLETED};
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(acks[i]->state, expected[i]) << fp::to_string(static_cast<fp::AckState>(acks[i]->state));
    EXPECT_EQ(acks[i]->session_id, c->session_id);
    EXPECT_EQ(acks[i]->sequence_number, c->sequence_number);
    EXPECT_EQ(acks[i]->kind, foresight_msg_CMD_GOTO_JOINT);
    EXPECT_EQ(acks[i]->code, foresight_msg_REASON_NONE);
  }
  EXPECT_EQ(seq(acks[3]->final_q_rad), q);  // the update step: the ground resets its arm to these
}

TEST_F(ProtocolLoopback, BadCommandsAreRejectedWithReasonCodeAndText) {
  GroundLink link(*participant_);
  ASSERT_NO_FATAL_FAILURE(link.connect());
  {
    fp::Sample<msg::Command> c = link.make(foresight_msg_CMD_TRAJECTORY);
    c->payload._u.trajectory.trajectory_id = 999;
    link.command.write(c);
    const auto acks = link.acks_until_done(c->command_id);
    ASSERT_EQ(acks.size(), 2u);
    EXPECT_EQ(acks[0]->state, foresight_msg_ACK_RECEIVED);
    EXPECT_EQ(acks[1]->state, foresight_msg_ACK_REJECTED);
    EXPECT_EQ(acks[1]->code, foresight_msg_REASON_UNKNOWN_TRAJECTORY);
    EXPECT_EQ(fp::text(acks[1]->reason), "trajectory 999 is not committed");
  }
  {
    fp::Sample<msg::Command> c = link.make(foresight_msg_CMD_REQUEST);
    c->protocol_version = 99;
    link.command.write(c);
    const auto acks = link.acks_until_done(c->command_id);
    ASSERT_EQ(acks.size(), 2u);
    EXPECT_EQ(acks[1]->code, foresight_msg_REASON_VERSION_MISMATCH);
    EXPECT_EQ(fp::text(acks[1]->reason),
              "command " + std::to_string(c->command_id) + ": protocol version 99, this remote speaks " + std::to_string(msg::kProtocolVersion));
  }
  {
    fp::Sample<msg::Command> c = link.make(foresight_msg_CMD_REQUEST);
    c->sequence_number = 1;  // a replay
    link.command.write(c);
    const auto acks = link.acks_until_done(c->command_id);
    ASSERT_EQ(acks.size(), 2u);
    EXPECT_EQ(acks[1]->code, foresight_msg_REASON_BAD_SEQUENCE);
    EXPECT_EQ(fp::text(acks[1]->reason), "command " + std::to_string(c->command_id) + ": sequence 1 is not after " +
                                             std::to_string(link.sequencer.last_sequence() - 2) +
                                             " (replayed or reordered)");
  }
}

// ------------------------------------------------------------------- uploads

TEST_F(ProtocolLoopback, ChunkedTrajectoryUploadIsAssembledVerifiedCommittedAndRun) {
  GroundLink link(*participant_);
  ASSERT_NO_FATAL_FAILURE(link.connect());
  // Transient-local, as the peer's echo writer: the echoes reach this reader
  // even when the peer's writer has not yet matched it (discovery is not
  // symmetric in time; a volatile echo would then be lost).
  fp::Reader<msg::TrajectoryChunk> echo(*participant_, echo_topic(fp::topics::kTrajectoryChunk),
                                        fp::qos::trajectory_chunk().transient_local());
  ASSERT_TRUE(echo.wait_for_writers(1, kDiscoveryTimeout));

  // Prove the chunk echo path first, as round_trip() does: the peer's echo
  // reader may not have matched link.chunk yet (discovery is not symmetric),
  // and a volatile reader skips what was written before its match. A 1-chunk
  // warm-up upload is re-sent until its echo comes back.
  {
    const foresight::Trajectory w = make_trajectory(10, 7);
    const auto warm = fp::make_chunks(w, 0x7a10, 0x5e55, foresight::trajectory_hash(w), 250);
    ASSERT_EQ(warm.size(), 1u);
    fp::Sample<msg::TrajectoryChunk> got;
    bool echoed = false;
    for (const auto until = Clock::now() + kReplyTimeout; !echoed && Clock::now() < until;) {
      link.chunk.write(warm[0]);
      echoed = echo.wait_take(got, 250ms);
    }
    ASSERT_TRUE(echoed) << "no echo of the warm-up chunk";
    while (echo.wait_take(got, 100ms)) {
    }  // re-sent warm-up echoes
  }

  const foresight::Trajectory t = make_trajectory(2000, 7);
  const foresight::TrajectoryHash hash = foresight::trajectory_hash(t);
  const std::uint64_t id = 0x7a11;
  const auto chunks = fp::make_chunks(t, id, 0x5e55, hash, 250);
  ASSERT_EQ(chunks.size(), 8u);
  const auto t0 = Clock::now();
  for (const auto& c : chunks) link.chunk.write(c);
  const auto status = link.final_status(id);
  const double upload_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  ASSERT_EQ(status->state, foresight_msg_UPLOAD_COMMITTED) << fp::text(status->reason);
  EXPECT_EQ(status->chunks_received, 8u);
  EXPECT_EQ(status->chunk_count, 8u);
  EXPECT_EQ(fp::get_hash(status->content_hash), hash);  // the remote computed the same SHA-256
  std::printf("[ measure  ] 2000x7 upload in 8 chunks -> committed: %.2f ms\n", upload_ms);

  // Every chunk came through the wire bit for bit (echo), hash bytes included.
  std::vector<bool> seen(8, false);
  fp::Sample<msg::TrajectoryChunk> got;
  for (int n = 0; n < 8; ++n) {
    ASSERT_TRUE(echo.wait_take(got, kReplyTimeout)) << "chunk echo " << n;
    ASSERT_LT(got->chunk_index, 8u);
    const msg::TrajectoryChunk& sent = *chunks[got->chunk_index];
    seen[got->chunk_index] = true;
    EXPECT_EQ(got->trajectory_id, id);
    EXPECT_EQ(got->session_id, sent.session_id);
    EXPECT_EQ(got->chunk_count, 8u);
    EXPECT_EQ(got->joint_count, 7u);
    EXPECT_EQ(got->sample_count, 2000u);
    EXPECT_EQ(got->first_sample, sent.first_sample);
    EXPECT_EQ(got->issued_ns, sent.issued_ns);
    EXPECT_EQ(0, std::memcmp(got->content_hash, hash.data(), 32));
    ASSERT_EQ(got->samples._length, sent.samples._length);
    EXPECT_EQ(0, std::memcmp(got->samples._buffer, sent.samples._buffer, sent.samples._length * sizeof(double)));
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), true), 8);

  // Run it: the COMPLETED ack carries the final joint angles (the last sample).
  fp::Sample<msg::Command> run = link.make(foresight_msg_CMD_TRAJECTORY);
  run->payload._u.trajectory.trajectory_id = id;
  fp::set_hash(run->payload._u.trajectory.content_hash, hash);
  link.command.write(run);
  const auto acks = link.acks_until_done(run->command_id);
  ASSERT_EQ(acks.size(), 4u);
  EXPECT_EQ(acks[3]->state, foresight_msg_ACK_COMPLETED);
  std::vector<double> last(7);
  for (int j = 0; j < 7; ++j) last[static_cast<std::size_t>(j)] = t.positions_rad(1999, j);
  EXPECT_EQ(seq(acks[3]->final_q_rad), last);

  // The same id with another hash in the command is refused.
  fp::Sample<msg::Command> wrong = link.make(foresight_msg_CMD_TRAJECTORY);
  wrong->payload._u.trajectory.trajectory_id = id;
  link.command.write(wrong);
  const auto refused = link.acks_until_done(wrong->command_id);
  ASSERT_EQ(refused.size(), 2u);
  EXPECT_EQ(refused[1]->state, foresight_msg_ACK_REJECTED);
  EXPECT_EQ(refused[1]->code, foresight_msg_REASON_HASH_MISMATCH);
  EXPECT_EQ(fp::text(refused[1]->reason), "command hash " + foresight::to_hex(foresight::TrajectoryHash{}) +
                                              " differs from the upload's " + foresight::to_hex(hash));
}

TEST_F(ProtocolLoopback, CorruptOrInvalidUploadsAreRejectedAndNeverRun) {
  GroundLink link(*participant_);
  ASSERT_NO_FATAL_FAILURE(link.connect());
  const foresight::Trajectory t = make_trajectory(300, 7);
  {
    // Declared hash does not match the content (e.g. corrupted on the way).
    foresight::TrajectoryHash bad = foresight::trajectory_hash(t);
    bad[0] ^= 0xff;
    for (const auto& c : fp::make_chunks(t, 21, 0x5e55, bad, 100)) link.chunk.write(c);
    const auto status = link.final_status(21);
    EXPECT_EQ(status->state, foresight_msg_UPLOAD_REJECTED);
    EXPECT_EQ(status->code, foresight_msg_REASON_HASH_MISMATCH);
    EXPECT_EQ(fp::text(status->reason), "trajectory 21: content hash " + foresight::to_hex(foresight::trajectory_hash(t)) +
                                            " differs from the declared " + foresight::to_hex(bad));
    fp::Sample<msg::Command> run = link.make(foresight_msg_CMD_TRAJECTORY);
    run->payload._u.trajectory.trajectory_id = 21;
    fp::set_hash(run->payload._u.trajectory.content_hash, bad);
    link.command.write(run);
    const auto acks = link.acks_until_done(run->command_id);
    ASSERT_EQ(acks.size(), 2u);
    EXPECT_EQ(acks[1]->code, foresight_msg_REASON_UNKNOWN_TRAJECTORY);
  }
  {
    // Joint 4 of sample 151 beyond the peer's +-10 rad limit.
    foresight::Trajectory v = t;
    v.positions_rad(150, 3) = 12.0;
    for (const auto& c : fp::make_chunks(v, 22, 0x5e55, 100)) link.chunk.write(c);
    const auto status = link.final_status(22);
    EXPECT_EQ(status->state, foresight_msg_UPLOAD_REJECTED);
    EXPECT_EQ(status->code, foresight_msg_REASON_VALIDATION_FAILED);
    const std::string reason(fp::text(status->reason));
    EXPECT_EQ(reason.rfind("trajectory 22: ", 0), 0u) << reason;
    EXPECT_NE(reason.find("151"), std::string::npos) << reason;  // names the row
  }
}

// ------------------------------------------------------------- delay, discovery

TEST_F(ProtocolLoopback, PingPongRoundTripAndClockOffset) {
  fp::Writer<msg::Ping> ping(*participant_);
  fp::Reader<msg::Pong> pong(*participant_);
  const auto t_discovery = Clock::now();
  ASSERT_TRUE(ping.wait_for_readers(2, kDiscoveryTimeout));
  ASSERT_TRUE(pong.wait_for_writers(1, kDiscoveryTimeout));
  std::printf("[ measure  ] endpoint discovery (ping/pong): %.2f ms\n",
              std::chrono::duration<double, std::milli>(Clock::now() - t_discovery).count());

  std::vector<double> rtt_us, offset_us;
  fp::Sample<msg::Pong> got;
  const auto deadline = Clock::now() + 20s;
  std::uint64_t id = 0;
  while (rtt_us.size() < 500 && Clock::now() < deadline) {
    msg::Ping p{};
    p.ping_id = ++id;
    p.ground_send_ns = fp::now_ns();
    ping.write(p);
    // Best-effort: a lost ping is a lost measurement; stale pongs are skipped by id.
    const auto wait_end = Clock::now() + 200ms;
    while (Clock::now() < wait_end && pong.wait_take(got, wait_end - Clock::now())) {
      if (got->ping_id != id) continue;
      const fp::DelaySample d = fp::delay_from_pong(*got, fp::now_ns());
      rtt_us.push_back(static_cast<double>(d.rtt_ns) * 1e-3);
      offset_us.push_back(static_cast<double>(d.offset_ns) * 1e-3);
      EXPECT_EQ(got->ground_send_ns, p.ground_send_ns);
      EXPECT_GE(got->remote_send_ns, got->remote_receive_ns);
      break;
    }
  }
  ASSERT_GE(rtt_us.size(), 450u) << "more than 10% of pings lost on loopback";
  const double median = percentile(rtt_us, 0.5), p99 = percentile(rtt_us, 0.99);
  std::printf("[ measure  ] ping/pong RTT over %zu: median %.1f us, p99 %.1f us; offset median %.1f us\n",
              rtt_us.size(), median, p99, percentile(offset_us, 0.5));
  RecordProperty("rtt_median_us", std::to_string(median));
  RecordProperty("rtt_p99_us", std::to_string(p99));
  EXPECT_GT(median, 0.0);
  // Same machine, same clock: the offset estimate is bounded by half the
  // round trip. Loose bounds: this is a correctness test, not a benchmark.
  EXPECT_LT(std::abs(percentile(offset_us, 0.5)), std::max(500.0, median));
  EXPECT_LT(median, 20'000.0);
}

// A Command whose DHEADER ends before the payload union (what a hostile or
// broken participant can send): Cyclone 0.10.2 accepts it and then abort()s
// building the sample at take time. Reader<Command> checks the DHEADER first:
// the sample is dropped and counted, the process lives, and the next
// well-formed command is taken (fuzz/regressions/fuzz_dds_samples).
TEST(ProtocolHostile, ACommandTruncatedBeforeItsPayloadIsDroppedNotFatal) {
  fp::use_loopback_if_unconfigured();
  fp::Participant participant(fp::unique_test_domain());
  fp::Writer<msg::Command> writer(participant);
  fp::Reader<msg::Command> reader(participant);
  fp::Reader<msg::Command> probe(participant);  // only for its serialized sample (the type's sertype)
  ASSERT_TRUE(writer.wait_for_readers(2, kDiscoveryTimeout));

  fp::Sample<msg::Command> good;
  good->protocol_version = msg::kProtocolVersion;
  good->session_id = 7;
  good->sequence_number = 1;
  good->command_id = 41;
  good->payload._d = foresight_msg_CMD_REQUEST;
  writer.write(*good);
  fp::Sample<msg::Command> got;
  ASSERT_TRUE(reader.wait_take(got, kReplyTimeout));
  EXPECT_EQ(got->command_id, 41u);
  ddsi_serdata* sample = nullptr;
  dds_sample_info_t info;
  for (auto deadline = Clock::now() + kReplyTimeout; sample == nullptr && Clock::now() < deadline;)
    if (dds_takecdr(probe.get(), &sample, 1, &info, DDS_ANY_STATE) <= 0) std::this_thread::sleep_for(5ms);
  ASSERT_NE(sample, nullptr);

  // D_CDR2 little endian, DHEADER 44: the envelope and no union.
  unsigned char bytes[4 + 4 + 44] = {0x00, 0x09, 0x00, 0x00, 44, 0, 0, 0};
  bytes[8] = static_cast<unsigned char>(msg::kProtocolVersion);
  ddsrt_iovec_t iov;
  iov.iov_base = bytes;
  iov.iov_len = sizeof bytes;
  ddsi_serdata* truncated = ddsi_serdata_from_ser_iov(sample->type, SDK_DATA, 1, &iov, sizeof bytes);
  ddsi_serdata_unref(sample);
  ASSERT_NE(truncated, nullptr) << "Cyclone refused the truncated sample itself (then the guard is moot)";
  ASSERT_EQ(dds_writecdr(writer.get(), truncated), DDS_RETCODE_OK);

  good->sequence_number = 2;
  good->command_id = 42;
  writer.write(*good);
  ASSERT_TRUE(reader.wait_take(got, kReplyTimeout));
  EXPECT_EQ(got->command_id, 42u);
  EXPECT_EQ(reader.malformed_dropped(), 1u);
}

namespace {
/// Writes `payload` (XCDR2, little endian; `identifier` CDR2_LE 0x07 for a
/// final type, D_CDR2_LE 0x09 for an appendable one) as a sample of T through
/// `writer`, as a hostile participant could put it on the wire. The sertype
/// comes from a sample `probe` took. Returns whether Cyclone accepted it.
template <class T>
bool write_raw(fp::Writer<T>& writer, fp::Reader<T>& probe, const T& any, unsigned char identifier,
               const std::vector<unsigned char>& payload) {
  writer.write(any);
  ddsi_serdata* sample = nullptr;
  dds_sample_info_t info;
  for (auto deadline = Clock::now() + kReplyTimeout; sample == nullptr && Clock::now() < deadline;)
    if (dds_takecdr(probe.get(), &sample, 1, &info, DDS_ANY_STATE) <= 0) std::this_thread::sleep_for(5ms);
  if (sample == nullptr) return false;
  std::vector<unsigned char> bytes{0x00, identifier, 0x00, 0x00};
  bytes.insert(bytes.end(), payload.begin(), payload.end());
  ddsrt_iovec_t iov;
  iov.iov_base = bytes.data();
  iov.iov_len = static_cast<ddsrt_iov_len_t>(bytes.size());
  ddsi_serdata* raw = ddsi_serdata_from_ser_iov(sample->type, SDK_DATA, 1, &iov, bytes.size());
  ddsi_serdata_unref(sample);
  if (raw == nullptr) return false;
  return dds_writecdr(writer.get(), raw) == DDS_RETCODE_OK;
}

/// A sample's XCDR2 payload as Cyclone writes it (no encapsulation header).
template <class T>
std::vector<unsigned char> xcdr2_payload(const T& value) {
  dds_ostreamLE_t os;
  dds_ostreamLE_init(&os, 0, 2);
  dds_stream_writeLE(&os, reinterpret_cast<const char*>(&value), fp::MessageTraits<T>::descriptor()->m_ops);
  std::vector<unsigned char> out(os.x.m_buffer, os.x.m_buffer + os.x.m_index);
  dds_ostreamLE_fini(&os);
  return out;
}

/// Takes what `reader` holds (the sample write_raw() wrote first, whatever
/// the history depth kept) until it dropped one malformed sample.
template <class T>
bool drop_one(fp::Reader<T>& reader) {
  fp::Sample<T> got;
  for (auto deadline = Clock::now() + kReplyTimeout; reader.malformed_dropped() == 0 && Clock::now() < deadline;)
    (void)reader.wait_take(got, 50ms);
  return reader.malformed_dropped() == 1;
}

void put_u32_le(std::vector<unsigned char>& b, std::size_t off, std::uint32_t v) {
  for (std::size_t i = 0; i < 4; ++i) b[off + i] = static_cast<unsigned char>(v >> (8 * i));
}
}  // namespace

// A sample whose last sequence of doubles is longer than the bytes it carries
// (XCDR2): Cyclone 0.10.2's normalize checks 4 bytes per double, accepts it,
// and building the sample at take then read past the heap buffer (ASan:
// heap-buffer-overflow in dds_stream_read; fuzz/regressions/fuzz_dds_samples/
// *_overread_in_cyclone_read). Reader<T> walks the CDR first (cdr_check.hpp):
// dropped and counted, and the next well-formed sample is taken.
TEST(ProtocolHostile, AJointStateWhoseSequenceOutrunsItsBytesIsDroppedNotOverRead) {
  fp::use_loopback_if_unconfigured();
  fp::Participant participant(fp::unique_test_domain());
  fp::Writer<msg::JointState> writer(participant);
  fp::Reader<msg::JointState> reader(participant);
  fp::Reader<msg::JointState> probe(participant);
  ASSERT_TRUE(writer.wait_for_readers(2, kDiscoveryTimeout));

  fp::Sample<msg::JointState> good;
  const std::vector<double> q{0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7};
  fp::assign(good->torque_nm, std::span<const double>(q), msg::kMaxJoints, "torque");
  good->cycle = 1;
  fp::Sample<msg::JointState> got;
  // stamp 8, cycle 8, q and dq empty (4 + 4), torque: length at 24, 56 bytes.
  std::vector<unsigned char> lie = xcdr2_payload(*good);
  ASSERT_EQ(lie.size(), 84u);
  put_u32_le(lie, 24, 14);  // 14 doubles in 56 bytes: Cyclone reads 56 bytes past them
  ASSERT_TRUE(write_raw(writer, probe, *good, 0x07, lie)) << "Cyclone refused the lie itself (then the guard is moot)";
  ASSERT_TRUE(drop_one(reader));

  good->cycle = 2;
  writer.write(*good);
  ASSERT_TRUE(reader.wait_take(got, kReplyTimeout));
  EXPECT_EQ(got->cycle, 2u);
  ASSERT_EQ(got->torque_nm._length, 7u);
  EXPECT_EQ(got->torque_nm._buffer[6], 0.7);
  EXPECT_EQ(reader.malformed_dropped(), 1u);
}

TEST(ProtocolHostile, ATrajectoryChunkWhoseSamplesOutrunItsBytesIsDroppedNotOverRead) {
  fp::use_loopback_if_unconfigured();
  fp::Participant participant(fp::unique_test_domain());
  fp::Writer<msg::TrajectoryChunk> writer(participant);
  fp::Reader<msg::TrajectoryChunk> reader(participant);
  fp::Reader<msg::TrajectoryChunk> probe(participant);
  ASSERT_TRUE(writer.wait_for_readers(2, kDiscoveryTimeout));

  fp::Sample<msg::TrajectoryChunk> good;
  good->trajectory_id = 5;
  good->chunk_count = 1;
  std::vector<double> samples(8, 0.25);
  fp::assign(good->samples, std::span<const double>(samples), msg::kMaxChunkValues, "samples");
  fp::Sample<msg::TrajectoryChunk> got;
  // DHEADER 4, 76 bytes of members, samples' length at 80, 64 bytes.
  std::vector<unsigned char> lie = xcdr2_payload(*good);
  ASSERT_EQ(lie.size(), 148u);
  put_u32_le(lie, 80, 16);  // 16 doubles in 64 bytes
  ASSERT_TRUE(write_raw(writer, probe, *good, 0x09, lie)) << "Cyclone refused the lie itself (then the guard is moot)";
  ASSERT_TRUE(drop_one(reader));

  good->trajectory_id = 6;
  writer.write(*good);
  ASSERT_TRUE(reader.wait_take(got, kReplyTimeout));
  EXPECT_EQ(got->trajectory_id, 6u);
  EXPECT_EQ(got->samples._length, 8u);
  EXPECT_EQ(reader.malformed_dropped(), 1u);
}
