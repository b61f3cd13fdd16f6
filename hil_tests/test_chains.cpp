// Chains (issue 29 item 1) against the real daemon over DDS: commands that
// name the command they follow (after_command_id) are queued by the remote and
// run back to back without a round trip between them; a command of a chain
// that does not complete cancels the rest ("chain broken at command N: ...")
// and nothing of it moves the arm (the simulated drives' own record); bad
// predecessors are refused with their reason; the status lists the queue.

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "foresight/common/plan.hpp"
#include "hil_support.hpp"

namespace foresight {
namespace {

using namespace std::chrono_literals;
using protocol::AckState;
using protocol::CommandKind;
using protocol::Reason;
using test::DriveRecord;
using test::eventually;

class Chains : public test::DaemonTest {
 protected:
  void SetUp() override {
    use_sim_faults();
    DaemonTest::SetUp();
  }

  /// A GOTO_JOINT of joint 1 to q0[0] + delta at `speed` of the limits.
  static protocol::GotoJoint goto_joint1(const Eigen::VectorXd& q0, double delta, double speed = 0.3) {
    protocol::GotoJoint g;
    g.q_rad.assign(q0.data(), q0.data() + 7);
    g.q_rad[0] += delta;
    g.speed_fraction = speed;
    return g;
  }

  /// A joint move of joints 1 and 4 by `delta`, planned from q0 (about 1-2 s).
  Trajectory joint_move(const Eigen::VectorXd& q0, double delta) const {
    Goal goal;
    goal.name = "there";
    goal.kind = SegmentKind::Joint;
    goal.is_pose = false;
    goal.q = q0;
    goal.q[0] += delta;
    goal.q[3] -= delta;
    return plan_motion(model_, q0, {goal}).trajectory;
  }

  /// Every command of `ids` has its final state in the remote's journal.
  void expect_journaled(const std::vector<std::uint64_t>& ids) const {
    const auto j = journal_json();
    for (const auto id : ids) {
      bool final_row = false;
      for (const auto& c : j["commands"])
        if (c["command_id"] == id && c["session_id"] == ground_->session_id())
          final_row = final_row || c["state"] == "COMPLETED" || c["state"] == "FAILED" || c["state"] == "CANCELED";
      EXPECT_TRUE(final_row) << "command " << id << " has no final state in the journal";
    }
  }

  /// The arm stays still from now on (the drives' own record, about 0.5 s).
  void expect_nothing_moves(const char* why) {
    mark();
    const DriveRecord first = fresh_record();
    DriveRecord later;
    ASSERT_TRUE(eventually([&] { return (later = record()).seq >= first.seq + 25; }, 10s));
    ASSERT_EQ(later.q.size(), 7u);
    for (std::size_t j = 0; j < 7; ++j) EXPECT_LT(later.span(j), 1e-3) << "joint " << j + 1 << " moved " << why;
  }

