// Configuration from files (issue 12): each drive configured from its SDO
// list (config/drives/simdrive.sdo) at boot, every value read back; identity
// check; stop and fault reactions as configured, implemented by the simulated
// drive per code; unused PDOs off; unexpected COB-IDs reported once; the
// master refuses a target step beyond the following-error window.

#include <cmath>
#include <fstream>
#include <sstream>

#include "foresight/common/robot_model.hpp"
#include "sim_fixture.hpp"

using namespace foresight;
using namespace foresight::test;
using hw::canopen::PowerState;

namespace {
auto has = [](HwFault f) { return [f](const CycleStatus& s) { return find_event(s, f) != nullptr; }; };

hw::RemoteConfig with_entry(hw::RemoteConfig c, std::uint16_t index, std::int32_t value) {
  for (hw::DriveConfig& d : c.drives)
    for (hw::SdoEntry& e : d.sdo_entries)
      if (e.index == index) e.value = static_cast<std::uint32_t>(value) & (e.size == 4 ? 0xFFFFFFFFu : (1u << (8 * e.size)) - 1);
  return c;
}

}  // namespace

TEST(DriveConfigFile, EveryDriveIsConfiguredFromItsFileAndReadBack) {
  const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  SimRig rig(project_config(), hw::joint_limits_by_name(model));
  rig.drives->configure();
  for (std::size_t j = 0; j < 7; ++j) {
    const hw::DriveConfig& d = rig.config.drives[j];
    const std::size_t bus = static_cast<std::size_t>(d.bus_index);
    const std::uint8_t n = d.node_id;
    const hw::DriveInfo& info = rig.drives->drive_info(j);
    EXPECT_EQ(info.vendor_id, 0x00F0E5E7u);
    EXPECT_EQ(info.product_code, 0x402u);
    EXPECT_EQ(info.revision, 0x00010000u);
    EXPECT_EQ(info.pdos_disabled, 6u);  // RPDO2-4, TPDO2-4 (TPDO2 then mapped to the velocity)
    EXPECT_GE(info.verified, 5u + 12u);  // the file's 5 writes + the master's own objects
    for (const hw::SdoEntry& e : d.sdo_entries) {
      const std::uint32_t mask = e.size == 4 ? 0xFFFFFFFFu : (1u << (8 * e.size)) - 1;
      EXPECT_EQ(rig.drives->sdo_read(bus, n, e.index, e.sub) & mask, e.value) << e.origin;
    }
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x6061, 0), 8u);     // CSP, read back
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x60C2, 1), 2u);     // 2 ms ...
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x60C2, 2), 0xFDu);  // ... in 10^-3 s
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x6066, 0), 20u);
    const double vmax = model.limits()[j].velocity_rad_s * std::abs(d.counts_per_rad());
    EXPECT_NEAR(rig.drives->sdo_read(bus, n, 0x607F, 0), vmax, 0.6) << d.joint;  // from the URDF
    for (std::uint16_t i = 1; i < 4; ++i) {
      EXPECT_TRUE(rig.drives->sdo_read(bus, n, static_cast<std::uint16_t>(0x1400 + i), 1) & 0x80000000u);
      if (i == 1) continue;  // TPDO2: velocity actual 0x606C on every 5th SYNC
      EXPECT_TRUE(rig.drives->sdo_read(bus, n, static_cast<std::uint16_t>(0x1800 + i), 1) & 0x80000000u);
    }
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x1801, 1), 0x280u + n);
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x1801, 2), 5u);
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x1A01, 0), 1u);
    EXPECT_EQ(rig.drives->sdo_read(bus, n, 0x1A01, 1), 0x606C0020u);
  }
  // ... and runs CSP with no stray frames on the bus.
  rig.drives->enable();
  rig.drives->held_targets(rig.targets);
  rig.deadline = Clock::now();
  const double q0 = rig.targets.position_rad[2];
  for (int i = 1; i <= 100; ++i) {
    rig.targets.position_rad[2] = q0 + 0.02 * i / 100.0;
    const CycleStatus s = rig.cycle();
    EXPECT_EQ(find_event(s, HwFault::UnknownCobId), nullptr);
  }
  rig.run_until([](const CycleStatus&) { return false; }, 25);
  EXPECT_NEAR(rig.fb.joints[2].position_rad, q0 + 0.02, 1e-4);
  EXPECT_EQ(rig.drives->unexpected_frames(0), 0u);
  EXPECT_EQ(rig.drives->unexpected_frames(1), 0u);
}

