// Faults during the real-time cycle, each injected on the far end of the bus
// and reported by the master as a named event.

#include <linux/can/error.h>

#include <cmath>
#include <numbers>

#include "sim_fixture.hpp"

using namespace foresight;
using namespace foresight::test;
using hw::canopen::PowerState;

namespace {
auto has = [](HwFault f) { return [f](const CycleStatus& s) { return find_event(s, f) != nullptr; }; };
}

// Stepped (SimRig::bring_up_stepped): counted in cycles of simulated time.
// The drive's last heartbeat was produced within one producer period (50 ms,
// 25 cycles) before it fell silent and read by the master one cycle later;
// the master faults at the first read more than the consumer time (175 ms,
// the production 3.5 x producer) after that read: 176 ms, between 64 and 89
// cycles after the silence.
TEST(DriveFaults, HeartbeatLossIsDetectedWithinTheConsumerTime) {
  SimRig rig(hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml"));
  rig.bring_up_stepped();
  rig.run_until([](const CycleStatus&) { return false; }, 30);
  rig.sim->drive(4).silence_heartbeat(true);
  int n = 0;
  const auto [s, stops] = rig.run_until_stop(200, &n);
  ASSERT_EQ(stops.size(), 1u);
  const HwEvent* e = &stops[0];
  EXPECT_EQ(e->fault, HwFault::HeartbeatLost);
  EXPECT_EQ(e->joint, 4);
  EXPECT_TRUE(s.stop_required);
  EXPECT_GE(n, (175 - 50) / 2 + 2);
  EXPECT_LE(n, (175 + 2 * 2) / 2);
  EXPECT_EQ(e->code, 176u);
  EXPECT_EQ(rig.drives->describe(*e), "joint5 (bus arm_b node 5): heartbeat lost (silent for 176 ms)");
  EXPECT_TRUE(rig.fb.joints[4].heartbeat_lost);
  EXPECT_FALSE(rig.fb.joints[3].heartbeat_lost);
}

TEST(DriveFaults, EmcyIsMappedToItsFaultAndFaultResetRecovers) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.sim->drive(2).inject_fault(0x2310);
  CycleStatus all;
  bool emcy = false, fault = false;
  for (int i = 0; i < 50 && !(emcy && fault); ++i) {
    const CycleStatus s = rig.cycle();
    if (const HwEvent* e = find_event(s, HwFault::Emergency)) {
      emcy = true;
      EXPECT_EQ(e->code, 0x2310u);
      EXPECT_EQ(e->joint, 2);
      EXPECT_EQ(hw::canopen::classify_emcy(static_cast<std::uint16_t>(e->code)), hw::canopen::EmcyFault::OverCurrent);
      EXPECT_EQ(rig.drives->describe(*e), "joint3 (bus arm_a node 3): emergency (EMCY) 0x2310 over-current (error register 0x03)");
      EXPECT_TRUE(s.stop_required);
    }
    if (const HwEvent* e = find_event(s, HwFault::DriveFault)) {
      fault = true;
      EXPECT_EQ(e->joint, 2);
    }
  }
  EXPECT_TRUE(emcy);
  EXPECT_TRUE(fault);
  EXPECT_EQ(rig.fb.joints[2].state, PowerState::Fault);
  EXPECT_EQ(rig.fb.joints[2].last_emcy, 0x2310);
  // enable() resets the fault (rising edge of controlword bit 7) and re-enables.
  rig.drives->enable();
  EXPECT_EQ(rig.sim->drive(2).power_state(), PowerState::OperationEnabled);
}

TEST(DriveFaults, FollowingErrorFaultsTheDrive) {
  SimRig rig(project_config());
  rig.bring_up();
  // The shaft is pushed 0.3 rad away (far beyond the 0.02 rad window) while
  // the target stays: the drive cannot follow. (A target step that large is
  // refused by the master before it reaches the drive: InvalidTarget.)
  rig.sim->drive(0).set_position_counts(rig.sim->drive(0).position_counts() + 0.3 * rig.config.drives[0].counts_per_rad());
  const CycleStatus s = rig.run_until(has(HwFault::Emergency), 500);
  const HwEvent* e = find_event(s, HwFault::Emergency);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->code, 0x8611u);
  EXPECT_EQ(e->detail, 0x21u);  // error register: generic + device profile specific (not communication)
  EXPECT_EQ(hw::canopen::classify_emcy(0x8611), hw::canopen::EmcyFault::FollowingError);
  rig.run_until([&](const CycleStatus&) { return rig.fb.joints[0].state == PowerState::Fault; }, 500);
  EXPECT_EQ(rig.fb.joints[0].state, PowerState::Fault);
  EXPECT_TRUE(rig.fb.joints[0].statusword & hw::canopen::statusword::kCspFollowingError);
}