  /// The ack of `state` among a result's acks (null when none).
  static const protocol::Ack* ack_of(const ground_link::CommandResult& r, AckState state) {
    for (const auto& a : r.acks)
      if (a.state == state) return &a;
    return nullptr;
  }
};

// Three GOTOs sent at once, each following the one before: the remote queues
// them, shows them in its status, and starts each one as the one before it
// completes (its EXECUTING within 50 ms of the predecessor's COMPLETED, remote
// clock), without waiting for the ground; the arm ends where the last one goes.
TEST_F(Chains, AChainRunsBackToBackWithoutWaitingForTheGround) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t a = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.05));
  Eigen::VectorXd q1 = q0;
  q1[0] += 0.05;
  // The middle one slow (about 2 s): the 2 Hz status sees it running, its successor queued.
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q1, 0.05, 0.05), -1.0, a);
  Eigen::VectorXd q2 = q1;
  q2[0] += 0.05;
  const std::uint64_t c = ground_->send(CommandKind::GotoJoint, goto_joint1(q2, 0.05), -1.0, b);

  // The status lists what the remote holds: the running one, then its chain.
  bool listed = false;
  std::string seen;
  ASSERT_TRUE(eventually(
      [&] {
        const auto s = ground_->status();
        if (!s) return false;
        const auto& q = s->value.queue;
        seen = std::to_string(q.size()) + " held";
        listed = q.size() == 2 && q[0].command_id == b && q[0].state == AckState::Executing &&
                 q[0].after_command_id == a && q[1].command_id == c && q[1].after_command_id == b &&
                 q[1].state == AckState::Queued;
        return listed || (q.empty() && ground_->wait_final(c, 0ms).finished);
      },
      30s));
  EXPECT_TRUE(listed) << "never saw [b executing after a, c queued after b]; last: " << seen;

  const auto ra = ground_->wait_final(a, 30s);
  const auto rb = ground_->wait_final(b, 30s);
  const auto rc = ground_->wait_final(c, 30s);
  ASSERT_TRUE(ra.succeeded()) << ra.reason;
  ASSERT_TRUE(rb.succeeded()) << rb.reason;
  ASSERT_TRUE(rc.succeeded()) << rc.reason;
  // Sent ahead: queued on the remote before the one it follows completed.
  for (const auto* r : {&rb, &rc}) {
    const protocol::Ack* queued = ack_of(*r, AckState::Queued);
    ASSERT_NE(queued, nullptr);
    const protocol::Ack* before = ack_of(r == &rb ? ra : rb, AckState::Completed);
    ASSERT_NE(before, nullptr);
    EXPECT_LT(queued->stamp_ns, before->stamp_ns) << "command " << r->command_id << " was not queued ahead";
    // Started on the remote right after its predecessor: no round trip.
    const protocol::Ack* executing = ack_of(*r, AckState::Executing);
    ASSERT_NE(executing, nullptr);
    const double gap_s = 1e-9 * static_cast<double>(executing->stamp_ns - before->stamp_ns);
    EXPECT_GE(gap_s, 0.0);
    EXPECT_LT(gap_s, 0.05) << "command " << r->command_id << " started " << gap_s << " s after its predecessor";
    std::printf("chained command %llu: EXECUTING %.1f ms after its predecessor's COMPLETED (remote clock)\n",
                static_cast<unsigned long long>(r->command_id), 1e3 * gap_s);
  }
  const DriveRecord rec = fresh_record();
  ASSERT_EQ(rec.q.size(), 7u);
  EXPECT_NEAR(rec.q[0], q0[0] + 0.15, 2e-3);
  // The journal has the chain: each RECEIVED row names its predecessor.
  const nlohmann::json j = journal_json();
  int chained_rows = 0;
  for (const auto& row : j["commands"])
    if (row["state"] == "RECEIVED" && row["detail"].contains("after_command_id")) {
      const auto id = row["command_id"].get<std::uint64_t>();
      EXPECT_EQ(row["detail"]["after_command_id"].get<std::uint64_t>(), id == b ? a : b);
      ++chained_rows;
    }
  EXPECT_EQ(chained_rows, 2);
}

// The second command of a chain fails when it starts (a Cartesian goal out of
// reach, planned only when its turn comes): the third is CANCELED with the
// place and cause of the break, and the arm stays where the first left it
// (the drives' own record).
TEST_F(Chains, AFailureBreaksTheChainAndNothingAfterItMoves) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t a = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.08, 0.2));
  protocol::GotoCart far;
  far.frame = "lst_tip";
  far.base_T_frame = Pose(Eigen::Translation3d(3.0, 0.0, 0.5));  // beyond the arm's reach
  const std::uint64_t b = ground_->send(CommandKind::GotoCart, far, -1.0, a);
  Eigen::VectorXd q1 = q0;
  q1[0] += 0.08;
  const std::uint64_t c = ground_->send(CommandKind::GotoJoint, goto_joint1(q1, -0.2), -1.0, b);

  const auto ra = ground_->wait_final(a, 30s);
  const auto rb = ground_->wait_final(b, 30s);
  const auto rc = ground_->wait_final(c, 30s);
  ASSERT_TRUE(ra.succeeded()) << ra.reason;
  ASSERT_TRUE(rb.finished);
  EXPECT_EQ(rb.state, AckState::Failed) << protocol::to_string(rb.state) << ": " << rb.reason;
  EXPECT_EQ(rb.code, Reason::Unreachable) << rb.reason;
  ASSERT_TRUE(rc.finished);
  EXPECT_EQ(rc.state, AckState::Canceled) << protocol::to_string(rc.state) << ": " << rc.reason;
  EXPECT_EQ(rc.code, Reason::Aborted);
  EXPECT_EQ(rc.reason.rfind("chain broken at command " + std::to_string(b) + ": failed: ", 0), 0u) << rc.reason;
  EXPECT_EQ(ack_of(rc, AckState::Executing), nullptr) << "the canceled command ran";

  // Nothing moved after the first: the arm holds at its end.
  mark();
  const DriveRecord rec = fresh_record();
  ASSERT_EQ(rec.q.size(), 7u);
  EXPECT_NEAR(rec.q[0], ra.final_q_rad[0], 1e-3);
  EXPECT_NEAR(rec.q[0], q0[0] + 0.08, 2e-3);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_LT(rec.span(j), 1e-4) << "joint " << j + 1 << " moved";
  const auto s = ground_->status();
  ASSERT_TRUE(s);
  EXPECT_TRUE(s->value.queue.empty());
}

