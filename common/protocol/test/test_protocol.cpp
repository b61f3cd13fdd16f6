// In-process tests of the protocol library: QoS profiles, the C-struct
// helpers, delay arithmetic, chunking and assembly of trajectory uploads, and
// the RAII layer's error handling. The two-process exchange is in
// test_protocol_loopback.cpp.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <chrono>
#include <cctype>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include "foresight/protocol/command.hpp"
#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/trajectory_upload.hpp"

namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
using foresight::Trajectory;
using std::chrono::milliseconds;

namespace {

Trajectory make_trajectory(int samples, int joints, double dt = 0.01) {
  Trajectory t;
  t.time_s.resize(static_cast<std::size_t>(samples));
  t.positions_rad.resize(samples, joints);
  for (int s = 0; s < samples; ++s) {
    t.time_s[static_cast<std::size_t>(s)] = s * dt;
    for (int j = 0; j < joints; ++j) t.positions_rad(s, j) = 0.5 * std::sin(0.3 * s * dt + j) + 0.01 * j;
  }
  return t;
}

struct Policies {
  dds_reliability_kind_t reliability;
  dds_duration_t max_blocking;
  dds_history_kind_t history;
  int32_t depth;
  dds_durability_kind_t durability;
};

Policies policies(const fp::Qos& q) {
  Policies p{};
  EXPECT_TRUE(dds_qget_reliability(q.get(), &p.reliability, &p.max_blocking));
  EXPECT_TRUE(dds_qget_history(q.get(), &p.history, &p.depth));
  EXPECT_TRUE(dds_qget_durability(q.get(), &p.durability));
  return p;
}

}  // namespace

// ---------------------------------------------------------------- QoS

TEST(ProtocolQos, CommandsAcksAndUploadsAreReliableKeepAllVolatile) {
  for (const fp::Qos& q : {fp::qos::command(), fp::qos::command_ack(), fp::qos::trajectory_chunk()}) {
    const Policies p = policies(q);
    EXPECT_EQ(p.reliability, DDS_RELIABILITY_RELIABLE);
    EXPECT_EQ(p.history, DDS_HISTORY_KEEP_ALL);
    EXPECT_EQ(p.durability, DDS_DURABILITY_VOLATILE);  // a restarted remote must not replay commands
  }
  EXPECT_EQ(policies(fp::qos::trajectory_chunk()).max_blocking, DDS_SECS(30));
}

TEST(ProtocolQos, StatusIsReliableTransientLocalKeepLastOne) {
  for (const fp::Qos& q : {fp::qos::controller_status(), fp::qos::trajectory_status()}) {
    const Policies p = policies(q);
    EXPECT_EQ(p.reliability, DDS_RELIABILITY_RELIABLE);
    EXPECT_EQ(p.history, DDS_HISTORY_KEEP_LAST);
    EXPECT_EQ(p.depth, 1);
    EXPECT_EQ(p.durability, DDS_DURABILITY_TRANSIENT_LOCAL);
  }
}

TEST(ProtocolQos, TelemetryHeartbeatAndPingAreBestEffortKeepLast) {
  const Policies t = policies(fp::qos::telemetry(4));
  EXPECT_EQ(t.reliability, DDS_RELIABILITY_BEST_EFFORT);
  EXPECT_EQ(t.history, DDS_HISTORY_KEEP_LAST);
  EXPECT_EQ(t.depth, 4);
  const Policies h = policies(fp::qos::heartbeat());
  EXPECT_EQ(h.reliability, DDS_RELIABILITY_BEST_EFFORT);
  EXPECT_EQ(h.depth, 1);
  EXPECT_EQ(h.durability, DDS_DURABILITY_VOLATILE);
  const Policies p = policies(fp::qos::ping());
  EXPECT_EQ(p.reliability, DDS_RELIABILITY_BEST_EFFORT);
  EXPECT_EQ(p.depth, 16);
}

TEST(ProtocolQos, BadDepthIsRejected) {
  EXPECT_THROW(
      {
        try {
          fp::Qos().keep_last(0);
        } catch (const fp::ProtocolError& e) {
          EXPECT_STREQ(e.what(), "keep_last: depth must be >= 1, got 0");
          throw;
        }
      },
      fp::ProtocolError);
}

TEST(ProtocolQos, DefaultsPerMessageType) {
  EXPECT_STREQ(fp::MessageTraits<msg::Command>::topic, "foresight/command");
  EXPECT_STREQ(fp::MessageTraits<msg::JointState>::topic, "foresight/telemetry/joint_state");
  EXPECT_EQ(policies(fp::MessageTraits<msg::Wrench>::qos()).reliability, DDS_RELIABILITY_BEST_EFFORT);
  EXPECT_EQ(policies(fp::MessageTraits<msg::CommandAck>::qos()).history, DDS_HISTORY_KEEP_ALL);
}

// ---------------------------------------------------------------- codec

TEST(ProtocolCodec, BoundedTextRoundTripsAndRefusesOverlongNames) {
  msg::CameraCommand camera{};
  fp::set_text(camera.camera, "left_cam", "camera name");
  EXPECT_EQ(fp::text(camera.camera), "left_cam");
  const std::string max(63, 'x');
  fp::set_text(camera.camera, max, "camera name");
  EXPECT_EQ(fp::text(camera.camera), max);
  try {
    fp::set_text(camera.camera, std::string(64, 'x'), "CAMERA camera");
    FAIL() << "expected std::length_error";
  } catch (const std::length_error& e) {
    EXPECT_STREQ(e.what(), "CAMERA camera: 64 characters exceed the protocol bound of 63");
  }
}

TEST(ProtocolCodec, ReasonTextIsTruncatedVisibly) {
  msg::CommandAck ack{};
  fp::set_text_truncated(ack.reason, std::string(300, 'r'));
  const std::string_view t = fp::text(ack.reason);
  ASSERT_EQ(t.size(), 255u);
  EXPECT_EQ(t.substr(252), "...");
  fp::set_text_truncated(ack.reason, "short");
  EXPECT_EQ(fp::text(ack.reason), "short");
}

