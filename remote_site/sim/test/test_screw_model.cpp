// The simulated LST mechanics and screw, stepped with an explicit dt.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "foresight/common/error.hpp"
#include "foresight/hw/lst_tool_registers.hpp"
#include "foresight/sim/screw_model.hpp"

using namespace foresight;
using namespace foresight::sim;

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

LstMechanismParams params() {
  LstMechanismParams p;
  p.max_speed_rad_s = 20.0;
  p.max_torque_nm = 60.0;
  p.latch_travel_s = 0.3;
  p.stall_time_s = 0.2;
  p.screw.engaged_turns = 3.0;
  p.screw.breakaway_torque_nm = 15.0;
  p.screw.rundown_torque_nm = 2.0;
  p.screw.seated_stiffness_nm_per_rad = 40.0;
  p.screw.free_torque_nm = 0.05;
  p.screw.initial_engaged_turns = 3.0;
  return p;
}

LstCommand loosen(double speed, double limit) {
  LstCommand c;
  c.run = true;
  c.loosen = true;
  c.speed_rad_s = speed;
  c.torque_limit_nm = limit;
  return c;
}

/// Step until the tool stops by itself or t_max passes; returns the time.
double run_until_stop(LstMechanism& m, LstCommand cmd, double t_max, double dt = 1e-3) {
  double t = 0.0;
  while (t < t_max) {
    t += dt;
    if (m.step(cmd, dt)) break;
  }
  return t;
}

}  // namespace

TEST(ScrewModel, LooseningTakesNTurnsAboveBreakawayTorque) {
  LstMechanism m(params());
  const double speed = 10.0;  // rad/s
  LstCommand cmd = loosen(speed, 20.0);  // limit above T = 15
  // Halfway through: still engaged, the tool reads the breakaway torque.
  const double t_half = 1.5 * kTwoPi / speed;
  for (double t = 0.0; t < t_half - 1e-9; t += 1e-3) m.step(cmd, 1e-3);
  EXPECT_NEAR(m.state().engaged_turns, 1.5, 1e-3);
  EXPECT_NEAR(m.state().torque_nm, -15.0, 1e-12);  // loosening = counter-clockwise
  EXPECT_NEAR(m.state().speed_rad_s, -speed, 1e-9);
  EXPECT_TRUE(m.state().running);
  // Just before N = 3 turns the screw still holds; after them it is free.
  const double t_free = 3.0 * kTwoPi / speed;
  for (double t = t_half; t < t_free - 0.01; t += 1e-3) m.step(cmd, 1e-3);
  EXPECT_GT(m.state().engaged_turns, 0.0);
  EXPECT_FALSE(m.state().screw_free());
  for (int i = 0; i < 20; ++i) m.step(cmd, 1e-3);
  EXPECT_TRUE(m.state().screw_free());
  EXPECT_NEAR(m.state().torque_nm, -0.05, 1e-12);  // only the free drag now
  // The turns counter integrated the speed: -(t x speed) / 2 pi.
  EXPECT_NEAR(m.state().turns, -m.state().time_s * speed / kTwoPi, 1e-6);
  EXPECT_FALSE(m.state().torque_reached);
}

TEST(ScrewModel, BelowBreakawayTorqueItDoesNotTurn) {
  LstMechanism m(params());
  const double t = run_until_stop(m, loosen(10.0, 14.9), 2.0);
  EXPECT_LT(t, 0.01);  // stops at once
  EXPECT_TRUE(m.state().torque_reached);
  EXPECT_FALSE(m.state().running);
  EXPECT_DOUBLE_EQ(m.state().turns, 0.0);
  EXPECT_DOUBLE_EQ(m.state().engaged_turns, 3.0);
  EXPECT_NEAR(m.state().torque_nm, -14.9, 1e-12);  // the motor pushed at its limit
  EXPECT_EQ(m.state().fault_bits, 0);
}

TEST(ScrewModel, TightensToTheTargetTorque) {
  LstMechanismParams p = params();
  p.screw.initial_engaged_turns = 1.0;  // 2 turns to run down
  LstMechanism m(p);
  LstCommand cmd;
  cmd.run = true;
  cmd.speed_rad_s = 10.0;
  cmd.torque_limit_nm = 25.0;
  run_until_stop(m, cmd, 5.0);
  EXPECT_TRUE(m.state().torque_reached);
  EXPECT_FALSE(m.state().running);
  EXPECT_DOUBLE_EQ(m.state().engaged_turns, 3.0);
  EXPECT_NEAR(m.state().preload_nm, 25.0, 1e-9);
  // Turned: 2 turns of run-down + (25 - 2) / 40 rad past seating.
  EXPECT_NEAR(m.state().turns, 2.0 + (25.0 - 2.0) / 40.0 / kTwoPi, 1e-9);
  EXPECT_NEAR(m.state().torque_nm, 25.0, 1e-9);
  EXPECT_NEAR(m.state().peak_torque_nm, 25.0, 1e-9);
  // Breakaway of the preloaded screw: max(T, 0.8 x 25) = 20 N*m.
  m.step(LstCommand{}, 1e-3);  // RUN released
  LstMechanism copy = m;
  run_until_stop(copy, loosen(10.0, 19.9), 1.0);
  EXPECT_TRUE(copy.state().torque_reached);
  EXPECT_DOUBLE_EQ(copy.state().engaged_turns, 3.0);
  run_until_stop(m, loosen(10.0, 20.1), 0.05);
  EXPECT_LT(m.state().engaged_turns, 3.0);
}