// `foresight watch` shows the chain the remote holds: what runs, what is queued.
TEST_F(Chains, WatchShowsWhatRunsAndWhatIsQueued) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t a = start_slow_motion(q0, q0[0] > 0.0 ? -1.0 : 1.0);  // about 8 s at 10%
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.0), -1.0, a);
  const std::string want = "running " + std::to_string(a) + " goto_joint | queued " + std::to_string(b);
  std::string out;
  for (int i = 0; i < 3 && out.find(want) == std::string::npos && !ground_->wait_final(a, 0ms).finished; ++i)
    out = test::run_foresight("watch --count 1 --period 0.2 --domain " + std::to_string(domain_)).out;
  EXPECT_NE(out.find(want), std::string::npos) << out;
  protocol::Abort stop;
  stop.category = protocol::StopCategory::Cat2;
  EXPECT_TRUE(run(CommandKind::Abort, stop, 2.0).succeeded());
  EXPECT_EQ(ground_->wait_final(b, 10s).state, AckState::Canceled);
}

// An ABORT of a running chain's command stops it and cancels the rest.
TEST_F(Chains, AnAbortStopsTheRunningCommandAndCancelsTheRestOfItsChain) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t a = start_slow_motion(q0, 0.3);
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.0), -1.0, a);
  ASSERT_TRUE(wait_queued(b));
  protocol::Abort abort;
  abort.category = protocol::StopCategory::Cat2;
  const auto r = run(CommandKind::Abort, abort, 2.0);
  EXPECT_TRUE(r.succeeded()) << r.reason;
  const auto ra = ground_->wait_final(a, 10s);
  const auto rb = ground_->wait_final(b, 10s);
  EXPECT_EQ(ra.state, AckState::Canceled) << ra.reason;
  EXPECT_EQ(rb.state, AckState::Canceled) << rb.reason;
  EXPECT_EQ(ack_of(rb, AckState::Executing), nullptr) << "the canceled command ran";
}

// A REQUEST may follow a motion: the remote queues it and reports when the
// motion COMPLETED (the chain's end seen half a round trip later, not one and
// a half).
TEST_F(Chains, AReportChainedBehindAMotionComesOnceTheMotionCompleted) {
  take_and_recover();
  const std::uint64_t a = start_slow_motion(current_q(), 0.1);
  protocol::Request status;
  status.what = protocol::RequestWhat::Status;
  const std::uint64_t b = ground_->send(CommandKind::Request, status, -1.0, a);
  const auto rb = ground_->wait_final(b, 30s);
  const auto ra = ground_->wait_final(a, 1s);
  ASSERT_TRUE(ra.succeeded()) << ra.reason;
  ASSERT_TRUE(rb.succeeded()) << rb.reason;
  ASSERT_NE(ack_of(rb, AckState::Queued), nullptr) << "the report was not held behind the motion";
  const auto* done_a = ack_of(ra, AckState::Completed);
  const auto* done_b = ack_of(rb, AckState::Completed);
  ASSERT_TRUE(done_a && done_b);
  EXPECT_GE(done_b->stamp_ns, done_a->stamp_ns) << "reported before the motion ended";
  ASSERT_EQ(rb.final_q_rad.size(), 7u);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NEAR(rb.final_q_rad[j], ra.final_q_rad[j], 1e-3) << "joint " << j + 1;
}

