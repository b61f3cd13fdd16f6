#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <fstream>

#include "foresight/common/error.hpp"
#include "foresight/common/object_model.hpp"

using namespace foresight;

namespace {
std::string write_temp(const std::string& text) {
  char name[] = "/tmp/foresight_oru_XXXXXX";
  const int fd = mkstemp(name);
  close(fd);
  std::ofstream(name) << text;
  return name;
}
}  // namespace

TEST(ObjectModel, LoadsTheOru) {
  const ObjectModel m = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  EXPECT_EQ(m.name, "oru");
  EXPECT_DOUBLE_EQ(m.size_m.x(), 0.50);
  EXPECT_GE(m.points.size(), 8u);
  EXPECT_GE(m.point_index("hole_centre"), 0);
  EXPECT_EQ(m.point_index("nope"), -1);
  for (const char* tag : {"approach_20cm", "hole_entrance", "tool_inserted", "pulled_out_5cm", "withdrawn_15cm", "stow"})
    EXPECT_TRUE(m.tags.count(tag)) << tag;
  // The approach tag is 20 cm in front of the hole, along -axis.
  EXPECT_LT((m.tags.at("approach_20cm").translation() - (m.hole_entrance_m - 0.20 * m.hole_axis)).norm(), 1e-12);
}

TEST(ObjectModel, MissingFileNamesIt) {
  try {
    ObjectModel::from_file("/nonexistent/oru.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/oru.yaml: cannot open object model file");
  }
}

TEST(ObjectModel, MalformedYamlGivesLine) {
  const std::string p = write_temp("object: oru\nsize_m: [0.5, 0.4\n");
  try {
    ObjectModel::from_file(p);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), p);
    EXPECT_GT(e.line(), 0);
    EXPECT_NE(std::string(e.what()).find("malformed YAML"), std::string::npos);
  }
  std::remove(p.c_str());
}

TEST(ObjectModel, WrongSizedVectorNamesKey) {
  const std::string p = write_temp(
      "object: oru\nsize_m: [0.5, 0.4, 0.3]\nhole: {entrance_m: [0,0,0], axis: [0,0,2], diameter_m: 0.03, depth_m: 0.08}\n"
      "points: {a: [0,0,0]}\ntags: {}\n");
  EXPECT_THROW(
      {
        try {
          ObjectModel::from_file(p);
        } catch (const InputError& e) {
          EXPECT_NE(std::string(e.what()).find("'hole.axis' must be a unit vector"), std::string::npos) << e.what();
          throw;
        }
      },
      InputError);
  std::remove(p.c_str());
}

// The bay around the ORU (`surroundings`): read like `visuals`, kept apart
// from them (never drawn as the ORU), its errors named by their own key.
TEST(ObjectModel, SurroundingsAreReadApartFromTheVisuals) {
  const ObjectModel m = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  ASSERT_EQ(m.surroundings.size(), 1u);
  const VisualShape& bay = m.surroundings.front();
  EXPECT_EQ(bay.type, VisualShape::Type::Box);
  EXPECT_EQ(bay.size_m, Eigen::Vector3d(1.6, 1.2, 0.30));
  EXPECT_LT((bay.link_T_shape.translation() - Eigen::Vector3d(0.0, 0.0, 0.20)).norm(), 1e-12);
  EXPECT_EQ(m.visuals.size(), 4u);

  const std::string p = write_temp(
      "object: oru\nsize_m: [0.5, 0.4, 0.3]\nhole: {entrance_m: [0,0,0], axis: [0,0,1], diameter_m: 0.03, depth_m: 0.08}\n"
      "points: {a: [0,0,0]}\ntags: {}\nsurroundings:\n  - {type: cone, size_m: [1, 1, 1]}\n");
  try {
    ObjectModel::from_file(p);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), p + ":7: surroundings[0].type must be box, cylinder or sphere (got 'cone')");
  }
  std::remove(p.c_str());
}
