// `foresight teleop` through the executable: from a recorded hand input, in
// each reference frame (world, tool, a calibrated camera's view) every
// deflection moves or turns the tool tip along the commanded axis within
// 1 deg; the recorded motion is a trajectory `foresight validate` accepts;
// bad options and files exit 2 naming the problem.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "foresight/camera/camera.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/test/cli.hpp"

namespace {

using foresight::test::run_foresight;
using foresight::test::temp_path;
using foresight::test::write_temp_file;

const char* kJoints = "0.1,0.5,-0.1,-1.2,0.2,0.6,0.1";  // well conditioned, mid-workspace

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

Eigen::Vector3d vec3(const nlohmann::json& j) { return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()}; }

/// 1.5 s of one deflection at 0.6 (the input holds between its samples).
std::string one_axis_input(int axis) {
  std::string row = "";
  for (int i = 0; i < 6; ++i) row += std::string(",") + (i == axis ? "0.6" : "0");
  return write_temp_file("t,x,y,z,rx,ry,rz\n0" + row + "\n1.5" + row + "\n");
}

/// A camera with a known, oblique orientation in cameras.yaml.
std::string camera_file(Eigen::Matrix3d* base_R_camera) {
  foresight::camera::CameraRecord rec;
  rec.camera = foresight::camera::Camera::look_at("test_cam", {}, 700.0, Eigen::Vector3d(1.8, -1.2, 1.5),
                                          Eigen::Vector3d(0.4, 0.1, 0.4));
  *base_R_camera = rec.camera.base_T_camera.linear();
  const std::string path = temp_path(".yaml");
  foresight::camera::save_cameras(path, {{"test_cam", rec}});
  return path;
}

TEST(TeleopCli, EachFrameMovesTheToolAsCommandedWithin1Deg) {
  const auto model = foresight::RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  foresight::KinematicsWorkspace ws(model);
  Eigen::VectorXd q0(7);
  q0 << 0.1, 0.5, -0.1, -1.2, 0.2, 0.6, 0.1;
  const Eigen::Matrix3d R_tool = foresight::forward_kinematics(model, ws, q0).linear();
  Eigen::Matrix3d R_camera;
  const std::string cameras = camera_file(&R_camera);
  for (const std::string frame : {"world", "tool", "camera"}) {
    const Eigen::Matrix3d R = frame == "world" ? Eigen::Matrix3d::Identity() : frame == "tool" ? R_tool : R_camera;
    const std::string extra = frame == "camera" ? " --camera test_cam --cameras " + cameras : "";
    for (int axis = 0; axis < 6; ++axis) {
      const std::string input = one_axis_input(axis);
      const std::string record = temp_path(".csv");
      const auto r = run_foresight("teleop --input " + input + " --frame " + frame + extra + " --joints " + kJoints +
                                   " --record " + record + " --json");
      ASSERT_EQ(r.status, 0) << frame << " axis " << axis << ": " << r.err;
      const auto j = nlohmann::json::parse(r.out);
      EXPECT_EQ(j["valid"], true);
      EXPECT_EQ(j["frame"], frame);
      const Eigen::Vector3d expected = R.col(axis % 3);
      if (axis < 3) {
        const Eigen::Vector3d d = vec3(j["displacement_base_m"]);
        EXPECT_LT(angle_deg(d, expected), 1.0) << frame << " axis " << axis;
        // 1.5 s at 0.6 x 0.05 m/s less the 0.15 s ramp up, plus the 0.15 s
        // stop when the hand lets go at the end: 4.5 cm, within 3%.
        EXPECT_NEAR(d.norm(), 0.045, 0.0013) << frame << " axis " << axis;
        EXPECT_LT(vec3(j["rotation_base_rad"]).norm(), 2e-3) << "a translation must not turn the tool";
        // The same displacement read in the reference frame: along its own axis.
        const Eigen::Vector3d d_ref = vec3(j["displacement_frame_m"]);
        EXPECT_LT(angle_deg(d_ref, Eigen::Vector3d::Unit(axis)), 1.0) << frame << " axis " << axis;
      } else {
        // In tool mode the axis turns with the tool, but a rotation about a
        // tool axis leaves that axis fixed: the start frame's axis is the truth.
        const Eigen::Vector3d w = vec3(j["rotation_base_rad"]);
        EXPECT_LT(angle_deg(w, expected), 1.0) << frame << " axis " << axis;
        EXPECT_GT(w.norm(), 0.1) << frame << " axis " << axis;  // 0.6 x 10 deg/s x ~1.4 s
      }
      // The recorded motion is a trajectory the remote's rules accept.
      const auto v = run_foresight("validate " + record);
      EXPECT_EQ(v.status, 0) << frame << " axis " << axis << ": " << v.out << v.err;
    }
  }
}

TEST(TeleopCli, TheRecordStartsWhereTheArmWasAndKeepsTheRate) {
  const std::string record = temp_path(".csv");
  const auto r = run_foresight("teleop --input " + one_axis_input(2) + " --joints-deg 0,30,0,-70,0,40,0 --rate 50 --record " +
                               record + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  // 1.5 s at 50 Hz, both ends, then the stop when the hand lets go: 0.03 m/s
  // braked at 0.2 m/s^2 by 0.004 m/s a step, 8 steps.
  EXPECT_EQ(j["samples"], 84);
  EXPECT_NEAR(j["duration_s"].get<double>(), 1.66, 1e-9);
  std::ifstream in(record);
  std::string header, first;
  std::getline(in, header);
  std::getline(in, first);
  EXPECT_EQ(header.rfind("t,q1,", 0), 0u) << header;
  EXPECT_EQ(first.rfind("0,", 0) == 0 || first.rfind("0.0", 0) == 0, true) << first;
}

TEST(TeleopCli, BadInputExits2NamingIt) {
  const auto expect = [](const std::string& args, const std::string& err) {
    const auto r = run_foresight(args);
    EXPECT_EQ(r.status, 2) << args << "\n" << r.out << r.err;
    EXPECT_EQ(r.err, err) << args;
  };
  const std::string input = one_axis_input(0);
  const std::string j = std::string(" --joints ") + kJoints;
  expect("teleop --frame world" + j, "foresight teleop: error: give one of --device or --input\n");
  expect("teleop --input " + input + " --device /dev/null" + j,
         "foresight teleop: error: give one of --device or --input\n");
  expect("teleop --input " + input, "foresight teleop: error: give one of --joints or --joints-deg (the start)\n");
  expect("teleop --input " + input + " --frame camera" + j,
         "foresight teleop: error: --frame camera needs --camera NAME\n");
  expect("teleop --input " + input + " --camera oblique" + j,
         "foresight teleop: error: --camera and --cameras go with --frame camera\n");
  const std::string bad = write_temp_file("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n0.5,1.5,0,0,0,0,0\n");
  expect("teleop --input " + bad + j,
         "foresight teleop: error: " + bad + ":3: deflection 1 = 1.5 is outside [-1, 1]\n");
  expect("teleop --device /nonexistent/event7" + j,
         "foresight teleop: error: /nonexistent/event7: cannot open the input device: No such file or directory\n");
  const std::string not_device = write_temp_file("x");
  expect("teleop --device " + not_device + j, "foresight teleop: error: " + not_device + ": not an input event device\n");
  expect("teleop --device /nonexistent/event7 --axes X,Y" + j,
         "foresight teleop: error: --axes: expected 6 axes (x,y,z,rx,ry,rz), got 2\n");
}

}  // namespace