// Bad predecessors, each REJECTED with its reason, the running chain untouched.
TEST_F(Chains, BadPredecessorsAreRefusedWithTheirReason) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  auto rejected = [&](const ground_link::CommandResult& r, Reason code, const std::string& starts) {
    EXPECT_EQ(r.state, AckState::Rejected) << protocol::to_string(r.state) << ": " << r.reason;
    EXPECT_EQ(r.code, code) << protocol::to_string(r.code) << ": " << r.reason;
    EXPECT_NE(r.reason.find(starts), std::string::npos) << r.reason;
  };
  auto send_wait = [&](CommandKind kind, const protocol::Payload& p, std::uint64_t after) {
    return ground_->wait_final(ground_->send(kind, p, -1.0, after), 10s);
  };
  // Itself: the next command id of this session is the sequence's next.
  {
    const std::uint64_t next = ground_->send(CommandKind::Request, protocol::Request{}) + 1;
    rejected(send_wait(CommandKind::GotoJoint, goto_joint1(q0, 0.01), next), Reason::BadArgument,
             "command " + std::to_string(next) + " cannot follow itself");
  }
  // Unknown in this session.
  rejected(send_wait(CommandKind::GotoJoint, goto_joint1(q0, 0.01), 987654), Reason::BadArgument,
           "command 987654 is not a command of this session");
  // A predecessor that ended without completing: the chain is broken already.
  protocol::GotoJoint beyond = goto_joint1(q0, 0.0);
  beyond.q_rad[0] = 100.0;  // outside joint 1's limits: REJECTED at once
  const auto bad = run(CommandKind::GotoJoint, beyond);
  ASSERT_EQ(bad.state, AckState::Rejected) << bad.reason;
  rejected(send_wait(CommandKind::GotoJoint, goto_joint1(q0, 0.01), bad.command_id), Reason::Aborted,
           "chain broken at command " + std::to_string(bad.command_id) + ": rejected: ");
  // Kinds that do not chain.
  const std::uint64_t slow = start_slow_motion(q0, 0.1);
  protocol::Abort abort;
  abort.category = protocol::StopCategory::Cat2;
  rejected(send_wait(CommandKind::Abort, abort, slow), Reason::BadArgument,
           "abort cannot follow another command (after_command_id " + std::to_string(slow) + ")");
  // The running motion was not touched by any of it.
  const auto rs = ground_->wait_final(slow, 30s);
  EXPECT_TRUE(rs.succeeded()) << protocol::to_string(rs.state) << ": " << rs.reason;
  // A predecessor that completed: this one starts from where it left the arm.
  Eigen::VectorXd q1 = q0;
  q1[0] += 0.1;
  const auto after_done = send_wait(CommandKind::GotoJoint, goto_joint1(q1, -0.1), slow);
  EXPECT_TRUE(after_done.succeeded()) << protocol::to_string(after_done.state) << ": " << after_done.reason;
}

// controller.max_chain_length: the command that would make the chain longer
// is refused naming the key and the bound.
TEST_F(Chains, AChainLongerThanTheConfiguredBoundIsRefused) {
  // The shipped configuration with the bound at 2.
  ASSERT_NO_FATAL_FAILURE(restart_remote_with("max_chain_length: 32", "max_chain_length: 2"));
  take_and_recover();

  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t a = start_slow_motion(q0, 0.1);
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.0), -1.0, a);
  const auto rc = ground_->wait_final(ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.05), -1.0, b), 10s);
  EXPECT_EQ(rc.state, AckState::Rejected) << rc.reason;
  EXPECT_EQ(rc.code, Reason::BadArgument);
  EXPECT_NE(rc.reason.find("a chain of 3 commands exceeds controller.max_chain_length 2"), std::string::npos)
      << rc.reason;
  EXPECT_TRUE(ground_->wait_final(a, 30s).succeeded());
  EXPECT_TRUE(ground_->wait_final(b, 30s).succeeded());
}

