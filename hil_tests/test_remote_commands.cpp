// Every command path end to end: the real daemon `foresight-remote --sim`
// (CiA 402 drives and the F/T sensor simulated on mock CAN buses, the LST
// over Modbus TCP on 127.0.0.1) in its own process, the ground's GroundLink in
// this one, DDS between them on loopback.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sqlite3.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <set>

#include "foresight/common/plan.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/ground_link/ground_link.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/convert.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/security.hpp"
#include "foresight/test/cli.hpp"
#include "hil_support.hpp"

using namespace foresight;
using namespace std::chrono_literals;
using protocol::AckState;
using protocol::CommandKind;
using protocol::Reason;
namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;

namespace {

using test::DriveRecord;

class RemoteCommands : public test::DaemonTest {
 protected:
  void SetUp() override {
    estop_ = test::temp_path(".estop");
    remote_options_.estop_file = estop_;
    use_sim_faults();
    DaemonTest::SetUp();
  }
  void TearDown() override {
    DaemonTest::TearDown();
    std::remove(estop_.c_str());
  }

  static std::vector<AckState> states(const ground_link::CommandResult& r) {
    std::vector<AckState> s;
    for (const auto& a : r.acks) s.push_back(a.state);
    return s;
  }

  std::string estop_;
};

const std::vector<AckState> kCompletedMotion = {AckState::Received, AckState::Queued, AckState::Executing,
                                                AckState::Completed};

}  // namespace

TEST_F(RemoteCommands, ControlMustBeTakenAndDrivesEnabledBeforeAnythingMoves) {
  protocol::GotoJoint g;
  g.q_rad.assign(7, 0.1);
  auto r = run(CommandKind::GotoJoint, g);
  EXPECT_EQ(r.state, AckState::Rejected);
  EXPECT_EQ(r.code, Reason::NotInControl);
  EXPECT_EQ(r.reason, "no ground station holds control: send TAKE_CONTROL first");

  ASSERT_TRUE(run(CommandKind::TakeControl).succeeded());
  r = run(CommandKind::GotoJoint, g);
  EXPECT_EQ(r.state, AckState::Rejected);
  EXPECT_EQ(r.code, Reason::Faulted);
  EXPECT_EQ(r.reason, "the drives are not enabled: send RECOVER first");

  // A second ground station can watch but not command, nor take control.
  ground_link::Config c;
  c.domain = domain_;
  ground_link::GroundLink other(c);
  ASSERT_TRUE(other.wait_for_remote(30s));
  const auto take = other.execute(CommandKind::TakeControl, protocol::NoPayload{}, 1.0);
  EXPECT_EQ(take.state, AckState::Rejected);
  EXPECT_EQ(take.code, Reason::NotInControl);
  const auto req = other.execute(CommandKind::Request, protocol::Request{protocol::RequestWhat::Status}, 1.0);
  EXPECT_TRUE(req.succeeded()) << req.reason;
}

TEST_F(RemoteCommands, GotoJointRunsTheWholeLifecycleAndReportsTheFinalJoints) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  protocol::GotoJoint g;
  g.q_rad.resize(7);
  for (int j = 0; j < 7; ++j) g.q_rad[static_cast<std::size_t>(j)] = q0[j] + (j % 2 ? -0.05 : 0.05);
  g.speed_fraction = 0.5;
  const auto r = run(CommandKind::GotoJoint, g, 5.0);
  ASSERT_TRUE(r.succeeded()) << r.reason << "\n" << remote_->log();
  EXPECT_EQ(states(r), kCompletedMotion);
  ASSERT_EQ(r.final_q_rad.size(), 7u);
  for (int j = 0; j < 7; ++j) EXPECT_NEAR(r.final_q_rad[static_cast<std::size_t>(j)], g.q_rad[static_cast<std::size_t>(j)], 2e-3) << "joint " << j + 1;

  // Bad inputs: nothing moves, the reason names what is wrong.
  protocol::GotoJoint bad = g;
  bad.q_rad.pop_back();
  auto b = run(CommandKind::GotoJoint, bad);
  EXPECT_EQ(b.code, Reason::JointCount);
  EXPECT_EQ(b.reason, "command " + std::to_string(b.command_id) + ": goto_joint.q_rad has 6 angles; the arm has 7 joints");
  bad = g;
  bad.q_rad[2] = 9.0;
  b = run(CommandKind::GotoJoint, bad);
  EXPECT_EQ(b.code, Reason::BadArgument);
  EXPECT_NE(b.reason.find("joint 3: 9.0000 rad outside its limits"), std::string::npos) << b.reason;
  protocol::InvokeAlgorithm alg;
  alg.name = "dance";
  b = run(CommandKind::InvokeAlgorithm, alg);
  EXPECT_EQ(b.code, Reason::UnknownAlgorithm);
  alg.name = "insert";
  alg.params = {{"depth", 0.05}};
  b = run(CommandKind::InvokeAlgorithm, alg);
  EXPECT_EQ(b.code, Reason::BadArgument);
  EXPECT_EQ(b.reason.rfind("insert: unknown parameter 'depth' (expected one of: depth_m,", 0), 0u) << b.reason;
  // Issue 26: every parameter has a range; a value outside is refused, nothing moves.
  const Eigen::VectorXd q_before = current_q();
  alg.params = {{"depth_m", 1e300}};
  b = run(CommandKind::InvokeAlgorithm, alg);
  EXPECT_EQ(b.state, AckState::Rejected);
  EXPECT_EQ(b.code, Reason::BadArgument);
  EXPECT_EQ(b.reason, "insert: depth_m 1e+300 out of range [0.001, 0.2] m");
  alg.params = {{"speed_m_s", 1e-300}};
  b = run(CommandKind::InvokeAlgorithm, alg);
  EXPECT_EQ(b.reason, "insert: speed_m_s 1e-300 out of range [0.0001, 0.1] m/s");
  alg.params = {};
  alg.timeout_s = 1e300;
  b = run(CommandKind::InvokeAlgorithm, alg);
  EXPECT_EQ(b.code, Reason::BadArgument);
  EXPECT_EQ(b.reason, "insert: timeout_s 1e+300 out of range [0, 600] s (0: the default)");
  EXPECT_LT((current_q() - q_before).cwiseAbs().maxCoeff(), 1e-4);
}

