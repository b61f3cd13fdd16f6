// sim::Plant: the simulated arm, tool and ORU as one physical plant.
//  - through the real CAN path (simulated drives + F/T node, the master
//    decoding) the reading is contact + tool weight + bias, each computed
//    independently here, within the F/T quantization;
//  - the tool weight turns with the wrist in the sensor frame;
//  - the ORU state machine: fastened -> carried -> seated -> fastened, only
//    in the right order; the carried ORU follows the tool; its slot is a
//    contact like the tool's hole.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <atomic>
#include <functional>
#include <thread>
#include <cmath>
#include <fstream>
#include <sstream>
#include <memory>
#include <numbers>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/hw/lst_tool.hpp"
#include "foresight/sim/contact_model.hpp"
#include "foresight/sim/lst_server.hpp"
#include "foresight/sim/plant.hpp"
#include "sim_fixture.hpp"

using namespace foresight;
using namespace foresight::test;
using sim::OruState;

namespace {

struct World {
  RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  sim::PlantParams params = sim::load_plant_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  KinematicsWorkspace ws{robot};
  Eigen::VectorXd seed = robot.mid_configuration();

  /// Joint angles putting the tip at base_T_oru_ref * oru_T_tip (IK, 1 um).
  Eigen::VectorXd q_at(const Pose& oru_T_tip, const Pose* base_T_ref = nullptr) {
    IkOptions opt;
    opt.position_tolerance_m = 1e-7;
    opt.rotation_tolerance_rad = 1e-7;
    const Pose target = (base_T_ref ? *base_T_ref : base_T_oru) * oru_T_tip;
    const IkResult ik = inverse_kinematics(robot, ws, target, seed, opt);
    EXPECT_TRUE(ik.success);
    seed = ik.q;
    return ik.q;
  }
  Pose tip(const Eigen::VectorXd& q) { return forward_kinematics(robot, ws, q); }
};

Pose along_axis(double z) { return Pose(Eigen::Translation3d(0.0, 0.0, z)); }

sim::PlantStep step(sim::Plant& p, const Eigen::VectorXd& q, const sim::LstToolState& t) {
  const std::vector<double> qv(q.data(), q.data() + q.size());
  const std::vector<double> qd(qv.size(), 0.0);
  return p.step(qv, qd, t);
}

sim::LstToolState tool(bool latched, double engaged_turns) {
  sim::LstToolState t;
  t.latched = latched;
  t.unlatched = !latched;
  t.latch_position = latched ? 1.0 : 0.0;
  t.engaged_turns = engaged_turns;
  return t;
}

/// The tool's weight in the sensor frame, from the URDF by hand: the `lst`
/// link (2.6 kg at (0.015, 0, 0.09) in its frame; lst_tip has no mass).
sim::Wrench tool_weight(World& w, const Eigen::VectorXd& q) {
  const Pose base_T_s = forward_kinematics(w.robot, w.ws, q, w.robot.link_index("ft_sensor"));
  const Pose base_T_lst = forward_kinematics(w.robot, w.ws, q, w.robot.link_index("lst"));
  const Eigen::Vector3d com_base = base_T_lst * Eigen::Vector3d(0.015, 0.0, 0.09);
  const Eigen::Vector3d F_base(0.0, 0.0, -9.81 * 2.6);
  sim::Wrench out;
  out.force_n = base_T_s.linear().transpose() * F_base;
  out.torque_nm = (base_T_s.inverse() * com_base).cross(out.force_n);
  return out;
}

}  // namespace

TEST(Plant, LoadsTheSceneAndTheToolFromTheUrdf) {
  World w;
  EXPECT_DOUBLE_EQ(w.params.slot.radial_clearance_m, 0.001);
  EXPECT_DOUBLE_EQ(w.params.slot.depth_m, 0.10);
  EXPECT_DOUBLE_EQ(w.params.oru_mass_kg, 5.0);
  EXPECT_DOUBLE_EQ(w.params.screw_engaged_turns, 8.0);
  EXPECT_DOUBLE_EQ(w.params.sensor_bias[2], 2.5);
  sim::Plant plant(w.robot, w.oru, w.base_T_oru, w.params);
  EXPECT_NEAR(plant.tool_mass_kg(), 2.6, 1e-12);
  // lst sits 0.035 m above the sensor frame origin (URDF ft_sensor -> lst).
  const Pose s_T_lst = forward_kinematics(w.robot, w.ws, w.seed, w.robot.link_index("ft_sensor")).inverse() *
                       forward_kinematics(w.robot, w.ws, w.seed, w.robot.link_index("lst"));
  EXPECT_LT((plant.tool_com_sensor_m() - s_T_lst * Eigen::Vector3d(0.015, 0.0, 0.09)).norm(), 1e-9);
  // The scene's sensor_to_tip agrees with the URDF.
  EXPECT_LT((plant.sensor_T_tip().translation() - Eigen::Vector3d(0, 0, 0.295)).norm(), 1e-9);
  EXPECT_NEAR(plant.slot_contact_model().clearance_m(), 0.001, 1e-12);
  EXPECT_EQ(plant.oru_state(), OruState::Fastened);
}

