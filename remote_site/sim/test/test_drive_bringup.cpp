// Bring-up of the real master code over the mock bus against simulated
// CiA 402 drives: power-on -> NMT/SDO/PDO configuration -> Operation enabled,
// motion in cyclic synchronous position, and the configuration-phase errors.

#include <cmath>
#include <numbers>

#include "foresight/common/error.hpp"
#include "foresight/common/robot_model.hpp"
#include "sim_fixture.hpp"

using namespace foresight;
using namespace foresight::test;
using hw::canopen::PowerState;

TEST(DriveBringUp, PowerOnToOperationEnabledHoldsPosition) {
  // joint2 powers on away from zero: enabling must not move it.
  // Between configure() and enable() the master sends no cycles (no
  // heartbeat): on a loaded machine the checks below can outlast the drives'
  // 175 ms heartbeat consumer (they fault, EMCY 0x8130). This test is about
  // the bring-up, not the consumer (test_drive_faults): give it 1 s.
  hw::RemoteConfig cfg = project_config();
  cfg.heartbeat_consumer_s = 1.0;
  SimRig rig(cfg, {}, [](sim::CanSimulator& s) { s.drive(1).set_position_counts(1234567); });
  rig.drives->configure();
  for (std::size_t j = 0; j < 7; ++j) {
    EXPECT_EQ(rig.sim->drive(j).nmt_state(), hw::canopen::NmtState::Operational) << j;
    EXPECT_EQ(rig.sim->drive(j).following_error_window(),
              static_cast<std::uint32_t>(std::lround(std::abs(rig.config.drives[j].following_error_limit_rad *
                                                              rig.config.drives[j].counts_per_rad()))));
    EXPECT_NE(rig.sim->drive(j).power_state(), PowerState::OperationEnabled);
  }
  EXPECT_EQ(rig.drives->device_name(2), "Foresight SimDrive CSP (joint3)");  // segmented upload
  EXPECT_DOUBLE_EQ(rig.drives->rated_torque_nm(0), 2.0);
  rig.drives->enable();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::OperationEnabled) << j;
  // Read only (no new targets yet): the answer to enable()'s last SYNC.
  CycleStatus s;
  for (int i = 0; i < 100 && !rig.fb.joints[1].fresh; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    s = rig.drives->cycle_read(rig.fb, rig.ft);
  }
  EXPECT_TRUE(s.ok()) << (s.event_count ? rig.drives->describe(s.events[0]) : "");
  EXPECT_NEAR(rig.sim->drive(1).position_counts(), 1234567, 1.0);
  EXPECT_EQ(rig.fb.joints[1].position_counts, 1234567);
  EXPECT_NEAR(rig.fb.joints[1].position_rad, 1234567 * 2 * std::numbers::pi / (131072.0 * 160), 1e-12);
  EXPECT_EQ(rig.fb.joints[1].state, PowerState::OperationEnabled);
  EXPECT_EQ(rig.fb.count, 7u);
}

TEST(DriveBringUp, TracksACommandedMotionAndReportsTorque) {
  SimRig rig(project_config());
  rig.bring_up();
  const double q0 = rig.targets.position_rad[2];
  const double dq = 0.2;  // joint3, direction -1: counts go the other way
  const int n = 250;      // 0.5 s at 500 Hz, cosine profile, peak 0.63 rad/s
  rig.sim->drive(6).set_load_torque_nm(0.5);  // joint7 motor shaft
  CycleStatus worst;
  for (int i = 1; i <= n + 25; ++i) {
    const double s = std::min(1.0, static_cast<double>(i) / n);
    rig.targets.position_rad[2] = q0 + dq * 0.5 * (1 - std::cos(std::numbers::pi * s));
    const CycleStatus st = rig.cycle();
    if (!st.ok()) worst = st;
  }
  EXPECT_EQ(worst.event_count, 0) << (worst.event_count ? rig.drives->describe(worst.events[0]) : "");
  const double counts_per_rad = -131072.0 * 120 / (2 * std::numbers::pi);
  EXPECT_NEAR(rig.sim->drive(2).position_counts(), (q0 + dq) * counts_per_rad, 50.0);
  EXPECT_NEAR(rig.fb.joints[2].position_rad, q0 + dq, 1e-4);
  double q_sim[7];
  rig.sim->joint_positions_rad(q_sim);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NEAR(q_sim[j], rig.fb.joints[j].position_rad, 2e-6) << j;
  EXPECT_NEAR(q_sim[2], q0 + dq, 1e-4);
  // 0.5 N*m at the motor, gear 100, direction +1 -> 50 N*m (0.1% of 2 N*m resolution = 0.2 N*m)
  EXPECT_NEAR(rig.fb.joints[6].torque_nm, 50.0, 0.25);
}