TEST(DriveConfigFile, ADriveOfAnotherIdentityIsRefusedBeforeAnythingIsWritten) {
  hw::RemoteConfig c = project_config();
  for (hw::SdoEntry& e : c.drives[2].sdo_entries)
    if (e.index == 0x1018 && e.sub == 2) e.value = 0x403;
  SimRig rig(c);
  try {
    rig.drives->configure();
    FAIL();
  } catch (const hw::HwError& e) {
    EXPECT_EQ(std::string(e.what()),
              "joint3 (bus arm_a node 3): 0x1018:02 is 0x00000402, expected 0x00000403 (" FORESIGHT_CONFIG_DIR
              "/drives/simdrive.sdo:12): not the drive this configuration is for");
  }
  EXPECT_EQ(rig.sim->drive(2).following_error_window(), 0xFFFFFFFFu);  // untouched
}

TEST(DriveConfigFile, AValueTheDriveRefusesNamesTheFileLine) {
  SimRig rig(with_entry(project_config(), 0x605A, 3));  // 3 is not a quick stop option code
  try {
    rig.drives->configure();
    FAIL();
  } catch (const hw::SdoError& e) {
    EXPECT_EQ(std::string(e.what()),
              "SDO write 0x605A:00 of joint1 (bus arm_a node 1): aborted by the node: 0x06090030 value range of "
              "parameter exceeded");
  }
}

// Quick stop option 2 (the shipped file, DriveFaults.QuickStopRampsThenPowersOff)
// ramps down, then powers off; written here explicitly.
TEST(DriveConfigFile, QuickStopOption2RampsThenDisables) {
  SimRig rig(with_entry(project_config(), 0x605A, 2));
  rig.bring_up();
  rig.drives->request_quick_stop();
  rig.run_until([&](const CycleStatus&) { return rig.fb.joints[0].state == PowerState::SwitchOnDisabled; }, 500);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.fb.joints[j].state, PowerState::SwitchOnDisabled) << j;
}

// Abort connection option (0x6007) when the master falls silent: 1 (shipped)
// faults (DriveFaults.DrivesFaultWhenTheMasterStopsCycling), 3 quick-stops
// (then powers off: 0x605A = 2), 2 disables the voltage; each with EMCY 0x8130.
// Every option ends without power.
TEST(DriveConfigFile, AbortConnectionOptionsActAsConfigured) {
  for (const auto& [option, expected] : {std::pair{3, PowerState::SwitchOnDisabled}, std::pair{2, PowerState::SwitchOnDisabled}}) {
    SimRig rig(with_entry(project_config(), 0x6007, option));
    rig.bring_up();
    rig.run_until([](const CycleStatus&) { return false; }, 10);
    // The master stops cycling (no SYNC, no heartbeat).
    EXPECT_TRUE(eventually([&] {
      for (std::size_t j = 0; j < 7; ++j)
        if (rig.sim->drive(j).power_state() != expected) return false;
      return true;
    }, std::chrono::seconds(3))) << "option " << option;
    for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), expected) << option << " " << j;
  }
}

// Fault reaction (0x605E) 2: a drive faulting while moving ramps down in
// Fault reaction active before Fault; 0: Fault at once.
TEST(DriveConfigFile, FaultReactionRampsOrCoastsAsConfigured) {
  for (const int reaction : {2, 0}) {
    SimRig rig(with_entry(project_config(), 0x605E, reaction));
    rig.bring_up();
    const double q0 = rig.targets.position_rad[0];
    for (int i = 1; i <= 50; ++i) {  // moving at 0.5 rad/s
      rig.targets.position_rad[0] = q0 + 0.001 * i;
      rig.cycle();
    }
    rig.sim->drive(0).inject_fault(0x2310);
    bool saw_reaction = false;
    for (int i = 0; i < 500 && rig.fb.joints[0].state != PowerState::Fault; ++i) {
      rig.targets.position_rad[0] = rig.fb.joints[0].position_rad;
      rig.cycle();
      saw_reaction = saw_reaction || rig.fb.joints[0].state == PowerState::FaultReactionActive;
    }
    EXPECT_EQ(rig.fb.joints[0].state, PowerState::Fault) << reaction;
    EXPECT_EQ(saw_reaction, reaction == 2) << reaction;
  }
}