TEST(Plant, BadParametersAreRefusedByName) {
  World w;
  sim::PlantParams p = w.params;
  p.slot.radial_clearance_m = 0.0;
  EXPECT_THROW(
      {
        try {
          sim::Plant plant(w.robot, w.oru, w.base_T_oru, p);
        } catch (const std::invalid_argument& e) {
          EXPECT_STREQ(e.what(), "slot.radial_clearance_m must be a positive number");
          throw;
        }
      },
      std::invalid_argument);
  p = w.params;
  p.grasp_depth_m = -0.01;
  EXPECT_THROW(sim::validate(p), std::invalid_argument);
}

TEST(Plant, ToolWeightTurnsWithTheWristInTheSensorFrame) {
  World w;
  w.params.sensor_bias = {};
  sim::Plant plant(w.robot, w.oru, w.base_T_oru, w.params);
  // Tip 20 cm in front of the hole (no contact), then the last joint turned.
  Eigen::VectorXd q = w.q_at(along_axis(-0.20));
  const double m = 2.6, g = 9.81;
  double fx_min = 1e9, fx_max = -1e9;
  for (int k = 0; k < 8; ++k) {
    Eigen::VectorXd qk = q;
    qk[6] = q[6] + (k - 4) * 0.35;
    const sim::PlantStep r = step(plant, qk, tool(false, 8.0));
    ASSERT_FALSE(r.tool_contact.in_contact());
    const sim::Wrench want = tool_weight(w, qk);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(r.wrench_ft[static_cast<std::size_t>(i)], want.force_n[i], 1e-9) << "k " << k << " F" << i;
      EXPECT_NEAR(r.wrench_ft[static_cast<std::size_t>(3 + i)], want.torque_nm[i], 1e-9) << "k " << k << " T" << i;
    }
    const Eigen::Vector3d F(r.wrench_ft[0], r.wrench_ft[1], r.wrench_ft[2]);
    EXPECT_NEAR(F.norm(), m * g, 1e-9);
    fx_min = std::min(fx_min, F.x());
    fx_max = std::max(fx_max, F.x());
  }
  // The tool axis is horizontal here: turning the wrist swings the weight
  // between the sensor's x and y axes.
  EXPECT_GT(fx_max - fx_min, 0.5 * m * g);
}