TEST(DriveFaults, UrdfLimitIsEnforcedByTheDrive) {
  std::map<std::string, JointLimits> limits;
  for (int i = 1; i <= 7; ++i) limits["joint" + std::to_string(i)] = {-0.01, 0.01, 1, 1, 100};
  SimRig rig(project_config(), limits);
  rig.bring_up();
  rig.targets.position_rad[1] = 0.015;  // beyond +0.01, within the following-error window
  const CycleStatus s = rig.run_until(has(HwFault::Emergency), 500);
  const HwEvent* e = find_event(s, HwFault::Emergency);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->code, 0x8612u);
  EXPECT_EQ(e->detail, 0x21u);  // error register: generic + device profile specific
  EXPECT_EQ(e->joint, 1);
  EXPECT_NE(rig.drives->describe(*e).find("position (reference) limit"), std::string::npos);
}

TEST(DriveFaults, MalformedAndUnknownFramesAreNamedNotFatal) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.run_until([](const CycleStatus&) { return false; }, 5);
  rig.sim->inject(0, hw::make_frame(0x181, {1, 2, 3, 4}));           // TPDO of node 1, DLC 4
  rig.sim->inject(0, hw::make_frame(0x123, {1}));                    // nobody's COB-ID
  rig.sim->inject(0, hw::make_frame(0x702, {0x05, 0x00}));           // heartbeat, DLC 2
  rig.sim->inject(1, hw::make_frame(0x085, {0x10, 0x23}));           // EMCY, DLC 2
  can_frame ext = hw::make_frame(0x1ABCDE | CAN_EFF_FLAG, {1});      // extended id
  rig.sim->inject(1, ext);
  std::vector<HwEvent> seen;
  for (int i = 0; i < 10; ++i) {
    const CycleStatus s = rig.cycle();
    for (std::size_t k = 0; k < s.event_count; ++k) seen.push_back(s.events[k]);
  }
  auto count = [&](HwFault f, std::uint32_t code) {
    return std::count_if(seen.begin(), seen.end(), [&](const HwEvent& e) { return e.fault == f && e.code == code; });
  };
  EXPECT_EQ(count(HwFault::MalformedFrame, 0x181), 1);
  EXPECT_EQ(count(HwFault::UnknownCobId, 0x123), 1);
  EXPECT_EQ(count(HwFault::MalformedFrame, 0x702), 1);
  EXPECT_EQ(count(HwFault::MalformedFrame, 0x085), 1);
  EXPECT_EQ(count(HwFault::UnknownCobId, 0x1ABCDE), 1);
  for (const HwEvent& e : seen) EXPECT_FALSE(hw::requires_stop(e.fault)) << rig.drives->describe(e);
  const auto it = std::find_if(seen.begin(), seen.end(), [](const HwEvent& e) { return e.code == 0x181; });
  EXPECT_EQ(rig.drives->describe(*it), "joint1 (bus arm_a node 1): malformed frame COB-ID 0x181 with DLC 4");
  // The drives kept running.
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.fb.joints[j].state, PowerState::OperationEnabled);
}

TEST(DriveFaults, BusOffAndSilentDriveAreStops) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.sim->drive(6).stop_answering(true);
  int n = 0;
  CycleStatus s = rig.run_until(has(HwFault::TpdoMissing), 40, &n);
  const HwEvent* e = find_event(s, HwFault::TpdoMissing);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->joint, 6);
  EXPECT_EQ(e->code, 25u);  // tpdo_miss_limit
  EXPECT_GE(n, 25);
  EXPECT_LE(n, 27);
  EXPECT_TRUE(s.stop_required);
  rig.sim->inject(0, hw::make_frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF, {0, 0, 0, 0, 0, 0, 0, 0}));
  s = rig.run_until(has(HwFault::BusOff), 500);
  ASSERT_NE(find_event(s, HwFault::BusOff), nullptr);
  EXPECT_EQ(rig.drives->describe(*find_event(s, HwFault::BusOff)), "bus arm_a: CAN bus-off");
  EXPECT_TRUE(rig.drives->bus(0).health().bus_off);
}

TEST(DriveFaults, RebootedDriveIsAStopAndStopsSendingPdos) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.sim->drive(3).inject_reboot();
  CycleStatus s = rig.run_until(has(HwFault::NodeRebooted), 500);
  const HwEvent* e = find_event(s, HwFault::NodeRebooted);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->joint, 3);
  EXPECT_TRUE(s.stop_required);
  EXPECT_EQ(rig.drives->describe(*e), "joint4 (bus arm_a node 4): node rebooted (boot-up while operational)");
  // Pre-operational after boot: no more TPDOs from it.
  s = rig.run_until(has(HwFault::TpdoMissing), 100);
  ASSERT_NE(find_event(s, HwFault::TpdoMissing), nullptr);
  EXPECT_EQ(find_event(s, HwFault::TpdoMissing)->joint, 3);
  // A new configure() + enable() brings it back.
  rig.drives->configure();
  rig.drives->enable();
  EXPECT_EQ(rig.sim->drive(3).power_state(), PowerState::OperationEnabled);
}

