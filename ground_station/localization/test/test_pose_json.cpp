// The object pose file: its one writer and one reader (pose_json.hpp).
#include "foresight/localization/pose_json.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <random>
#include <string>

#include "foresight/common/error.hpp"
#include "foresight/test/cli.hpp"

using namespace foresight;

namespace {

std::string error_of(const std::string& text) {
  try {
    localization::parse_object_pose_json(text, "loc.json");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

const char* const kIdentityRows = "[[1,0,0,0.5],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";

std::string with_pose(const std::string& rows) { return "{\"base_T_object\": " + rows + "}"; }

}  // namespace

TEST(PoseJson, WriterGivesFourRowsOfFourNumbers) {
  const Pose T = make_pose(Eigen::Vector3d(1.0, -2.0, 0.25), Eigen::Vector3d(0.0, 0.0, M_PI / 2));
  const nlohmann::json j = localization::object_pose_json(T);
  ASSERT_TRUE(j.contains("base_T_object"));
  const nlohmann::json& m = j["base_T_object"];
  ASSERT_EQ(m.size(), 4u);
  for (int r = 0; r < 4; ++r) {
    ASSERT_EQ(m[r].size(), 4u);
    for (int c = 0; c < 4; ++c) EXPECT_EQ(m[r][c].get<double>(), T.matrix()(r, c));
  }
  EXPECT_DOUBLE_EQ(m[0][3].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(m[1][3].get<double>(), -2.0);
  EXPECT_DOUBLE_EQ(m[2][3].get<double>(), 0.25);
  EXPECT_NEAR(m[1][0].get<double>(), 1.0, 1e-15);  // Rz(90 deg): x -> y
  EXPECT_EQ(m[3], nlohmann::json::parse("[0, 0, 0, 1]"));
}

TEST(PoseJson, RoundTripThroughAFileIsExact) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> a(-M_PI, M_PI), u(-3.0, 3.0);
  for (int k = 0; k < 50; ++k) {
    const Pose T = make_pose(Eigen::Vector3d(u(rng), u(rng), u(rng)), Eigen::Vector3d(a(rng), a(rng) / 2, a(rng)));
    nlohmann::json j = localization::object_pose_json(T);
    j["rms_px"] = 0.4;  // a localize result carries other keys beside the pose
    const std::string path = foresight::test::write_temp_file(j.dump(2), ".json");
    const Pose back = localization::read_object_pose_json(path);
    std::remove(path.c_str());
    EXPECT_EQ((back.matrix() - T.matrix()).cwiseAbs().maxCoeff(), 0.0) << k;  // 17 digits: exact
  }
}

TEST(PoseJson, BadInputNamesTheFileAndTheKey) {
  EXPECT_EQ(error_of(with_pose(kIdentityRows)), "no error");
  EXPECT_EQ(error_of("{\"base_T_object\": [[1,0,0,0]"),
            "loc.json: malformed JSON: [json.exception.parse_error.101] parse error at line 1, column 29: syntax "
            "error while parsing array - unexpected end of input; expected ']'");
  EXPECT_EQ(error_of("[1, 2]"), "loc.json: no key 'base_T_object'");
  EXPECT_EQ(error_of("{\"pose\": 1}"), "loc.json: no key 'base_T_object'");
  EXPECT_EQ(error_of(with_pose("[[1,0,0,0],[0,1,0,0],[0,0,1,0]]")),
            "loc.json: base_T_object must be 4 rows of 4 numbers");
  EXPECT_EQ(error_of(with_pose("\"identity\"")), "loc.json: base_T_object must be 4 rows of 4 numbers");
  EXPECT_EQ(error_of(with_pose("[[1,0,0,0],[0,1,0],[0,0,1,0],[0,0,0,1]]")),
            "loc.json: base_T_object row 2 must have 4 numbers");
  EXPECT_EQ(error_of(with_pose("[[1,0,0,0],[0,1,0,0],[0,0,1,\"x\"],[0,0,0,1]]")),
            "loc.json: base_T_object row 3 has a non-number");
  EXPECT_EQ(error_of(with_pose("[[1,0,0,1e400],[0,1,0,0],[0,0,1,0],[0,0,0,1]]")).rfind("loc.json: malformed JSON: ", 0),
            0u);
  EXPECT_EQ(error_of(with_pose("[[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]")),
            "loc.json: base_T_object is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)");
  EXPECT_EQ(error_of(with_pose("[[-1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]")),  // a reflection
            "loc.json: base_T_object is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)");
  EXPECT_EQ(error_of(with_pose("[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]")),
            "loc.json: base_T_object is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)");
}

TEST(PoseJson, MissingFileIsInputErrorNamingIt) {
  const std::string path = foresight::test::temp_path(".json");
  try {
    localization::read_object_pose_json(path);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open object pose file");
  }
}