TEST_F(RemoteCommands, UploadedTrajectoryRunsOnlyWithItsCommittedHash) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  Goal goal;
  goal.name = "there";
  goal.kind = SegmentKind::Joint;
  goal.is_pose = false;
  goal.q = q0;
  goal.q[0] += 0.1;
  goal.q[3] -= 0.1;
  const Plan plan = plan_motion(model_, q0, {goal});
  const auto up = ground_->upload(plan.trajectory, 30s);
  ASSERT_TRUE(up.committed()) << up.reason;
  EXPECT_EQ(up.remote_hash, trajectory_hash(plan.trajectory));

  protocol::RunTrajectory run_cmd;
  run_cmd.trajectory_id = up.trajectory_id;
  run_cmd.content_hash = up.local_hash;
  run_cmd.content_hash[0] ^= 1;
  auto r = run(CommandKind::Trajectory, run_cmd);
  EXPECT_EQ(r.code, Reason::HashMismatch);
  run_cmd.trajectory_id = up.trajectory_id + 1;
  r = run(CommandKind::Trajectory, run_cmd);
  EXPECT_EQ(r.code, Reason::UnknownTrajectory);

  run_cmd.trajectory_id = up.trajectory_id;
  run_cmd.content_hash = up.local_hash;
  r = run(CommandKind::Trajectory, run_cmd, plan.trajectory.duration_s());
  ASSERT_TRUE(r.succeeded()) << r.reason << "\n" << remote_->log();
  EXPECT_EQ(states(r), kCompletedMotion);
  for (int j = 0; j < 7; ++j) EXPECT_NEAR(r.final_q_rad[static_cast<std::size_t>(j)], goal.q[j], 2e-3);

  // Run again: the arm is at the end now, the trajectory starts elsewhere.
  r = run(CommandKind::Trajectory, run_cmd);
  EXPECT_EQ(r.state, AckState::Rejected);
  EXPECT_EQ(r.code, Reason::StartMismatch);
  EXPECT_EQ(r.reason, "the trajectory starts 0.1000 rad from the arm at joint 1 (tolerance 0.0100 rad): plan an "
                      "approach segment (a GOTO_JOINT to its first sample)");
  // A command may not widen the tolerance past 0.02 rad (issue 25: 2.5 rad let the arm jump).
  run_cmd.start_tolerance_rad = 0.5;
  r = run(CommandKind::Trajectory, run_cmd);
  EXPECT_EQ(r.state, AckState::Rejected);
  EXPECT_EQ(r.code, Reason::BadArgument);
  EXPECT_EQ(r.reason, "start_tolerance_rad 0.5 out of range [0, 0.02] rad: a larger start offset would jump the arm; "
                      "plan an approach segment (a GOTO_JOINT to the first sample)");
}

// Issue 25: the control loop knows each command by an id of the
// supervisor's own, so another session's ABORT that happens to carry the
// running command's id stops the arm without finishing that command in its
// name (it used to be acked COMPLETED, the ABORT FAILED with its text).
TEST_F(RemoteCommands, AnAbortCarryingTheRunningCommandsIdFromAnotherSessionDoesNotFinishIt) {
  take_and_recover();
  const std::uint64_t id = start_slow_motion(0.4);
  ASSERT_GT(id, 1u);
  ground_link::Config c = ground_config_;
  c.domain = domain_;
  ground_link::GroundLink other(c);
  ASSERT_TRUE(other.wait_for_remote(30s));
  protocol::Request status;
  status.what = protocol::RequestWhat::Status;
  std::uint64_t last = 0;
  for (int i = 0; i < 100 && last + 1 < id; ++i) last = other.send(CommandKind::Request, status);
  protocol::Abort a;
  a.category = protocol::StopCategory::Cat2;
  a.reason = "second session";
  const std::uint64_t abort_id = other.send(CommandKind::Abort, a);
  ASSERT_EQ(abort_id, id);
  const auto stopped = other.wait_final(abort_id, 10s);
  EXPECT_EQ(stopped.state, AckState::Completed) << stopped.reason;
  const auto moved = ground_->wait_final(id, 15s);
  EXPECT_EQ(moved.state, AckState::Canceled) << moved.reason;
  EXPECT_EQ(moved.code, Reason::Aborted);
  EXPECT_NE(moved.reason.find("stop commanded"), std::string::npos) << moved.reason;
}

