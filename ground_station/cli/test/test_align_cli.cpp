// `foresight align` end to end: a synthetic frame (foresight synth) and a
// camera 4 px off its truth; the refined camera written to cameras.yaml is
// back on the truth. Bad input (wrong frame size, unknown camera, the model
// not in view) exits 2 with the exact message and writes nothing; a frame
// without the model's edges is refused (exit 1), nothing written.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "foresight/camera/camera.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/test/cli.hpp"

using namespace foresight;
using foresight::test::run_foresight;
using foresight::test::temp_path;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

struct Fixture {
  RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  KinematicsWorkspace ws{model};
  std::string q_text, frame, truth_yaml, start_yaml;
  std::map<std::string, CameraRecord> truth;

  Fixture() {
    const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"),
                                       model.mid_configuration());
    EXPECT_TRUE(ik.success);
    for (int i = 0; i < ik.q.size(); ++i) {
      char b[32];
      std::snprintf(b, sizeof b, "%s%.9f", i ? "," : "", ik.q[i]);
      q_text += b;
    }
    frame = temp_path(".png");
    truth_yaml = temp_path(".yaml");
    const auto r = run_foresight("synth --camera side --joints " + q_text + " --out " + frame + " --write-cameras " +
                                 truth_yaml + " --seed 4");
    EXPECT_EQ(r.status, 0) << r.err;
    truth = load_cameras(truth_yaml);
    // The start: side 4 px right and 3 px down of its truth.
    auto start = truth;
    Camera& c = start.at("side").camera;
    c.base_T_camera.linear() = c.base_T_camera.linear() * exp_so3(Eigen::Vector3d(-3.0 / c.f_px, 4.0 / c.f_px, 0.0));
    // A camera looking away from the work site.
    start["away"].camera = Camera::look_at("away", c.viewport, 700.0, {0.75, -1.9, 0.85}, {0.75, -5.0, 0.85});
    start_yaml = temp_path(".yaml");
    save_cameras(start_yaml, start);
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

}  // namespace

TEST(AlignCli, RefinesTheCameraBackOntoTheTruth) {
  auto& f = fixture();
  const std::string out = temp_path(".yaml");
  const auto r = run_foresight("align --cameras " + f.start_yaml + " --camera side --image " + f.frame + " --joints " +
                               f.q_text + " --out " + out + " --json");
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["status"], "aligned");
  EXPECT_LT(j["final_score_px"].get<double>(), j["start_score_px"].get<double>());
  EXPECT_EQ(j["covariance"].size(), 7u);
  const auto cams = load_cameras(out);
  ASSERT_TRUE(cams.count("side"));
  ASSERT_TRUE(cams.at("side").calibration);
  // Reprojection of the arm's link origins: refined vs true camera.
  const Camera& est = cams.at("side").camera;
  const Camera& tru = f.truth.at("side").camera;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(f.model.dof());
  std::vector<double> values;
  std::stringstream ss(f.q_text);
  for (std::string t; std::getline(ss, t, ',');) values.push_back(std::stod(t));
  for (int i = 0; i < q.size(); ++i) q[i] = values[i];
  double s = 0.0;
  int n = 0;
  for (int link = 0; link < static_cast<int>(f.model.links().size()); ++link) {
    const Eigen::Vector3d p = forward_kinematics(f.model, f.ws, q, link).translation();
    s += (est.project(p) - tru.project(p)).squaredNorm();
    ++n;
  }
  EXPECT_LT(std::sqrt(s / n), 0.5);
}

TEST(AlignCli, WrongFrameSizeIsBadInputAndWritesNothing) {
  auto& f = fixture();
  const std::string small = temp_path(".png"), out = temp_path(".yaml");
  cv::imwrite(small, cv::Mat(100, 120, CV_8UC3, cv::Scalar(20, 20, 20)));
  const auto r = run_foresight("align --cameras " + f.start_yaml + " --camera side --image " + small + " --joints " +
                               f.q_text + " --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight align: error: " + small +
                       ": image is 120x100 but camera 'side' has a 646x486 viewport (pass --scale-image to resize it)\n");
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(AlignCli, ScaleImageResizesAFrameOfAnotherResolution) {
  auto& f = fixture();
  const std::string big = temp_path(".png"), out = temp_path(".yaml");
  cv::Mat frame = cv::imread(f.frame), twice;
  cv::resize(frame, twice, cv::Size(), 2.0, 2.0, cv::INTER_LINEAR);
  cv::imwrite(big, twice);
  const std::string base = "align --cameras " + f.start_yaml + " --camera side --image " + big + " --joints " +
                           f.q_text + " --out " + out + " --json";
  EXPECT_EQ(run_foresight(base).status, 2);
  const auto r = run_foresight(base + " --scale-image");
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["status"], "aligned");
  EXPECT_LT(j["final_score_px"].get<double>(), j["start_score_px"].get<double>());
  EXPECT_TRUE(load_cameras(out).at("side").calibration);
}