TEST(ProtocolCodec, AssignOwnsAndReusesBuffersBorrowDoesNot) {
  fp::Sample<msg::JointState> js;
  const std::vector<double> q{0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7};
  fp::assign(js->q_rad, std::span<const double>(q), msg::kMaxJoints, "q_rad");
  ASSERT_EQ(js->q_rad._length, 7u);
  EXPECT_TRUE(js->q_rad._release);
  EXPECT_TRUE(std::equal(q.begin(), q.end(), fp::view(js->q_rad).begin()));
  double* const buffer = js->q_rad._buffer;
  fp::assign(js->q_rad, std::span<const double>(q).first(3), msg::kMaxJoints, "q_rad");
  EXPECT_EQ(js->q_rad._buffer, buffer);  // shrinking reuses the buffer
  EXPECT_EQ(js->q_rad._length, 3u);
  const std::vector<double> too_many(17, 0.0);
  try {
    fp::assign(js->q_rad, std::span<const double>(too_many), msg::kMaxJoints, "GOTO_JOINT q_rad");
    FAIL() << "expected std::length_error";
  } catch (const std::length_error& e) {
    EXPECT_STREQ(e.what(), "GOTO_JOINT q_rad: 17 elements exceed the protocol bound of 16");
  }
  std::vector<double> mine{1.0, 2.0};
  fp::Sample<msg::JointState> borrowed;
  fp::borrow(borrowed->dq_rad_s, std::span<double>(mine));
  EXPECT_FALSE(borrowed->dq_rad_s._release);
  EXPECT_EQ(borrowed->dq_rad_s._buffer, mine.data());
  // ~Sample frees q_rad of `js` and leaves `mine` alone (ASan/valgrind would object otherwise).
}

TEST(ProtocolCodec, SampleMoveTransfersOwnership) {
  fp::Sample<msg::CommandAck> a;
  const std::vector<double> q{1.0, 2.0, 3.0};
  fp::assign(a->final_q_rad, std::span<const double>(q), msg::kMaxJoints, "final_q_rad");
  double* const buffer = a->final_q_rad._buffer;
  fp::Sample<msg::CommandAck> b(std::move(a));
  EXPECT_EQ(b->final_q_rad._buffer, buffer);
  EXPECT_EQ(a->final_q_rad._buffer, nullptr);  // NOLINT(bugprone-use-after-move): moved-from is zeroed
  a = std::move(b);
  EXPECT_EQ(a->final_q_rad._buffer, buffer);
  a.clear();
  EXPECT_EQ(a->final_q_rad._length, 0u);
}

TEST(ProtocolCodec, DelayFromPongKnownAnswer) {
  // Remote clock 5 ms ahead of the ground; 40 ms each way; 1 ms processing.
  const std::int64_t ms = 1'000'000;
  msg::Pong pong{};
  pong.ground_send_ns = 1000 * ms;                    // t1 (ground clock)
  pong.remote_receive_ns = 1000 * ms + 40 * ms + 5 * ms;  // t2 (remote clock)
  pong.remote_send_ns = pong.remote_receive_ns + 1 * ms;  // t3
  const std::int64_t t4 = 1000 * ms + 81 * ms;            // ground clock
  const fp::DelaySample d = fp::delay_from_pong(pong, t4);
  EXPECT_EQ(d.rtt_ns, 80 * ms);
  EXPECT_EQ(d.offset_ns, 5 * ms);
  EXPECT_DOUBLE_EQ(d.one_way_s(), 0.040);
}

TEST(ProtocolCodec, DelayFromHostilePongStampsIsInvalidNotOverflowed) {
  // Stamps from a hostile remote: each subtraction would overflow int64
  // (undefined behaviour before: UBSan, found by fuzz_dds_samples).
  msg::Pong pong{};
  pong.ground_send_ns = INT64_MIN;
  pong.remote_receive_ns = 0;
  pong.remote_send_ns = INT64_MAX;
  fp::DelaySample d = fp::delay_from_pong(pong, INT64_MAX);
  EXPECT_FALSE(d.valid);
  EXPECT_EQ(d.rtt_ns, 0);
  EXPECT_EQ(d.offset_ns, 0);
  pong.ground_send_ns = 10;
  pong.remote_receive_ns = INT64_MIN;
  pong.remote_send_ns = INT64_MAX;
  EXPECT_FALSE(fp::delay_from_pong(pong, 20).valid);
  // Large but representable stamps stay valid and exact.
  pong.ground_send_ns = INT64_MAX - 100;
  pong.remote_receive_ns = INT64_MAX - 60;
  pong.remote_send_ns = INT64_MAX - 50;
  d = fp::delay_from_pong(pong, INT64_MAX - 10);
  EXPECT_TRUE(d.valid);
  EXPECT_EQ(d.rtt_ns, 80);
  EXPECT_EQ(d.offset_ns, 0);
}

// One name table for both sides: the plain enums' to_string (command.hpp),
// reached from a wire value by a static_cast. Every IDL value has a name, the
// value after the IDL's last has none, and the names are the IDL's own in
// snake case without the prefix.
template <typename Plain>
void expect_names(std::initializer_list<std::pair<int, const char*>> idl, int count) {
  for (const auto& [value, idl_name] : idl) {
    std::string expected = std::string(idl_name).substr(std::string(idl_name).find('_') + 1);
    for (char& ch : expected) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    EXPECT_EQ(fp::to_string(static_cast<Plain>(value)), expected) << idl_name;
  }
  for (int v = 0; v < count; ++v) EXPECT_STRNE(fp::to_string(static_cast<Plain>(v)), "unknown") << v;
  EXPECT_STREQ(fp::to_string(static_cast<Plain>(count)), "unknown");
}