TEST(ScrewModel, JamRaisesTheFaultBitAfterTheStallTime) {
  LstMechanism m(params());
  m.set_jam(true);
  const LstCommand cmd = loosen(10.0, 40.0);
  for (int i = 0; i < 190; ++i) ASSERT_FALSE(m.step(cmd, 1e-3)) << "step " << i;
  EXPECT_EQ(m.state().fault_bits, 0);
  EXPECT_DOUBLE_EQ(m.state().speed_rad_s, 0.0);
  double t = 0.19;
  while (!m.step(cmd, 1e-3) && t < 1.0) t += 1e-3;
  EXPECT_NEAR(t, 0.2, 2e-3);
  EXPECT_EQ(m.state().fault_bits, hw::lst::kFaultJam);
  EXPECT_FALSE(m.state().running);
  EXPECT_DOUBLE_EQ(m.state().turns, 0.0);
  EXPECT_DOUBLE_EQ(m.state().engaged_turns, 3.0);
  // A new run is refused while faulted; after a reset (jam cleared) it runs.
  m.step(LstCommand{}, 1e-3);
  EXPECT_TRUE(m.step(cmd, 1e-3));
  EXPECT_FALSE(m.state().running);
  m.set_jam(false);
  m.reset_fault();
  m.step(LstCommand{}, 1e-3);
  EXPECT_FALSE(m.step(cmd, 1e-3));
  EXPECT_TRUE(m.state().running);
  EXPECT_LT(m.state().turns, 0.0);
}

TEST(ScrewModel, LatchTravelsAndAStuckLatchFaults) {
  LstMechanism m(params());
  EXPECT_TRUE(m.state().unlatched);
  LstCommand cmd;
  cmd.latch = true;
  for (int i = 0; i < 150; ++i) m.step(cmd, 1e-3);
  EXPECT_FALSE(m.state().latched);
  EXPECT_FALSE(m.state().unlatched);
  for (int i = 0; i < 151; ++i) m.step(cmd, 1e-3);
  EXPECT_TRUE(m.state().latched);
  LstMechanism stuck(params());
  stuck.set_latch_stuck(true);
  for (int i = 0; i < 590; ++i) stuck.step(cmd, 1e-3);
  EXPECT_EQ(stuck.state().fault_bits, 0);
  for (int i = 0; i < 20; ++i) stuck.step(cmd, 1e-3);
  EXPECT_EQ(stuck.state().fault_bits, hw::lst::kFaultLatch);
  EXPECT_TRUE(stuck.state().unlatched);
}

TEST(ScrewModel, SocketOffTheBoltSpinsFree) {
  LstMechanism m(params());
  m.set_socket_engaged(false);
  run_until_stop(m, loosen(10.0, 1.0), 0.5);
  EXPECT_FALSE(m.state().torque_reached);
  EXPECT_DOUBLE_EQ(m.state().engaged_turns, 3.0);
  EXPECT_NEAR(m.state().turns, -0.5 * 10.0 / kTwoPi, 1e-6);
}

TEST(ScrewModel, BadParametersAreNamed) {
  LstMechanismParams p = params();
  p.screw.breakaway_torque_nm = -1.0;
  try {
    LstMechanism m(p);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "lst_sim.screw.breakaway_torque_nm must be a positive number");
  }
  p = params();
  p.screw.initial_engaged_turns = 4.0;
  EXPECT_THROW(LstMechanism{p}, std::invalid_argument);
}

TEST(ScrewModel, LoadsTheSceneSection) {
  const LstMechanismParams p = load_lst_mechanism_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  EXPECT_GT(p.screw.engaged_turns, 0.0);
  EXPECT_GT(p.screw.breakaway_torque_nm, 0.0);
  EXPECT_LE(p.screw.breakaway_torque_nm, p.max_torque_nm);
  try {
    load_lst_mechanism_params("/nonexistent/scene.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/scene.yaml: cannot open the scene file");
  }
}