// The object pose's covariance (as `localize --json` writes it) is read for
// the clicks-agreement check; a malformed one is bad input, nothing written.
TEST(AlignCli, MalformedObjectPoseCovarianceIsBadInput) {
  auto& f = fixture();
  const std::string pose = temp_path(".json"), out = temp_path(".json");
  const Eigen::Vector3d t = f.scene.base_T_object.translation();
  const Eigen::Matrix3d R = f.scene.base_T_object.linear();
  nlohmann::json j;
  j["base_T_object"] = {{R(0, 0), R(0, 1), R(0, 2), t.x()},
                        {R(1, 0), R(1, 1), R(1, 2), t.y()},
                        {R(2, 0), R(2, 1), R(2, 2), t.z()},
                        {0.0, 0.0, 0.0, 1.0}};
  j["covariance"] = {{1e-4, 0.0}, {0.0, 1e-4}};
  std::ofstream(pose) << j.dump();
  const auto r = run_foresight("align --cameras " + f.truth_yaml + " --camera side --image " + f.frame + " --joints " +
                               f.q_text + " --object-pose " + pose + " --refine object --object-out " + out);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_EQ(r.err, "foresight align: error: " + pose + ": covariance must be 6 rows of 6 numbers\n");
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(AlignCli, UnknownCameraIsBadInput) {
  auto& f = fixture();
  const std::string out = temp_path(".yaml");
  const auto r = run_foresight("align --cameras " + f.start_yaml + " --camera nope --image " + f.frame + " --joints " +
                               f.q_text + " --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight align: error: " + f.start_yaml + ": no camera 'nope' (known: away, oblique, overhead_wide, "
                   "overhead_zoom, side)\n");
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(AlignCli, ModelNotInViewIsBadInput) {
  auto& f = fixture();
  const std::string out = temp_path(".yaml");
  const auto r = run_foresight("align --cameras " + f.start_yaml + " --camera away --image " + f.frame + " --joints " +
                               f.q_text + " --out " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight align: error: " + f.frame +
                       ": the arm model is not in view of camera 'away': none of its edges projects visibly into the "
                       "image\n");
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(AlignCli, AFrameWithoutTheModelIsRefused) {
  auto& f = fixture();
  const std::string blank = temp_path(".png"), out = temp_path(".yaml");
  cv::imwrite(blank, cv::Mat(486, 646, CV_8UC3, cv::Scalar(40, 40, 40)));
  const auto r = run_foresight("align --cameras " + f.start_yaml + " --camera side --image " + blank + " --joints " +
                               f.q_text + " --out " + out + " --json");
  EXPECT_EQ(r.status, 1);
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["status"], "refused");
  EXPECT_NE(j["reason"].get<std::string>().find("within 1 px of an image edge"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("foresight align: refused: "), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(out));
}

// `foresight eval alignment`: bad input exits 2 with its message; one trial
// gives the issue's --json contract (combinations[{views, clicks{...},
// aligned{...}}], views written like 1+2+3+4), all 15 combinations.
TEST(EvalAlignmentCli, BadInputIsExitTwo) {
  const auto r = run_foresight("eval alignment --trials 0");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err, "foresight eval: error: --trials must be at least 1\n");
  const auto n = run_foresight("eval alignment --noise-px -1");
  EXPECT_EQ(n.status, 2);
  EXPECT_EQ(n.err, "foresight eval: error: --noise-px must be a positive number\n");
}

TEST(EvalAlignmentCli, OneTrialGivesTheJsonContract) {
  const auto r = run_foresight("eval alignment --trials 1 --seed 3 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["study"], "alignment");
  EXPECT_EQ(j["arm_error_mm"].get<double>(), 2.0);
  ASSERT_EQ(j["combinations"].size(), 15u);
  EXPECT_EQ(j["combinations"][0]["views"], "1");
  EXPECT_EQ(j["combinations"][14]["views"], "1+2+3+4");
  for (const auto& c : j["combinations"])
    for (const char* k : {"clicks", "aligned"}) {
      ASSERT_TRUE(c.contains(k));
      for (const char* f : {"position_rmse_m", "rotation_rmse_deg", "alignment95_m"}) {
        ASSERT_TRUE(c[k].contains(f)) << k << "." << f;
        EXPECT_GE(c[k][f].get<double>(), 0.0);
      }
      EXPECT_EQ(c[k]["n"], 1);
    }
  // The arm self-calibration: one entry per link offset, the estimate's
  // error against the truth beside the truth's own error.
  EXPECT_EQ(j["arm_prior_mm"].get<double>(), 2.0);
  ASSERT_FALSE(j["arm_links"].empty());
  for (const auto& l : j["arm_links"])
    for (const char* f : {"true_rms_m", "estimate_error_rms_m", "sigma_mean_m"}) EXPECT_GE(l[f].get<double>(), 0.0);
  EXPECT_TRUE(j["combinations"][14].contains("aligned_cameras_only"));
  // Refusals per combination, and of them those for moving beyond the
  // clicks' uncertainty (never more than the refusals).
  for (const auto& c : j["combinations"]) {
    ASSERT_TRUE(c.contains("aligned_refused_disagreement"));
    EXPECT_LE(c["aligned_refused_disagreement"].get<int>(), c["aligned_refused"].get<int>());
  }
}

// `foresight health --json`: the per-frame silhouette IoU beside the edge measures.
TEST(HealthCli, JsonHasTheIouPerFrame) {
  auto& f = fixture();
  const std::string joints = temp_path(".txt");
  {
    std::FILE* out = std::fopen(joints.c_str(), "w");
    ASSERT_NE(out, nullptr);
    std::fprintf(out, "%s\n", f.q_text.c_str());
    std::fclose(out);
  }
  const auto r = run_foresight("health --cameras " + f.truth_yaml + " --camera side --video " + f.frame +
                               " --joints-from " + joints + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["frames"].size(), 1u);
  const double iou = j["frames"][0]["iou"].get<double>();
  EXPECT_GT(iou, 0.85);
  EXPECT_LE(iou, 1.0);
}
