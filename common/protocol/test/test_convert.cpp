// The wire <-> plain type conversions and the hostile-payload checks, without
// a network: every kind survives fill_payload -> from_wire unchanged, and
// every hostile value is refused with its exact reason.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/command.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/convert.hpp"

namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;

namespace {

fp::Sample<msg::Command> make(fp::CommandKind kind, const fp::Payload& payload) {
  fp::CommandSequencer seq(5);
  auto c = seq.next(static_cast<msg::CommandKind>(kind));
  fp::fill_payload(*c, kind, payload);
  return c;
}

fp::Command round_trip(fp::CommandKind kind, const fp::Payload& payload) {
  const auto c = make(kind, payload);
  const auto verdict = fp::check_payload(*c, fp::PayloadLimits{7});
  EXPECT_TRUE(verdict.ok()) << verdict.reason;
  return fp::from_wire(*c, 123);
}

fp::PayloadVerdict verdict_of(const fp::Sample<msg::Command>& c) { return fp::check_payload(*c, fp::PayloadLimits{7}); }

const double kNan = std::numeric_limits<double>::quiet_NaN();

}  // namespace

TEST(LinkConvert, EveryKindRoundTripsThroughTheWireType) {
  fp::RunTrajectory run;
  run.trajectory_id = 42;
  run.content_hash[0] = 0xab;
  run.content_hash[31] = 0xcd;
  run.compliant = true;
  run.start_tolerance_rad = 0.01;
  auto c = round_trip(fp::CommandKind::Trajectory, run);
  EXPECT_EQ(c.kind, fp::CommandKind::Trajectory);
  EXPECT_EQ(c.received_ns, 123);
  EXPECT_EQ(c.session_id, 5u);
  const auto& r = std::get<fp::RunTrajectory>(c.payload);
  EXPECT_EQ(r.trajectory_id, 42u);
  EXPECT_EQ(r.content_hash, run.content_hash);
  EXPECT_TRUE(r.compliant);
  EXPECT_DOUBLE_EQ(r.start_tolerance_rad, 0.01);

  fp::InvokeAlgorithm alg{"guarded_insert", {{"depth_m", 0.05}, {"force_n", 20.0}}, 30.0};
  const auto a = std::get<fp::InvokeAlgorithm>(round_trip(fp::CommandKind::InvokeAlgorithm, alg).payload);
  EXPECT_EQ(a.name, "guarded_insert");
  ASSERT_EQ(a.params.size(), 2u);
  EXPECT_EQ(a.params[1].name, "force_n");
  EXPECT_DOUBLE_EQ(a.params[1].value, 20.0);
  EXPECT_DOUBLE_EQ(a.timeout_s, 30.0);

  const auto q = std::get<fp::Request>(
      round_trip(fp::CommandKind::Request, fp::Request{fp::RequestWhat::Wrench}).payload);
  EXPECT_EQ(q.what, fp::RequestWhat::Wrench);

  fp::CameraCommand cam{"oblique", fp::CameraAction::Point, 0.1, -0.2, 800.0};
  const auto cc = std::get<fp::CameraCommand>(round_trip(fp::CommandKind::Camera, cam).payload);
  EXPECT_EQ(cc.camera, "oblique");
  EXPECT_EQ(cc.action, fp::CameraAction::Point);
  EXPECT_DOUBLE_EQ(cc.tilt_rad, -0.2);
  EXPECT_DOUBLE_EQ(cc.focal_px, 800.0);

  fp::GotoJoint go{{0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7}, 0.25};
  const auto g = std::get<fp::GotoJoint>(round_trip(fp::CommandKind::GotoJoint, go).payload);
  EXPECT_EQ(g.q_rad, go.q_rad);
  EXPECT_DOUBLE_EQ(g.speed_fraction, 0.25);

  fp::GotoCart cart;
  cart.frame = "lst_tip";
  cart.base_T_frame = foresight::make_pose(Eigen::Vector3d(0.5, -0.2, 0.8), Eigen::Vector3d(0.1, 0.2, 0.3));
  cart.speed_fraction = 0.5;
  const auto gc = std::get<fp::GotoCart>(round_trip(fp::CommandKind::GotoCart, cart).payload);
  EXPECT_EQ(gc.frame, "lst_tip");
  EXPECT_LT((gc.base_T_frame.matrix() - cart.base_T_frame.matrix()).norm(), 1e-12);

  fp::Abort ab{7, fp::StopCategory::Cat1, "operator"};
  const auto b = std::get<fp::Abort>(round_trip(fp::CommandKind::Abort, ab).payload);
  EXPECT_EQ(b.target_command_id, 7u);
  EXPECT_EQ(b.category, fp::StopCategory::Cat1);
  EXPECT_EQ(b.reason, "operator");

  for (auto kind : {fp::CommandKind::TakeControl, fp::CommandKind::ReleaseControl,
                    fp::CommandKind::Recover}) {
    const auto none = round_trip(kind, fp::NoPayload{});
    EXPECT_EQ(none.kind, kind);
    EXPECT_TRUE(std::holds_alternative<fp::NoPayload>(none.payload));
  }
}

