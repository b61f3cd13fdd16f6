// The whole simulated sensing path: simulated CiA 402 drives hold the arm in
// a pose that presses the LST 1 mm into the ORU face (tilted); at every SYNC
// the F/T sensor node asks the contact model for the wrench at FK(simulated
// joint angles); the frames cross the mock CAN bus and the real master
// (hw::DriveSystem) decodes them. The reading must be the hand-computed
// contact force within 5% (the physics check).
#include <cmath>
#include <memory>
#include <mutex>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/sim/contact_model.hpp"
#include "sim_fixture.hpp"

using namespace foresight;
using namespace foresight::test;

namespace {

struct Plant {
  RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  sim::ContactModel contact{oru, sim::load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml")};
};

double rel_err(double got, double want) { return std::abs(got - want) / std::abs(want); }

}  // namespace

TEST(ContactThroughFtSensor, PressingTheFaceReadsTheModelForceOverCan) {
  auto plant = std::make_shared<Plant>();
  const hw::RemoteConfig config = project_config();
  ASSERT_EQ(config.drives.size(), static_cast<std::size_t>(plant->robot.dof()));
  for (std::size_t j = 0; j < config.drives.size(); ++j)
    ASSERT_EQ(config.drives[j].joint, plant->robot.joint_names()[j]);  // drive order = chain order

  // Joint angles that press the tool, tilted 0.05 rad about its x axis, 1 mm
  // into the face 10 cm beside the hole.
  const double th = 0.05;
  Pose oru_T_goal(Eigen::Translation3d(0.10, 0.10, 1.0e-3));
  oru_T_goal.linear() = Eigen::AngleAxisd(th, Eigen::Vector3d::UnitX()).toRotationMatrix();
  KinematicsWorkspace ws(plant->robot);
  IkOptions opt;
  opt.position_tolerance_m = 1e-6;
  opt.rotation_tolerance_rad = 1e-6;
  const IkResult ik =
      inverse_kinematics(plant->robot, ws, plant->base_T_oru * oru_T_goal, plant->robot.mid_configuration(), opt);
  ASSERT_TRUE(ik.success);

  // The plant: the F/T node's wrench source runs on the simulator thread.
  auto sim_ws = std::make_shared<KinematicsWorkspace>(plant->robot);
  auto q_sim = std::make_shared<std::vector<double>>(config.drives.size());
  SimRig rig(config, hw::joint_limits_by_name(plant->robot), [&](sim::CanSimulator& s) {
    for (std::size_t j = 0; j < config.drives.size(); ++j) {
      std::int32_t counts = 0;
      ASSERT_TRUE(config.drives[j].to_counts(ik.q[static_cast<Eigen::Index>(j)], counts));
      s.drive(j).set_position_counts(counts);
    }
    sim::CanSimulator* simulator = &s;
    s.ft_sensor()->set_wrench_source([plant, sim_ws, q_sim, simulator]() {
      simulator->joint_positions_rad(*q_sim);
      const Eigen::Map<const Eigen::VectorXd> q(q_sim->data(), static_cast<Eigen::Index>(q_sim->size()));
      const Pose base_T_tip = forward_kinematics(plant->robot, *sim_ws, q);
      const sim::ContactResult r = plant->contact.compute(base_T_tip, plant->base_T_oru);
      const Eigen::Vector3d& f = r.sensor.force_n;
      const Eigen::Vector3d& m = r.sensor.torque_nm;
      return sim::SimFtSensor::Wrench{f.x(), f.y(), f.z(), m.x(), m.y(), m.z()};
    });
  });
  // Hold the arm where it powered on (SimRig::bring_up starts from the
  // targets enable() holds, i.e. the actual positions).
  rig.bring_up();
  ASSERT_EQ(rig.fb.count, config.drives.size());
  rig.deadline = Clock::now();
  int fresh = 0;
  for (int i = 0; i < 500 && fresh < 10; ++i) {
    const CycleStatus s = rig.cycle();
    ASSERT_TRUE(s.ok()) << rig.drives->describe(s.events[0]);
    if (rig.ft.fresh) ++fresh;
  }
  ASSERT_GE(fresh, 10);

  // Hand computation from the simulated joint angles (FK of the tip and of
  // the URDF's ft_sensor link): every end-face point penetrates, so
  // F = (0, 0, -k d0) in `oru` with d0 the tip-centre depth, and the moment
  // about the sensor is (tip - sensor) x F plus the tilt term
  // -k sin(th) cos(th) r^2 / 4 about the tip x axis.
  std::vector<double> q_now(config.drives.size());
  rig.sim->joint_positions_rad(q_now);
  const Eigen::Map<const Eigen::VectorXd> q(q_now.data(), static_cast<Eigen::Index>(q_now.size()));
  const Pose oru_T_tip = plant->base_T_oru.inverse() * forward_kinematics(plant->robot, ws, q);
  const Pose oru_T_sensor =
      plant->base_T_oru.inverse() * forward_kinematics(plant->robot, ws, q, plant->robot.link_index("ft_sensor"));
  const double k = 2.0e5, r = 0.014;  // config/scene.yaml contact
  const double d0 = oru_T_tip.translation().z();
  ASSERT_NEAR(d0, 1.0e-3, 2e-5);
  const Eigen::Vector3d F(0.0, 0.0, -k * d0);
  const Eigen::Vector3d M = (oru_T_tip.translation() - oru_T_sensor.translation()).cross(F) +
                            Eigen::Vector3d(-k * std::sin(th) * std::cos(th) * r * r / 4.0, 0.0, 0.0);
  const Eigen::Vector3d F_s = oru_T_sensor.linear().transpose() * F;
  const Eigen::Vector3d M_s = oru_T_sensor.linear().transpose() * M;
  const auto& w = rig.ft.wrench_ft;
  EXPECT_LT(rel_err(w[2], F_s.z()), 0.05) << w[2] << " vs " << F_s.z();
  EXPECT_LT(rel_err(w[1], F_s.y()), 0.05) << w[1] << " vs " << F_s.y();
  EXPECT_LT(rel_err(w[3], M_s.x()), 0.05) << w[3] << " vs " << M_s.x();
  // Quantisation of the CAN frames (the configured counts per N and per N*m)
  // is the only difference left: within 1.1 counts.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(w[i], F_s[i], 1.1 / config.ft.force_counts_per_n) << "force " << i;
    EXPECT_NEAR(w[3 + i], M_s[i], 1.1 / config.ft.torque_counts_per_nm) << "torque " << i;
  }
  EXPECT_EQ(rig.ft.saturated_mask, 0);
  RecordProperty("force_z_n", std::to_string(w[2]));
  RecordProperty("expected_force_z_n", std::to_string(F_s.z()));
  RecordProperty("torque_x_nm", std::to_string(w[3]));
  RecordProperty("expected_torque_x_nm", std::to_string(M_s.x()));
}