// Issue 28: the commander's session id read off its published acks, sent
// from another participant with a sequence number and command id ahead of the
// commander's (it used to run: joint 2 moved 0.3 rad). It is refused
// NOT_IN_CONTROL naming both participants, journaled with its writer, nothing
// moves on the drives' own record, and the commander's own sequence is
// untouched: its next command runs.
TEST_F(RemoteCommands, ACommandInTheCommandersSessionFromAnotherParticipantIsRefusedAndMovesNothing) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  mark();

  protocol::Participant forger(static_cast<dds_domainid_t>(domain_));
  protocol::Writer<protocol::msg::Command> commands(forger);
  protocol::Reader<protocol::msg::CommandAck> acks(forger);
  ASSERT_TRUE(commands.wait_for_readers(1, 30s));
  protocol::CommandSequencer sequencer(ground_->session_id());
  protocol::Sample<protocol::msg::Command> c;
  for (int i = 0; i < 1000; ++i) c = sequencer.next(foresight_msg_CMD_REQUEST);  // ahead of the commander
  c = sequencer.next(foresight_msg_CMD_GOTO_JOINT);
  protocol::GotoJoint g;
  g.q_rad.assign(q0.data(), q0.data() + 7);
  g.q_rad[1] += 0.3;
  g.speed_fraction = 0.5;
  protocol::fill_payload(*c, CommandKind::GotoJoint, g);
  const std::uint64_t forged_id = c->command_id;
  commands.write(c);

  protocol::Sample<protocol::msg::CommandAck> ack;
  std::optional<protocol::Ack> final;
  ASSERT_TRUE(test::eventually(
      [&] {
        while (acks.take(ack)) {
          const protocol::Ack a = protocol::from_wire(*ack);
          if (a.session_id == ground_->session_id() && a.command_id == forged_id && a.state != AckState::Received)
            final = a;
        }
        return final.has_value();
      },
      30s));
  EXPECT_EQ(final->state, AckState::Rejected);
  EXPECT_EQ(final->code, Reason::NotInControl);
  EXPECT_NE(final->reason.find("is in control from participant "), std::string::npos) << final->reason;
  EXPECT_NE(final->reason.find("; this command came from participant "), std::string::npos) << final->reason;

  // Nothing moved on the drives' own record; the commander still commands.
  const DriveRecord r = fresh_record();
  ASSERT_EQ(r.hi.size(), 7u);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_LT(r.hi[j] - r.lo[j], 1e-3) << "joint " << j + 1 << " moved";
  protocol::GotoJoint mine;
  mine.q_rad.assign(q0.data(), q0.data() + 7);
  mine.q_rad[0] += 0.05;
  const auto ok = run(CommandKind::GotoJoint, mine, 5.0);
  EXPECT_TRUE(ok.succeeded()) << ok.reason;

  // The journal names each command's writer: the forged one is not the commander's.
  std::string commander_writer, forged_writer;
  const nlohmann::json journal = journal_json();
  for (const auto& row : journal["commands"]) {
    if (row["state"] != "RECEIVED" || !row["detail"].contains("writer")) continue;
    if (row["kind"] == "TAKE_CONTROL") commander_writer = row["detail"]["writer"];
    if (row["command_id"] == forged_id) forged_writer = row["detail"]["writer"];
  }
  EXPECT_EQ(commander_writer.size(), 35u) << journal.dump();  // 32 hex digits in 4 groups
  EXPECT_EQ(forged_writer.size(), 35u) << journal.dump();
  EXPECT_NE(commander_writer, forged_writer);
}

// Issue 28 / 25: an ABORT reaches the control loop before its RECEIVED row is
// synced to the disk. The journal's write lock held by another connection (a
// disk that stalls, an engineer's sqlite3 shell) keeps the supervisor waiting
// on that row; the arm stops anyway, on the drives' own record, while the
// lock is still held.
TEST_F(RemoteCommands, AnAbortStopsTheArmWhileTheJournalCannotBeWritten) {
  take_and_recover();
  start_slow_motion(1.0);  // several seconds at a tenth of joint 1's speed
  // Joint 1 moved over about 200 ms of the drives' record (10 records).
  auto moving = [&] {
    const double q = record().q.at(0);
    DriveRecord later;
    for (int i = 0; i < 5; ++i) later = fresh_record();
    return std::abs(later.q.at(0) - q) > 1e-4;
  };
  ASSERT_TRUE(test::eventually(moving, 5s)) << "the motion did not run";
  // The journal's write lock, released however the test ends (the daemon
  // must be able to write again to stop cleanly).
  struct Lock {
    sqlite3* db = nullptr;
    ~Lock() {
      if (db == nullptr) return;
      sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
      sqlite3_close(db);
    }
  } lock;
  ASSERT_EQ(sqlite3_open(remote_->journal().c_str(), &lock.db), SQLITE_OK);
  sqlite3_busy_timeout(lock.db, 5000);
  ASSERT_EQ(sqlite3_exec(lock.db, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(lock.db);
  protocol::Abort a;
  a.category = protocol::StopCategory::Cat2;
  a.reason = "journal stalled";
  const std::uint64_t abort_id = ground_->send(CommandKind::Abort, a);
  const auto sent = std::chrono::steady_clock::now();
  const bool stopped = test::eventually([&] { return !moving(); }, 3s);
  const double stop_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
  EXPECT_TRUE(stopped) << "the arm still moved with the journal locked";
  EXPECT_LT(stop_s, 3.0);
  sqlite3_exec(lock.db, "ROLLBACK", nullptr, nullptr, nullptr);
  sqlite3_close(lock.db);
  lock.db = nullptr;
  const auto final = ground_->wait_final(abort_id, 20s);
  EXPECT_EQ(final.state, AckState::Completed) << final.reason;
  const nlohmann::json journal = journal_json();
  bool received = false;
  for (const auto& row : journal["commands"])
    received = received || (row["command_id"] == abort_id && row["state"] == "RECEIVED" && row["kind"] == "ABORT");
  EXPECT_TRUE(received) << "the ABORT's RECEIVED row is missing";
}

// Issue 28: a ground station whose process ended (its participant left the
// domain) does not keep the lease: the next one takes control at once (it
// used to wait out control_lease_s, 10 s: `foresight take-control` on its own
// left every later command refused for that long).
TEST_F(RemoteCommands, ControlIsReleasedWhenTheCommandersParticipantLeaves) {
  {
    ground_link::Config c = ground_config_;
    c.domain = domain_;
    ground_link::GroundLink other(c);
    ASSERT_TRUE(other.wait_for_remote(30s));
    ASSERT_TRUE(other.execute(CommandKind::TakeControl, protocol::NoPayload{}, 2.0).succeeded());
    const auto refused = run(CommandKind::TakeControl);
    EXPECT_EQ(refused.code, Reason::NotInControl) << refused.reason;
  }  // the other station's participant is gone
  const auto left = std::chrono::steady_clock::now();
  ASSERT_TRUE(test::eventually([&] { return run(CommandKind::TakeControl).succeeded(); }, 20s));
  const double after_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - left).count();
  EXPECT_LT(after_s, 5.0) << "control was taken only " << after_s << " s after the commander left (the lease is 10 s)";
  bool released = false;
  const nlohmann::json journal = journal_json();
  for (const auto& e : journal["events"])
    released = released || e["text"].get<std::string>().find("control released: the commander's participant") == 0;
  EXPECT_TRUE(released) << journal["events"].dump();
}

TEST_F(RemoteCommands, AbortStopsTheMotionAndRecoverResumes) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t id = start_slow_motion(0.6);
  protocol::GotoJoint g;
  g.q_rad.assign(q0.data(), q0.data() + 7);
  g.q_rad[0] += 0.6;
  protocol::Abort a;
  a.category = protocol::StopCategory::Cat2;
  a.reason = "test";
  const auto ab = run(CommandKind::Abort, a);
  EXPECT_TRUE(ab.succeeded()) << ab.reason;
  const auto moved = ground_->wait_final(id, 10s);
  EXPECT_EQ(moved.state, AckState::Canceled);
  ASSERT_EQ(moved.final_q_rad.size(), 7u);
  EXPECT_LT(moved.final_q_rad[0], q0[0] + 0.6 - 0.05);  // stopped well short of the goal

  protocol::GotoJoint again = g;
  auto r = run(CommandKind::GotoJoint, again);
  EXPECT_EQ(r.code, Reason::Faulted);
  ASSERT_TRUE(run(CommandKind::Recover, protocol::NoPayload{}, 5.0).succeeded());
  again.speed_fraction = 0.5;
  r = run(CommandKind::GotoJoint, again, 10.0);
  EXPECT_TRUE(r.succeeded()) << r.reason;
}