TEST(LinkConvert, FillPayloadRefusesAPayloadOfAnotherKindAndOversizedValues) {
  fp::Sample<msg::Command> c;
  try {
    fp::fill_payload(*c, fp::CommandKind::GotoJoint, fp::Abort{});
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "command CMD_GOTO_JOINT: the payload is of another kind");
  }
  try {
    fp::fill_payload(*c, fp::CommandKind::Camera, fp::CameraCommand{std::string(64, 'x')});
    FAIL() << "no throw";
  } catch (const std::length_error& e) {
    EXPECT_STREQ(e.what(), "camera name: 64 characters exceed the protocol bound of 63");
  }
  try {
    fp::fill_payload(*c, fp::CommandKind::GotoJoint, fp::GotoJoint{std::vector<double>(17, 0.0), 0.5});
    FAIL() << "no throw";
  } catch (const std::length_error& e) {
    EXPECT_STREQ(e.what(), "goto joint angles: 17 elements exceed the protocol bound of 16");
  }
}

TEST(LinkConvert, HostilePayloadsAreRefusedWithTheirReason) {
  struct Case {
    fp::CommandKind kind;
    fp::Payload payload;
    fp::Reason code;
    const char* reason;
  };
  const std::vector<double> q7{0, 0, 0, 0, 0, 0, 0};
  std::vector<double> q_nan = q7;
  q_nan[2] = kNan;
  fp::GotoCart bad_quat;
  bad_quat.frame = "lst_tip";
  const std::vector<Case> cases = {
      {fp::CommandKind::GotoJoint, fp::GotoJoint{q_nan, 0.5}, fp::Reason::BadArgument,
       "goto_joint.q_rad[2] is not finite"},
      {fp::CommandKind::GotoJoint, fp::GotoJoint{{0.0, 0.0}, 0.5}, fp::Reason::JointCount,
       "goto_joint.q_rad has 2 angles; the arm has 7 joints"},
      {fp::CommandKind::GotoJoint, fp::GotoJoint{q7, 0.0}, fp::Reason::BadArgument,
       "goto_joint.speed_fraction 0.000000 is not in (0, 1]"},
      {fp::CommandKind::GotoJoint, fp::GotoJoint{q7, kNan}, fp::Reason::BadArgument,
       "goto_joint.speed_fraction is not finite"},
      {fp::CommandKind::InvokeAlgorithm, fp::InvokeAlgorithm{"", {}, 1.0}, fp::Reason::BadArgument,
       "algorithm.name is empty"},
      {fp::CommandKind::InvokeAlgorithm, fp::InvokeAlgorithm{"ins\x01rt", {}, 1.0},
       fp::Reason::BadArgument, "algorithm.name has a non-printable character"},
      {fp::CommandKind::InvokeAlgorithm, fp::InvokeAlgorithm{"insert", {{"depth_m", kNan}}, 1.0},
       fp::Reason::BadArgument, "algorithm.params[0].value is not finite"},
      {fp::CommandKind::InvokeAlgorithm, fp::InvokeAlgorithm{"insert", {}, -1.0},
       fp::Reason::BadArgument, "algorithm.timeout_s -1.000000 is negative"},
      {fp::CommandKind::Trajectory, fp::RunTrajectory{}, fp::Reason::UnknownTrajectory,
       "trajectory.trajectory_id is 0"},
      {fp::CommandKind::Camera, fp::CameraCommand{"side", fp::CameraAction::Point, kNan, 0, 0},
       fp::Reason::BadArgument, "camera.pan_rad is not finite"},
      {fp::CommandKind::Camera, fp::CameraCommand{}, fp::Reason::BadArgument, "camera.camera is empty"},
      {fp::CommandKind::Abort, fp::Abort{0, fp::StopCategory::Cat2, "a\nb"}, fp::Reason::BadArgument,
       "abort.reason has a non-printable character"},
  };
  for (const auto& k : cases) {
    const auto v = verdict_of(make(k.kind, k.payload));
    EXPECT_EQ(v.code, k.code) << k.reason;
    EXPECT_EQ(v.reason, k.reason);
  }
  // Raw wire values no control type can express.
  auto c = make(fp::CommandKind::GotoCart, [] {
    fp::GotoCart g;
    g.frame = "lst_tip";
    return g;
  }());
  c->payload._u.goto_cart.orientation_xyzw[3] = 2.0;
  EXPECT_EQ(verdict_of(c).reason, "goto_cart.orientation_xyzw has norm 2.000000, not a unit quaternion");
  c->payload._u.goto_cart.position_m[1] = std::numeric_limits<double>::infinity();
  EXPECT_EQ(verdict_of(c).reason, "goto_cart.position_m[1] is not finite");
  auto r = make(fp::CommandKind::Request, fp::Request{});
  fp::set_raw(r->payload._u.request.what, 9);
  EXPECT_EQ(verdict_of(r).reason, "request.what 9 is unknown");
  auto ab = make(fp::CommandKind::Abort, fp::Abort{});
  fp::set_raw(ab->payload._u.abort.category, 7);
  EXPECT_EQ(verdict_of(ab).reason, "abort.category 7 is unknown");
  auto unknown = make(fp::CommandKind::Recover, fp::NoPayload{});
  fp::set_raw(unknown->payload._d, 42);
  EXPECT_EQ(verdict_of(unknown).reason, "unknown kind 42");
}