TEST(DriveFaults, FullTransmitQueueIsReportedOncePerBus) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.sim->stop();  // nobody drains the far end any more: the queues fill up
  int tx_failed[2] = {0, 0};
  for (int i = 0; i < 1000; ++i) {
    rig.deadline = Clock::now();  // no need to wait: nothing answers
    const CycleStatus s = rig.cycle();
    for (std::size_t k = 0; k < s.event_count; ++k) {
      if (s.events[k].fault == HwFault::TxFailed) {
        ++tx_failed[s.events[k].bus];
        EXPECT_EQ(s.events[k].code, static_cast<std::uint32_t>(hw::CanIo::WouldBlock));
        EXPECT_TRUE(s.stop_required);
      }
    }
  }
  EXPECT_EQ(tx_failed[0], 1);
  EXPECT_EQ(tx_failed[1], 1);
  EXPECT_FALSE(rig.drives->bus(0).health().bus_off);  // a full queue is not bus-off
}

// Issue 25: an EMCY is classified by its error register (CiA 301): a code
// with an empty register is a warning (a notice; the arm goes on), with bit 0
// set an error (a stop).
TEST(DriveFaults, AnEmcyWithAnEmptyErrorRegisterIsAWarningNotAStop) {
  SimRig rig(project_config());
  rig.bring_up_stepped();
  rig.sim->inject(0, hw::make_frame(0x83, {0x10, 0x42, 0x00, 0, 0, 0, 0, 0}));  // 0x4210 temperature, register 0
  CycleStatus s = rig.run_until(has(HwFault::EmergencyWarning), 5);
  const HwEvent* w = find_event(s, HwFault::EmergencyWarning);
  ASSERT_NE(w, nullptr);
  EXPECT_FALSE(s.stop_required);
  EXPECT_FALSE(hw::requires_stop(HwFault::EmergencyWarning));
  EXPECT_EQ(rig.drives->describe(*w),
            "joint3 (bus arm_a node 3): emergency message, a warning (EMCY, error register 0) 0x4210 "
            "over-temperature (error register 0x00)");
  rig.sim->inject(0, hw::make_frame(0x83, {0x10, 0x42, 0x09, 0, 0, 0, 0, 0}));  // the same code, generic + temperature
  s = rig.run_until(has(HwFault::Emergency), 5);
  ASSERT_NE(find_event(s, HwFault::Emergency), nullptr);
  EXPECT_TRUE(s.stop_required);
}

// The shipped quick stop option (0x605A = 2): the drives' own ramp, then
// Switch on disabled; never left in Quick stop active with voltage on.
TEST(DriveFaults, QuickStopRampsThenPowersOff) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.drives->request_quick_stop();
  rig.run_until([&](const CycleStatus&) {
    for (std::size_t j = 0; j < 7; ++j)
      if (rig.fb.joints[j].state != PowerState::SwitchOnDisabled) return false;
    return true;
  }, 500);
  for (std::size_t j = 0; j < 7; ++j) {
    EXPECT_EQ(rig.fb.joints[j].state, PowerState::SwitchOnDisabled) << j;
    EXPECT_FALSE(rig.sim->drive(j).power_record().powered) << j;
  }
  const double x = rig.sim->drive(0).position_counts();
  rig.targets.position_rad[0] += 0.01;  // ignored: no power
  rig.run_until([](const CycleStatus&) { return false; }, 10);
  EXPECT_NEAR(rig.sim->drive(0).position_counts(), x, 1.0);
}

// Category 0 as the drives see it (stepped: counted in cycles). Mid-motion,
// request_power_off() puts Disable Voltage in the very next cycle's RPDOs;
// each drive latches it at the following SYNC and is unpowered there (Switch
// on disabled) within two cycles, never passing through Quick stop active;
// the master reads the new state one cycle later; disable() then confirms
// at once; and the arm no longer follows any target.
TEST(DriveFaults, PowerOffIsCategoryZeroWithinTwoCycles) {
  SimRig rig(project_config());
  rig.bring_up_stepped();
  for (int i = 0; i < 50; ++i) {  // moving: 0.2 rad/s on every joint
    for (std::size_t j = 0; j < 7; ++j) rig.targets.position_rad[j] += 0.2 * 0.002;
    rig.cycle();
  }
  for (std::size_t j = 0; j < 7; ++j) {
    ASSERT_EQ(rig.sim->drive(j).power_state(), PowerState::OperationEnabled) << j;
    ASSERT_GT(std::abs(rig.sim->drive(j).velocity_counts_s()), 1000.0) << j;
    rig.sim->drive(j).clear_power_record();
  }
  rig.drives->request_power_off();
  int cycles = 0;
  auto all_unpowered = [&] {
    for (std::size_t j = 0; j < 7; ++j)
      if (rig.sim->drive(j).power_record().powered) return false;
    return true;
  };
  while (!all_unpowered() && cycles < 10) {
    rig.cycle();
    ++cycles;
  }
  EXPECT_LE(cycles, 2);
  for (std::size_t j = 0; j < 7; ++j) {
    const sim::DrivePowerRecord r = rig.sim->drive(j).power_record();
    EXPECT_EQ(r.state, PowerState::SwitchOnDisabled) << j;
    EXPECT_FALSE(r.powered) << j;
    EXPECT_EQ(r.states_seen & (1u << static_cast<unsigned>(PowerState::QuickStopActive)), 0u) << j;
    EXPECT_EQ(r.states_seen & (1u << static_cast<unsigned>(PowerState::ReadyToSwitchOn)), 0u) << j;
  }
  rig.cycle();
  rig.cycle();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.fb.joints[j].state, PowerState::SwitchOnDisabled) << j;
  // Latched: later cycles keep commanding Disable Voltage whatever was set.
  const double x = rig.sim->drive(2).position_counts();
  rig.targets.position_rad[2] += 0.005;
  for (int i = 0; i < 20; ++i) rig.cycle();
  EXPECT_EQ(rig.sim->drive(2).controlword(), hw::canopen::controlword::kDisableVoltage);
  EXPECT_NEAR(rig.sim->drive(2).position_counts(), x, 1.0);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_FALSE(rig.sim->drive(j).power_record().powered) << j;
}