TEST(DriveBringUp, SdoAbortIsNamedAndNothingIsEnabled) {
  SimRig rig(project_config(), {}, [](sim::CanSimulator& s) {
    s.drive(2).inject_sdo_abort(0x6060, 0, 0x06090030);
  });
  try {
    rig.drives->configure();
    FAIL() << "configure() accepted an aborted SDO";
  } catch (const hw::SdoError& e) {
    EXPECT_EQ(e.kind(), hw::SdoError::Kind::Abort);
    EXPECT_EQ(e.abort_code(), 0x06090030u);
    EXPECT_STREQ(e.what(), "SDO write 0x6060:00 of joint3 (bus arm_a node 3): aborted by the node: "
                           "0x06090030 value range of parameter exceeded");
  }
  EXPECT_THROW(rig.drives->enable(), hw::HwError);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NE(rig.sim->drive(j).power_state(), PowerState::OperationEnabled);
}

TEST(DriveBringUp, SdoTimeoutIsNamedAndTimed) {
  SimRig rig(project_config());
  rig.drives->configure();
  rig.sim->drive(4).stop_answering(true);
  const auto t0 = Clock::now();
  try {
    rig.drives->sdo_read(1, 5, 0x6064, 0);
    FAIL();
  } catch (const hw::SdoError& e) {
    const double dt = std::chrono::duration<double>(Clock::now() - t0).count();
    EXPECT_EQ(e.kind(), hw::SdoError::Kind::Timeout);
    EXPECT_EQ(e.abort_code(), 0x05040000u);
    // sdo_timeout_ms 500, and one retry after the first timeout: 1 s.
    EXPECT_STREQ(e.what(), "SDO read 0x6064:00 of joint5 (bus arm_b node 5): timed out after 500 ms (no response), "
                           "also on the retry");
    EXPECT_GE(dt, 0.999);
    EXPECT_LT(dt, 3.0);
  }
}

// A lost SDO response (one frame on a busy bus) does not fail the bring-up:
// the transfer is aborted and sent once more, and the bring-up says so.
TEST(DriveBringUp, OneLostSdoResponseIsRetriedOnceAndNoticed) {
  SimRig rig(project_config(), {}, [](sim::CanSimulator& s) { s.drive(2).drop_sdo_responses(0x1000, 0, 1); });
  const auto t0 = Clock::now();
  rig.drives->configure();
  const double dt = std::chrono::duration<double>(Clock::now() - t0).count();
  const std::vector<std::string> notices = rig.drives->setup_notices();
  ASSERT_EQ(notices.size(), 1u);
  EXPECT_EQ(notices[0], "SDO read 0x1000:00 of joint3 (bus arm_a node 3): no response within 500 ms; "
                        "the retry was answered");
  EXPECT_GE(dt, 0.5);  // the first attempt waited out its timeout
  // A clean bring-up has nothing to say.
  rig.drives->configure();
  EXPECT_TRUE(rig.drives->setup_notices().empty());
  rig.drives->enable();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::OperationEnabled) << j;
}

