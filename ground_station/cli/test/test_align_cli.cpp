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

#include "foresight/align/arm_links_file.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/accuracy_study.hpp"
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
  std::map<std::string, camera::CameraRecord> truth;

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
    truth = camera::load_cameras(truth_yaml);
    // The start: side 4 px right and 3 px down of its truth.
    auto start = truth;
    camera::Camera& c = start.at("side").camera;
    c.base_T_camera.linear() = c.base_T_camera.linear() * camera::exp_so3(Eigen::Vector3d(-3.0 / c.f_px, 4.0 / c.f_px, 0.0));
    // A camera looking away from the work site.
    start["away"].camera = camera::Camera::look_at("away", c.viewport, 700.0, {0.75, -1.9, 0.85}, {0.75, -5.0, 0.85});
    start_yaml = temp_path(".yaml");
    camera::save_cameras(start_yaml, start);
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
  const auto cams = camera::load_cameras(out);
  ASSERT_TRUE(cams.count("side"));
  ASSERT_TRUE(cams.at("side").calibration);
  // Reprojection of the arm's link origins: refined vs true camera.
  const camera::Camera& est = cams.at("side").camera;
  const camera::Camera& tru = f.truth.at("side").camera;
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
  EXPECT_TRUE(camera::load_cameras(out).at("side").calibration);
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