TEST(ProtocolCodec, EnumNamesAreTheIdlsInSnakeCase) {
  expect_names<fp::CommandKind>({{foresight_msg_CMD_TRAJECTORY, "CMD_TRAJECTORY"},
                                 {foresight_msg_CMD_INVOKE_ALGORITHM, "CMD_INVOKE_ALGORITHM"},
                                 {foresight_msg_CMD_GOTO_CART, "CMD_GOTO_CART"},
                                 {foresight_msg_CMD_TAKE_CONTROL, "CMD_TAKE_CONTROL"},
                                 {foresight_msg_CMD_RELEASE_CONTROL, "CMD_RELEASE_CONTROL"},
                                 {foresight_msg_CMD_RECOVER, "CMD_RECOVER"}},
                                foresight_msg_CMD_RECOVER + 1);
  expect_names<fp::AckState>({{foresight_msg_ACK_RECEIVED, "ACK_RECEIVED"}, {foresight_msg_ACK_CANCELED, "ACK_CANCELED"}},
                             foresight_msg_ACK_CANCELED + 1);
  expect_names<fp::Reason>({{foresight_msg_REASON_NONE, "REASON_NONE"},
                            {foresight_msg_REASON_HASH_MISMATCH, "REASON_HASH_MISMATCH"},
                            {foresight_msg_REASON_NOT_IN_CONTROL, "REASON_NOT_IN_CONTROL"}},
                           foresight_msg_REASON_NOT_IN_CONTROL + 1);
  expect_names<fp::UploadState>({{foresight_msg_UPLOAD_COMMITTED, "UPLOAD_COMMITTED"},
                                 {foresight_msg_UPLOAD_DISCARDED, "UPLOAD_DISCARDED"}},
                                foresight_msg_UPLOAD_DISCARDED + 1);
  expect_names<fp::ControllerMode>({{foresight_msg_MODE_STOPPED, "MODE_STOPPED"}, {foresight_msg_MODE_FAULT, "MODE_FAULT"}},
                                   foresight_msg_MODE_FAULT + 1);
  expect_names<fp::StopCategory>({{foresight_msg_STOP_NONE, "STOP_NONE"}, {foresight_msg_STOP_CAT1, "STOP_CAT1"}},
                                 foresight_msg_STOP_CAT2 + 1);
  EXPECT_EQ(msg::kProtocolVersion, 2u);
}

// ---------------------------------------------------------------- upload

TEST(ProtocolUpload, ChunksCarrySizesHashAndRowMajorSamples) {
  const Trajectory t = make_trajectory(2000, 7);
  const auto hash = foresight::trajectory_hash(t);
  const auto chunks = fp::make_chunks(t, 42, 7, 300);
  ASSERT_EQ(chunks.size(), 7u);  // 6 x 300 + 200
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    const msg::TrajectoryChunk& k = *chunks[c];
    EXPECT_EQ(k.trajectory_id, 42u);
    EXPECT_EQ(k.session_id, 7u);
    EXPECT_EQ(k.chunk_index, c);
    EXPECT_EQ(k.chunk_count, 7u);
    EXPECT_EQ(k.joint_count, 7u);
    EXPECT_EQ(k.sample_count, 2000u);
    EXPECT_EQ(k.first_sample, 300 * c);
    EXPECT_EQ(fp::get_hash(k.content_hash), hash);
    EXPECT_EQ(k.samples._length, (c < 6 ? 300u : 200u) * 8u);
  }
  const msg::TrajectoryChunk& last = *chunks.back();
  EXPECT_EQ(last.samples._buffer[0], t.time_s[1800]);
  EXPECT_EQ(last.samples._buffer[1 + 3], t.positions_rad(1800, 3));
  // Default chunking: as many samples as fit in MAX_CHUNK_VALUES doubles.
  const auto big = fp::make_chunks(t, 43, 7);
  ASSERT_EQ(big.size(), 2u);
  EXPECT_EQ(big[0]->samples._length, 1024u * 8u);
}

TEST(ProtocolUpload, ChunkingRefusesWhatTheProtocolCannotCarry) {
  try {
    fp::make_chunks(make_trajectory(10, 17), 1, 1);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "make_chunks: 17 joints; the protocol carries 1 to 16");
  }
  try {
    fp::make_chunks(Trajectory{}, 1, 1);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "make_chunks: the trajectory has no samples");
  }
  try {
    fp::make_chunks(make_trajectory(5000, 2), 1, 1, 1);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "make_chunks: 5000 samples need 5000 chunks; the protocol allows 4096");
  }
}

TEST(ProtocolUpload, AssemblesOutOfOrderWithDuplicatesBitExact) {
  const Trajectory t = make_trajectory(2000, 7);
  auto chunks = fp::make_chunks(t, 9, 3, 250);
  std::mt19937 rng(1);
  std::shuffle(chunks.begin(), chunks.end(), rng);
  fp::TrajectoryAssembler assembler;
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    const auto p = assembler.add(*chunks[i]);
    EXPECT_EQ(p.chunks_received, i + 1);
    EXPECT_EQ(p.chunk_count, 8u);
    if (i + 1 < chunks.size()) {
      EXPECT_EQ(p.state, foresight_msg_UPLOAD_ASSEMBLING);
      EXPECT_FALSE(assembler.take(9).has_value()) << "an incomplete upload must not be handed out";
      const auto again = assembler.add(*chunks[i]);  // exact duplicate: ignored
      EXPECT_EQ(again.chunks_received, i + 1);
      EXPECT_EQ(again.state, foresight_msg_UPLOAD_ASSEMBLING);
    } else {
      EXPECT_TRUE(p.whole());
    }
  }
  const auto whole = assembler.take(9);
  ASSERT_TRUE(whole.has_value());
  EXPECT_EQ(whole->session_id, 3u);
  EXPECT_EQ(whole->trajectory.time_s, t.time_s);
  EXPECT_TRUE(whole->trajectory.positions_rad == t.positions_rad);
  EXPECT_EQ(whole->declared_hash, foresight::trajectory_hash(t));
  EXPECT_EQ(assembler.pending(), 0u);
  foresight::TrajectoryLimits limits;
  limits.joints = 7;
  limits.joint_limits.assign(7, foresight::JointLimits{-3.0, 3.0, 10.0, 100.0, 100.0});
  const fp::UploadVerdict v = fp::verify(*whole, limits);
  EXPECT_TRUE(v.ok()) << v.reason;
  EXPECT_EQ(v.computed_hash, whole->declared_hash);
}

TEST(ProtocolUpload, ContradictingChunkRejectsTheWholeUpload) {
  const Trajectory t = make_trajectory(100, 3);
  auto chunks = fp::make_chunks(t, 5, 1, 40);
  chunks[1]->sample_count = 101;
  fp::TrajectoryAssembler assembler;
  EXPECT_EQ(assembler.add(*chunks[0]).state, foresight_msg_UPLOAD_ASSEMBLING);
  const auto p = assembler.add(*chunks[1]);
  EXPECT_EQ(p.state, foresight_msg_UPLOAD_REJECTED);
  EXPECT_EQ(p.code, foresight_msg_REASON_BAD_ARGUMENT);
  EXPECT_EQ(p.reason, "trajectory 5: chunk 1: sample_count 101 differs from 100 in the upload's first chunk");
  // Later chunks of a rejected upload stay rejected; nothing is handed out.
  EXPECT_EQ(assembler.add(*chunks[2]).state, foresight_msg_UPLOAD_REJECTED);
  EXPECT_FALSE(assembler.take(5).has_value());
  assembler.discard(5);
  EXPECT_EQ(assembler.pending(), 0u);
}