TEST(Plant, WrenchThroughTheCanPathIsContactPlusWeightPlusBias) {
  auto w = std::make_shared<World>();
  const hw::RemoteConfig config = project_config();
  // Pressing 1 mm into the ORU face 10 cm beside the hole, tilted 0.05 rad.
  Pose oru_T_goal(Eigen::Translation3d(0.10, 0.10, 1.0e-3));
  oru_T_goal.linear() = Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::VectorXd q_goal = w->q_at(oru_T_goal);
  auto plant = std::make_shared<sim::Plant>(w->robot, w->oru, w->base_T_oru, w->params);
  SimRig rig(config, hw::joint_limits_by_name(w->robot), [&](sim::CanSimulator& s) {
    for (std::size_t j = 0; j < config.drives.size(); ++j) {
      std::int32_t counts = 0;
      ASSERT_TRUE(config.drives[j].to_counts(q_goal[static_cast<Eigen::Index>(j)], counts));
      s.drive(j).set_position_counts(counts);
    }
    plant->attach(s);
  });
  rig.bring_up();
  int fresh = 0;
  for (int i = 0; i < 500 && fresh < 10; ++i) {
    const CycleStatus s = rig.cycle();
    ASSERT_TRUE(s.ok()) << rig.drives->describe(s.events[0]);
    if (rig.ft.fresh) ++fresh;
  }
  ASSERT_GE(fresh, 10);
  EXPECT_GT(plant->truth().steps, 10u);

  std::vector<double> q_now(config.drives.size());
  rig.sim->joint_positions_rad(q_now);
  const Eigen::Map<const Eigen::VectorXd> q(q_now.data(), static_cast<Eigen::Index>(q_now.size()));
  const sim::ContactModel contact(w->oru, sim::load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  const sim::ContactResult c = contact.compute(w->tip(q), w->base_T_oru);
  ASSERT_GT(c.face_contacts, 0);
  const sim::Wrench weight = tool_weight(*w, q);
  const auto& bias = w->params.sensor_bias;
  const auto& got = rig.ft.wrench_ft;
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    // Within the F/T quantization (1.1 counts of the configured scales).
    EXPECT_NEAR(got[k], c.sensor.force_n[i] + weight.force_n[i] + bias[k], 1.1 / config.ft.force_counts_per_n)
        << "force " << i;
    EXPECT_NEAR(got[k + 3], c.sensor.torque_nm[i] + weight.torque_nm[i] + bias[k + 3],
                1.1 / config.ft.torque_counts_per_nm)
        << "torque " << i;
  }
  EXPECT_LT(got[2], -150.0);  // ~200 N pressing: the contact dominates
  EXPECT_EQ(rig.ft.saturated_mask, 0);
  plant->detach();
}

TEST(Plant, OruStateMachineInTheRightOrderOnly) {
  World w;
  w.params.sensor_bias = {};
  sim::Plant plant(w.robot, w.oru, w.base_T_oru, w.params);
  const Eigen::VectorXd q_front = w.q_at(along_axis(-0.20));
  const Eigen::VectorXd q_in = w.q_at(along_axis(0.06));  // the tool_inserted tag

  // A latch closed outside the hole grips nothing.
  EXPECT_EQ(step(plant, q_front, tool(true, 8.0)).state, OruState::Fastened);
  EXPECT_FALSE(plant.truth().gripped);
  sim::PlantStep r = step(plant, q_in, tool(true, 8.0));
  EXPECT_TRUE(r.socket_engaged);
  EXPECT_FALSE(plant.truth().gripped);
  r = step(plant, q_in, tool(true, 0.0));  // loosened, but not gripped
  EXPECT_EQ(r.state, OruState::Fastened);
  step(plant, q_in, tool(false, 8.0));  // open the latch

  // Latched in the hole while the screw is fastened: gripped, not carried;
  // pulling back 1 mm meets the latch (k = 1e5 N/m: 100 N into the ORU).
  r = step(plant, q_in, tool(true, 8.0));
  EXPECT_EQ(r.state, OruState::Fastened);
  EXPECT_TRUE(plant.truth().gripped);
  r = step(plant, w.q_at(along_axis(0.059)), tool(true, 3.0));  // partly loosened
  EXPECT_EQ(r.state, OruState::Fastened);
  const Eigen::Vector3d f_base =
      plant.truth().base_T_tip.linear() * plant.sensor_T_tip().linear().transpose() * r.contact_ft.force_n;
  EXPECT_NEAR(f_base.dot(w.base_T_oru.linear().col(2)), 100.0, 1.0);
  EXPECT_LT((plant.truth().base_T_oru.translation() - w.base_T_oru.translation()).norm(), 1e-12);

  // Screw free and gripped: loose in the slot (seated), held by the tool;
  // pulled out it is carried. No contact with the tool any more; the ORU's
  // weight joins the tool's.
  r = step(plant, q_in, tool(true, 0.0));
  EXPECT_EQ(r.state, OruState::Seated);
  EXPECT_TRUE(r.socket_engaged);
  r = step(plant, w.q_at(along_axis(0.055)), tool(true, 0.0));  // 5 mm: still seated
  EXPECT_EQ(r.state, OruState::Seated);
  const Eigen::VectorXd q_out = w.q_at(along_axis(-0.09));  // 15 cm back: clear of the slot
  r = step(plant, q_out, tool(true, 0.0));
  EXPECT_EQ(r.state, OruState::Carried);
  EXPECT_FALSE(r.socket_engaged);  // the loose screw spins with the socket
  EXPECT_EQ(step(plant, q_out, tool(true, 2.0)).state, OruState::Carried);  // carried: the screw fastens nothing
  const sim::PlantTruth t = plant.truth();
  const Pose home_T_now = w.base_T_oru.inverse() * t.base_T_oru;
  EXPECT_NEAR(home_T_now.translation().z(), -0.15, 1e-6);
  EXPECT_NEAR(home_T_now.translation().head<2>().norm(), 0.0, 1e-6);
  EXPECT_NEAR(t.alignment_error_m, 0.15, 1e-6);
  EXPECT_FALSE(r.slot_contact.in_contact());
  const Eigen::Vector3d F(r.wrench_ft[0], r.wrench_ft[1], r.wrench_ft[2]);
  EXPECT_NEAR(F.norm(), (2.6 + 5.0) * 9.81, 1e-6);
  EXPECT_NEAR(r.weight_ft.force_n.norm(), (2.6 + 5.0) * 9.81, 1e-6);

  // Back into the slot: seated at depth, not fastened until the screw seats;
  // a partly run-down screw holds the ORU where it is.
  r = step(plant, q_in, tool(true, 0.0));
  EXPECT_EQ(r.state, OruState::Seated);
  EXPECT_TRUE(r.socket_engaged);
  EXPECT_NEAR(plant.truth().oru_slot_depth_m, 0.10, 1e-6);
  r = step(plant, q_in, tool(true, 4.0));
  EXPECT_EQ(r.state, OruState::Seated);
  r = step(plant, q_in, tool(true, 8.0));
  EXPECT_EQ(r.state, OruState::Fastened);
  EXPECT_LT(plant.truth().alignment_error_m, 1e-6);
  EXPECT_LT(plant.truth().alignment_error_rad, 1e-6);

  // Unlatch releases: the tool leaves, the ORU stays fastened.
  step(plant, q_in, tool(false, 8.0));
  r = step(plant, q_front, tool(false, 8.0));
  EXPECT_EQ(r.state, OruState::Fastened);
  EXPECT_FALSE(plant.truth().gripped);
  EXPECT_LT(plant.truth().alignment_error_m, 1e-6);
}