// Upload and run in one go (item 2): a RUN that arrives before any chunk of
// its upload is QUEUED ("waiting for upload N"), and starts as soon as the
// whole upload committed with its hash; the arm ends at the trajectory's end.
TEST_F(Chains, ARunThatOvertakesItsUploadRunsOnceTheUploadCommitted) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const Trajectory traj = joint_move(q0, 0.1);
  const std::uint64_t id = 424242;
  protocol::RunTrajectory run_cmd;
  run_cmd.trajectory_id = id;
  run_cmd.content_hash = trajectory_hash(traj);
  run_cmd.upload_wait_s = 20.0;
  const std::uint64_t c = ground_->send(CommandKind::Trajectory, run_cmd);
  // The RUN is held, waiting, before a single chunk went out.
  std::string note;
  ASSERT_TRUE(eventually(
      [&] {
        for (const auto& a : ground_->wait_final(c, 0ms).acks)
          if (a.state == AckState::Queued) note = a.reason;
        return !note.empty();
      },
      10s));
  EXPECT_EQ(note, "waiting for upload 424242 to commit (at most 20.0 s)");
  auto up = ground_->start_upload(traj, id);
  const auto r = ground_->wait_final(c, 30s);
  ASSERT_TRUE(r.succeeded()) << protocol::to_string(r.state) << ": " << r.reason;
  ground_->wait_upload(up, 5s);
  EXPECT_TRUE(up.committed());
  const DriveRecord rec = fresh_record();
  ASSERT_EQ(rec.q.size(), 7u);
  EXPECT_NEAR(rec.q[0], q0[0] + 0.1, 2e-3);
  EXPECT_NEAR(rec.q[3], q0[3] - 0.1, 2e-3);
}

// An upload that never arrives fails its RUN after upload_wait_s, with the
// reason; the command chained after it is canceled; nothing moves. A RUN
// whose hash differs from the upload that then commits FAILS with both
// hashes; a wait above controller.max_upload_wait_s is REJECTED.
TEST_F(Chains, ARunWhoseUploadNeverCommitsFailsAndBreaksItsChain) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  mark();
  protocol::RunTrajectory run_cmd;
  run_cmd.trajectory_id = 777001;
  run_cmd.upload_wait_s = 1.0;
  const std::uint64_t a = ground_->send(CommandKind::Trajectory, run_cmd);
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.05), -1.0, a);
  const auto ra = ground_->wait_final(a, 15s);
  const auto rb = ground_->wait_final(b, 15s);
  ASSERT_TRUE(ra.finished);
  EXPECT_EQ(ra.state, AckState::Failed) << ra.reason;
  EXPECT_EQ(ra.code, Reason::IncompleteUpload);
  EXPECT_EQ(ra.reason, "upload 777001 did not commit within 1.0 s of the RUN (upload_wait_s): nothing of it ran");
  EXPECT_EQ(rb.state, AckState::Canceled) << rb.reason;
  EXPECT_EQ(rb.reason.rfind("chain broken at command " + std::to_string(a) + ": failed: upload 777001", 0), 0u)
      << rb.reason;
  EXPECT_EQ(ack_of(rb, AckState::Executing), nullptr) << "the canceled command ran";

  // The hash in the RUN is not the upload's: FAILED when the upload commits.
  const Trajectory traj = joint_move(q0, 0.1);
  run_cmd.trajectory_id = 777002;
  run_cmd.content_hash = trajectory_hash(traj);
  run_cmd.content_hash[0] ^= 1;
  run_cmd.upload_wait_s = 20.0;
  const std::uint64_t c = ground_->send(CommandKind::Trajectory, run_cmd);
  ASSERT_TRUE(eventually([&] { return ack_of(ground_->wait_final(c, 0ms), AckState::Queued) != nullptr; }, 10s));
  (void)ground_->start_upload(traj, 777002);
  const auto rc = ground_->wait_final(c, 30s);
  EXPECT_EQ(rc.state, AckState::Failed) << rc.reason;
  EXPECT_EQ(rc.code, Reason::HashMismatch);
  EXPECT_NE(rc.reason.find("differs from the committed upload's " + to_hex(trajectory_hash(traj))), std::string::npos)
      << rc.reason;

  // Longer than the remote allows (controller.max_upload_wait_s 60).
  run_cmd.upload_wait_s = 61.0;
  const auto rd = run(CommandKind::Trajectory, run_cmd);
  EXPECT_EQ(rd.state, AckState::Rejected);
  EXPECT_EQ(rd.reason, "upload_wait_s 61 out of range [0, 60] s (controller.max_upload_wait_s)");

  // Nothing of it moved the arm: the drives' own record since the mark.
  const DriveRecord rec = fresh_record();
  ASSERT_EQ(rec.q.size(), 7u);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_LT(rec.span(j), 1e-4) << "joint " << j + 1 << " moved";
}