// disable() succeeds only once every drive reports a state without power;
// after it, enable() brings them back.
TEST(DriveFaults, DisableEndsWithEveryDriveUnpoweredAndEnableReturns) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.drives->disable();
  for (std::size_t j = 0; j < 7; ++j) {
    EXPECT_FALSE(hw::canopen::power_enabled(rig.sim->drive(j).power_state())) << j;
    EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::SwitchOnDisabled) << j;
  }
  rig.drives->enable();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::OperationEnabled) << j;
}

TEST(FtSensorOnBus, ReadsTheTrueWrenchTaresAndReportsSaturation) {
  SimRig rig(project_config());
  rig.bring_up();
  sim::SimFtSensor& ft = *rig.sim->ft_sensor();
  ft.set_offset({2.0, -1.0, 0.5, 0.01, 0.02, -0.03});
  // Tare only once the offset shows in the readings: samples already on the
  // bus when it was set (more of them on a loaded machine) would bias the tare.
  // Bounded waits of up to 1 s (500 cycles) for the simulator thread.
  rig.run_until([&](const CycleStatus&) { return rig.ft.fresh && std::abs(rig.ft.raw_ft[0] - 2.0) < 0.01; }, 500);
  ASSERT_NEAR(rig.ft.raw_ft[0], 2.0, 0.01);
  rig.drives->request_tare(10);
  rig.run_until([&](const CycleStatus&) { return rig.ft.fresh && !rig.ft.tare_in_progress; }, 500);
  ASSERT_FALSE(rig.ft.tare_in_progress);
  ft.set_true_wrench({10.0, -20.0, 30.5, 1.5, -0.25, 0.125});
  rig.run_until([&](const CycleStatus&) { return rig.ft.fresh && std::abs(rig.ft.wrench_ft[0] - 10.0) < 0.1; }, 500);
  const double expect[6] = {10.0, -20.0, 30.5, 1.5, -0.25, 0.125};
  for (std::size_t i = 0; i < 6; ++i) EXPECT_NEAR(rig.ft.wrench_ft[i], expect[i], i < 3 ? 0.01 : 0.001) << i;
  EXPECT_NEAR(rig.ft.raw_ft[0], 12.0, 0.01);
  ft.set_true_wrench({0.0, 0.0, 400.0, 0.0, 0.0, 0.0});
  const CycleStatus s = rig.run_until(has(HwFault::FtSaturated), 500);
  const HwEvent* e = find_event(s, HwFault::FtSaturated);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->code, 0b000100u);  // Fz
  EXPECT_TRUE(s.stop_required);
}

TEST(FtSensorOnBus, SilentSensorAndSensorFaultAreNamed) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.sim->ft_sensor()->inject_sensor_fault(true);
  CycleStatus s = rig.run_until(has(HwFault::FtSensorFault), 500);
  ASSERT_NE(find_event(s, HwFault::FtSensorFault), nullptr);
  EXPECT_TRUE(rig.ft.sensor_fault);
  rig.sim->ft_sensor()->stop_answering(true);
  s = rig.run_until(has(HwFault::HeartbeatLost), 200);
  const HwEvent* e = find_event(s, HwFault::HeartbeatLost);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->joint, -1);
  EXPECT_EQ(e->node, 32);
  EXPECT_NE(rig.drives->describe(*e).find("F/T sensor (bus arm_b node 32): heartbeat lost"), std::string::npos)
      << rig.drives->describe(*e);
}

// A master that goes away with the drives enabled quick-stops them: their
// own ramp (on their own clock: no more SYNCs come), then power off.
TEST(DriveFaults, DestroyingTheMasterQuickStopsEnabledDrivesThenTheyPowerOff) {
  SimRig rig(project_config());
  rig.bring_up();
  for (std::size_t j = 0; j < 7; ++j) rig.sim->drive(j).clear_power_record();
  rig.drives.reset();
  EXPECT_TRUE(eventually([&] {
    for (std::size_t j = 0; j < 7; ++j)
      if (rig.sim->drive(j).power_record().powered) return false;
    return true;
  }, std::chrono::seconds(5)));
  for (std::size_t j = 0; j < 7; ++j) {
    const sim::DrivePowerRecord r = rig.sim->drive(j).power_record();
    EXPECT_EQ(r.state, PowerState::SwitchOnDisabled) << j;
    EXPECT_NE(r.states_seen & (1u << static_cast<unsigned>(PowerState::QuickStopActive)), 0u) << j;
  }
}