TEST(LinkConvert, AcksAndReportsRoundTrip) {
  fp::Ack a;
  a.session_id = 1;
  a.command_id = 2;
  a.sequence_number = 3;
  a.kind = fp::CommandKind::GotoJoint;
  a.state = fp::AckState::Completed;
  a.code = fp::Reason::NotInControl;
  a.reason = "held by session 9";
  a.stamp_ns = 99;
  a.final_q_rad = {0.5, -0.5};
  fp::Sample<msg::CommandAck> wire;
  fp::to_wire(*wire, a);
  EXPECT_EQ(wire->code, foresight_msg_REASON_NOT_IN_CONTROL);
  const auto back = fp::from_wire(*wire);
  EXPECT_EQ(back.command_id, 2u);
  EXPECT_EQ(back.state, fp::AckState::Completed);
  EXPECT_EQ(back.code, fp::Reason::NotInControl);
  EXPECT_EQ(back.reason, "held by session 9");
  EXPECT_EQ(back.stamp_ns, 99);
  EXPECT_EQ(back.final_q_rad, a.final_q_rad);
  EXPECT_TRUE(fp::is_terminal(back.state));
  EXPECT_FALSE(fp::is_terminal(fp::AckState::Executing));
  EXPECT_STREQ(fp::to_string(fp::Reason::NotInControl), "not_in_control");

  fp::JointReport j{5, 6, {1, 2}, {3, 4}, {5, 6}};
  fp::Sample<msg::JointState> js;
  fp::to_wire(*js, j);
  const auto jb = fp::from_wire(*js);
  EXPECT_EQ(jb.cycle, 6u);
  EXPECT_EQ(jb.torque_nm, j.torque_nm);
  fp::StatusReport s;
  s.mode = fp::ControllerMode::Stopped;
  s.stop_category = fp::StopCategory::Cat1;
  s.stop_reason = "link lost";
  s.drives = {{1, 1, 1, false}, {2, 2, 4, true}, {3, 5, fp::kDriveStateUnknown, false}};
  fp::Sample<msg::ControllerStatus> cs;
  fp::to_wire(*cs, s);
  ASSERT_EQ(cs->drives._length, 3u);
  EXPECT_EQ(cs->drives._buffer[1].state, foresight_msg_DRIVE_OPERATION_ENABLED);
  EXPECT_STREQ(fp::drive_state_name(cs->drives._buffer[0].state), "switch_on_disabled");
  EXPECT_STREQ(fp::drive_state_name(cs->drives._buffer[2].state), "unknown");
  const auto sb = fp::from_wire(*cs);
  EXPECT_EQ(sb.mode, fp::ControllerMode::Stopped);
  EXPECT_EQ(sb.stop_category, fp::StopCategory::Cat1);
  EXPECT_EQ(sb.stop_reason, "link lost");
  ASSERT_EQ(sb.drives.size(), 3u);
  EXPECT_EQ(sb.drives[2].node_id, 5);
  EXPECT_EQ(sb.drives[1].state, 4u);
  EXPECT_TRUE(sb.drives[1].powered);
  EXPECT_EQ(sb.drives[2].state, fp::kDriveStateUnknown);
}
