// The operator's chain end to end through the real executable: simulated
// clicks -> calibrate -> localize -> plan, against the scene's ground truth,
// and the plan command's bad inputs with their exact messages.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "foresight/common/scene.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/test/cli.hpp"

using namespace foresight;
using foresight::test::run_foresight;
using foresight::test::temp_path;

namespace {

Eigen::Matrix4d matrix_of(const nlohmann::json& rows) {
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) M(r, c) = rows.at(r).at(c).get<double>();
  return M;
}

}  // namespace

class OperatorChain : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cal_ = temp_path(".csv");
    oru_ = temp_path(".csv");
    q_ = temp_path(".txt");
    cams_ = temp_path(".yaml");
    loc_ = temp_path(".json");
    const auto r = run_foresight("synth-clicks --noise-px 0 --calibration-out " + cal_ + " --object-out " + oru_ +
                                 " --joints-out " + q_);
    ASSERT_EQ(r.status, 0) << r.err;
    for (const char* cam : {"side", "oblique", "overhead_wide", "overhead_zoom"}) {
      const auto c = run_foresight("calibrate " + cal_ + " --camera " + cam + " --out " + cams_);
      ASSERT_EQ(c.status, 0) << cam << ": " << c.err;
    }
    const auto l = run_foresight("localize " + oru_ + " --cameras " + cams_ + " --json > " + loc_);
    ASSERT_EQ(l.status, 0) << l.err;
  }
  static std::string cal_, oru_, q_, cams_, loc_;
};
std::string OperatorChain::cal_, OperatorChain::oru_, OperatorChain::q_, OperatorChain::cams_, OperatorChain::loc_;

TEST_F(OperatorChain, NoiseFreeClicksRecoverTheTrueCamerasAndOruPose) {
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const auto side = run_foresight("calibrate " + cal_ + " --camera side --json");
  ASSERT_EQ(side.status, 0) << side.err;
  const auto j = nlohmann::json::parse(side.out);
  EXPECT_NEAR(j["f_px"].get<double>(), scene.cameras.at("side").f_px, 1e-6);
  EXPECT_LT(j["rms_px"].get<double>(), 1e-6);
  EXPECT_GE(j["n_points"].get<int>(), 24);
  const auto loc = nlohmann::json::parse(test::read_file(loc_));
  EXPECT_TRUE(matrix_of(loc["base_T_object"]).isApprox(scene.base_T_object.matrix(), 1e-6))
      << matrix_of(loc["base_T_object"]) << "\nvs\n" << scene.base_T_object.matrix();
  EXPECT_EQ(loc["views"].size(), 4u);
}

TEST_F(OperatorChain, PlanWritesATrajectoryTheRemoteAccepts) {
  const std::string traj = temp_path(".csv");
  const auto r = run_foresight("plan --object-pose " + loc_ + " --from $(cat " + q_ +
                               ") --to approach_20cm,hole_entrance:linear,start --json --out " + traj);
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["segments"].size(), 3u);
  EXPECT_EQ(j["segments"][1]["kind"], "linear");
  EXPECT_LT(j["segments"][1]["position_error_m"].get<double>(), 2e-5);
  const Trajectory t = read_trajectory_csv(traj);
  EXPECT_EQ(j["samples"].get<int>(), t.samples());
  EXPECT_EQ(j["sha256"].get<std::string>(), to_hex(trajectory_hash(t)));
  const auto v = run_foresight("validate " + traj);
  EXPECT_EQ(v.status, 0) << v.out << v.err;
}

TEST_F(OperatorChain, PlanBadInputs) {
  const std::string out = temp_path(".csv");
  auto r = run_foresight("plan --object-pose " + loc_ + " --from $(cat " + q_ + ") --to nowhere --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--to: unknown goal 'nowhere' (tags of oru: approach_20cm, hole_entrance, insert_start, pulled_out_5cm, "
                       "stow, tool_inserted, withdrawn_15cm; or start)"),
            std::string::npos)
      << r.err;
  r = run_foresight("plan --object-pose " + loc_ + " --from $(cat " + q_ + ") --to start:linear --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--to: 'start' is a joint-space goal; it cannot be linear"), std::string::npos) << r.err;
  r = run_foresight("plan --object-pose " + loc_ + " --from 0,0,0 --to start --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--from has 3 values but the arm has 7 joints"), std::string::npos) << r.err;
  r = run_foresight("plan --object-pose /nonexistent.json --from $(cat " + q_ + ") --to start --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("/nonexistent.json"), std::string::npos) << r.err;
  r = run_foresight("synth-clicks --noise-px -1");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--noise-px must be a number in [0, 1000] px"), std::string::npos) << r.err;
  EXPECT_FALSE(std::ifstream(out).good()) << "nothing written on bad input";
}
