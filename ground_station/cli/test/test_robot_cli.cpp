// `foresight robot` end to end: the real executable, its output, its exit
// statuses (0 ok, 1 IK failed, 2 bad input) and its error messages.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "foresight/test/cli.hpp"

namespace {

using foresight::test::CliRun;

CliRun run(const std::string& args) { return foresight::test::run_foresight("robot " + args); }

}  // namespace

TEST(RobotCli, PrintsModelAndFkAtMidConfiguration) {
  const CliRun r = run("");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("7 joints, 11 links on the chain base -> lst_tip"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("joint4       -160.0      160.0"), std::string::npos) << r.out;
  // Mid configuration is straight up: the tip at z = 1.985 m.
  EXPECT_NE(r.out.find("lst_tip      0.0000   0.0000   1.9850"), std::string::npos) << r.out;
}

TEST(RobotCli, JsonFkAndIk) {
  // Joints in degrees; shoulder pitch 90: the arm points along +x.
  CliRun r = run("--json --joints-deg 0,90,0,0,0,0,0");
  ASSERT_EQ(r.status, 0) << r.err;
  nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["dof"], 7);
  EXPECT_EQ(j["links"].size(), 11u);
  EXPECT_EQ(j["links"][10]["name"], "lst_tip");
  EXPECT_NEAR(j["links"][10]["xyz_m"][0].get<double>(), 1.605, 1e-9);
  EXPECT_NEAR(j["links"][10]["xyz_m"][2].get<double>(), 0.38, 1e-9);
  EXPECT_NEAR(j["q_rad"][1].get<double>(), M_PI / 2, 1e-12);
  EXPECT_NEAR(j["joints"][1]["upper_deg"].get<double>(), 120.0, 1e-4);

  // IK to the ORU hole entrance (config/scene.yaml): tool along +x.
  r = run("--json --target 1.0,0.15,0.55,0,90,0");
  ASSERT_EQ(r.status, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["ik"]["success"].get<bool>());
  EXPECT_LT(j["ik"]["position_error_m"].get<double>(), 1e-4);
  const auto& tip = j["ik"]["tip"]["xyz_m"];
  EXPECT_NEAR(tip[0].get<double>(), 1.0, 1e-4);
  EXPECT_NEAR(tip[1].get<double>(), 0.15, 1e-4);
  EXPECT_NEAR(tip[2].get<double>(), 0.55, 1e-4);
  EXPECT_NEAR(j["ik"]["tip"]["base_T_link"][0][2].get<double>(), 1.0, 1e-4);  // tip z along base +x
}

TEST(RobotCli, UnreachableTargetExitsOneWithResidual) {
  const CliRun r = run("--target 3,0,0.5,0,0,0");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("FAILED after 51 attempt(s); residual"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("foresight robot: IK did not reach the target (residual"), std::string::npos) << r.err;
}

TEST(RobotCli, BadArgumentsExitTwoWithMessage) {
  CliRun r = run("--joints 1,2,3");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --joints has 3 values but the arm has 7 joints\n");
  EXPECT_TRUE(r.out.empty());
  r = run("--joints 1,2,x,4,5,6,7");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --joints: element 3 ('x') is not a finite number\n");
  r = run("--joints-deg 0,0,0,170,0,0,0");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --joints-deg: joint4 = 170 deg is outside its limits [-160.0, 160.0] deg\n");
  r = run("--joints 0,0,0,3,0,0,0");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --joints: joint4 = 3 rad is outside its limits [-2.7925, 2.7925] rad\n");
  r = run("--target 1,2");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --target: expected 6 numbers x,y,z (m), roll,pitch,yaw (deg), got 2\n");
  EXPECT_TRUE(r.out.empty());
  r = run("--seed 0,0,0,0,0,0,0");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --seed: only meaningful with --target\n");
  r = run("--target 1,0,0.5,0,90,0 --seed-deg 0,0,0");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: --seed-deg has 3 values but the arm has 7 joints\n");
  r = run("--robot /nonexistent/robot.urdf");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight robot: error: /nonexistent/robot.urdf: cannot open URDF file\n");
}