TEST(FtSensorOnBus, WrenchSourceSeesTheSimulatedArm) {
  // A stand-in for the contact model: a spring on joint1, Fz = -1000 N/rad * q1,
  // evaluated on the simulator thread at every SYNC from the simulated joints.
  SimRig rig(project_config());
  sim::CanSimulator* s = rig.sim.get();
  s->ft_sensor()->set_wrench_source([s] {
    double q[7];
    s->joint_positions_rad(q);
    return sim::SimFtSensor::Wrench{0.0, 0.0, -1000.0 * q[0], 0.0, 0.0, 0.0};
  });
  rig.bring_up();
  const double q0 = rig.targets.position_rad[0];
  for (int i = 1; i <= 100; ++i) {  // 0.2 s ramp to +0.01 rad
    rig.targets.position_rad[0] = q0 + 0.01 * i / 100.0;
    rig.cycle();
  }
  rig.run_until([](const CycleStatus&) { return false; }, 25);
  EXPECT_NEAR(rig.fb.joints[0].position_rad, q0 + 0.01, 1e-5);
  EXPECT_NEAR(rig.ft.wrench_ft[2], -1000.0 * (q0 + 0.01), 0.02);
}

TEST(DriveFaults, DrivesFaultWhenTheMasterStopsCycling) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.run_until([](const CycleStatus&) { return false; }, 30);
  // The master falls silent (no SYNC, no heartbeat): after heartbeat.consumer_ms
  // the drives fault on their own (0x1016 consumer), EMCY 0x8130.
  // Poll with a deadline (no fixed sleep): 175 ms consumer time, 3 s bound.
  auto all_faulted = [&] {
    for (std::size_t j = 0; j < 7; ++j)
      if (rig.sim->drive(j).power_state() != PowerState::Fault) return false;
    return true;
  };
  const auto until = Clock::now() + std::chrono::seconds(3);
  while (!all_faulted() && Clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  // (A drive sends its EMCY under the same lock as it enters Fault: seen Fault, the EMCY is on the bus.)
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::Fault) << j;
  const CycleStatus s = rig.drives->cycle_read(rig.fb, rig.ft);
  int heartbeat_emcy = 0;
  for (std::size_t k = 0; k < s.event_count; ++k)
    if (s.events[k].fault == HwFault::Emergency && s.events[k].code == 0x8130) {
      ++heartbeat_emcy;
      EXPECT_NE(rig.drives->describe(s.events[k]).find("0x8130 life guard or heartbeat error"), std::string::npos);
    }
  EXPECT_EQ(heartbeat_emcy, 7);
  // Cycling again and enable() recover.
  rig.drives->enable();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_EQ(rig.sim->drive(j).power_state(), PowerState::OperationEnabled) << j;
  rig.deadline = Clock::now();
  for (std::size_t j = 0; j < 7; ++j) rig.targets.position_rad[j] = rig.fb.joints[j].position_rad;
  const CycleStatus after = rig.run_until([](const CycleStatus& st) { return !st.ok(); }, 50);
  EXPECT_TRUE(after.ok()) << (after.event_count ? rig.drives->describe(after.events[0]) : "");
}

// ---- power changes stepped by the cycle (issue 25, item 5) -----------------------
// DriveSystem::begin_enable / begin_disable: one controlword per drive per
// cycle, judged on the drives' answers in cycle_read (CycleStatus::power),
// counted in cycles of simulated time (stepped).

namespace {

/// Cycles until the power change ends (or `max`); every event on the way.
struct PowerRun {
  CycleStatus last;
  int cycles = 0;
  std::vector<HwEvent> events;
};
PowerRun run_power(SimRig& rig, int max, const std::function<void(int)>& each = {}) {
  PowerRun r;
  for (; r.cycles < max; ) {
    r.last = rig.cycle();
    ++r.cycles;
    for (std::size_t i = 0; i < r.last.event_count; ++i) r.events.push_back(r.last.events[i]);
    if (r.last.power.finished) break;
    if (each) each(r.cycles);
  }
  return r;
}

constexpr unsigned bit(PowerState s) { return 1u << static_cast<unsigned>(s); }

}  // namespace