// Faults in the middle of a chain (issue 29): each fails its own step with its
// reason, cancels the rest of the chain ("chain broken at command N: failed:
// ..."), nothing of the rest runs or moves the arm (the drives' record), and
// the journal has every command's end.
TEST_F(Chains, AToolJamInLoosenBreaksTheChainAndNothingAfterItMoves) {
  take_and_recover();
  fault_on("tool_jam");
  const Eigen::VectorXd q0 = current_q();
  protocol::InvokeAlgorithm loosen;
  loosen.name = "loosen";
  loosen.params = {{"turns", 2.0}};
  const std::uint64_t a = ground_->send(CommandKind::InvokeAlgorithm, loosen);
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.1), -1.0, a);
  const std::uint64_t c = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, -0.1), -1.0, b);
  const auto ra = ground_->wait_final(a, 30s);
  const auto rb = ground_->wait_final(b, 10s);
  const auto rc = ground_->wait_final(c, 10s);
  EXPECT_EQ(ra.state, AckState::Failed) << ra.reason;
  EXPECT_EQ(ra.code, Reason::ToolFault) << ra.reason;
  EXPECT_EQ(ra.reason.rfind("loosen: tool jammed", 0), 0u) << ra.reason;
  for (const auto* r : {&rb, &rc}) {
    EXPECT_EQ(r->state, AckState::Canceled) << r->reason;
    EXPECT_EQ(r->code, Reason::Aborted);
    EXPECT_EQ(ack_of(*r, AckState::Executing), nullptr) << "a canceled command ran";
  }
  // Both name the cause: the command that broke the chain, not the one before them.
  for (const auto* r : {&rb, &rc})
    EXPECT_EQ(r->reason.rfind("chain broken at command " + std::to_string(a) + ": failed: loosen: tool jammed", 0), 0u)
        << r->reason;
  expect_nothing_moves("after the jam");
  const auto rec = record();
  EXPECT_NEAR(rec.q[0], q0[0], 1e-3) << "the chained GOTO moved joint 1";
  fault_off("tool_jam");
  expect_journaled({a, b, c});
}