TEST(Plant, UnlatchingACarriedOruDropsIt) {
  World w;
  sim::Plant plant(w.robot, w.oru, w.base_T_oru, w.params);
  const Eigen::VectorXd q_in = w.q_at(along_axis(0.06));
  step(plant, q_in, tool(true, 8.0));
  EXPECT_EQ(step(plant, q_in, tool(true, 0.0)).state, OruState::Seated);
  EXPECT_EQ(step(plant, w.q_at(along_axis(-0.09)), tool(true, 0.0)).state, OruState::Carried);
  EXPECT_EQ(step(plant, w.q_at(along_axis(-0.09)), tool(false, 0.0)).state, OruState::Dropped);
  const Pose where = plant.truth().base_T_oru;
  EXPECT_EQ(step(plant, w.q_at(along_axis(0.06)), tool(true, 0.0)).state, OruState::Dropped);
  EXPECT_LT((plant.truth().base_T_oru.translation() - where.translation()).norm(), 1e-12);
  plant.reset();
  step(plant, q_in, tool(false, 8.0));
  EXPECT_EQ(plant.oru_state(), OruState::Fastened);
  EXPECT_LT(plant.truth().alignment_error_m, 1e-12);
}

TEST(Plant, CarriedOruFollowsTheToolAndItsSlotIsAContact) {
  World w;
  w.params.sensor_bias = {};
  sim::Plant plant(w.robot, w.oru, w.base_T_oru, w.params);
  const Eigen::VectorXd q_in = w.q_at(along_axis(0.06));
  step(plant, q_in, tool(true, 8.0));
  ASSERT_EQ(step(plant, q_in, tool(true, 0.0)).state, OruState::Seated);
  const Pose tip_T_oru = w.tip(q_in).inverse() * w.base_T_oru;

  // Rotations and translations of the tool well clear of the slot: the
  // relative pose stays frozen.
  for (int k = 0; k < 5; ++k) {
    Pose goal = along_axis(-0.15 - 0.02 * k);
    goal.linear() = (Eigen::AngleAxisd(0.1 * k, Eigen::Vector3d::UnitZ()) *
                     Eigen::AngleAxisd(0.03 * k, Eigen::Vector3d::UnitX()))
                        .toRotationMatrix();
    const Eigen::VectorXd q = w.q_at(goal);
    const sim::PlantStep r = step(plant, q, tool(true, 0.0));
    ASSERT_EQ(r.state, OruState::Carried);
    const Pose want = w.tip(q) * tip_T_oru;
    const sim::PlantTruth t = plant.truth();
    EXPECT_LT((t.base_T_oru.translation() - want.translation()).norm(), 1e-9) << k;
    EXPECT_LT((t.base_T_oru.linear() - want.linear()).norm(), 1e-9) << k;
    EXPECT_FALSE(r.tool_contact.in_contact() && r.contact_ft.force_n.norm() > 0.0);  // internal while carried
  }

  // 5 cm into the slot, 2 mm off its axis (1 mm clearance): the bore wall
  // pushes back over the ~5 cm in the bore, 5e6 N/m^2 x 1 mm x 0.05 m ~ 250 N.
  const Eigen::Vector3d off = w.base_T_oru.linear().col(0);  // oru x in base
  Pose base_T_ref = w.base_T_oru;
  base_T_ref.translation() += 0.002 * off;
  const sim::PlantStep r = step(plant, w.q_at(along_axis(0.01), &base_T_ref), tool(true, 0.0));
  ASSERT_EQ(r.state, OruState::Carried);
  EXPECT_NEAR(plant.truth().oru_slot_depth_m, 0.05, 1e-6);
  ASSERT_GT(r.slot_contact.wall_contacts, 0);
  const Eigen::Vector3d f = r.slot_contact.force_base_n;
  EXPECT_NEAR(f.dot(off), -250.0, 25.0);
  EXPECT_LT((f - f.dot(off) * off).norm(), 1.0);
  // The same force reaches the sensor (slot_ft is in the sensor frame).
  const Pose base_T_s = w.tip(w.seed) * plant.params().contact.tip_T_sensor;
  EXPECT_LT((base_T_s.linear() * r.slot_ft.force_n - f).norm(), 1e-6);
}