TEST_F(RemoteCommands, EstopInputStopsCategoryZeroAndTheJournalKeepsTheEvidence) {
  take_and_recover();
  // Powered and enabled, as the drives themselves and the status say.
  ASSERT_TRUE(test::eventually([&] {
    const auto s = ground_->status();
    if (!s || s->value.drives.size() != 7) return false;
    for (const auto& d : s->value.drives)
      if (d.state != 4 || !d.powered) return false;  // operation_enabled
    return true;
  }, 10s));
  DriveRecord before = fresh_record();
  ASSERT_EQ(before.state.size(), 7u);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(before.state[j], "operation_enabled") << j;
  mark();
  const double q0 = before.q[0];
  const std::uint64_t moving = start_slow_motion(0.5);
  ASSERT_NE(moving, 0u);
  ASSERT_TRUE(test::eventually([&] { return record().hi[0] > q0 + 1e-3; }, 10s)) << "joint 1 never moved";
  const auto pressed = std::chrono::steady_clock::now();
  std::ofstream(estop_) << "pressed\n";
  // The drives' own record: every drive loses power (Disable Voltage, Switch
  // on disabled), none ever in Quick stop active.
  DriveRecord d;
  const bool off = test::eventually([&] {
    d = record();
    if (d.powered.size() != 7) return false;
    for (bool p : d.powered)
      if (p) return false;
    return true;
  }, 10s);
  const double to_off_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - pressed).count();
  ASSERT_TRUE(off) << "drives still powered after the E-stop\n" << remote_->log();
  std::printf("E-stop file to every drive unpowered (the drives' record, 20 ms file polls): %.3f s\n", to_off_s);
  for (std::size_t j = 0; j < 7; ++j) {
    EXPECT_EQ(d.state[j], "switch_on_disabled") << j;
    EXPECT_FALSE(d.was_in(j, 5)) << "joint " << j + 1 << " passed through quick_stop_active";
  }
  // The status reports the stop, and the drives as they reported themselves.
  protocol::StatusReport st;
  const bool reported = test::eventually([&] {
    const auto s = ground_->status();
    if (!s || s->value.stop_category != protocol::StopCategory::Cat0 || s->value.drives.size() != 7) return false;
    st = s->value;
    for (const auto& dr : st.drives)
      if (dr.state != 1 || dr.powered) return false;  // switch_on_disabled
    return true;
  }, 10s);
  EXPECT_TRUE(reported) << "status drives never showed all switch_on_disabled";
  for (std::size_t j = 0; j < st.drives.size(); ++j) {
    EXPECT_EQ(st.drives[j].joint, static_cast<int>(j + 1));
    EXPECT_GT(st.drives[j].node_id, 0);
  }
  // Nothing moves after the stop.
  mark();
  const DriveRecord still = [&] {
    DriveRecord r;
    const std::uint64_t s0 = record().seq;
    test::eventually([&] { return (r = record()).seq >= s0 + 25; }, 10s);  // ~0.5 s of polls
    return r;
  }();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_LT(still.span(j), 1e-6) << "joint " << j + 1 << " moved after the stop";
  std::remove(estop_.c_str());
  const int rc = remote_->stop(SIGTERM);
  EXPECT_EQ(rc, 0);
  const auto json = journal_json();
  bool cat0 = false;
  for (const auto& f : json["faults"]) cat0 = cat0 || f["category"] == 0;
  EXPECT_TRUE(cat0) << json.dump().substr(0, 2000);
  bool recover_completed = false;
  for (const auto& c : json["commands"]) recover_completed = recover_completed || (c["kind"] == "RECOVER" && c["state"] == "COMPLETED");
  EXPECT_TRUE(recover_completed);
  remote_.reset();
}