// Two lost responses in a row: the retry times out too, and the bring-up
// fails naming the node, the object and the timeout.
TEST(DriveBringUp, SdoResponseLostTwiceFailsTheBringUpNamingNodeObjectAndTimeout) {
  SimRig rig(project_config(), {}, [](sim::CanSimulator& s) { s.drive(5).drop_sdo_responses(0x1000, 0, 2); });
  try {
    rig.drives->configure();
    FAIL();
  } catch (const hw::SdoError& e) {
    EXPECT_EQ(e.kind(), hw::SdoError::Kind::Timeout);
    EXPECT_STREQ(e.what(), "SDO read 0x1000:00 of joint6 (bus arm_b node 6): timed out after 500 ms (no response), "
                           "also on the retry");
  }
}

TEST(DriveBringUp, SdoToggleErrorIsAbortedAndNamed) {
  SimRig rig(project_config(), {}, [](sim::CanSimulator& s) { s.drive(0).inject_bad_toggle(true); });
  try {
    rig.drives->configure();
    FAIL();
  } catch (const hw::SdoError& e) {
    EXPECT_EQ(e.kind(), hw::SdoError::Kind::Protocol);
    EXPECT_EQ(e.abort_code(), 0x05030000u);
    EXPECT_STREQ(e.what(), "SDO read 0x1008:00 of joint1 (bus arm_a node 1): segment 1 has toggle bit 0, expected 1 "
                           "(sent abort 0x05030000 toggle bit not alternated)");
  }
}

TEST(DriveBringUp, SilentNodeAtBootIsNamed) {
  SimRig rig(project_config(), {}, [](sim::CanSimulator& s) { s.drive(6).stop_answering(true); });
  try {
    rig.drives->configure();
    FAIL();
  } catch (const hw::HwError& e) {
    EXPECT_NE(std::string(e.what()).find("no boot-up message after NMT reset node within 2000 ms from: "
                                         "joint7 (bus arm_b node 7)"), std::string::npos) << e.what();
  }
}

TEST(DriveBringUp, OverloadedBusIsRefusedBeforeAnyFrameIsSent) {
  hw::RemoteConfig c = project_config();
  for (auto& d : c.drives) d.bus = "arm_a";
  c.ft.bus = "arm_a";
  c.buses.pop_back();
  auto buses = sim::make_mock_buses(c);
  auto sim = sim::CanSimulator::from_config(c, std::move(buses.far));
  sim->process();  // power on, single-threaded: no thread to wait for below
  try {
    hw::DriveSystem drives(c, std::move(buses.master));
    FAIL() << "an overloaded bus was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bus arm_a: 7 drives + F/T, 17 frames/cycle (SYNC + 16 PDOs), 2085 bits/cycle "
                                         "worst case x 500 Hz + velocity TPDOs 66500 bit/s + heartbeats 11700 bit/s = "
                                         "1120.7 kbit/s = 112.1% of "
                                         "1000 kbit/s exceeds the 70% limit"), std::string::npos) << e.what();
  }
  // Whatever the constructor sent is already in the socket: process() reads it all.
  sim->process();
  EXPECT_EQ(sim->frames_received(), 0u);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NE(sim->drive(j).power_state(), PowerState::OperationEnabled);
}

TEST(DriveBringUp, JointsMissingFromTheRobotModelAreRefused) {
  std::map<std::string, JointLimits> limits;
  for (int i = 1; i <= 6; ++i) limits["joint" + std::to_string(i)] = {-1, 1, 1, 1, 100};
  try {
    SimRig rig(project_config(), limits);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("drives[6]: joint 'joint7' is not in the robot model"), std::string::npos) << e.what();
  }
}