// The CiA 402 sequence per drive, from Switch on disabled, one step per
// answer: shutdown -> Ready to switch on -> switch on -> Switched on ->
// enable operation -> Operation enabled; each change an event. The targets
// given to cycle_write meanwhile are not taken: every drive holds its actual
// position (nothing moves), and after the enable the held targets are the
// actual positions.
TEST(DrivePower, EnableIsSteppedByTheCycleHoldingTheActualPositions) {
  SimRig rig(project_config());
  rig.drives->configure();
  rig.go_stepped_disabled();
  for (std::size_t j = 0; j < 7; ++j) rig.sim->drive(j).clear_power_record();
  std::vector<double> x0(7);
  for (std::size_t j = 0; j < 7; ++j) x0[j] = rig.sim->drive(j).position_counts();
  for (std::size_t j = 0; j < 7; ++j) rig.targets.position_rad[j] += 0.3;  // a jump nobody may take
  ASSERT_TRUE(rig.drives->begin_enable());
  EXPECT_EQ(rig.drives->power_status().phase, hw::PowerPhase::Enabling);
  const PowerRun r = run_power(rig, 1000);
  ASSERT_TRUE(r.last.power.finished);
  EXPECT_EQ(r.last.power.phase, hw::PowerPhase::Enabled);
  EXPECT_EQ(static_cast<int>(r.last.power.cycles), r.cycles);
  std::printf("enable on the simulator: %d cycles (%.0f ms at %.0f Hz)\n", r.cycles, r.cycles * 1e3 / rig.config.cycle_rate_hz,
              rig.config.cycle_rate_hz);
  // The first answer after one cycle (the TPDO of the first SYNC), then
  // four transitions (the simulated drive leaves Not ready to switch on at
  // its first command, as a drive after its self test), each one SYNC to
  // latch the command and one to report: 1 + 4 x 2 = 9 cycles, plus the
  // SYNC the master sends before the command reaches the drive (SYNC first,
  // then the RPDO: a command written in cycle k is latched at SYNC k+1, read
  // back at the read of cycle k+2): 11.
  EXPECT_EQ(r.cycles, 11);
  for (std::size_t j = 0; j < 7; ++j) {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> chain;
    for (const HwEvent& e : r.events)
      if (e.fault == HwFault::PowerStateChanged && e.joint == static_cast<std::int8_t>(j)) chain.emplace_back(e.detail, e.code);
    const std::vector<std::pair<std::uint32_t, std::uint32_t>> want = {
        {hw::kUnknownState, static_cast<std::uint32_t>(PowerState::NotReadyToSwitchOn)},
        {static_cast<std::uint32_t>(PowerState::NotReadyToSwitchOn), static_cast<std::uint32_t>(PowerState::SwitchOnDisabled)},
        {static_cast<std::uint32_t>(PowerState::SwitchOnDisabled), static_cast<std::uint32_t>(PowerState::ReadyToSwitchOn)},
        {static_cast<std::uint32_t>(PowerState::ReadyToSwitchOn), static_cast<std::uint32_t>(PowerState::SwitchedOn)},
        {static_cast<std::uint32_t>(PowerState::SwitchedOn), static_cast<std::uint32_t>(PowerState::OperationEnabled)}};
    EXPECT_EQ(chain, want) << "joint " << j + 1;
    const sim::DrivePowerRecord rec = rig.sim->drive(j).power_record();
    EXPECT_EQ(rec.state, PowerState::OperationEnabled) << j;
    EXPECT_EQ(rec.states_seen & (bit(PowerState::Fault) | bit(PowerState::QuickStopActive)), 0u) << j;
    EXPECT_NEAR(rig.sim->drive(j).position_counts(), x0[j], 1.0) << j;
    EXPECT_NEAR(rig.sim->drive(j).target_counts(), x0[j], 1.0) << j;
  }
  for (const HwEvent& e : r.events) EXPECT_FALSE(hw::requires_stop(e.fault)) << rig.drives->describe(e);
  const auto it = std::find_if(r.events.begin(), r.events.end(),
                               [](const HwEvent& e) { return e.fault == HwFault::PowerStateChanged && e.joint == 2; });
  ASSERT_NE(it, r.events.end());
  EXPECT_EQ(rig.drives->describe(*it), "joint3 (bus arm_a node 3): power state changed: 'unknown' -> 'Not ready to switch on'");
  rig.drives->held_targets(rig.targets);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NEAR(rig.targets.position_rad[j], rig.fb.joints[j].position_rad, 1e-3) << j;

  // Disable the same way: Disable Voltage until every drive confirms.
  ASSERT_TRUE(rig.drives->begin_disable());
  const PowerRun d = run_power(rig, 1000);
  EXPECT_EQ(d.last.power.phase, hw::PowerPhase::Disabled);
  std::printf("disable on the simulator: %d cycles\n", d.cycles);
  EXPECT_EQ(d.cycles, 4);  // written in cycle 1, latched at SYNC 2, read back with the TPDO of SYNC 3 in cycle 4
  for (std::size_t j = 0; j < 7; ++j) EXPECT_FALSE(rig.sim->drive(j).power_record().powered) << j;
}