TEST_F(Chains, AnFtOverloadInTheInsertBreaksTheChainAndTheArmHolds) {
  take_and_recover();
  protocol::InvokeAlgorithm tare;
  tare.name = "tare";
  ASSERT_TRUE(run(CommandKind::InvokeAlgorithm, tare).succeeded());
  // 1 cm in front of the bore, then a fast insert with a low force limit
  // (the tool bottoms in the bore), then a pull-out and a GOTO chained behind it.
  const Eigen::VectorXd q_home = current_q();
  const Trajectory to_bore = plan_to_before_the_bore();
  const auto up = ground_->upload(to_bore, 30s);
  ASSERT_TRUE(up.committed()) << up.reason;
  protocol::RunTrajectory go;
  go.trajectory_id = up.trajectory_id;
  go.content_hash = up.local_hash;
  const std::uint64_t t = ground_->send(CommandKind::Trajectory, go);
  protocol::InvokeAlgorithm insert;
  insert.name = "insert";
  insert.params = {{"depth_m", 0.12}, {"speed_m_s", 0.06}, {"contact_force_n", 10.0}, {"max_force_n", 20.0}};
  const std::uint64_t a = ground_->send(CommandKind::InvokeAlgorithm, insert, -1.0, t);
  protocol::InvokeAlgorithm pull;
  pull.name = "pull_out";
  pull.params = {{"distance_m", 0.05}};
  const std::uint64_t b = ground_->send(CommandKind::InvokeAlgorithm, pull, -1.0, a);
  const std::uint64_t c = ground_->send(CommandKind::GotoJoint, goto_joint1(q_home, 0.0), -1.0, b);
  ASSERT_TRUE(ground_->wait_final(t, 60s).succeeded());
  const auto ra = ground_->wait_final(a, 30s);
  const auto rb = ground_->wait_final(b, 10s);
  const auto rc = ground_->wait_final(c, 10s);
  EXPECT_EQ(ra.state, AckState::Failed) << ra.reason;
  EXPECT_EQ(ra.code, Reason::ForceLimit) << ra.reason;
  EXPECT_EQ(ra.reason.rfind("insert: force limit ", 0), 0u) << ra.reason;
  EXPECT_EQ(rb.state, AckState::Canceled) << rb.reason;
  EXPECT_EQ(rb.reason.rfind("chain broken at command " + std::to_string(a) + ": failed: insert: force limit", 0), 0u)
      << rb.reason;
  EXPECT_EQ(rc.state, AckState::Canceled) << rc.reason;
  EXPECT_EQ(ack_of(rb, AckState::Executing), nullptr) << "the pull-out ran";
  EXPECT_EQ(ack_of(rc, AckState::Executing), nullptr) << "the GOTO ran";
  // The arm holds where the insert stopped (not a controller stop: IDLE).
  ASSERT_TRUE(eventually(
      [&] {
        const auto s = ground_->status();
        return s && s->age_s < 0.5 && s->value.mode == protocol::ControllerMode::Idle &&
               s->value.stop_category == protocol::StopCategory::None;
      },
      5s));
  expect_nothing_moves("after the overload");
  ASSERT_EQ(ra.final_q_rad.size(), 7u);
  const auto rec = record();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NEAR(rec.q[j], ra.final_q_rad[j], 2e-3) << "joint " << j + 1;
  expect_journaled({t, a, b, c});
}

TEST_F(Chains, ALostDriveHeartbeatMidChainStopsTheArmAndCancelsTheRest) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const double delta = 0.4;
  const std::uint64_t a = start_slow_motion(q0, delta);
  const std::uint64_t b = ground_->send(CommandKind::GotoJoint, goto_joint1(q0, 0.0), -1.0, a);
  ASSERT_TRUE(wait_queued(b));
  fault_on("drive_silent_4");
  const auto ra = ground_->wait_final(a, 15s);
  const auto rb = ground_->wait_final(b, 10s);
  EXPECT_TRUE(ra.state == AckState::Canceled || ra.state == AckState::Failed) << protocol::to_string(ra.state);
  EXPECT_NE(ra.reason.find("heartbeat"), std::string::npos) << ra.reason;
  // The stop itself cancels every queued command, with its cause.
  EXPECT_EQ(rb.state, AckState::Canceled) << rb.reason;
  EXPECT_EQ(rb.reason.rfind("the controller stopped: hw: heartbeat lost node 4 joint 4", 0), 0u) << rb.reason;
  EXPECT_EQ(ack_of(rb, AckState::Executing), nullptr) << "the chained GOTO ran";
  ASSERT_TRUE(eventually(
      [&] {
        const auto s = ground_->status();
        return s && s->value.stop_category == protocol::StopCategory::Cat0;
      },
      10s));
  expect_nothing_moves("after the category 0 stop");
  const auto rec = record();
  EXPECT_GE(rec.q[0], q0[0] - 2e-3);
  EXPECT_LE(rec.q[0], q0[0] + delta + 2e-3);
  fault_off("drive_silent_4");
  expect_journaled({a, b});
}

}  // namespace
}  // namespace foresight