// An aligned ORU carries its covariance on: align --json's per-tag
// uncertainty, and --object-out a pose file check-insert takes (it says the
// pose came from align, so its advice does not send the operator to align).
TEST(AlignCli, TheAlignedObjectsCovarianceGoesToTheTagsAndTheGoNoGo) {
  auto& f = fixture();
  const std::string pose = temp_path(".json"), out = temp_path(".json");
  nlohmann::json j;
  const Pose T = f.scene.base_T_object * Pose(Eigen::Translation3d(0.002, -0.001, 0.0));
  for (int r = 0; r < 4; ++r) j["base_T_object"].push_back({T(r, 0), T(r, 1), T(r, 2), T(r, 3)});
  for (int r = 0; r < 6; ++r) {
    j["covariance"].push_back(nlohmann::json::array());
    for (int c = 0; c < 6; ++c) j["covariance"][r].push_back(r == c ? (r < 3 ? 1e-4 : 1e-5) : 0.0);
  }
  std::ofstream(pose) << j.dump();
  const auto r = run_foresight("align --cameras " + f.truth_yaml + " --camera side --image " + f.frame + " --joints " +
                               f.q_text + " --object-pose " + pose + " --refine object --object-out " + out + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto a = nlohmann::json::parse(r.out);
  ASSERT_TRUE(a.contains("object_covariance")) << r.out;
  const auto& tag = a["tag_uncertainty"]["insert_start"];
  EXPECT_EQ(tag["covariance"].size(), 6u);
  EXPECT_GT(tag["sigma_position_m"][0].get<double>(), 0.0);
  EXPECT_LT(tag["sigma_position_m"][0].get<double>(), 0.003);  // sharper than the 3 mm start
  EXPECT_EQ(tag["tool_tip"]["frame"], "tag");
  const auto pose_file = nlohmann::json::parse(test::read_file(out));
  EXPECT_EQ(pose_file["source"], "foresight align");
  EXPECT_EQ(pose_file["covariance"], a["object_covariance"]);
  const auto c = run_foresight("check-insert --object-pose " + out + " --json");
  ASSERT_TRUE(c.status == 0 || c.status == 1) << c.err;
  const auto k = nlohmann::json::parse(c.out);
  EXPECT_GT(k["p_success"].get<double>(), 0.0);
  for (const auto& advice : k["advice"]) EXPECT_EQ(advice.get<std::string>().find("foresight align"), std::string::npos);
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
  EXPECT_TRUE(j["combinations"][14].contains("aligned_held_cameras"));
  // The accepted alignments' claims: counted, and none above the accepted.
  for (const auto& c : j["combinations"]) {
    const int accepted = c["aligned_accepted"].get<int>();
    EXPECT_EQ(accepted + c["aligned_refused"].get<int>(), 1);
    EXPECT_LE(c["aligned_within_3_sigma"].get<int>(), accepted);
    EXPECT_GE(c["aligned_mahalanobis2_mean"].get<double>(), 0.0);
  }
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

// The operator's arm self-calibration: a true arm whose link offsets are off
// by a known +-2-3 mm (synth --arm-links renders it), three cameras at the four
// calibration poses, every frame in one `align` (a camera named again gets
// another frame), the cameras started 2-3 px off: --arm-prior-mm refines the
// link lengths with the cameras, --arm-out writes them, and they come back
// well inside their 2 mm prior (the library's ArmLinkLengthsWithTheCameras,
// through the command line). --arm-links reads them back.
TEST(AlignCli, ArmLinkLengthsFromFramesOfSeveralCamerasAndPoses) {
  auto& f = fixture();
  const std::size_t nseg = f.model.segment_count();
  align::ArmLinkCorrections truth;
  truth.delta_m.assign(nseg, 0.0);
  std::vector<int> segs;
  for (const int k : f.model.offset_segments()) {
    truth.delta_m[k] = (segs.size() % 2 ? -1.0 : 1.0) * (0.002 + 0.0005 * static_cast<double>(segs.size() % 3));
    segs.push_back(k);
  }
  const std::string truth_arm = temp_path(".yaml");
  align::save_arm_links(truth_arm, truth, "config/robot.urdf", "2026-12-03T00:00:00Z");
  auto start = f.truth;
  std::string args;
  const auto poses = localization::arm_calibration_poses(f.model);
  int n = 0;
  for (const std::string name : {"side", "oblique", "overhead_zoom"}) {
    camera::Camera& c = start.at(name).camera;
    c.base_T_camera.linear() = c.base_T_camera.linear() * camera::exp_so3(Eigen::Vector3d(1.5 / c.f_px, 2.5 / c.f_px, 0.0));
    c.f_px *= 1.004;
    for (const auto& p : poses) {
      std::string q;
      for (int i = 0; i < p.q.size(); ++i) q += (i ? "," : "") + std::to_string(p.q[i]);
      const std::string frame = temp_path(".png");
      const auto s = run_foresight("synth --camera " + name + " --joints " + q + " --out " + frame +
                                   " --arm-links " + truth_arm + " --seed " + std::to_string(21 + n++));
      ASSERT_EQ(s.status, 0) << s.err;
      args += " --camera " + name + " --image " + frame + " --joints " + q;
    }
  }
  const std::string start_yaml = temp_path(".yaml"), out = temp_path(".yaml"), arm_out = temp_path(".yaml");
  camera::save_cameras(start_yaml, start);
  const auto r = run_foresight("align --cameras " + start_yaml + args + " --arm-prior-mm 2 --arm-out " + arm_out +
                               " --out " + out + " --json");
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["cameras"].size(), 3u);  // three cameras, four frames each
  const align::ArmLinkCorrections est = align::load_arm_links(arm_out, f.model);
  ASSERT_EQ(est.sigma_m.size(), nseg);
  EXPECT_EQ(j["arm_link_delta_m"].get<std::vector<double>>().size(), nseg);
  double t2 = 0.0, e2 = 0.0;
  for (const int k : segs) {
    const double err = est.delta_m[k] - truth.delta_m[k];
    std::printf("link %d: truth %+.2f mm, estimate %+.2f mm (sd %.2f)\n", k, truth.delta_m[k] * 1e3, est.delta_m[k] * 1e3,
                est.sigma_m[k] * 1e3);
    EXPECT_NEAR(est.delta_m[k], j["arm_link_delta_m"][k].get<double>(), 1e-9);
    t2 += truth.delta_m[k] * truth.delta_m[k];
    e2 += err * err;
  }
  std::printf("links: true error %.2f mm rms, estimate's error %.2f mm rms\n", std::sqrt(t2 / segs.size()) * 1e3,
              std::sqrt(e2 / segs.size()) * 1e3);
  EXPECT_LT(std::sqrt(e2), 0.5 * std::sqrt(t2));
  EXPECT_EQ(camera::load_cameras(out).size(), 3u);  // the refined cameras

  // Read back: the model rendered and sampled with the corrections.
  const auto back = run_foresight("align --cameras " + out + " --camera side --image " + f.frame + " --joints " +
                                  f.q_text + " --arm-links " + arm_out + " --json");
  ASSERT_EQ(back.status, 0) << back.err;
  const auto jb = nlohmann::json::parse(back.out);
  for (const int k : segs) EXPECT_NEAR(jb["arm_link_delta_m"][k].get<double>(), est.delta_m[k], 1e-9);
}

TEST(AlignCli, ArmOptionsBadInputIsExitTwoAndWritesNothing) {
  auto& f = fixture();
  const std::string base = "align --cameras " + f.start_yaml + " --camera side --image " + f.frame + " --joints " + f.q_text;
  const std::string arm_out = temp_path(".yaml");
  const auto object = run_foresight(base + " --refine object --object-pose x.json --arm-prior-mm 2");
  EXPECT_EQ(object.status, 2);
  EXPECT_EQ(object.err, "foresight align: error: --arm-prior-mm refines the arm with the cameras: use --refine camera or both\n");
  const auto no_prior = run_foresight(base + " --arm-out " + arm_out);
  EXPECT_EQ(no_prior.status, 2);
  EXPECT_EQ(no_prior.err, "foresight align: error: --arm-out writes the refined arm: give --arm-prior-mm\n");
  const auto negative = run_foresight(base + " --arm-prior-mm -1");
  EXPECT_EQ(negative.status, 2);
  EXPECT_EQ(negative.err, "foresight align: error: --arm-prior-mm must be a non-negative number\n");
  const std::string few = temp_path(".yaml");
  {
    std::ofstream o(few);
    o << "arm_link_delta_m: [0.001, 0, 0]\n";
  }
  const auto short_list = run_foresight(base + " --arm-links " + few + " --arm-prior-mm 2 --arm-out " + arm_out);
  EXPECT_EQ(short_list.status, 2);
  EXPECT_EQ(short_list.err, "foresight align: error: " + few + ": arm_link_delta_m: 3 values for the arm's " +
                                std::to_string(f.model.segment_count()) + " chain segments\n");
  // A correction on a segment without a length offset (the base's fixed
  // frame, if it has none) or beyond 0.1 m: not this arm's link error.
  const std::string far = temp_path(".yaml");
  {
    std::vector<double> d(f.model.segment_count(), 0.0);
    d[f.model.offset_segments().front()] = 0.25;
    align::save_arm_links(far, {d, {}}, "config/robot.urdf", "2026-12-03T00:00:00Z");
  }
  const auto too_far = run_foresight(base + " --arm-links " + far);
  EXPECT_EQ(too_far.status, 2);
  EXPECT_NE(too_far.err.find(far + ": arm_link_delta_m[" + std::to_string(f.model.offset_segments().front()) +
                             "]: 0.250000 m is not a link-length error (limit 0.1 m): is this file for another arm?"),
            std::string::npos)
      << too_far.err;
  EXPECT_FALSE(std::filesystem::exists(arm_out));
}