// One fault reset per enable: the faulted drive gets one rising edge of
// bit 7; when it faults again before Operation enabled the enable fails
// naming it (joint, node, its EMCY code) and it stays in Fault (no second
// reset; every drive is left without power). The next enable (the next
// RECOVER) resets it once more.
TEST(DrivePower, AFaultedDriveGetsOneFaultResetPerEnableAndFaultingAgainStaysFaulted) {
  SimRig rig(project_config());
  rig.bring_up_stepped();
  rig.sim->drive(2).inject_fault(0x2310);
  ASSERT_NE(find_event(rig.run_until(has(HwFault::DriveFault), 50), HwFault::DriveFault), nullptr);
  ASSERT_EQ(rig.sim->drive(2).power_state(), PowerState::Fault);
  ASSERT_TRUE(rig.drives->begin_enable());
  bool again = false;
  const PowerRun r = run_power(rig, 1000, [&](int) {
    if (!again && rig.sim->drive(2).power_state() != PowerState::Fault) {
      rig.sim->drive(2).inject_fault(0x2310);  // the cause is still there
      again = true;
    }
  });
  ASSERT_TRUE(again);
  ASSERT_TRUE(r.last.power.finished);
  EXPECT_EQ(r.last.power.phase, hw::PowerPhase::Failed);
  const HwEvent& c = r.last.power.cause;
  EXPECT_EQ(c.fault, HwFault::FaultAfterReset);
  EXPECT_EQ(c.joint, 2);
  EXPECT_EQ(c.node, 3);
  EXPECT_EQ(c.code, 0x2310u);
  char text[96];
  rig.drives->describe_power_failure(c, text, sizeof text);
  EXPECT_STREQ(text, "joint3 (node 3): in Fault again after its fault reset, EMCY 0x2310 (statusword 0x0608)");
  EXPECT_EQ(rig.drives->describe(c),
            "joint3 (bus arm_a node 3): in Fault again after its fault reset, EMCY 0x2310 (statusword 0x0608) over-current");
  EXPECT_TRUE(hw::requires_stop(c.fault));
  // Stays faulted: no second reset, and every drive is commanded off.
  for (int i = 0; i < 100; ++i) rig.cycle();
  EXPECT_EQ(rig.sim->drive(2).power_state(), PowerState::Fault);
  for (std::size_t j = 0; j < 7; ++j) {
    EXPECT_EQ(rig.sim->drive(j).controlword(), hw::canopen::controlword::kDisableVoltage) << j;
    EXPECT_FALSE(rig.sim->drive(j).power_record().powered) << j;
  }
  // The next enable resets it once more, and it comes back.
  ASSERT_TRUE(rig.drives->begin_enable());
  const PowerRun ok = run_power(rig, 1000);
  EXPECT_EQ(ok.last.power.phase, hw::PowerPhase::Enabled);
  EXPECT_EQ(rig.sim->drive(2).power_state(), PowerState::OperationEnabled);
}

// A drive that does not answer fails the enable at the step deadline
// (power_step_timeout_ms, counted in cycles), naming it.
TEST(DrivePower, ADriveThatDoesNotAnswerFailsTheEnableAtTheStepDeadline) {
  hw::RemoteConfig c = project_config();
  c.power_step_timeout_s = 0.1;  // 50 cycles
  SimRig rig(c);
  rig.drives->configure();
  rig.go_stepped_disabled();
  rig.sim->drive(5).stop_answering(true);
  for (int i = 0; i < 3; ++i) rig.cycle();  // its last TPDOs read
  ASSERT_TRUE(rig.drives->begin_enable());
  const PowerRun r = run_power(rig, 1000);
  EXPECT_EQ(r.last.power.phase, hw::PowerPhase::Failed);
  EXPECT_EQ(r.cycles, 51);
  EXPECT_EQ(r.last.power.cause.fault, HwFault::PowerStepTimeout);
  EXPECT_EQ(r.last.power.cause.joint, 5);
  EXPECT_EQ(r.last.power.cause.code, hw::kUnknownState);
  char text[96];
  rig.drives->describe_power_failure(r.last.power.cause, text, sizeof text);
  EXPECT_STREQ(text, "joint6 (node 6): no answer for 100 ms (power_step_timeout_ms)");
  // The others were on their way: a failed enable leaves every drive off.
  for (int i = 0; i < 10; ++i) rig.cycle();
  for (std::size_t j = 0; j < 7; ++j) {
    if (j == 5) continue;
    EXPECT_FALSE(rig.sim->drive(j).power_record().powered) << j;
  }
}

// Category 0 during an enable: request_power_off() (what the controller's
// E-stop sends) puts Disable Voltage in the next RPDOs whatever the stepper
// was commanding; the drives' own record: every drive unpowered within two
// cycles, and none reaches Operation enabled after it; the enable fails
// (PowerChangeAborted).
TEST(DrivePower, APowerOffDuringAnEnableAbortsItWithinTheCategoryZeroDeadline) {
  SimRig rig(project_config());
  rig.drives->configure();
  rig.go_stepped_disabled();
  ASSERT_TRUE(rig.drives->begin_enable());
  auto powered = [&] {
    int n = 0;
    for (std::size_t j = 0; j < 7; ++j) n += rig.sim->drive(j).power_record().powered ? 1 : 0;
    return n;
  };
  int cycles = 0;
  while (powered() == 0 && cycles < 100) {
    rig.cycle();
    ++cycles;
  }
  ASSERT_EQ(powered(), 7);  // Switched on: powered, not yet Operation enabled
  for (std::size_t j = 0; j < 7; ++j) {
    ASSERT_NE(rig.sim->drive(j).power_state(), PowerState::OperationEnabled) << j;
    rig.sim->drive(j).clear_power_record();
  }
  rig.drives->request_power_off();
  int off = 0;
  CycleStatus s;
  bool aborted = false;
  while (powered() > 0 && off < 10) {
    s = rig.cycle();
    aborted = aborted || (s.power.finished && s.power.cause.fault == HwFault::PowerChangeAborted);
    ++off;
  }
  EXPECT_LE(off, 2);
  for (int i = 0; i < 20 && !aborted; ++i) {
    s = rig.cycle();
    aborted = s.power.finished && s.power.cause.fault == HwFault::PowerChangeAborted;
  }
  EXPECT_TRUE(aborted);
  EXPECT_EQ(rig.drives->power_status().phase, hw::PowerPhase::Failed);
  for (int i = 0; i < 50; ++i) rig.cycle();
  for (std::size_t j = 0; j < 7; ++j) {
    const sim::DrivePowerRecord rec = rig.sim->drive(j).power_record();
    EXPECT_FALSE(rec.powered) << j;
    EXPECT_EQ(rec.states_seen & bit(PowerState::OperationEnabled), 0u) << j;
  }
}