TEST(ProtocolUpload, StructuralErrorsNameChunkAndField) {
  const Trajectory t = make_trajectory(100, 3);
  struct Case {
    const char* name;
    void (*mutate)(msg::TrajectoryChunk&);
    msg::ReasonCode code;
    const char* reason;
  };
  const Case cases[] = {
      {"hash", [](msg::TrajectoryChunk& k) { k.content_hash[0] ^= 1; }, foresight_msg_REASON_HASH_MISMATCH, nullptr},
      {"index", [](msg::TrajectoryChunk& k) { k.chunk_index = 3; }, foresight_msg_REASON_BAD_ARGUMENT,
       "trajectory 5: chunk 3: chunk_index is not below chunk_count 3"},
      {"ragged", [](msg::TrajectoryChunk& k) { k.samples._length -= 1; }, foresight_msg_REASON_BAD_ARGUMENT,
       "trajectory 5: chunk 1: 159 values are not a positive multiple of joint_count + 1 = 4"},
      {"range", [](msg::TrajectoryChunk& k) { k.first_sample = 80; }, foresight_msg_REASON_BAD_ARGUMENT,
       "trajectory 5: chunk 1: samples 81..120 exceed sample_count 100"},
      {"overlap", [](msg::TrajectoryChunk& k) { k.first_sample = 20; }, foresight_msg_REASON_BAD_ARGUMENT,
       "trajectory 5: chunk 1: sample 21 was already sent in another chunk"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    auto chunks = fp::make_chunks(t, 5, 1, 40);
    fp::TrajectoryAssembler assembler;
    ASSERT_EQ(assembler.add(*chunks[0]).state, foresight_msg_UPLOAD_ASSEMBLING);
    c.mutate(*chunks[1]);
    const auto p = assembler.add(*chunks[1]);
    EXPECT_EQ(p.state, foresight_msg_UPLOAD_REJECTED);
    EXPECT_EQ(p.code, c.code);
    if (c.reason != nullptr) {
      EXPECT_EQ(p.reason, c.reason);
    }
  }
}

TEST(ProtocolUpload, GapIsIncompleteUpload) {
  const Trajectory t = make_trajectory(100, 3);
  auto chunks = fp::make_chunks(t, 5, 1, 40);  // samples 1..40, 41..80, 81..100
  chunks[2]->samples._length = 10 * 4;         // the last chunk carries only 81..90
  fp::TrajectoryAssembler assembler;
  for (auto& c : chunks) assembler.add(*c);
  const auto p = assembler.add(*chunks[2]);
  EXPECT_EQ(p.state, foresight_msg_UPLOAD_REJECTED);
  EXPECT_EQ(p.code, foresight_msg_REASON_INCOMPLETE_UPLOAD);
  EXPECT_EQ(p.reason, "trajectory 5: all 3 chunks arrived but sample 91 is in none of them");
  EXPECT_FALSE(assembler.take(5).has_value());
}

TEST(ProtocolUpload, FirstChunkSizesAreCheckedAndPendingUploadsBounded) {
  const Trajectory t = make_trajectory(10, 3);
  {
    auto chunks = fp::make_chunks(t, 1, 1);
    chunks[0]->joint_count = 0;
    fp::TrajectoryAssembler assembler;
    const auto p = assembler.add(*chunks[0]);
    EXPECT_EQ(p.code, foresight_msg_REASON_JOINT_COUNT);
    EXPECT_EQ(p.reason, "trajectory 1: chunk 0: joint_count 0 is not in 1..16");
  }
  {
    auto chunks = fp::make_chunks(t, 1, 1);
    fp::TrajectoryAssembler::Limits limits;
    limits.max_samples = 5;
    fp::TrajectoryAssembler assembler(limits);
    const auto p = assembler.add(*chunks[0]);
    EXPECT_EQ(p.code, foresight_msg_REASON_BAD_ARGUMENT);
    EXPECT_EQ(p.reason, "trajectory 1: chunk 0: sample_count 10 is not in 1..5");
  }
  {
    fp::TrajectoryAssembler::Limits limits;
    limits.max_pending = 2;
    fp::TrajectoryAssembler assembler(limits);
    for (std::uint64_t id = 1; id <= 2; ++id) {
      auto chunks = fp::make_chunks(t, id, 1, 4);
      EXPECT_EQ(assembler.add(*chunks[0]).state, foresight_msg_UPLOAD_ASSEMBLING);
    }
    auto third = fp::make_chunks(t, 3, 1, 4);
    const auto p = assembler.add(*third[0]);
    EXPECT_EQ(p.code, foresight_msg_REASON_BUSY);
    EXPECT_EQ(p.reason, "trajectory 3: 2 uploads are already pending (limit 2)");
    EXPECT_EQ(assembler.pending(), 2u);
  }
}

// Issue 28: half uploads hold memory for what arrived, not for what their
// first chunk declared (8 first chunks declaring 200,000 x 16 values took the
// daemon from 153 to 365 MB); one session cannot take every slot; an idle
// half upload is rejected and freed.
TEST(ProtocolUpload, HalfUploadsHoldWhatArrivedAreCappedPerSessionAndExpire) {
  fp::TrajectoryAssembler::Limits limits;
  limits.max_pending = 8;
  limits.max_pending_per_session = 2;
  fp::TrajectoryAssembler assembler(limits);
  const Trajectory t = make_trajectory(100, 16);
  auto chunks = fp::make_chunks(t, 1, 7, 10);  // 10 chunks of 10 samples x 17 values
  for (auto& c : chunks) c->sample_count = 200000;  // the first chunk declares a huge whole
  for (auto& c : chunks) c->chunk_count = 4000;
  EXPECT_EQ(assembler.add(*chunks[0]).state, foresight_msg_UPLOAD_ASSEMBLING);
  EXPECT_EQ(assembler.values_held(), 10u * 17u);  // one chunk's values, not 200,000 x 17
  EXPECT_EQ(assembler.add(*chunks[1]).state, foresight_msg_UPLOAD_ASSEMBLING);
  EXPECT_EQ(assembler.values_held(), 2u * 10u * 17u);

  // Session 7's second upload fits, its third does not; session 8's does.
  auto second = fp::make_chunks(t, 2, 7, 10);
  EXPECT_EQ(assembler.add(*second[0]).state, foresight_msg_UPLOAD_ASSEMBLING);
  auto third = fp::make_chunks(t, 3, 7, 10);
  const auto busy = assembler.add(*third[0]);
  EXPECT_EQ(busy.code, foresight_msg_REASON_BUSY);
  EXPECT_EQ(busy.reason, "trajectory 3: 2 uploads of this session are already pending (limit 2 per session)");
  auto other = fp::make_chunks(t, 4, 8, 10);
  EXPECT_EQ(assembler.add(*other[0]).state, foresight_msg_UPLOAD_ASSEMBLING);

  // Idle past the timeout: every half upload rejected, its data freed.
  const auto later = std::chrono::steady_clock::now() + std::chrono::seconds(61);
  const auto expired = assembler.expire(later, std::chrono::seconds(60));
  ASSERT_EQ(expired.size(), 3u);
  EXPECT_EQ(expired[0].code, foresight_msg_REASON_INCOMPLETE_UPLOAD);
  EXPECT_EQ(expired[0].reason, "trajectory 1: no chunk for 60 s: 2 of 4000 chunks arrived");
  EXPECT_EQ(assembler.values_held(), 0u);
  EXPECT_EQ(assembler.add(*chunks[2]).state, foresight_msg_UPLOAD_REJECTED);  // stays rejected
  EXPECT_TRUE(assembler.expire(later, std::chrono::seconds(60)).empty());
  // A whole upload still assembles and takes the same values back.
  auto whole = fp::make_chunks(t, 5, 8, 10);
  for (auto& c : whole) assembler.add(*c);
  const auto a = assembler.take(5);
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->trajectory.time_s, t.time_s);
  EXPECT_EQ(a->trajectory.positions_rad, t.positions_rad);
}