TEST(DriveConfigFile, UnexpectedCobIdsAreCountedAndReportedOnce) {
  SimRig rig(project_config());
  rig.bring_up();
  int reported = 0;
  for (int i = 0; i < 20; ++i) {
    if (i < 10) rig.sim->inject(1, hw::make_frame(0x2A5, {1, 2}));  // a TPDO2 nobody configured
    const CycleStatus s = rig.cycle();
    for (std::size_t k = 0; k < s.event_count; ++k) reported += s.events[k].fault == HwFault::UnknownCobId;
  }
  rig.run_until([&](const CycleStatus&) { return rig.drives->unexpected_frames(1) >= 10; }, 200);
  EXPECT_EQ(reported, 1);
  EXPECT_EQ(rig.drives->unexpected_frames(1), 10u);
  EXPECT_EQ(rig.drives->unexpected_frames(0), 0u);
}

TEST(DriveConfigFile, TheMasterRefusesATargetStepBeyondTheFollowingErrorWindow) {
  SimRig rig(project_config());
  rig.bring_up();
  const double q0 = rig.targets.position_rad[0];
  rig.targets.position_rad[0] = q0 + 0.05;  // window 0.02 rad
  const CycleStatus s = rig.run_until(has(HwFault::InvalidTarget), 10);
  const HwEvent* e = find_event(s, HwFault::InvalidTarget);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->joint, 0);
  EXPECT_EQ(e->detail, 1u);
  EXPECT_TRUE(s.stop_required);
  const double counts = 0.05 * rig.config.drives[0].counts_per_rad();
  EXPECT_NEAR(e->code, counts, 1.0);
  EXPECT_NE(rig.drives->describe(*e).find("joint1 (bus arm_a node 1): invalid joint target (not finite or out of range): a step of "),
            std::string::npos) << rig.drives->describe(*e);
  // The drive never saw it: still enabled, holding.
  rig.run_until([](const CycleStatus&) { return false; }, 20);
  EXPECT_EQ(rig.sim->drive(0).power_state(), PowerState::OperationEnabled);
  EXPECT_NEAR(rig.fb.joints[0].position_rad, q0, 1e-4);
}

// Following-error timeout (0x6066): a disturbance beyond the window that the
// drive corrects within the timeout is not a fault; with timeout 0 it is.
TEST(DriveConfigFile, FollowingErrorTimeoutIsHonoured) {
  for (const double timeout_s : {0.3, 0.0}) {
    hw::RemoteConfig c = project_config();
    for (hw::DriveConfig& d : c.drives) d.following_error_timeout_s = timeout_s;
    SimRig rig(c);
    rig.bring_up();
    // Push joint1 0.1 rad (window 0.02): the position loop pulls it back in ~40 ms.
    rig.sim->drive(0).set_position_counts(rig.sim->drive(0).position_counts() + 0.1 * c.drives[0].counts_per_rad());
    bool faulted = false;
    for (int i = 0; i < 150 && !faulted; ++i) {
      const CycleStatus s = rig.cycle();
      if (const HwEvent* e = find_event(s, HwFault::Emergency)) faulted = e->code == 0x8611;
    }
    EXPECT_EQ(faulted, timeout_s == 0.0) << timeout_s;
  }
}

