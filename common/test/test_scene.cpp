#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "foresight/common/error.hpp"
#include "foresight/common/scene.hpp"

using namespace foresight;

namespace {

std::string write_temp(const std::string& text) {
  char name[] = "/tmp/foresight_scene_XXXXXX";
  const int fd = mkstemp(name);
  EXPECT_GE(fd, 0);
  ::close(fd);
  std::ofstream(name) << text;
  return name;
}

std::string error_of(const std::string& text) {
  const std::string path = write_temp(text);
  std::string msg;
  try {
    Scene::from_file(path);
  } catch (const InputError& e) {
    msg = e.what();
  }
  std::remove(path.c_str());
  return msg;
}

const char* kPanel = "panel: {size_m: [0.3, 1.6, 1.2], xyz_m: [1.2, 0.15, 0.55], rpy_deg: [0, 0, 0]}\n";

}  // namespace

TEST(Scene, LoadsProjectScene) {
  const Scene s = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  ASSERT_EQ(s.camera_order.size(), 4u);
  EXPECT_EQ(s.camera_order[0], "side");
  EXPECT_EQ(s.camera_order[3], "overhead_zoom");
  EXPECT_NEAR(s.base_T_object.translation().x(), 1.00, 1e-12);
  // rpy (-90, 0, -90): the ORU's z (hole axis) points along base +x.
  EXPECT_NEAR((s.base_T_object.linear().col(2) - Eigen::Vector3d::UnitX()).norm(), 0.0, 1e-12);
  EXPECT_EQ(s.cameras.at("side").width_px, 646);
  EXPECT_GT(s.cameras.at("overhead_zoom").f_px, s.cameras.at("overhead_wide").f_px);
  EXPECT_NEAR(s.panel.size_m.y(), 1.6, 1e-12);
}

TEST(Scene, BadInputsNameKeyAndLine) {
  const std::string pose = "object_pose: {xyz_m: [1, 0, 0], rpy_deg: [0, 0, 0]}\n";
  EXPECT_NE(error_of(pose + kPanel + "cameras:\n  a: {viewport: [646, 486], f_px: -1, position_m: [0,0,0], look_at_m: [1,0,0], up: [0,0,1]}\n")
                .find(":4: 'cameras.a.f_px' must be a positive number"),
            std::string::npos);
  EXPECT_NE(error_of(pose + kPanel + "cameras:\n  a: {viewport: [646, 486], f_px: 5, position_m: [0,0,0], look_at_m: [0,0,1], up: [0,0,1]}\n")
                .find("'cameras.a': up is zero or parallel to the viewing direction"),
            std::string::npos);
  EXPECT_NE(error_of(pose + kPanel + "cameras:\n  a: {viewport: [646, 486], f_px: 5, position_m: [0,0], look_at_m: [0,0,1], up: [0,0,1]}\n")
                .find("'cameras.a.position_m' must be a list of 3 numbers"),
            std::string::npos);
  EXPECT_NE(error_of(kPanel).find("missing key 'object_pose'"), std::string::npos);
  EXPECT_NE(error_of(pose + kPanel).find("missing or empty map 'cameras'"), std::string::npos);
  EXPECT_NE(error_of("object_pose: [").find("malformed YAML"), std::string::npos);
}
