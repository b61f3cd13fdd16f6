// RobotModel: loading config/robot.urdf, and every bad input with its exact
// message (file, line, element).

#include <gtest/gtest.h>
#include <kdl/chain.hpp>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"

using namespace foresight;

namespace {

constexpr double kDeg = M_PI / 180.0;

// A small valid arm: base -j1-> l1 -j2-> l2 -tip_joint-> tip. One element a line.
const std::string kLine1 = R"(<?xml version="1.0"?>)";
std::string small_urdf(const std::string& j2_type = "revolute",
                       const std::string& j2_limit =
                           R"(<limit lower="-1" upper="1" velocity="1" acceleration="2" effort="10"/>)",
                       const std::string& extra = "") {
  return kLine1 + "\n" +                                                     // 1
         "<robot name=\"small\">\n" +                                        // 2
         "<link name=\"base\"/>\n" +                                         // 3
         "<link name=\"l1\"><inertial><mass value=\"2\"/><inertia ixx=\"0.1\" ixy=\"0\" ixz=\"0\" iyy=\"0.1\" "
         "iyz=\"0\" izz=\"0.1\"/></inertial></link>\n" +                     // 4
         "<link name=\"l2\"/>\n" +                                           // 5
         "<link name=\"tip\"/>\n" +                                          // 6
         "<joint name=\"j1\" type=\"revolute\">\n" +                        // 7
         "<parent link=\"base\"/><child link=\"l1\"/>\n" +                   // 8
         "<origin xyz=\"0 0 0.5\"/><axis xyz=\"0 0 1\"/>\n" +               // 9
         "<limit lower=\"-2\" upper=\"2\" velocity=\"1\" acceleration=\"3\" effort=\"50\"/>\n" +  // 10
         "</joint>\n" +                                                      // 11
         "<joint name=\"j2\" type=\"" + j2_type + "\">\n" +                  // 12
         "<parent link=\"l1\"/><child link=\"l2\"/>\n" +                     // 13
         "<origin xyz=\"0 0 0.4\"/><axis xyz=\"0 1 0\"/>\n" +               // 14
         j2_limit + "\n" +                                                   // 15
         "</joint>\n" +                                                      // 16
         "<joint name=\"tip_joint\" type=\"fixed\">\n" +                    // 17
         "<parent link=\"l2\"/><child link=\"tip\"/><origin xyz=\"0 0 0.3\"/>\n" +  // 18
         "</joint>\n" +                                                      // 19
         extra +                                                             // 20...
         "</robot>\n";
}

RobotModelOptions small_options() {
  RobotModelOptions o;
  o.tip_link = "tip";
  return o;
}

std::string error_of(const std::string& xml, const RobotModelOptions& options = small_options()) {
  try {
    RobotModel::from_xml(xml, "test.urdf", options);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

std::string write_temp(const std::string& text) {
  char name[] = "/tmp/foresight_urdf_XXXXXX";
  const int fd = mkstemp(name);
  EXPECT_GE(fd, 0);
  ::close(fd);
  std::ofstream(name) << text;
  return name;
}

}  // namespace

TEST(RobotModel, LoadsTheArm) {
  const RobotModel m = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  EXPECT_EQ(m.source(), FORESIGHT_CONFIG_DIR "/robot.urdf");
  ASSERT_EQ(m.dof(), 7);
  for (int i = 0; i < 7; ++i) {
    EXPECT_EQ(m.joint_names()[i], "joint" + std::to_string(i + 1));
    const JointLimits& l = m.limits()[i];
    EXPECT_LT(l.lower_rad, l.upper_rad);
    EXPECT_GT(l.velocity_rad_s, 0.0);
    EXPECT_GT(l.acceleration_rad_s2, 0.0);
    EXPECT_GT(l.effort_nm, 0.0);
  }
  EXPECT_NEAR(m.limits()[3].upper_rad, 160 * kDeg, 1e-6);
  EXPECT_DOUBLE_EQ(m.limits()[0].acceleration_rad_s2, 2.0);
  EXPECT_DOUBLE_EQ(m.limits()[6].acceleration_rad_s2, 6.0);
  EXPECT_EQ(m.chain().getNrOfJoints(), 7u);
  EXPECT_EQ(m.segment_count(), 10);  // 7 joints + F/T sensor + tool + tip
  ASSERT_EQ(m.links().size(), 11u);
  EXPECT_EQ(m.links()[0].name, "base");
  EXPECT_EQ(m.links()[8].name, "ft_sensor");
  EXPECT_EQ(m.links()[9].name, "lst");
  EXPECT_EQ(m.links()[10].name, "lst_tip");
  // Visuals: several primitives per moving link, with their colours.
  int shapes = 0;
  for (int k = 1; k <= 9; ++k) {
    EXPECT_GE(m.links()[k].visuals.size(), 2u) << m.links()[k].name;
    shapes += static_cast<int>(m.links()[k].visuals.size());
  }
  EXPECT_GE(shapes, 25);
  const VisualShape& socket = m.links()[9].visuals.back();
  EXPECT_EQ(socket.type, VisualShape::Type::Cylinder);
  EXPECT_DOUBLE_EQ(socket.size_m.x(), 0.014);  // radius: 28 mm socket in the 30 mm hole
  EXPECT_DOUBLE_EQ(socket.size_m.y(), 0.035);  // length
  EXPECT_NEAR(socket.link_T_shape.translation().z(), 0.2425, 1e-12);
  EXPECT_NEAR(socket.rgba[0], 0.60, 1e-6);  // urdfdom keeps colours as float
  EXPECT_DOUBLE_EQ(m.links()[9].mass_kg, 2.6);
  // Mid configuration and limit checks.
  const Eigen::VectorXd mid = m.mid_configuration();
  EXPECT_TRUE(m.within_limits(mid));
  Eigen::VectorXd q = mid;
  q[3] = m.limits()[3].upper_rad + 0.01;
  EXPECT_FALSE(m.within_limits(q));
  EXPECT_TRUE(m.within_limits(q, 0.02));
  q[3] = NAN;
  EXPECT_FALSE(m.within_limits(q, 1.0));
  EXPECT_FALSE(m.within_limits(Eigen::VectorXd::Zero(6)));
}

TEST(RobotModel, InertiaOfARotatedInertialFrameIsRotated) {
  // A link whose inertial frame is turned 90 deg about z: ixx and iyy swap in the link frame.
  const std::string extra =
      "<link name=\"spin\"><inertial><origin xyz=\"0.1 0 0\" rpy=\"0 0 1.5707963267948966\"/><mass value=\"3\"/>"
      "<inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"2\" iyz=\"0\" izz=\"3\"/></inertial></link>\n"
      "<joint name=\"spin_joint\" type=\"fixed\"><parent link=\"tip\"/><child link=\"spin\"/></joint>\n";
  RobotModelOptions o;
  o.tip_link = "spin";
  const RobotModel m = RobotModel::from_xml(small_urdf("revolute",
                                                       R"(<limit lower="-1" upper="1" velocity="1" acceleration="2" effort="10"/>)",
                                                       extra),
                                            "test.urdf", o);
  const KDL::RigidBodyInertia& I = m.chain().getSegment(3).getInertia();
  EXPECT_DOUBLE_EQ(I.getMass(), 3.0);
  EXPECT_NEAR(I.getCOG().x(), 0.1, 1e-12);
  // KDL stores the rotational inertia about the link origin: about the COM plus m d^2 (parallel axis).
  const KDL::RotationalInertia Io = I.getRotationalInertia();
  EXPECT_NEAR(Io.data[0], 2.0, 1e-9);              // Ixx (was iyy)
  EXPECT_NEAR(Io.data[4], 1.0 + 3 * 0.01, 1e-9);   // Iyy (was ixx) + m x^2
  EXPECT_NEAR(Io.data[8], 3.0 + 3 * 0.01, 1e-9);   // Izz + m x^2
}

TEST(RobotModel, OruTagsAreReachableWithMarginToLimits) {
  const RobotModel m = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  KinematicsWorkspace ws(m);
  ASSERT_EQ(oru.tags.size(), 7u);
  const Eigen::VectorXd seed = m.mid_configuration();
  IkOptions options;
  options.centre_joints = true;
  for (const auto& [name, oru_T_tag] : oru.tags) {
    const Pose target = scene.base_T_object * oru_T_tag;
    const IkResult r = inverse_kinematics(m, ws, target, seed, options);
    ASSERT_TRUE(r.success) << name << ": " << r.position_error_m << " m, " << r.rotation_error_rad << " rad";
    double margin = 1e9;
    for (int i = 0; i < m.dof(); ++i)
      margin = std::min({margin, r.q[i] - m.limits()[i].lower_rad, m.limits()[i].upper_rad - r.q[i]});
    std::printf("tag %-15s q_deg = [", name.c_str());
    for (int i = 0; i < m.dof(); ++i) std::printf("%7.1f", r.q[i] / kDeg);
    std::printf(" ]  min margin %.1f deg\n", margin / kDeg);
    EXPECT_GT(margin, 30 * kDeg) << name;
    // The LST tip's z axis is along the hole axis (+x of the base in this scene).
    const Pose T = forward_kinematics(m, ws, r.q);
    EXPECT_GT(T.linear().col(2).dot(scene.base_T_object.linear() * oru.hole_axis), 1.0 - 1e-6);
  }
}

// ---- bad input: each with its exact message ----

TEST(RobotModelBadInput, MissingFile) {
  try {
    RobotModel::from_file("/nonexistent/robot.urdf");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/robot.urdf: cannot open URDF file");
  }
}

TEST(RobotModelBadInput, SmallValidArmLoadsFromFile) {
  const std::string path = write_temp(small_urdf());
  const RobotModel m = RobotModel::from_file(path, small_options());
  EXPECT_EQ(m.dof(), 2);
  EXPECT_EQ(m.links().size(), 4u);
  EXPECT_DOUBLE_EQ(m.limits()[1].acceleration_rad_s2, 2.0);
  EXPECT_DOUBLE_EQ(m.limits()[0].effort_nm, 50.0);
  std::remove(path.c_str());
}

TEST(RobotModelBadInput, MalformedXmlGivesLine) {
  std::string xml = small_urdf();
  xml.replace(xml.find("</joint>\n<joint name=\"tip_joint\""), 8, "</jont>");  // line 16
  const std::string path = write_temp(xml);
  try {
    RobotModel::from_file(path, small_options());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(std::string(e.what()), path + ":16: malformed XML: Error reading end tag.");
  }
  std::remove(path.c_str());
  EXPECT_EQ(error_of(""), "test.urdf: malformed XML: Error document empty.");
  EXPECT_EQ(error_of("<robot name=\"x\">\n<link name=\"base\">\n"), "test.urdf:3: malformed XML: Error reading end tag.");
}

TEST(RobotModelBadInput, RootIsNotRobot) {
  EXPECT_EQ(error_of("<?xml version=\"1.0\"?>\n<sdf version=\"1.6\"/>\n"),
            "test.urdf:2: root element is <sdf>, expected <robot>");
}

TEST(RobotModelBadInput, MissingBaseOrTipLink) {
  RobotModelOptions o = small_options();
  o.base_link = "pedestal";
  EXPECT_EQ(error_of(small_urdf(), o), "test.urdf: base link 'pedestal' not found (no <link name=\"pedestal\">)");
  EXPECT_EQ(error_of(small_urdf(), RobotModelOptions{}),
            "test.urdf: tip link 'lst_tip' not found (no <link name=\"lst_tip\">)");
  o = small_options();
  o.base_link = "l2";
  o.tip_link = "l1";
  EXPECT_EQ(error_of(small_urdf(), o), "test.urdf:4: tip link 'l1' is not below base link 'l2'");
}

TEST(RobotModelBadInput, NonSerialChain) {
  const std::string camera =
      "<link name=\"camera\"/>\n<joint name=\"camera_joint\" type=\"fixed\"><parent link=\"l1\"/><child "
      "link=\"camera\"/></joint>\n";
  EXPECT_EQ(error_of(small_urdf("revolute", R"(<limit lower="-1" upper="1" velocity="1" acceleration="2" effort="10"/>)",
                                camera)),
            "test.urdf:4: non-serial chain: link 'l1' on the chain base -> tip has 2 child joints ('camera_joint', 'j2')");
  // A branch off the tip itself is not on the chain: fine.
  const std::string after_tip =
      "<link name=\"marker\"/>\n<joint name=\"marker_joint\" type=\"fixed\"><parent link=\"tip\"/><child "
      "link=\"marker\"/></joint>\n";
  EXPECT_NO_THROW(RobotModel::from_xml(
      small_urdf("revolute", R"(<limit lower="-1" upper="1" velocity="1" acceleration="2" effort="10"/>)", after_tip),
      "test.urdf", small_options()));
}

TEST(RobotModelBadInput, RevoluteJointWithoutLimit) {
  EXPECT_EQ(error_of(small_urdf("revolute", "")), "test.urdf:12: joint 'j2': revolute joint has no <limit> element");
}

TEST(RobotModelBadInput, LowerAboveUpper) {
  EXPECT_EQ(error_of(small_urdf("revolute", R"(<limit lower="1.5" upper="-1.5" velocity="1" acceleration="2" effort="10"/>)")),
            "test.urdf:15: joint 'j2': <limit> lower (1.5) > upper (-1.5)");
}

TEST(RobotModelBadInput, MissingOrBadAcceleration) {
  EXPECT_EQ(error_of(small_urdf("revolute", R"(<limit lower="-1" upper="1" velocity="1" effort="10"/>)")),
            "test.urdf:15: joint 'j2': <limit> has no acceleration attribute (rad/s^2, required by Foresight)");
  EXPECT_EQ(error_of(small_urdf("revolute", R"(<limit lower="-1" upper="1" velocity="1" acceleration="fast" effort="10"/>)")),
            "test.urdf:15: joint 'j2': <limit acceleration=\"fast\"> is not a positive number");
  EXPECT_EQ(error_of(small_urdf("revolute", R"(<limit lower="-1" upper="1" velocity="1" acceleration="-2" effort="10"/>)")),
            "test.urdf:15: joint 'j2': <limit acceleration=\"-2\"> is not a positive number");
  EXPECT_EQ(error_of(small_urdf("revolute", R"(<limit lower="-1" upper="1" velocity="0" acceleration="2" effort="10"/>)")),
            "test.urdf:15: joint 'j2': <limit velocity=\"0\"> is not a positive number");
}

TEST(RobotModelBadInput, UnsupportedJointTypes) {
  const std::string limit = R"(<limit lower="-1" upper="1" velocity="1" acceleration="2" effort="10"/>)";
  EXPECT_EQ(error_of(small_urdf("continuous", limit)),
            "test.urdf:12: joint 'j2': unsupported joint type 'continuous' (only revolute and fixed)");
  EXPECT_EQ(error_of(small_urdf("prismatic", limit)),
            "test.urdf:12: joint 'j2': unsupported joint type 'prismatic' (only revolute and fixed)");
  EXPECT_EQ(error_of(small_urdf("floating", limit)),
            "test.urdf:12: joint 'j2': unsupported joint type 'floating' (only revolute and fixed)");
  EXPECT_EQ(error_of(small_urdf("planar", limit)),
            "test.urdf:12: joint 'j2': unsupported joint type 'planar' (only revolute and fixed)");
}

TEST(RobotModelBadInput, UrdfdomRejectionIsReported) {
  std::string xml = small_urdf();
  xml.replace(xml.find("<parent link=\"l1\"/>"), 19, "<parent link=\"nowhere\"/>");
  EXPECT_EQ(error_of(xml), "test.urdf: URDF rejected by urdfdom: Failed to build tree: parent link [nowhere] of joint [j2] not found.  This "
                           "is not valid according to the URDF spec. Every link you refer to from a joint needs to be "
                           "explicitly defined in the robot description. To fix this problem you can either remove "
                           "this joint [j2] from your urdf file, or add \"<link name=\"nowhere\" />\" to your urdf file.");
}

TEST(RobotModelBadInput, JointWithoutNameOrWithZeroAxis) {
  std::string xml = small_urdf();
  xml.replace(xml.find("<joint name=\"j2\""), 16, "<joint");
  EXPECT_EQ(error_of(xml), "test.urdf:12: <joint> without a name attribute");
  xml = small_urdf();
  xml.replace(xml.find("<axis xyz=\"0 1 0\"/>"), 19, "<axis xyz=\"0 0 0\"/>");
  EXPECT_EQ(error_of(xml), "test.urdf:12: joint 'j2': zero <axis>");
}

TEST(RobotModelBadInput, NoRevoluteJointOnTheChain) {
  RobotModelOptions o;
  o.base_link = "l2";
  o.tip_link = "tip";
  EXPECT_EQ(error_of(small_urdf(), o), "test.urdf: no revolute joint between base link 'l2' and tip link 'tip'");
}