// The whole simulated site: drives holding the tool 6 cm deep in the hole,
// the plant as the F/T node's wrench source, the LST over Modbus TCP. The
// real LST client latches and loosens; the plant engages the socket on the
// bolt (the screw model turns it loose) and the ORU comes free, following
// the tool.
TEST(Plant, LatchAndLoosenThroughTheLstFreeTheOru) {
  auto w = std::make_shared<World>();
  const hw::RemoteConfig config = project_config();
  const Eigen::VectorXd q_in = w->q_at(along_axis(0.06));
  auto plant = std::make_shared<sim::Plant>(w->robot, w->oru, w->base_T_oru, w->params);
  sim::LstServerOptions lo;
  lo.mechanism = sim::load_lst_mechanism_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  sim::LstServer server(lo);
  SimRig rig(config, hw::joint_limits_by_name(w->robot), [&](sim::CanSimulator& s) {
    for (std::size_t j = 0; j < config.drives.size(); ++j) {
      std::int32_t counts = 0;
      ASSERT_TRUE(config.drives[j].to_counts(q_in[static_cast<Eigen::Index>(j)], counts));
      s.drive(j).set_position_counts(counts);
    }
    plant->attach(s, &server);
  });
  rig.bring_up();
  // The master cycles on its own thread while this one talks to the tool.
  std::atomic<bool> run{true};
  // No stop-requiring event (a notice, e.g. an F/T frame pair split by a
  // descheduled simulator on a loaded machine, is not a failure: it failed
  // once in a full ctest -j2 run here); the first one is named.
  std::atomic<bool> cycles_ok{true};
  std::string first_stop;  // written by the cycler before cycles_ok goes false, read after join
  std::thread cycler([&] {
    while (run) {
      const CycleStatus s = rig.cycle();
      if (s.stop_required && cycles_ok) {
        for (std::size_t i = 0; i < s.event_count && first_stop.empty(); ++i)
          if (hw::requires_stop(s.events[i].fault)) first_stop = rig.drives->describe(s.events[i]);
        if (first_stop.empty()) first_stop = rig.drives->describe(s.first_active);
        cycles_ok = false;
      }
    }
  });
  auto wait_for = [&](const std::function<bool(const sim::PlantTruth&)>& pred, double timeout_s) {
    const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
    while (Clock::now() < deadline) {
      if (pred(plant->truth())) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return pred(plant->truth());
  };
  EXPECT_TRUE(wait_for([](const sim::PlantTruth& t) { return t.steps > 5 && t.socket_engaged; }, 5.0));

  hw::LstToolConfig tc;
  tc.port = server.port();
  tc.response_timeout_s = 1.0;
  hw::LstTool lst(tc);
  ASSERT_FALSE(lst.latch()) << lst.last_error_message();
  hw::LstStatus st;
  ASSERT_FALSE(lst.wait_for([](const hw::LstStatus& s) { return s.latched(); }, 5.0, st)) << lst.last_error_message();
  EXPECT_TRUE(wait_for([](const sim::PlantTruth& t) { return t.gripped; }, 5.0));
  EXPECT_EQ(plant->oru_state(), OruState::Fastened);

  hw::LstTool::RunResult rr;
  ASSERT_FALSE(lst.loosen(8.5, 40.0, 20.0, 10.0, rr)) << lst.last_error_message();
  EXPECT_TRUE(server.state().screw_free());
  EXPECT_TRUE(wait_for([](const sim::PlantTruth& t) { return t.state == OruState::Seated; }, 5.0));
  run = false;
  cycler.join();
  EXPECT_TRUE(cycles_ok) << first_stop;
  EXPECT_TRUE(plant->truth().gripped);
  plant->detach();
}

TEST(Plant, AStuckOruStaysFastenedAndThePullMeetsTheLatch) {
  World w;
  sim::Plant plant(w.robot, w.oru, w.base_T_oru, w.params);
  plant.set_oru_stuck(true);
  const Eigen::VectorXd q_in = w.q_at(along_axis(0.06));
  step(plant, q_in, tool(true, 8.0));
  EXPECT_EQ(step(plant, q_in, tool(true, 0.0)).state, OruState::Fastened);
  // 2 mm of pull: 200 N from the latch into the ORU.
  const sim::PlantStep r = step(plant, w.q_at(along_axis(0.058)), tool(true, 0.0));
  EXPECT_EQ(r.state, OruState::Fastened);
  const Eigen::Vector3d f_base =
      plant.truth().base_T_tip.linear() * plant.sensor_T_tip().linear().transpose() * r.contact_ft.force_n;
  EXPECT_NEAR(f_base.dot(w.base_T_oru.linear().col(2)), 200.0, 2.0);
  plant.set_oru_stuck(false);
  EXPECT_EQ(step(plant, q_in, tool(true, 0.0)).state, OruState::Seated);
}

namespace {

/// config/scene.yaml with `from` replaced by `to`, written to a scratch file.
std::string scene_with(const std::string& from, const std::string& to) {
  std::ifstream in(FORESIGHT_CONFIG_DIR "/scene.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  const std::string path = ::testing::TempDir() + "plant_scene_" +
                           ::testing::UnitTest::GetInstance()->current_test_info()->name() + ".yaml";
  std::ofstream(path) << text;
  return path;
}

int line_of(const std::string& path, const std::string& needle) {
  std::ifstream in(path);
  std::string line;
  for (int n = 1; std::getline(in, line); ++n)
    if (line.find(needle) != std::string::npos) return n;
  return 0;
}

}  // namespace

TEST(Plant, BadSceneSectionsNameFileLineAndKey) {
  {
    const std::string path = scene_with("  radial_clearance_m: 0.001", "  radial_clearance: 0.001");
    try {
      sim::load_plant_params(path);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), path + ":" + std::to_string(line_of(path, "radial_clearance:")) +
                                           ": slot.radial_clearance: unknown key");
    }
  }
  {
    const std::string path = scene_with("  oru_mass_kg: 5.0", "  oru_mass_kg: heavy");
    try {
      sim::load_plant_params(path);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()),
                path + ":" + std::to_string(line_of(path, "oru_mass_kg:")) + ": plant.oru_mass_kg: not a number: 'heavy'");
    }
  }
  {
    const std::string path = scene_with("  depth_m: 0.10 ", "  depth_m: -0.10 ");
    try {
      sim::load_plant_params(path);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()),
                path + ":" + std::to_string(line_of(path, "depth_m: -0.10")) + ": slot.depth_m must be a positive number");
    }
  }
  {
    const std::string path = scene_with("  sensor_bias: [1.2, -0.8, 2.5, 0.04, -0.03, 0.02]", "  sensor_bias: [1, 2]");
    try {
      sim::load_plant_params(path);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), path + ":" + std::to_string(line_of(path, "sensor_bias:")) +
                                           ": 'plant.sensor_bias' must be a list of 6 numbers");
    }
  }
}