// A node that reboots (boot-up while operational) has lost its configuration
// (PDO mapping, mode, limits): it is marked unconfigured and no enable
// starts (nothing is sent) until it is configured again; the refusal names it.
TEST(DrivePower, ARebootedNodeIsNotEnabledUntilConfiguredAgain) {
  SimRig rig(project_config());
  rig.bring_up();
  EXPECT_EQ(rig.drives->unconfigured_nodes(), 0u);
  rig.sim->drive(3).inject_reboot();
  ASSERT_NE(find_event(rig.run_until(has(HwFault::NodeRebooted), 500), HwFault::NodeRebooted), nullptr);
  EXPECT_EQ(rig.drives->unconfigured_nodes(), 1u);
  HwEvent why;
  EXPECT_FALSE(rig.drives->begin_enable(&why));
  EXPECT_EQ(why.fault, HwFault::NodeUnconfigured);
  EXPECT_EQ(why.joint, 3);
  char text[96];
  rig.drives->describe_power_failure(why, text, sizeof text);
  EXPECT_STREQ(text, "joint4 (node 4): rebooted or left NMT operational: not configured");
  try {
    rig.drives->enable();
    FAIL() << "enable() went on with joint4 unconfigured";
  } catch (const hw::HwError& e) {
    EXPECT_EQ(std::string(e.what()),
              "enable(): joint4 (bus arm_a node 4): not configured (rebooted or left NMT operational since configure)");
  }
  rig.drives->configure();
  EXPECT_EQ(rig.drives->unconfigured_nodes(), 0u);
  rig.drives->enable();
  EXPECT_EQ(rig.sim->drive(3).power_state(), PowerState::OperationEnabled);
}

// The rebooted node configured again from its configuration file while the
// cycle goes on in another thread (as the control loop's): its SDO answers
// are handed over by the cycle (never reported as unexpected), the other
// drives stay supervised, and then the enable brings it back with its PDO
// mapping rewritten (its TPDOs read right).
TEST(DrivePower, ARebootedNodeIsConfiguredAgainWhileTheCycleGoesOn) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.sim->drive(3).inject_reboot();
  ASSERT_NE(find_event(rig.run_until(has(HwFault::NodeRebooted), 500), HwFault::NodeRebooted), nullptr);
  ASSERT_EQ(rig.drives->unconfigured_nodes(), 1u);
  std::atomic<bool> quit{false};
  std::vector<HwEvent> events;
  std::uint64_t cycles = 0;
  std::thread cycle([&] {
    while (!quit.load()) {
      const CycleStatus s = rig.cycle();
      ++cycles;
      for (std::size_t i = 0; i < s.event_count; ++i) events.push_back(s.events[i]);
    }
  });
  const auto t0 = Clock::now();
  std::size_t configured = 0;
  try {
    configured = rig.drives->configure_nodes();
  } catch (const std::exception& e) {
    ADD_FAILURE() << e.what();
  }
  const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  EXPECT_TRUE(eventually([&] { return rig.drives->unconfigured_nodes() == 0; }, 2.0));
  quit.store(true);
  cycle.join();
  EXPECT_EQ(configured, 1u);
  std::printf("joint4 configured again in %.0f ms while the cycle ran (%llu cycles)\n", ms,
              static_cast<unsigned long long>(cycles));
  EXPECT_GT(cycles, 5u);
  for (const HwEvent& e : events) {
    EXPECT_NE(e.fault, HwFault::UnexpectedSdo) << rig.drives->describe(e);
    if (!hw::requires_stop(e.fault)) continue;
    EXPECT_EQ(e.joint, 3) << rig.drives->describe(e);  // only the node configured
  }
  EXPECT_EQ(rig.sim->drive(3).nmt_state(), hw::canopen::NmtState::Operational);
  rig.drives->enable();
  EXPECT_EQ(rig.sim->drive(3).power_state(), PowerState::OperationEnabled);
  const CycleStatus s = rig.cycle();
  EXPECT_TRUE(s.ok()) << (s.event_count ? rig.drives->describe(s.events[0]) : std::string("persisting fault"));
  std::vector<double> q(7);
  rig.sim->joint_positions_rad(q);
  EXPECT_NEAR(rig.fb.joints[3].position_rad, q[3], 1e-3);
}