TEST(ProtocolUpload, VerifyReportsHashMismatchAndViolations) {
  const Trajectory t = make_trajectory(50, 2);
  fp::TrajectoryAssembler assembler;
  foresight::TrajectoryHash wrong{};
  wrong[31] = 0xab;
  for (auto& c : fp::make_chunks(t, 11, 1, wrong, 20)) assembler.add(*c);
  const auto a = assembler.take(11);
  ASSERT_TRUE(a.has_value());
  foresight::TrajectoryLimits limits;
  limits.joints = 2;
  limits.joint_limits.assign(2, foresight::JointLimits{0.1, 3.0, 10.0, 100.0, 100.0});
  const fp::UploadVerdict v = fp::verify(*a, limits);
  EXPECT_EQ(v.code, foresight_msg_REASON_HASH_MISMATCH);
  EXPECT_EQ(v.reason, "trajectory 11: content hash " + foresight::to_hex(foresight::trajectory_hash(t)) +
                          " differs from the declared " + foresight::to_hex(wrong));
  // Right hash, but joint 1 starts at 0 rad, below its lower limit of 0.1 rad.
  fp::AssembledTrajectory b = *a;
  b.declared_hash = foresight::trajectory_hash(t);
  const fp::UploadVerdict w = fp::verify(b, limits);
  EXPECT_EQ(w.code, foresight_msg_REASON_VALIDATION_FAILED);
  ASSERT_FALSE(w.violations.empty());
  EXPECT_EQ(w.violations[0].rule, foresight::Violation::Rule::PositionLimit);
  EXPECT_EQ(w.violations[0].joint, 1);
  EXPECT_NE(w.reason.find("trajectory 11: "), std::string::npos);
  EXPECT_NE(w.reason.find(w.violations[0].message), std::string::npos);
}

// Issue 25: the remote's check on arrival is the ground's validate(): a ramp
// whose samples pass but which leaves rest at 2 sqrt(3) v / h = 173 rad/s^2
// (limit 2) is refused with the row, joint and limit, in the words
// `foresight validate` prints for it (ValidateCli.RefusesWhatTheRemoteWouldExecuteOverTheAccelerationLimit).
TEST(ProtocolUpload, TheRemoteRefusesTheExecutedAccelerationWithTheGroundsMessage) {
  Trajectory t;
  t.positions_rad = Eigen::MatrixXd::Zero(101, 2);
  for (int i = 0; i <= 100; ++i) {
    t.time_s.push_back(0.01 * i);
    t.positions_rad(i, 0) = 0.005 * i;  // 0.5 rad/s from the first sample to the last
  }
  fp::TrajectoryAssembler assembler;
  for (auto& c : fp::make_chunks(t, 12, 1, foresight::trajectory_hash(t), 20)) assembler.add(*c);
  const auto a = assembler.take(12);
  ASSERT_TRUE(a.has_value());
  foresight::TrajectoryLimits limits;
  limits.joints = 2;
  limits.joint_limits.assign(2, foresight::JointLimits{-1.0, 1.0, 0.9, 2.0, 100.0});
  const fp::UploadVerdict v = fp::verify(*a, limits);
  EXPECT_EQ(v.code, foresight_msg_REASON_VALIDATION_FAILED);
  ASSERT_EQ(v.violations.size(), 8u);  // the first four segments and the last four
  EXPECT_EQ(v.violations[0].rule, foresight::Violation::Rule::AccelerationLimit);
  EXPECT_EQ(v.violations[0].row, 2);
  EXPECT_EQ(v.violations[0].joint, 1);
  EXPECT_DOUBLE_EQ(v.violations[0].limit, 2.0);
  const std::string message =
      "between rows 1 and 2, joint q1: the executed acceleration reaches 173.205 rad/s^2, over the limit 2 rad/s^2";
  EXPECT_EQ(v.violations[0].message, message);
  EXPECT_EQ(v.reason.rfind("trajectory 12: 8 violation(s): " + message + "; ", 0), 0u) << v.reason;
}

// ---------------------------------------------------------------- RAII layer

class ProtocolDds : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { fp::use_loopback_if_unconfigured(); }
};

TEST_F(ProtocolDds, BadDomainThrowsWithCycloneText) {
  try {
    fp::Participant p(1000);
    FAIL() << "domain 1000 should not be creatable";
  } catch (const fp::ProtocolError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("create participant in domain 1000: ", 0), 0u) << e.what();
    EXPECT_LT(e.code(), 0);
  }
}