// Velocity actual (0x606C) in TPDO2 on every 5th SYNC, reported beside the
// position. Stepped: a ramp at 0.05 rad/s on joint 6 (direction -1) and
// joint 2; the drive's velocity is the ramp's once it has caught up.
TEST(DriveConfigFile, VelocityActualComesInTpdo2EveryFifthSync) {
  SimRig rig(hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml"));
  ASSERT_EQ(rig.config.velocity_tpdo_every, 5);
  rig.bring_up_stepped();
  const JointTargets q0 = rig.targets;
  std::uint64_t last_cycle = 0;
  int updates = 0;
  for (int i = 1; i <= 200; ++i) {  // 0.4 s
    rig.targets.position_rad[5] = q0.position_rad[5] + 0.05 * i * 0.002;
    rig.targets.position_rad[1] = q0.position_rad[1] - 0.05 * i * 0.002;
    const CycleStatus s = rig.cycle();
    EXPECT_TRUE(s.ok()) << i;
    if (rig.fb.joints[5].velocity_cycle != last_cycle) {
      ++updates;
      last_cycle = rig.fb.joints[5].velocity_cycle;
    }
  }
  EXPECT_GE(updates, 39);  // 200 SYNCs / 5
  EXPECT_LE(updates, 41);
  EXPECT_NEAR(rig.fb.joints[5].velocity_rad_s, 0.05, 0.002);
  EXPECT_NEAR(rig.fb.joints[1].velocity_rad_s, -0.05, 0.002);
  EXPECT_NEAR(rig.fb.joints[3].velocity_rad_s, 0.0, 1e-6);
  // The same number the simulated drive holds, in counts/s through the scaling.
  EXPECT_NEAR(rig.fb.joints[5].velocity_counts_s, 0.05 * rig.config.drives[5].counts_per_rad(), 0.002 * 2.1e6);
  EXPECT_EQ(rig.drives->unexpected_frames(0), 0u);
  EXPECT_EQ(rig.drives->unexpected_frames(1), 0u);
}

// Without velocity_tpdo_every (0) TPDO2 stays off and nothing else changes.
TEST(DriveConfigFile, VelocityTpdoCanBeSwitchedOff) {
  hw::RemoteConfig c = hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  c.velocity_tpdo_every = 0;
  SimRig rig(c);
  rig.drives->configure();
  EXPECT_TRUE(rig.drives->sdo_read(0, 1, 0x1801, 1) & 0x80000000u);
  rig.go_stepped();
  for (int i = 0; i < 20; ++i) EXPECT_TRUE(rig.cycle().ok()) << i;
  EXPECT_EQ(rig.fb.joints[0].velocity_cycle, 0u);
  EXPECT_EQ(rig.drives->unexpected_frames(0), 0u);
}

// Homing at bring-up for incremental encoders (DriveSystem::home): joint2
// runs to its home switch (method 19) 30,000 counts below where it powered
// on, joint5 takes its current position (method 37); both then read the home
// offset (0 counts); the others (absolute encoders) are not moved. Back in
// CSP, the arm runs from the new zero.
TEST(DriveConfigFile, HomingRunsToTheSwitchAndRedefinesThePosition) {
  hw::RemoteConfig c = project_config();
  c.drives[1].homing = {true, 19, 0.02, 0.002, 1.0, 5.0};
  c.drives[4].homing = {true, 37, 0.02, 0.002, 1.0, 5.0};
  SimRig rig(c);
  rig.sim->drive(1).set_position_counts(50000.0);  // an incremental encoder counts from anywhere
  rig.sim->drive(1).set_home_switch_counts(20000.0);
  rig.sim->drive(4).set_position_counts(-12345.0);
  rig.drives->configure();
  const double other = rig.sim->drive(0).position_counts();
  EXPECT_EQ(rig.drives->home(), 2u);
  EXPECT_TRUE(rig.sim->drive(1).homing_attained());
  EXPECT_TRUE(rig.sim->drive(4).homing_attained());
  EXPECT_NEAR(rig.sim->drive(1).position_counts(), 0.0, 0.5);
  EXPECT_NEAR(rig.sim->drive(4).position_counts(), 0.0, 0.5);
  EXPECT_NEAR(rig.sim->drive(0).position_counts(), other, 0.5);
  // (30,000 counts: 28,690 at 0.02 rad/s = 66,757 counts/s, the last 1/100
  // rev, 1,311, at 0.002 rad/s: 0.63 s of simulated motion. Not asserted in
  // wall time: on a loaded machine late SYNCs bunch up and the drive's
  // physics, bounded per SYNC, runs ahead of or behind the wall clock.)
  const double cpr = c.drives[1].counts_per_rad();
  EXPECT_EQ(rig.drives->sdo_read(0, 2, 0x6098, 0), 19u);
  EXPECT_EQ(rig.drives->sdo_read(0, 2, 0x6099, 1), static_cast<std::uint32_t>(std::lround(0.02 * cpr)));
  EXPECT_EQ(rig.drives->sdo_read(0, 2, 0x6099, 2), static_cast<std::uint32_t>(std::lround(0.002 * cpr)));
  EXPECT_EQ(rig.drives->sdo_read(0, 2, 0x609A, 0), static_cast<std::uint32_t>(std::lround(1.0 * cpr)));
  EXPECT_EQ(rig.drives->sdo_read(0, 2, 0x6061, 0), 8u);  // back in CSP
  EXPECT_EQ(rig.drives->sdo_read(1, 5, 0x6061, 0), 8u);
  EXPECT_EQ(rig.sim->drive(1).power_state(), PowerState::SwitchOnDisabled);  // disabled (no power) after homing
  // CSP from the new zero.
  rig.drives->enable();
  rig.drives->held_targets(rig.targets);
  EXPECT_NEAR(rig.targets.position_rad[1], 0.0, 1e-6);
  EXPECT_NEAR(rig.targets.position_rad[4], 0.0, 1e-6);
  rig.deadline = Clock::now();
  for (int i = 1; i <= 50; ++i) {
    rig.targets.position_rad[1] = 0.01 * i / 50.0;
    EXPECT_TRUE(rig.cycle().ok()) << i;
  }
  rig.run_until([](const CycleStatus&) { return false; }, 25);
  EXPECT_NEAR(rig.fb.joints[1].position_rad, 0.01, 1e-4);
}

TEST(DriveConfigFile, HomingThatDoesNotFinishInTimeNamesTheDrive) {
  hw::RemoteConfig c = project_config();
  c.drives[1].homing = {true, 19, 0.02, 0.002, 1.0, 0.2};
  SimRig rig(c);
  rig.sim->drive(1).set_home_switch_counts(-131072.0 * 160);  // a joint revolution away: 314 s at 0.02 rad/s
  rig.drives->configure();
  try {
    rig.drives->home();
    FAIL() << "homing that cannot finish in 200 ms was accepted";
  } catch (const hw::HwError& e) {
    EXPECT_NE(std::string(e.what()).find("home(): not homed within 200 ms: joint2 (bus arm_a node 2) (statusword 0x"),
              std::string::npos) << e.what();
  }
  EXPECT_EQ(rig.sim->drive(1).power_state(), PowerState::SwitchOnDisabled);  // left disabled (no power)
  EXPECT_FALSE(rig.sim->drive(1).homing_attained());
}

TEST(DriveConfigFile, AHomingMethodTheDriveLacksIsRefusedByIt) {
  hw::RemoteConfig c = project_config();
  c.drives[1].homing = {true, 1, 0.02, 0.002, 1.0, 1.0};  // limit switch with index: not in this drive
  SimRig rig(c);
  rig.drives->configure();
  try {
    rig.drives->home();
    FAIL();
  } catch (const hw::SdoError& e) {
    EXPECT_NE(std::string(e.what()).find("0x6098"), std::string::npos) << e.what();
  }
}

// The `homing:` block of a drive in remote.yaml, and a bad one named.
TEST(DriveConfigFile, HomingBlockIsReadFromRemoteYaml) {
  std::ifstream in(FORESIGHT_CONFIG_DIR "/remote.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  const std::string joint2 = "{joint: joint2,";
  const auto at = text.find(joint2);
  ASSERT_NE(at, std::string::npos);
  const auto end = text.find("sdo_file: drives/simdrive.sdo}", at);
  ASSERT_NE(end, std::string::npos);
  auto with = [&](const std::string& block) {
    std::string t = text;
    t.replace(end, std::string("sdo_file: drives/simdrive.sdo}").size(), "sdo_file: drives/simdrive.sdo, homing: " + block + "}");
    return t;
  };
  const hw::RemoteConfig c = hw::parse_remote_config(
      with("{method: 19, speed_switch_rad_s: 0.02, speed_zero_rad_s: 0.002, acceleration_rad_s2: 1.0, timeout_ms: 5000}"),
      FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_TRUE(c.drives[1].homing.enabled);
  EXPECT_EQ(c.drives[1].homing.method, 19);
  EXPECT_DOUBLE_EQ(c.drives[1].homing.speed_switch_rad_s, 0.02);
  EXPECT_DOUBLE_EQ(c.drives[1].homing.speed_zero_rad_s, 0.002);
  EXPECT_DOUBLE_EQ(c.drives[1].homing.acceleration_rad_s2, 1.0);
  EXPECT_DOUBLE_EQ(c.drives[1].homing.timeout_s, 5.0);
  EXPECT_FALSE(c.drives[0].homing.enabled);  // absolute encoders: no block, offset_rad
  try {
    hw::parse_remote_config(with("{method: 36, speed_switch_rad_s: 0.02, speed_zero_rad_s: 0.002, acceleration_rad_s2: 1}"),
                            FORESIGHT_CONFIG_DIR "/remote.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("method: 36 is not a CiA 402 homing method (1..35, 37)"), std::string::npos)
        << e.what();
  }
  try {
    hw::parse_remote_config(with("{method: 19, speed_switch_rad_s: 0, speed_zero_rad_s: 0.002, acceleration_rad_s2: 1}"),
                            FORESIGHT_CONFIG_DIR "/remote.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("speed_switch_rad_s: must be a positive finite number"), std::string::npos)
        << e.what();
  }
}
