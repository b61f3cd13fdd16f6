// The tool/ORU contact model against hand-computed forces and moments, through
// the whole path: tip pose in base -> contact -> wrench in the sensor frame.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <fstream>

#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/sim/contact_model.hpp"

using namespace foresight;
using namespace foresight::sim;

namespace {

constexpr double kArm = 0.295;  // ft_sensor -> lst_tip along z (config/robot.urdf)

ContactParams params() {
  ContactParams p;
  p.socket_diameter_m = 0.028;  // hole 0.030: 1 mm radial clearance
  p.tool_length_m = 0.10;
  p.face_stiffness_n_per_m = 2.0e5;
  p.bottom_stiffness_n_per_m = 2.0e5;
  p.wall_stiffness_n_per_m2 = 5.0e6;
  p.friction_coefficient = 0.3;
  p.friction_velocity_m_s = 1.0e-3;
  p.face_rings = 4;
  p.face_ring_points = 16;
  p.shaft_stations = 50;
  p.tip_T_sensor = Pose(Eigen::Translation3d(0.0, 0.0, -kArm));
  return p;
}

struct ContactTest : ::testing::Test {
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  ContactModel model{oru, params()};

  ContactResult at(const Pose& oru_T_tip, const Twist& v = Twist{}) const {
    return model.compute(base_T_oru * oru_T_tip, base_T_oru, v);
  }
};

Pose translation(double x, double y, double z) { return Pose(Eigen::Translation3d(x, y, z)); }

double rel_err(double got, double want) { return std::abs(got - want) / std::abs(want); }

}  // namespace

TEST_F(ContactTest, PressingOnTheFaceReadsStiffnessTimesPenetration) {
  // Tool square to the face, 10 cm beside the hole, 1 mm into the face.
  const double depth = 1.0e-3;
  const ContactResult r = at(translation(0.10, 0.10, depth));
  const double expected = 2.0e5 * depth;  // 200 N, pushing the tool back along -z of the tip
  EXPECT_EQ(r.face_contacts, 64);
  EXPECT_LT(rel_err(-r.sensor.force_n.z(), expected), 0.05);
  EXPECT_NEAR(r.sensor.force_n.z(), -expected, 1e-9);  // in fact exact
  EXPECT_NEAR(r.sensor.force_n.head<2>().norm(), 0.0, 1e-9);
  EXPECT_NEAR(r.sensor.torque_nm.norm(), 0.0, 1e-9);  // the force acts along the axis through the sensor
  // In base: the hole axis is +x of base (scene.yaml), the face pushes along -x.
  EXPECT_NEAR(r.force_base_n.x(), -expected, 1e-9);
  EXPECT_NEAR(r.force_base_n.tail<2>().norm(), 0.0, 1e-9);
  EXPECT_NEAR(r.max_penetration_m, depth, 1e-15);
  // Not touching: nothing.
  EXPECT_FALSE(at(translation(0.10, 0.10, -1e-4)).in_contact());
  EXPECT_EQ(at(translation(0.10, 0.10, -1e-4)).sensor.force_n.norm(), 0.0);
}

TEST_F(ContactTest, TiltedPressHasTheRightMomentArm) {
  // Tilted by theta about the tip x axis, pressed d0 = 1 mm at the tip centre.
  // Each end-face point at tip-frame (x, y) penetrates d0 + y sin(theta). By
  // hand (disk second moment r^2/4), in the `oru` frame:
  //   F = (0, 0, -k d0)
  //   M_sensor = (kArm sin(theta) k d0 - k sin(theta) cos(theta) r^2 / 4, 0, 0)
  // and the sensor (same orientation as the tip) reads R^T F, R^T M.
  const double th = 0.05, d0 = 1.0e-3, k = 2.0e5, r = 0.014;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(th, Eigen::Vector3d::UnitX()).toRotationMatrix();
  Pose oru_T_tip = translation(0.10, 0.10, d0);
  oru_T_tip.linear() = R;
  const ContactResult res = at(oru_T_tip);
  const Eigen::Vector3d F(0.0, 0.0, -k * d0);
  const Eigen::Vector3d M(kArm * std::sin(th) * k * d0 - k * std::sin(th) * std::cos(th) * r * r / 4.0, 0.0, 0.0);
  const Eigen::Vector3d F_s = R.transpose() * F;
  const Eigen::Vector3d M_s = R.transpose() * M;
  EXPECT_EQ(res.face_contacts, 64);
  EXPECT_LT(rel_err(res.sensor.force_n.z(), F_s.z()), 0.05);
  EXPECT_LT(rel_err(res.sensor.force_n.y(), F_s.y()), 0.05);  // -k d0 sin(theta): ~10 N sideways in the sensor frame
  EXPECT_LT(rel_err(res.sensor.torque_nm.x(), M_s.x()), 0.05);
  EXPECT_NEAR(res.sensor.force_n.x(), 0.0, 1e-9);
  EXPECT_NEAR(res.sensor.torque_nm.y(), 0.0, 1e-9);
  EXPECT_NEAR(res.sensor.torque_nm.z(), 0.0, 1e-9);
  EXPECT_NEAR(M_s.x(), 2.46, 0.01);  // the number itself, N*m
  EXPECT_LT((res.sensor.force_n - F_s).norm(), 1e-9);
  EXPECT_LT((res.sensor.torque_nm - M_s).norm(), 1e-9);
}