TEST_F(ProtocolDds, InProcessWriteTakeAndTimeouts) {
  fp::Participant p(fp::unique_test_domain());
  fp::Writer<msg::CommandAck> writer(p);
  fp::Reader<msg::CommandAck> reader(p);
  fp::Sample<msg::CommandAck> got;
  EXPECT_FALSE(reader.take(got));
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(reader.wait_take(got, milliseconds(50)));
  EXPECT_GE(std::chrono::steady_clock::now() - t0, milliseconds(45));

  fp::Sample<msg::CommandAck> ack;
  ack->command_id = 17;
  ack->state = foresight_msg_ACK_COMPLETED;
  const std::vector<double> q{0.5, -0.5};
  fp::assign(ack->final_q_rad, std::span<const double>(q), msg::kMaxJoints, "final_q_rad");
  writer.write(ack);
  ASSERT_TRUE(reader.wait_take(got, std::chrono::seconds(5)));
  EXPECT_EQ(got->command_id, 17u);
  EXPECT_EQ(got->state, foresight_msg_ACK_COMPLETED);
  ASSERT_EQ(got->final_q_rad._length, 2u);
  EXPECT_EQ(got->final_q_rad._buffer[1], -0.5);
  EXPECT_FALSE(reader.take(got));
}

TEST_F(ProtocolDds, OversizedSequenceIsRefusedByTheWriter) {
  fp::Participant p(fp::unique_test_domain());
  fp::Writer<msg::JointState> writer(p);
  fp::Sample<msg::JointState> js;
  std::vector<double> q(17, 0.0);  // bound is 16
  fp::borrow(js->q_rad, std::span<double>(q));
  try {
    writer.write(js);
    FAIL() << "a 17-element q_rad must not be written";
  } catch (const fp::ProtocolError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("write on foresight/telemetry/joint_state: ", 0), 0u) << e.what();
  }
  js->q_rad = {};  // do not let ~Sample look at the borrowed buffer
}

TEST_F(ProtocolDds, WaitSetWakesOnGuardConditionAndTimesOut) {
  fp::Participant p(fp::unique_test_domain());
  fp::WaitSet ws(p);
  fp::GuardCondition guard(p);
  ws.attach(guard, 7);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(ws.wait(milliseconds(30)), 0);
  EXPECT_GE(std::chrono::steady_clock::now() - t0, milliseconds(25));
  guard.trigger();
  EXPECT_TRUE(guard.triggered());
  dds_attach_t tokens[2] = {0, 0};
  EXPECT_EQ(ws.wait(milliseconds(1000), tokens), 1);
  EXPECT_EQ(tokens[0], 7);
  guard.reset();
  EXPECT_FALSE(guard.triggered());
}

TEST_F(ProtocolDds, HandlesAreMoveOnlyAndOutliveNothing) {
  static_assert(!std::is_copy_constructible_v<fp::Participant>);
  static_assert(!std::is_copy_constructible_v<fp::Writer<msg::Ping>>);
  static_assert(!std::is_copy_constructible_v<fp::Sample<msg::Ping>>);
  static_assert(std::is_nothrow_move_constructible_v<fp::Entity>);
  auto p = std::make_unique<fp::Participant>(fp::unique_test_domain());
  auto w = std::make_unique<fp::Writer<msg::Ping>>(*p);
  const dds_entity_t handle = w->get();
  p.reset();  // deleting the participant deletes the writer too
  EXPECT_LT(dds_get_parent(handle), 0);
  w.reset();  // the writer's own delete then fails quietly
}

// ---------------------------------------------------------------- commands