TEST_F(RemoteCommands, AJammedToolFailsItsStepCleanlyAndTheArmHolds) {
  take_and_recover();
  fault_on("tool_jam");
  protocol::InvokeAlgorithm loosen;
  loosen.name = "loosen";
  loosen.params = {{"turns", 2.0}};
  const auto r = run(CommandKind::InvokeAlgorithm, loosen, 5.0);
  EXPECT_EQ(r.state, AckState::Failed);
  EXPECT_EQ(r.code, Reason::ToolFault);
  EXPECT_EQ(r.reason.rfind("loosen: tool jammed", 0), 0u) << r.reason;
  // The tool stopped (its next report says so); the arm holds and takes the next motion.
  bool stopped = false;
  for (int i = 0; i < 300 && !stopped; ++i) {
    const auto tool = ground_->tool();
    stopped = tool && tool->age_s < 0.5 && !tool->value.running && (tool->value.fault_bits & 1u);
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(stopped);
  fault_off("tool_jam");
  const Eigen::VectorXd q0 = current_q();
  protocol::GotoJoint g;
  g.q_rad.assign(q0.data(), q0.data() + 7);
  g.q_rad[1] += 0.02;
  EXPECT_TRUE(run(CommandKind::GotoJoint, g, 3.0).succeeded());
}

// CAMERA runs on the video switch's own thread: a hung switch fails its
// command after the client's retries, and meanwhile the supervisor answers
// (a second CAMERA is refused as busy at once instead of queuing behind it).
TEST_F(RemoteCommands, CameraCommandsRunOffTheSupervisorThreadAndAHungSwitchFailsCleanly) {
  ASSERT_TRUE(run(CommandKind::TakeControl).succeeded());
  protocol::CameraCommand cam;
  cam.camera = "oblique";
  auto r = run(CommandKind::Camera, cam);
  EXPECT_TRUE(r.succeeded()) << r.reason;
  EXPECT_EQ(r.reason, "camera oblique");
  cam.camera = "nowhere";
  r = run(CommandKind::Camera, cam);
  EXPECT_EQ(r.state, AckState::Rejected);
  EXPECT_EQ(r.reason, "unknown camera 'nowhere' (expected one of: side, oblique, overhead_wide, overhead_zoom)");

  fault_on("video_silent");
  bool applied = false;
  for (int i = 0; i < 500 && !applied; ++i) {
    applied = remote_->log().find("simulated fault video_silent: on") != std::string::npos;
    if (!applied) std::this_thread::sleep_for(10ms);
  }
  ASSERT_TRUE(applied) << remote_->log();
  cam.camera = "side";
  const std::uint64_t hung = ground_->send(CommandKind::Camera, cam);
  const std::uint64_t second = ground_->send(CommandKind::Camera, cam);
  const auto busy = ground_->wait_final(second, 20s);
  EXPECT_EQ(busy.state, AckState::Rejected);
  EXPECT_EQ(busy.code, Reason::Busy);
  EXPECT_EQ(busy.reason, "the video switch is busy with command " + std::to_string(hung));
  const auto failed = ground_->wait_final(hung, 20s);
  EXPECT_EQ(failed.state, AckState::Failed);
  EXPECT_EQ(failed.code, Reason::Internal);
  EXPECT_EQ(failed.reason.rfind("video switch: ", 0), 0u) << failed.reason;

  fault_off("video_silent");
  bool back = false;
  for (int i = 0; i < 20 && !back; ++i) back = run(CommandKind::Camera, cam).succeeded();
  EXPECT_TRUE(back) << "the switch did not come back after the fault cleared";
}

TEST_F(RemoteCommands, ADriveEmergencyMidMotionIsACategoryZeroStopWithItsEvidence) {
  take_and_recover();
  const std::uint64_t id = start_slow_motion(0.5);
  fault_on("drive_emcy_3", "2310");
  const auto moved = ground_->wait_final(id, 10s);
  EXPECT_EQ(moved.state, AckState::Canceled);
  EXPECT_NE(moved.reason.find("0x2310"), std::string::npos) << moved.reason;
  bool cat0 = false;
  for (int i = 0; i < 300 && !cat0; ++i) {
    if (auto s = ground_->status(); s && s->value.stop_category == protocol::StopCategory::Cat0) cat0 = true;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(cat0);
  // Recover (fault reset, enable) and go on.
  fault_off("drive_emcy_3");
  ASSERT_TRUE(run(CommandKind::Recover, protocol::NoPayload{}, 5.0).succeeded()) << remote_->log();
  const auto json = journal_json();
  bool found = false;
  for (const auto& f : json["faults"])
    if (f["category"] == 0 && f["cause"] == "drive_fault") found = found || !f["evidence"]["samples"].empty();
  EXPECT_TRUE(found) << json["faults"].dump();
}

namespace {
/// The daemon with the overrun stop on (--sim leaves it off by default), at
/// 25 periods (50 ms): a loaded test machine misses 4 in a row now and then.
class RemoteOverrun : public RemoteCommands {
 protected:
  void SetUp() override {
    remote_options_.extra_args.push_back("--max-missed-cycles");
    remote_options_.extra_args.push_back("25");
    RemoteCommands::SetUp();
  }
};

/// The process's state letter from /proc/PID/stat ('T' when stopped).
char proc_state(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  std::getline(f, line);
  const auto close = line.rfind(')');
  return close == std::string::npos || close + 2 >= line.size() ? '?' : line[close + 2];
}
}  // namespace

// The whole daemon frozen for 300 ms mid-motion (SIGSTOP: the loop misses
// ~150 periods): on waking it stops the arm, category 1, the drives end
// unpowered in their own record, and the status says why and counts it.
TEST_F(RemoteOverrun, AStalledLoopStopsTheArmCategoryOne) {
  take_and_recover();
  ASSERT_TRUE(test::eventually([&] {
    const auto s = ground_->status();
    return s && s->value.loop.cycles > 0;
  }, 10s));
  const protocol::LoopTiming before = ground_->status()->value.loop;
  EXPECT_EQ(before.max_missed_cycles, 25u);
  EXPECT_FALSE(before.realtime_required);  // --sim
  EXPECT_LT(before.missed_streak_max, 25u) << "the loop had already missed 25 periods in a row";
  const std::uint64_t id = start_slow_motion(0.5);
  ASSERT_NE(id, 0u);
  const pid_t pid = remote_->pid();
  ASSERT_EQ(::kill(pid, SIGSTOP), 0);
  EXPECT_TRUE(test::eventually([&] { return proc_state(pid) == 'T'; }, 10s));
  std::this_thread::sleep_for(300ms);  // the stall itself (the stimulus, not a wait)
  ASSERT_EQ(::kill(pid, SIGCONT), 0);
  const auto moved = ground_->wait_final(id, 10s);
  EXPECT_EQ(moved.state, AckState::Canceled);
  EXPECT_NE(moved.reason.find("control loop overrun"), std::string::npos) << moved.reason;
  DriveRecord d;
  ASSERT_TRUE(test::eventually([&] {
    d = record();
    if (d.powered.size() != 7) return false;
    for (bool p : d.powered)
      if (p) return false;
    return true;
  }, 10s)) << "drives still powered after the overrun stop\n" << remote_->log();
  protocol::StatusReport st;
  ASSERT_TRUE(test::eventually([&] {
    const auto s = ground_->status();
    if (!s || s->value.stop_category != protocol::StopCategory::Cat1) return false;
    st = s->value;
    return true;
  }, 10s));
  EXPECT_NE(st.stop_reason.find("periods missed in a row (limit 25)"), std::string::npos) << st.stop_reason;
  EXPECT_GE(st.loop.missed_streak_max, 25u);
  EXPECT_GE(st.loop.overruns, before.overruns + 1);
  EXPECT_GE(st.loop.wakeup_latency_max_us, 250000.0);  // the 300 ms it slept through
  EXPECT_EQ(remote_->stop(SIGTERM), 0);
  const auto json = journal_json();
  bool found = false;
  for (const auto& f : json["faults"]) found = found || (f["category"] == 1 && f["cause"] == "overrun");
  EXPECT_TRUE(found) << json["faults"].dump().substr(0, 2000);
}

TEST_F(RemoteCommands, KilledMidMotionTheJournalIsCompleteAndARestartComesUpHolding) {
  take_and_recover();
  const std::uint64_t id = start_slow_motion(0.5);
  EXPECT_EQ(remote_->stop(SIGKILL), 128 + SIGKILL);
  const std::string db = remote_->journal();
  const auto json = journal_json();
  std::vector<std::string> seen;
  for (const auto& c : json["commands"])
    if (c["command_id"] == id && c["kind"] == "GOTO_JOINT") seen.push_back(c["state"]);
  EXPECT_EQ(seen, (std::vector<std::string>{"RECEIVED", "QUEUED", "EXECUTING"}));

  // A restart on the same journal: it appends, and nothing moves until RECOVER.
  ground_.reset();
  test::RemoteProcess::Options o;
  o.journal = db;
  ASSERT_NO_FATAL_FAILURE(start_remote(o));
  EXPECT_NE(remote_->log().find("did not shut down cleanly"), std::string::npos) << remote_->log();
  ASSERT_NO_FATAL_FAILURE(connect_ground());
  bool disabled = false;
  for (int i = 0; i < 300 && !disabled; ++i) {
    if (auto s = ground_->status(); s && s->value.mode == protocol::ControllerMode::Disabled) disabled = true;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(disabled);
}

TEST_F(RemoteCommands, LinkLossMidMotionFinishesTheMotionAndTheGroundSeesTheLoss) {
  // config/remote.yaml: controller.link {loss_timeout_s: 3, loss_policy: finish_and_hold}
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  const std::uint64_t id = start_slow_motion(0.25);
  ground_->pause_heartbeat();  // the remote hears nothing from the ground from now on
  bool lost = false;
  for (int i = 0; i < 1000 && !lost; ++i) {
    if (auto s = ground_->status(); s && (s->value.fault_bits & 2u)) lost = true;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(lost) << "the ground never saw the remote report the link lost\n" << remote_->log();
  const auto moved = ground_->wait_final(id, 30s);
  EXPECT_EQ(moved.state, AckState::Completed) << moved.reason;  // the committed motion ran to its end
  ASSERT_EQ(moved.final_q_rad.size(), 7u);
  EXPECT_NEAR(moved.final_q_rad[0], q0[0] + 0.25, 2e-3);
  // Still lost after the motion: the arm holds (the controller refuses new
  // motions while lost: test_control); the ground's heartbeat returns.
  bool holding_lost = false;
  for (int i = 0; i < 500 && !holding_lost; ++i) {
    const auto s = ground_->status();
    holding_lost = s && (s->value.fault_bits & 2u) && s->value.mode == protocol::ControllerMode::Idle;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(holding_lost);
  protocol::GotoJoint back;
  back.q_rad.assign(q0.data(), q0.data() + 7);
  ground_->resume_heartbeat();
  bool back_up = false;
  for (int i = 0; i < 1000 && !back_up; ++i) {
    if (auto s = ground_->status(); s && !(s->value.fault_bits & 2u) && s->age_s < 1.0) back_up = true;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(back_up);
  const auto r = run(CommandKind::GotoJoint, back, 8.0);
  EXPECT_TRUE(r.succeeded()) << r.reason;
}

// Issue 28: another participant's heartbeats (an observer, an impostor) do
// not keep the commander's link up, and its command does not declare the link
// regained (it used to: the loss was then never declared again).
TEST_F(RemoteCommands, OnlyTheCommandersHeartbeatsKeepTheLink) {
  take_and_recover();
  ground_link::Config c = ground_config_;
  c.domain = domain_;
  ground_link::GroundLink other(c);  // heartbeats from now on, never paused
  ASSERT_TRUE(other.wait_for_remote(30s));
  auto link_lost = [&] {
    const auto s = ground_->status();
    return s && (s->value.fault_bits & 2u) != 0 && s->age_s < 1.0;
  };
  auto regained = [&] {
    int n = 0;
    const nlohmann::json journal = journal_json();
    for (const auto& e : journal["events"]) n += e["kind"] == "link_regained" ? 1 : 0;
    return n;
  };
  ground_->pause_heartbeat();
  EXPECT_TRUE(test::eventually(link_lost, 20s)) << "the other participant's heartbeats kept the link\n" << remote_->log();
  const int regained_before = regained();
  protocol::Request status;
  status.what = protocol::RequestWhat::Status;
  const auto r = other.execute(CommandKind::Request, status, 2.0);
  EXPECT_TRUE(r.succeeded()) << r.reason;  // anyone may ask
  const auto s = ground_->status();
  ASSERT_TRUE(s.has_value());
  EXPECT_NE(s->value.fault_bits & 2u, 0u) << "another participant's command declared the link regained";
  EXPECT_EQ(regained(), regained_before) << "another participant's command declared the link regained";
  ground_->resume_heartbeat();
  EXPECT_TRUE(test::eventually([&] { const auto t = ground_->status(); return t && !(t->value.fault_bits & 2u) && t->age_s < 1.0; }, 20s));
}

namespace {

/// The daemon and the ground with DDS Security (scripts/make_dds_security.sh):
/// the ground authenticated as "ground".
class SecureRemote : public test::DaemonTest {
 protected:
  void SetUp() override {
    dir_ = test::temp_path(".sec");
    const int rc = std::system(
        ("bash " FORESIGHT_SOURCE_DIR "/scripts/make_dds_security.sh " + dir_ + " 0-230 station-b > /dev/null 2>&1").c_str());
    ASSERT_EQ(rc, 0) << "make_dds_security.sh failed";
    remote_options_.extra_args.insert(remote_options_.extra_args.end(), {"--security", dir_});
    ground_config_.security_dir = dir_;
    ground_config_.security_identity = "ground";
    DaemonTest::SetUp();
  }
  void TearDown() override {
    DaemonTest::TearDown();
    std::filesystem::remove_all(dir_);
  }
  std::string dir_;
};

}  // namespace

TEST_F(SecureRemote, AuthenticatedGroundCommandsAndAnObserverOnlyWatches) {
  EXPECT_TRUE(run(CommandKind::TakeControl, protocol::NoPayload{}, 1.0).succeeded());
  EXPECT_TRUE(run(CommandKind::Recover, protocol::NoPayload{}, 5.0).succeeded());
  ground_.reset();
  ground_link::Config w = ground_config_;
  w.domain = domain_;
  w.security_identity = "observer";
  w.read_only = true;
  ground_link::GroundLink observer(w);
  bool watching = false;
  for (int i = 0; i < 1000 && !watching; ++i) {
    watching = observer.joint_state().has_value() && observer.status().has_value();
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(watching);
  EXPECT_THROW(observer.send(CommandKind::TakeControl), std::logic_error);
  EXPECT_EQ(remote_->stop(SIGTERM), 0);
}

// Issue 28, item 6: with DDS Security a ground station is its identity. The
// operator types take-control, recover, goto, each a process of its own, and
// keeps control between them (the remote binds it to the identity, not to a
// process): another station cannot slip in while the lease lives, and gets
// control once the operator releases it. The journal names the station.
TEST_F(SecureRemote, TheStationKeepsControlAcrossItsCommandsAndAnotherStationWaits) {
  ground_.reset();  // only the CLI's processes from here on
  const std::string link = "--domain " + std::to_string(domain_) + " --security " + dir_ + " --connect-timeout 60";
  auto cli = [&](const std::string& args) {
    const test::CliRun r = test::run_foresight(args + " " + link);
    return r;
  };
  test::CliRun r = cli("take-control");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("take_control"), std::string::npos) << r.out;
  r = cli("recover");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const auto t_recovered = std::chrono::steady_clock::now();

  // Another station, while the operator's lease lives (10 s of silence).
  r = cli("take-control --identity station-b --json");
  const double since_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_recovered).count();
  if (since_s < 9.0) {
    EXPECT_EQ(r.status, 1) << r.out << r.err;
    const auto j = nlohmann::json::parse(r.out, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << r.out;
    EXPECT_EQ(j["state"], "rejected");
    EXPECT_EQ(j["code"], "not_in_control");
    const std::string ground_id = protocol::identity_of_certificate(dir_ + "/identities/ground/cert.pem").hex();
    EXPECT_EQ(j["reason"], "station 'ground' (" + ground_id +
                               ") holds control (it may RELEASE_CONTROL, or its lease ends after 10 s of silence)");
  } else {
    std::cerr << "the other station's take-control came " << since_s << " s after the recover: past the lease\n";
  }

  // The operator's next command, in a process of its own, needs no take-control.
  r = cli("goto --joints-deg 5,0,0,0,0,0,0");
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("completed"), std::string::npos) << r.out;
  r = cli("release-control");
  EXPECT_EQ(r.status, 0) << r.out << r.err;

  // Now the other station may take it, and the operator's station is the one refused.
  r = cli("take-control --identity station-b");
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  r = cli("goto --joints-deg 0,0,0,0,0,0,0");
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("station 'station-b' ("), std::string::npos) << r.out << r.err;

  r = cli("status --json --identity station-b");
  EXPECT_EQ(r.status, 0) << r.err;
  const auto status = nlohmann::json::parse(r.out, nullptr, false);
  ASSERT_FALSE(status.is_discarded()) << r.out;
  EXPECT_EQ(status["link_security"], (nlohmann::json{{"dds_security", true}, {"identity", "station-b"}}));

  // Every RECEIVED row names its station.
  std::set<std::string> stations;
  const nlohmann::json journal = journal_json();
  for (const auto& row : journal["commands"])
    if (row["state"] == "RECEIVED" && row["detail"].contains("station")) stations.insert(row["detail"]["station"]);
  std::set<std::string> names;
  for (const auto& st : stations) names.insert(st.substr(0, st.find(" (")));
  EXPECT_EQ(names, (std::set<std::string>{"station 'ground'", "station 'station-b'"}));
}

// Issue 28, item 4: an observer station watches and may stop the arm (ABORT,
// on the one command topic its permissions grant), and nothing else.
TEST_F(SecureRemote, AnObserverMayAbortTheArmButNotCommandIt) {
  ASSERT_TRUE(run(CommandKind::TakeControl, protocol::NoPayload{}, 1.0).succeeded());
  ASSERT_TRUE(run(CommandKind::Recover, protocol::NoPayload{}, 5.0).succeeded());
  const std::uint64_t motion = start_slow_motion(0.5);
  const std::string link =
      "--domain " + std::to_string(domain_) + " --security " + dir_ + " --identity observer --connect-timeout 60";
  test::CliRun r = test::run_foresight("abort --json " + link);
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  const auto j = nlohmann::json::parse(r.out, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << r.out;
  EXPECT_EQ(j["state"], "completed") << r.out;
  const auto final_ack = ground_->wait_final(motion, std::chrono::seconds(20));
  EXPECT_TRUE(final_ack.finished);
  EXPECT_EQ(final_ack.state, protocol::AckState::Canceled) << final_ack.reason;

  // Anything but ABORT is refused at the observer's own station: it has no command writer.
  r = test::run_foresight("take-control " + link);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("cannot send commands but ABORT"), std::string::npos) << r.err;

  const nlohmann::json journal = journal_json();
  bool named = false;
  for (const auto& row : journal["commands"])
    if (row["kind"] == "ABORT" && row["state"] == "RECEIVED" && row["detail"].contains("station"))
      named = named || row["detail"]["station"].get<std::string>().rfind("station 'observer' (", 0) == 0;
  EXPECT_TRUE(named) << "the observer's ABORT is journaled with its station";
}

namespace {
/// SecureRemote with the simulated drives' own record.
class SecureRemoteRecorded : public SecureRemote {
 protected:
  void SetUp() override {
    use_sim_faults();
    SecureRemote::SetUp();
  }
};
}  // namespace

// Issue 28's attacks with DDS Security on: a station of the project's CA
// forging the commander's session (read off its acks), ahead in sequence, is
// its own writer: REJECTED NOT_IN_CONTROL naming both stations, nothing
// moves on the drives' own record; a participant of another CA reaches
// nothing at all (its command is never received).
TEST_F(SecureRemoteRecorded, AForgingStationIsRefusedByNameAndAnOutsiderReachesNothing) {
  take_and_recover();
  const Eigen::VectorXd q0 = current_q();
  ASSERT_TRUE(test::eventually([&] { return record().seq > 0; }, 10s)) << "no drive_record";
  mark();
  std::vector<double> far(q0.data(), q0.data() + 7);
  far[0] += 0.3;
  {
    fp::Participant forger(static_cast<dds_domainid_t>(domain_), fp::security_qos(dir_, "station-b"));
    fp::Writer<msg::Command> writer(forger);
    fp::Reader<msg::CommandAck> acks(forger);
    ASSERT_TRUE(writer.wait_for_readers(1, 30s));
    ASSERT_TRUE(acks.wait_for_writers(1, 30s));
    fp::CommandSequencer forged(ground_->session_id());
    for (int i = 0; i < 500; ++i) (void)forged.next(foresight_msg_CMD_REQUEST);
    auto f = forged.next(foresight_msg_CMD_GOTO_JOINT);
    protocol::fill_payload(*f, CommandKind::GotoJoint, protocol::GotoJoint{far, 0.5});
    writer.write(f);
    std::string reason;
    fp::Sample<msg::CommandAck> a;
    for (const auto until = std::chrono::steady_clock::now() + 20s; reason.empty() && std::chrono::steady_clock::now() < until;)
      if (acks.wait_take(a, 100ms) && a->command_id == f->command_id && a->state == foresight_msg_ACK_REJECTED)
        reason = fp::from_wire(*a).reason;
    char session[20];
    std::snprintf(session, sizeof session, "%016llx", static_cast<unsigned long long>(ground_->session_id()));
    const std::string ground_id = protocol::identity_of_certificate(dir_ + "/identities/ground/cert.pem").hex();
    const std::string b_id = protocol::identity_of_certificate(dir_ + "/identities/station-b/cert.pem").hex();
    EXPECT_EQ(reason, "session " + std::string(session) + " is in control from station 'ground' (" + ground_id +
                          "); this command came from station 'station-b' (" + b_id + ")");
  }
  {
    fp::Participant outsider(static_cast<dds_domainid_t>(domain_), fp::security_qos(dir_ + "/foreign", "intruder"));
    fp::Writer<msg::Command> writer(outsider);
    EXPECT_FALSE(writer.wait_for_readers(1, 4s)) << "the outsider's command writer matched the remote";
    fp::CommandSequencer seq;
    auto go = seq.next(foresight_msg_CMD_GOTO_JOINT);
    protocol::fill_payload(*go, CommandKind::GotoJoint, protocol::GotoJoint{far, 0.5});
    writer.write(go);
    const std::uint64_t outsider_session = seq.session_id();
    const nlohmann::json journal = journal_json();
    for (const auto& row : journal["commands"])
      EXPECT_NE(row["session_id"].get<std::uint64_t>(), outsider_session) << "the outsider's command was received";
  }
  const test::DriveRecord d = fresh_record();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_LT(d.span(j), 1e-3) << "joint " << j + 1 << " moved";
  // The operator still commands.
  std::vector<double> near(q0.data(), q0.data() + 7);
  near[0] += 0.02;
  EXPECT_TRUE(run(CommandKind::GotoJoint, protocol::GotoJoint{near, 0.5}, 10.0).succeeded());
}