TEST_F(ContactTest, FrictionWhileSlidingActsAtTheTipWithItsMomentArm) {
  // Pressed 1 mm, sliding at 5 cm/s along +x of the ORU face:
  // friction = mu k d v / sqrt(v^2 + vs^2) along -x, at the tip plane, so the
  // sensor reads M_y = -kArm x friction.
  const double d = 1.0e-3, v = 0.05;
  Twist tw;
  tw.v_m_s = base_T_oru.linear() * Eigen::Vector3d(v, 0.0, 0.0);
  const ContactResult r = at(translation(0.10, 0.10, d), tw);
  const double friction = 0.3 * 2.0e5 * d * v / std::sqrt(v * v + 1e-6);  // 59.99 N
  EXPECT_LT(rel_err(-r.sensor.force_n.x(), friction), 0.05);
  EXPECT_NEAR(r.sensor.force_n.x(), -friction, 1e-9);
  EXPECT_NEAR(r.sensor.force_n.z(), -2.0e5 * d, 1e-9);
  EXPECT_NEAR(r.sensor.torque_nm.y(), -kArm * friction, 1e-9);
  EXPECT_NEAR(r.sensor.torque_nm.x(), 0.0, 1e-9);
}

TEST_F(ContactTest, ToolInTheHoleWithClearanceReadsZero) {
  for (const char* tag : {"hole_entrance", "tool_inserted", "pulled_out_5cm", "approach_20cm"}) {
    const ContactResult r = at(oru.tags.at(tag));
    EXPECT_FALSE(r.in_contact()) << tag;
    EXPECT_EQ(r.sensor.force_n.norm(), 0.0) << tag;
  }
  const ContactResult inserted = at(oru.tags.at("tool_inserted"));
  EXPECT_TRUE(inserted.tip_in_hole());
  EXPECT_NEAR(inserted.insertion_depth_m, 0.06, 1e-12);
  EXPECT_NEAR(inserted.tip_radial_offset_m, 0.0, 1e-12);
  EXPECT_NEAR(inserted.tilt_rad, 0.0, 1e-7);
  EXPECT_FALSE(at(oru.tags.at("approach_20cm")).tip_in_hole());
  // Offset by half the clearance, any direction: still free.
  ASSERT_NEAR(model.clearance_m(), 1.0e-3, 1e-15);
  for (double phi = 0.0; phi < 6.28; phi += 0.5) {
    const ContactResult r = at(translation(0.5e-3 * std::cos(phi), 0.5e-3 * std::sin(phi), 0.06));
    EXPECT_EQ(r.sensor.force_n.norm(), 0.0) << phi;
  }
}

TEST_F(ContactTest, OffsetInsertionPushesBackFromTheWall) {
  // Axis offset e = clearance + 0.2 mm along +x, 6 cm deep: the wall pushes
  // back along -x with k_wall x 0.2 mm x 0.06 m = 60 N, spread evenly over the
  // inserted 6 cm, so its centroid is 3 cm behind the tip: 0.265 m from the
  // sensor. M_y = -60 N x 0.265 m.
  const double pen = 0.2e-3, depth = 0.06;
  const double e = model.clearance_m() + pen;
  const ContactResult r = at(translation(e, 0.0, depth));
  const double F = 5.0e6 * pen * depth;
  EXPECT_EQ(r.wall_contacts, 30);
  EXPECT_EQ(r.face_contacts + r.bottom_contacts, 0);
  EXPECT_LT(rel_err(-r.sensor.force_n.x(), F), 0.05);
  EXPECT_NEAR(r.sensor.force_n.x(), -F, 1e-6);
  EXPECT_NEAR(r.sensor.force_n.y(), 0.0, 1e-9);
  EXPECT_NEAR(r.sensor.force_n.z(), 0.0, 1e-9);
  EXPECT_LT(rel_err(r.sensor.torque_nm.y(), -F * (kArm - depth / 2)), 0.05);
  EXPECT_NEAR(r.sensor.torque_nm.y(), -F * (kArm - depth / 2), 1e-6);
  // Same along -y of the ORU: the force turns with the offset.
  const ContactResult ry = at(translation(0.0, -e, depth));
  EXPECT_NEAR(ry.sensor.force_n.y(), F, 1e-6);
  EXPECT_NEAR(ry.sensor.force_n.x(), 0.0, 1e-9);
}