TEST(ProtocolCommands, SequencerNumbersCommandsWithinASession) {
  fp::CommandSequencer seq(0x1234);
  const auto a = seq.next(foresight_msg_CMD_GOTO_JOINT);
  const auto b = seq.next(foresight_msg_CMD_ABORT, 2.0);
  EXPECT_EQ(a->protocol_version, msg::kProtocolVersion);
  EXPECT_EQ(a->session_id, 0x1234u);
  EXPECT_EQ(a->sequence_number, 1u);
  EXPECT_EQ(b->sequence_number, 2u);
  EXPECT_NE(a->command_id, b->command_id);
  EXPECT_EQ(a->payload._d, foresight_msg_CMD_GOTO_JOINT);
  EXPECT_EQ(b->payload._d, foresight_msg_CMD_ABORT);
  EXPECT_EQ(a->expires_ns, 0);
  EXPECT_EQ(b->expires_ns - b->issued_ns, 2'000'000'000);
  EXPECT_NE(fp::CommandSequencer().session_id(), fp::CommandSequencer().session_id());
}

TEST(ProtocolCommands, CheckerRejectsVersionReplayExpiryAndUnknownKind) {
  fp::CommandSequencer ground(77);
  fp::CommandChecker remote;
  const std::int64_t now = 1'000'000'000'000;
  auto c1 = ground.next(foresight_msg_CMD_REQUEST);
  c1->issued_ns = now;
  EXPECT_TRUE(remote.check(*c1, now).ok());
  // The same command again (a replay) and an older one are refused.
  auto replay = remote.check(*c1, now);
  EXPECT_EQ(replay.code, foresight_msg_REASON_BAD_SEQUENCE);
  EXPECT_EQ(replay.reason, "command 1: sequence 1 is not after 1 (replayed or reordered)");
  auto c2 = ground.next(foresight_msg_CMD_REQUEST);
  c2->protocol_version = 1;  // the version before the IDL 4 renames
  auto v = remote.check(*c2, now);
  EXPECT_EQ(v.code, foresight_msg_REASON_VERSION_MISMATCH);
  EXPECT_EQ(v.reason, "command 2: protocol version 1, this remote speaks 2");
  // Expiry is judged on the ground's clock: remote clock 3 s ahead.
  auto c3 = ground.next(foresight_msg_CMD_GOTO_JOINT);
  c3->expires_ns = now + 1'000'000'000;
  const std::int64_t remote_now = now + 3'500'000'000;
  EXPECT_TRUE(remote.check(*c3, remote_now, 3'000'000'000).ok());  // 0.5 s on the ground clock: in time
  auto c4 = ground.next(foresight_msg_CMD_GOTO_JOINT);
  c4->expires_ns = now + 1'000'000'000;
  auto e = remote.check(*c4, now + 1'250'000'000);
  EXPECT_EQ(e.code, foresight_msg_REASON_EXPIRED);
  EXPECT_EQ(e.reason, "command 4: expired 0.250000 s ago");
  // A hostile expiry stamp far in the past: refused, no signed overflow
  // computing its age (UBSan; found by fuzz_dds_samples).
  auto c4b = ground.next(foresight_msg_CMD_GOTO_JOINT);
  c4b->expires_ns = INT64_MIN + 1;
  auto eb = remote.check(*c4b, now, -5'000'000'000);
  EXPECT_EQ(eb.code, foresight_msg_REASON_EXPIRED);
  EXPECT_EQ(eb.reason.rfind("command 5: expired ", 0), 0u) << eb.reason;
  auto c5 = ground.next(foresight_msg_CMD_REQUEST);
  fp::set_raw(c5->payload._d, 42);  // as a hostile participant's sample holds it (no enum value formed)
  auto k = remote.check(*c5, now);
  EXPECT_EQ(k.code, foresight_msg_REASON_BAD_ARGUMENT);
  EXPECT_EQ(k.reason, "command 6: unknown kind 42");
  EXPECT_EQ(remote.last_sequence(), 3u);
  // A restarted ground (new session) starts again at 1.
  fp::CommandSequencer restarted(78);
  EXPECT_TRUE(remote.check(*restarted.next(foresight_msg_CMD_REQUEST), now).ok());
  EXPECT_EQ(remote.last_sequence(), 1u);
}

TEST(ProtocolCommands, AckEchoesTheCommandAndCarriesFinalJointAngles) {
  fp::CommandSequencer ground(9);
  const auto c = ground.next(foresight_msg_CMD_GOTO_JOINT);
  fp::Sample<msg::CommandAck> ack;
  const std::vector<double> q{0.1, 0.2};
  fp::fill_ack(*ack, *c, foresight_msg_ACK_COMPLETED, foresight_msg_REASON_NONE, "done", q);
  EXPECT_EQ(ack->session_id, 9u);
  EXPECT_EQ(ack->command_id, c->command_id);
  EXPECT_EQ(ack->sequence_number, c->sequence_number);
  EXPECT_EQ(ack->kind, foresight_msg_CMD_GOTO_JOINT);
  EXPECT_EQ(ack->state, foresight_msg_ACK_COMPLETED);
  EXPECT_EQ(fp::text(ack->reason), "done");
  EXPECT_GT(ack->stamp_ns, 0);
  ASSERT_EQ(ack->final_q_rad._length, 2u);
  EXPECT_EQ(ack->final_q_rad._buffer[1], 0.2);
  EXPECT_TRUE(fp::is_terminal(foresight_msg_ACK_COMPLETED));
  EXPECT_TRUE(fp::is_terminal(foresight_msg_ACK_REJECTED));
  EXPECT_TRUE(fp::is_terminal(foresight_msg_ACK_CANCELED));
  EXPECT_TRUE(fp::is_terminal(foresight_msg_ACK_FAILED));
  EXPECT_FALSE(fp::is_terminal(foresight_msg_ACK_EXECUTING));
  EXPECT_FALSE(fp::is_terminal(foresight_msg_ACK_RECEIVED));
  EXPECT_FALSE(fp::is_terminal(foresight_msg_ACK_QUEUED));
}

// ---------------------------------------------------------------- QoS behaviour

TEST_F(ProtocolDds, LateJoinerSeesStatusButNeverOldCommands) {
  fp::Participant remote(fp::unique_test_domain());
  fp::Participant ground(fp::unique_test_domain());
  fp::Writer<msg::ControllerStatus> status(remote);
  fp::Writer<msg::Command> commands(ground);
  msg::ControllerStatus s{};
  s.mode = foresight_msg_MODE_STOPPED;
  s.stop_category = foresight_msg_STOP_CAT2;
  fp::set_text(s.stop_reason, "operator abort", "stop_reason");
  status.write(s);
  fp::CommandSequencer seq(5);
  commands.write(seq.next(foresight_msg_CMD_GOTO_JOINT));

  // Readers created after the writes: transient-local status is delivered,
  // the volatile command is not (a restarted remote must not replay it).
  fp::Reader<msg::ControllerStatus> late_status(ground);
  fp::Reader<msg::Command> late_commands(remote);
  fp::Sample<msg::ControllerStatus> got;
  ASSERT_TRUE(late_status.wait_take(got, std::chrono::seconds(5)));
  EXPECT_EQ(got->mode, foresight_msg_MODE_STOPPED);
  EXPECT_EQ(fp::text(got->stop_reason), "operator abort");
  fp::Sample<msg::Command> old;
  EXPECT_FALSE(late_commands.wait_take(old, milliseconds(300)));
}

TEST_F(ProtocolDds, TakeReusesTheSamplesBuffers) {
  fp::Participant p(fp::unique_test_domain());
  fp::Writer<msg::JointState> writer(p);
  fp::Reader<msg::JointState> reader(p);
  fp::Sample<msg::JointState> js;
  std::vector<double> q(7, 0.0);
  fp::Sample<msg::JointState> got;
  const double* first_buffer = nullptr;
  for (int i = 0; i < 5; ++i) {
    q[0] = i;
    fp::assign(js->q_rad, std::span<const double>(q), msg::kMaxJoints, "q");
    writer.write(js);
    ASSERT_TRUE(reader.wait_take(got, std::chrono::seconds(5)));
    EXPECT_EQ(got->q_rad._buffer[0], i);
    if (i == 0) first_buffer = got->q_rad._buffer;
    EXPECT_EQ(got->q_rad._buffer, first_buffer) << "take " << i << " reallocated q_rad";
  }
}

// Issue 13 (UBSan): a received sample's enum fields hold whatever a hostile
// participant wrote; each is checked as a raw integer before it is loaded as
// an enum, for every sample type either side decodes.
TEST(ProtocolEnums, EveryEnumFieldOfAReceivedSampleIsCheckedAsARawInteger) {
  char buf[96];
  fp::CommandSequencer ground(5);
  auto c = ground.next(foresight_msg_CMD_ABORT);
  EXPECT_EQ(fp::enum_error(*c, buf, sizeof buf), nullptr);
  fp::set_raw(c->payload._u.abort.category, 7);
  EXPECT_STREQ(fp::enum_error(*c, buf, sizeof buf), "abort.category 7 is unknown");
  fp::set_raw(c->payload._d, 42);
  EXPECT_EQ(fp::raw(c->payload._d), 42u);
  EXPECT_STREQ(fp::enum_error(*c, buf, sizeof buf), "unknown kind 42");
  auto r = ground.next(foresight_msg_CMD_REQUEST);
  fp::set_raw(r->payload._u.request.what, 200);
  EXPECT_STREQ(fp::enum_error(*r, buf, sizeof buf), "request.what 200 is unknown");
  auto cam = ground.next(foresight_msg_CMD_CAMERA);
  fp::set_raw(cam->payload._u.camera.action, 3);
  EXPECT_STREQ(fp::enum_error(*cam, buf, sizeof buf), "camera.action 3 is unknown");

  // The rejected command's ack echoes the raw kind without forming an enum value.
  fp::Sample<msg::CommandAck> ack;
  fp::fill_ack(*ack, *c, foresight_msg_ACK_REJECTED, foresight_msg_REASON_BAD_ARGUMENT, "unknown kind 42");
  EXPECT_EQ(fp::raw(ack->kind), 42u);
  EXPECT_STREQ(fp::enum_error(*ack, buf, sizeof buf), "unknown kind 42");  // and the ground refuses to trust it
  fp::set_raw(ack->kind, foresight_msg_CMD_ABORT);
  EXPECT_EQ(fp::enum_error(*ack, buf, sizeof buf), nullptr);
  fp::set_raw(ack->state, 9);
  EXPECT_STREQ(fp::enum_error(*ack, buf, sizeof buf), "state 9 is unknown");
  fp::set_raw(ack->state, foresight_msg_ACK_COMPLETED);
  fp::set_raw(ack->code, 65535);
  EXPECT_STREQ(fp::enum_error(*ack, buf, sizeof buf), "code 65535 is unknown");

  fp::Sample<msg::TrajectoryStatus> up;
  EXPECT_EQ(fp::enum_error(*up, buf, sizeof buf), nullptr);
  fp::set_raw(up->state, 4);
  EXPECT_STREQ(fp::enum_error(*up, buf, sizeof buf), "state 4 is unknown");
  fp::Sample<msg::ToolState> tool;
  fp::set_raw(tool->direction, 3);
  EXPECT_STREQ(fp::enum_error(*tool, buf, sizeof buf), "direction 3 is unknown");
  fp::Sample<msg::ControllerStatus> status;
  fp::set_raw(status->mode, 8);
  EXPECT_STREQ(fp::enum_error(*status, buf, sizeof buf), "mode 8 is unknown");
  fp::set_raw(status->mode, foresight_msg_MODE_IDLE);
  fp::set_raw(status->stop_category, 4);
  EXPECT_STREQ(fp::enum_error(*status, buf, sizeof buf), "stop_category 4 is unknown");
  fp::Sample<msg::Heartbeat> hb;
  fp::set_raw(hb->side, 2);
  EXPECT_STREQ(fp::enum_error(*hb, buf, sizeof buf), "side 2 is unknown");

  // The remote's envelope check refuses it first, with the same words.
  fp::CommandChecker remote;
  const auto v = remote.check(*c, fp::now_ns());
  EXPECT_EQ(v.code, foresight_msg_REASON_BAD_ARGUMENT);
  EXPECT_EQ(v.reason, "command 1: unknown kind 42");
}

// A received JointState is used only when its sequences describe one arm of
// finite numbers: each defect with its reason and its kind.
TEST(ProtocolNumbers, JointStateErrorNamesTheSequenceAndTheValue) {
  char buf[96];
  fp::JointStateDefect defect{};
  fp::Sample<msg::JointState> s;
  const auto set = [&](std::vector<double> q, std::vector<double> dq, std::vector<double> t) {
    fp::assign(s->q_rad, std::span<const double>(q), msg::kMaxJoints, "q");
    fp::assign(s->dq_rad_s, std::span<const double>(dq), msg::kMaxJoints, "dq");
    fp::assign(s->torque_nm, std::span<const double>(t), msg::kMaxJoints, "t");
  };
  const std::vector<double> three = {0.1, -0.2, 0.3};
  set(three, three, three);
  EXPECT_EQ(fp::joint_state_error(*s, 3, defect, buf, sizeof buf), nullptr);
  EXPECT_EQ(defect, fp::JointStateDefect::None);
  EXPECT_EQ(fp::joint_state_error(*s, 0, defect, buf, sizeof buf), nullptr);  // 0: any joint count
  EXPECT_STREQ(fp::joint_state_error(*s, 7, defect, buf, sizeof buf), "q_rad has 3 joints; the arm has 7");
  EXPECT_EQ(defect, fp::JointStateDefect::JointCount);
  set({}, {}, {});
  EXPECT_STREQ(fp::joint_state_error(*s, 0, defect, buf, sizeof buf), "q_rad is empty");
  EXPECT_EQ(defect, fp::JointStateDefect::JointCount);
  set(three, {0.1, 0.2}, three);
  EXPECT_STREQ(fp::joint_state_error(*s, 3, defect, buf, sizeof buf), "dq_rad_s has 2 values for 3 joints");
  EXPECT_EQ(defect, fp::JointStateDefect::Length);
  set(three, three, {});
  EXPECT_STREQ(fp::joint_state_error(*s, 3, defect, buf, sizeof buf), "torque_nm has 0 values for 3 joints");
  EXPECT_EQ(defect, fp::JointStateDefect::Length);
  set(three, {0.1, std::numeric_limits<double>::infinity(), 0.3}, three);
  EXPECT_STREQ(fp::joint_state_error(*s, 3, defect, buf, sizeof buf), "dq_rad_s[1] is not finite");
  EXPECT_EQ(defect, fp::JointStateDefect::NotFinite);
  EXPECT_STREQ(fp::to_string(defect), "not_finite");
  set({0.1, 0.2, std::numeric_limits<double>::quiet_NaN()}, three, three);
  EXPECT_STREQ(fp::joint_state_error(*s, 3, defect, buf, sizeof buf), "q_rad[2] is not finite");
}

// Two claims never share a domain, also within one process (a pid modulo the
// range did now and then: a long HIL test met a short one's ground heartbeats
// and never saw its link lost). 231..232 are valid ids no other claimer uses.
TEST(DomainClaim, ClaimsAreExclusiveAndAFullRangeIsSaid) {
  const dds_domainid_t a = fp::claim_free_domain(231, 232);
  const dds_domainid_t b = fp::claim_free_domain(231, 232);
  EXPECT_NE(a, b);
  EXPECT_TRUE((a == 231 || a == 232) && (b == 231 || b == 232));
  try {
    (void)fp::claim_free_domain(231, 232);
    FAIL() << "a third claim on a two-id range must be refused";
  } catch (const fp::ProtocolError& e) {
    EXPECT_STREQ(e.what(), "no free DDS domain in 231..232: every one is held by another process "
                           "(/tmp/foresight-dds-domain-*.lock)");
  }
  EXPECT_EQ(fp::unique_test_domain(), fp::unique_test_domain());  // one claim per process
}