TEST(DriveBringUp, DisableThenNmtStopIsSeenByTheHeartbeatConsumer) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.drives->disable();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::SwitchOnDisabled) << j;
  rig.drives->nmt_all(hw::canopen::NmtCommand::Stop);
  // Stopped nodes send no PDOs, but their heartbeat says "stopped" (0x04).
  int stopped = 0;
  for (int i = 0; i < 100 && stopped < 8; ++i) {
    const CycleStatus s = rig.cycle();
    for (std::size_t k = 0; k < s.event_count; ++k)
      if (s.events[k].fault == HwFault::NodeNotOperational) {
        EXPECT_EQ(s.events[k].code, 0x04u);
        ++stopped;
      }
  }
  EXPECT_EQ(stopped, 8);  // 7 drives + F/T, each reported once
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).nmt_state(), hw::canopen::NmtState::Stopped);
}

TEST(DriveBringUp, UrdfLimitsAreWrittenToTheDrives) {
  const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  SimRig rig(project_config(), hw::joint_limits_by_name(model));
  rig.drives->configure();
  for (std::size_t j = 0; j < 7; ++j) {
    const hw::DriveConfig& d = rig.config.drives[j];
    const std::size_t bus = static_cast<std::size_t>(d.bus_index);
    std::int32_t lo = 0, hi = 0;
    ASSERT_TRUE(d.to_counts(model.limits()[j].lower_rad, lo));
    ASSERT_TRUE(d.to_counts(model.limits()[j].upper_rad, hi));
    if (lo > hi) std::swap(lo, hi);  // direction -1
    EXPECT_EQ(static_cast<std::int32_t>(rig.drives->sdo_read(bus, d.node_id, 0x607D, 1)), lo) << d.joint;
    EXPECT_EQ(static_cast<std::int32_t>(rig.drives->sdo_read(bus, d.node_id, 0x607D, 2)), hi) << d.joint;
  }
  // joint1: +-2.96706 rad x 131072 x 160 / 2 pi = +-9903333 counts (direction +1)
  EXPECT_NEAR(static_cast<std::int32_t>(rig.drives->sdo_read(0, 1, 0x607D, 2)), 2.967060 * 131072 * 160 / (2 * std::numbers::pi), 0.6);
}

// Issue 12: configure() must drain frames queued before its NMT reset. Here
// every node's power-on boot-up is already waiting on the master's side when
// joint7 falls silent: its stale boot-up must not count as the reset's answer.
TEST(DriveBringUp, BootUpQueuedBeforeTheResetIsNotItsAnswer) {
  hw::RemoteConfig c = project_config();
  c.enable_timeout_s = 0.3;
  SimRig rig(c);
  const auto until = Clock::now() + std::chrono::seconds(5);
  while (rig.sim->frames_sent() < 8 && Clock::now() < until)  // 7 drives + F/T booted
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  ASSERT_GE(rig.sim->frames_sent(), 8u);
  rig.sim->drive(6).stop_answering(true);
  try {
    rig.drives->configure();
    FAIL() << "configure() took the boot-up sent before the reset as its answer";
  } catch (const hw::SdoError& e) {
    FAIL() << "the stale boot-up was taken as the answer; then: " << e.what();
  } catch (const hw::HwError& e) {
    EXPECT_EQ(std::string(e.what()), "no boot-up message after NMT reset node within 300 ms from: "
                                     "joint7 (bus arm_b node 7) (powered? node id right? bus wired?)");
  }
}

// Issue 12: disable() gave up silently when a drive never answered.
TEST(DriveBringUp, DisableReportsDrivesThatNeverAnswered) {
  hw::RemoteConfig c = project_config();
  c.enable_timeout_s = 0.3;
  SimRig rig(c);
  rig.bring_up();
  rig.sim->drive(3).stop_answering(true);
  try {
    rig.drives->disable();
    FAIL() << "disable() returned although joint4 never answered";
  } catch (const hw::HwError& e) {
    EXPECT_EQ(std::string(e.what()),
              "disable(): not confirmed after 300 ms: joint4 (bus arm_a node 4) never answered (no TPDO; state "
              "unknown, may still be enabled);");
  }
  for (std::size_t j : {0u, 1u, 2u, 4u, 5u, 6u}) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::SwitchOnDisabled) << j;
}