TEST_F(ContactTest, TiltedInsertionTouchesTheRimOnTheOppositeSide) {
  // Tip on the hole axis 3 cm deep, tool tilted 0.06 rad about y: the shaft
  // leans to -x at the entrance (x = -3 cm tan 0.06 = -1.8 mm > clearance), so
  // the rim on the -x side pushes the tool towards +x, near the entrance.
  const double th = 0.06;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(th, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Pose oru_T_tip = translation(0.0, 0.0, 0.03);
  oru_T_tip.linear() = R;
  const ContactResult r = at(oru_T_tip);
  EXPECT_GT(r.wall_contacts, 0);
  EXPECT_EQ(r.face_contacts + r.bottom_contacts, 0);
  EXPECT_NEAR(r.tilt_rad, th, 1e-12);
  const Eigen::Vector3d F_oru = R * r.sensor.force_n;
  EXPECT_GT(F_oru.x(), 1.0);
  EXPECT_NEAR(F_oru.y(), 0.0, 1e-9);
  EXPECT_NEAR(F_oru.z(), 0.0, 1e-9);
  // Penetration is largest at the rim: 1.8 mm - 1 mm clearance.
  EXPECT_NEAR(r.max_penetration_m, 0.03 * std::tan(th) - 1e-3, 1.5e-4);
  // The moment arm is the sensor-to-contact distance along the tool: between
  // the rim (0.295 - 0.03/cos) and where contact ends (x = -1 mm).
  const double arm = r.sensor.torque_nm.y() / r.sensor.force_n.x();
  EXPECT_GT(arm, kArm - 0.03 / std::cos(th) - 1e-3);
  EXPECT_LT(arm, kArm - (0.03 - 1e-3 / std::tan(th)));
  // Tilted the other way: mirror image.
  Pose mirrored = translation(0.0, 0.0, 0.03);
  mirrored.linear() = R.transpose();
  EXPECT_LT((mirrored.linear() * at(mirrored).sensor.force_n).x(), -1.0);
}

TEST_F(ContactTest, HoleBottomPushesBackAlongTheAxis) {
  const double over = 0.5e-3;
  const ContactResult r = at(translation(0.0, 0.0, oru.hole_depth_m + over));
  EXPECT_EQ(r.bottom_contacts, 64);
  EXPECT_LT(rel_err(-r.sensor.force_n.z(), 2.0e5 * over), 0.05);
  EXPECT_NEAR(r.sensor.force_n.z(), -2.0e5 * over, 1e-9);
  EXPECT_NEAR(r.sensor.torque_nm.norm(), 0.0, 1e-9);
}

TEST_F(ContactTest, LandingHalfOnTheRimLoadsOnlyThePartOnTheFace) {
  // Tool axis 2 cm off the hole axis (beyond the 1.5 cm radius): every probe
  // point outside the hole touches the face; those over the hole do not.
  const ContactResult r = at(translation(0.02, 0.0, 1.0e-3));
  EXPECT_GT(r.face_contacts, 0);
  EXPECT_LT(r.face_contacts, 64);
  EXPECT_LT(r.sensor.force_n.z(), 0.0);
  EXPECT_GT(r.sensor.force_n.z(), -200.0);
  // The load sits on the +x side of the socket: (x, 0, 0) x (0, 0, -f) = (0, x f, 0), M_y > 0.
  EXPECT_GT(r.sensor.torque_nm.y(), 0.0);
  // Axis inside the hole radius (1 cm off), 1 mm down: the socket sits across
  // the rim. Only the face pushes, straight back; no sideways wall force.
  const ContactResult across = at(translation(0.01, 0.0, 1.0e-3));
  EXPECT_GT(across.face_contacts, 0);
  EXPECT_EQ(across.wall_contacts, 0);
  EXPECT_LT(across.sensor.force_n.z(), 0.0);
  EXPECT_NEAR(across.sensor.force_n.head<2>().norm(), 0.0, 1e-12);
}

TEST_F(ContactTest, WholePathFromJointAnglesThroughFk) {
  // The arm (config/robot.urdf) holds the tool tilted 0.05 rad about the tip x
  // axis, 1 mm into the ORU face beside the hole (IK), then everything is
  // taken from FK of those joint angles: tip pose -> contact model ->
  // wrench in the sensor frame, against the hand formula evaluated with the
  // FK tip and FK `ft_sensor` frames (so the config's sensor_to_tip must
  // match the URDF).
  const RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  KinematicsWorkspace ws(robot);
  const int sensor_link = robot.link_index("ft_sensor");
  ASSERT_GE(sensor_link, 0);
  const double th = 0.05, k = 2.0e5, r = 0.014;
  Pose oru_T_goal = translation(0.10, 0.10, 1.0e-3);
  oru_T_goal.linear() = Eigen::AngleAxisd(th, Eigen::Vector3d::UnitX()).toRotationMatrix();
  IkOptions opt;
  opt.position_tolerance_m = 1e-6;
  opt.rotation_tolerance_rad = 1e-6;
  const IkResult ik = inverse_kinematics(robot, ws, base_T_oru * oru_T_goal, robot.mid_configuration(), opt);
  ASSERT_TRUE(ik.success) << ik.position_error_m;
  const Pose base_T_tip = forward_kinematics(robot, ws, ik.q);
  const Pose base_T_sensor = forward_kinematics(robot, ws, ik.q, sensor_link);
  // The URDF's sensor -> tip transform is what the contact config says.
  EXPECT_LT(((base_T_sensor.inverse() * base_T_tip).matrix() - params().tip_T_sensor.inverse().matrix()).norm(), 1e-9);

  const ContactResult res = model.compute(base_T_tip, base_T_oru);
  const Pose oru_T_tip = base_T_oru.inverse() * base_T_tip;
  const Pose oru_T_sensor = base_T_oru.inverse() * base_T_sensor;
  const double d0 = oru_T_tip.translation().z();  // FK penetration at the tip centre
  const Eigen::Vector3d F(0.0, 0.0, -k * d0);
  const Eigen::Vector3d M = (oru_T_tip.translation() - oru_T_sensor.translation()).cross(F) +
                            Eigen::Vector3d(-k * std::sin(th) * std::cos(th) * r * r / 4.0, 0.0, 0.0);
  const Eigen::Vector3d F_s = oru_T_sensor.linear().transpose() * F;
  const Eigen::Vector3d M_s = oru_T_sensor.linear().transpose() * M;
  EXPECT_EQ(res.face_contacts, 64);
  EXPECT_NEAR(d0, 1.0e-3, 1e-5);
  EXPECT_LT(rel_err(res.sensor.force_n.z(), F_s.z()), 0.05);
  EXPECT_LT(rel_err(res.sensor.force_n.y(), F_s.y()), 0.05);
  EXPECT_LT(rel_err(res.sensor.torque_nm.x(), M_s.x()), 0.05);
  EXPECT_LT((res.sensor.force_n - F_s).norm(), 1e-3);
  EXPECT_LT((res.sensor.torque_nm - M_s).norm(), 1e-3);
}

TEST(ContactModel, LoadsTheSceneSection) {
  const ContactParams p = load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  EXPECT_GT(p.face_stiffness_n_per_m, 0.0);
  EXPECT_NEAR(p.tip_T_sensor.translation().z(), -0.295, 1e-12);  // from the URDF
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  EXPECT_NO_THROW(ContactModel(oru, p));
}

TEST(ContactModel, BadInputsAreNamed) {
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  ContactParams p = params();
  p.socket_diameter_m = 0.032;
  try {
    ContactModel m(oru, p);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "contact.socket_diameter_m (0.032000) must be smaller than the hole diameter (0.030000)");
  }
  p = params();
  p.wall_stiffness_n_per_m2 = 0.0;
  try {
    ContactModel m(oru, p);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "contact.wall_stiffness_n_per_m2 must be a positive number");
  }
  char name[] = "/tmp/foresight_contact_XXXXXX";
  const int fd = mkstemp(name);
  ASSERT_GE(fd, 0);
  close(fd);
  std::ofstream(name) << "contact:\n  face_stiffness_n_per_m: 1.0e5\n  wall_stifness: 3\n";
  try {
    load_contact_params(name);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), std::string(name) + ":3: contact.wall_stifness: unknown key");
  }
  std::ofstream(name) << "contact:\n  face_stiffness_n_per_m: -5\n";
  try {
    load_contact_params(name);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), std::string(name) + ":2: contact.face_stiffness_n_per_m must be a positive number");
  }
  std::ofstream(name) << "contact:\n  sensor_to_tip_m: [0, 0]\n";
  try {
    load_contact_params(name);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), std::string(name) + ":2: contact.sensor_to_tip_m: expected a list of 3 numbers");
  }
  unlink(name);
}
