// The overlay, preview, predictive and synth commands end to end through the
// `foresight` binary: a synthetic frame and its true cameras, overlays on it,
// and every bad input with its exact message and exit status.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"

using namespace foresight;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;
const std::string kExe = std::string(FORESIGHT_BIN_DIR) + "/foresight";

struct CliRun {
  int rc = -1;
  std::string out, err;
};

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

class OverlayCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    char tmpl[] = "/tmp/foresight_overlay_cli_XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    const RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
    const ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
    const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
    KinematicsWorkspace ws(model);
    const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"), model.mid_configuration());
    ASSERT_TRUE(ik.success);
    q_ = ik.q;
    mid_ = model.mid_configuration();
    // localize --json output with the true object pose.
    nlohmann::json j;
    j["object"] = "oru";
    for (int r = 0; r < 4; ++r) {
      nlohmann::json row = nlohmann::json::array();
      for (int c = 0; c < 4; ++c) row.push_back(scene.base_T_object.matrix()(r, c));
      j["base_T_object"].push_back(row);
    }
    std::ofstream(dir_ + "/localize.json") << j.dump();
    const CliRun s = run("synth --camera side --joints " + joints(q_) + " --out " + dir_ + "/frame.png --arm-mask " + dir_ +
                      "/arm_mask.png --write-cameras " + dir_ + "/cameras.yaml");
    ASSERT_EQ(s.rc, 0) << s.err;
  }
  static void TearDownTestSuite() { std::system(("rm -rf " + dir_).c_str()); }

  static std::string joints(const Eigen::VectorXd& q) {
    std::string s;
    char b[40];
    for (int i = 0; i < q.size(); ++i) {
      std::snprintf(b, sizeof b, "%s%.17g", i ? "," : "", q[i]);
      s += b;
    }
    return s;
  }

  static CliRun run(const std::string& args) {
    static int counter = 0;
    const std::string out = dir_ + "/stdout" + std::to_string(counter), err = dir_ + "/stderr" + std::to_string(counter++);
    CliRun r;
    const int status = std::system(("timeout 120 " + kExe + " " + args + " >" + out + " 2>" + err).c_str());
    r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
  }

  std::string overlay_args(const std::string& extra) const {
    return "overlay --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ + "/frame.png --joints " +
           joints(q_) + " " + extra;
  }

  static std::string dir_;
  static Eigen::VectorXd q_, mid_;
};

std::string OverlayCli::dir_;
Eigen::VectorXd OverlayCli::q_, OverlayCli::mid_;

}  // namespace

// Wire-frame through the true camera: the green arm edges lie on the
// synthetic camera's arm silhouette; the yellow object edges appear with --object-pose.
TEST_F(OverlayCli, WireFrameLandsOnTheSyntheticArm) {
  const CliRun r = run(overlay_args("--mode wire --object-pose " + dir_ + "/localize.json --tags --out " + dir_ +
                                 "/wire.png --json"));
  ASSERT_EQ(r.rc, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["mode"], "wire");
  EXPECT_EQ(j["object_drawn"], true);
  const cv::Mat img = cv::imread(dir_ + "/wire.png"), mask = cv::imread(dir_ + "/arm_mask.png", cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty());
  ASSERT_FALSE(mask.empty());
  cv::Mat near_arm;
  cv::dilate(mask, near_arm, cv::Mat::ones(5, 5, CV_8U));
  // Arm edges are drawn in (R, G, B) = (51, 255, 77), the object's in (255, 217, 26),
  // the tag triads' y axes in pure green.
  auto is = [](const cv::Vec3b& p, int r, int g, int b) {
    return std::abs(p[2] - r) <= 2 && std::abs(p[1] - g) <= 2 && std::abs(p[0] - b) <= 2;
  };
  int green = 0, green_on_arm = 0, yellow = 0, triad = 0;
  for (int r = 0; r < img.rows; ++r)
    for (int c = 0; c < img.cols; ++c) {
      const cv::Vec3b p = img.at<cv::Vec3b>(r, c);
      if (is(p, 51, 255, 77)) {
        ++green;
        green_on_arm += near_arm.at<std::uint8_t>(r, c) > 0;
      }
      yellow += is(p, 255, 217, 26);
      triad += is(p, 0, 255, 0);
    }
  EXPECT_GT(green, 1000);
  EXPECT_GT(green_on_arm, 0.98 * green);
  EXPECT_GT(yellow, 200);
  EXPECT_GT(triad, 20);
}

TEST_F(OverlayCli, EveryModeAndBothBackEnds) {
  for (const std::string mode : {"wire", "solid", "hidden", "ghost"})
    for (const std::string gl : {"osmesa", "egl"}) {
      const std::string out = dir_ + "/" + mode + "_" + gl + ".png";
      const CliRun r = run(overlay_args("--mode " + mode + " --gl " + gl + " --alpha 0.4 --out " + out));
      EXPECT_EQ(r.rc, 0) << mode << " " << gl << ": " << r.err;
      EXPECT_NE(r.out.find("mode " + mode + ", " + gl + " back end"), std::string::npos) << r.out;
      EXPECT_FALSE(cv::imread(out).empty());
    }
}

TEST_F(OverlayCli, MissingImage) {
  const CliRun r = run("overlay --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ + "/none.png --joints " +
                    joints(q_) + " --mode wire --out " + dir_ + "/x.png");
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: " + dir_ + "/none.png: cannot read image or video\n");
}

TEST_F(OverlayCli, ImageSizeMismatchSaysSoAndScalesOnlyWhenAsked) {
  cv::imwrite(dir_ + "/small.png", cv::Mat(480, 640, CV_8UC3, cv::Scalar(50, 50, 50)));
  const std::string base = "overlay --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ +
                           "/small.png --joints " + joints(q_) + " --mode wire --out " + dir_ + "/scaled.png";
  CliRun r = run(base);
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: " + dir_ +
                       "/small.png: image is 640x480 but camera 'side' has a 646x486 viewport (pass --scale-image to "
                       "resize it)\n");
  r = run(base + " --scale-image");
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(cv::imread(dir_ + "/scaled.png").cols, 646);
}

TEST_F(OverlayCli, UnknownCamera) {
  const CliRun r = run("overlay --cameras " + dir_ + "/cameras.yaml --camera front --image " + dir_ + "/frame.png --joints " +
                    joints(q_) + " --mode wire --out " + dir_ + "/x.png");
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: " + dir_ +
                       "/cameras.yaml: no camera 'front' (known: oblique, overhead_wide, overhead_zoom, side)\n");
}

TEST_F(OverlayCli, WrongJointCount) {
  const CliRun r = run("overlay --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ +
                    "/frame.png --joints 0,0,0,0,0,0 --mode wire --out " + dir_ + "/x.png");
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: --joints has 6 values but the arm has 7 joints\n");
}

TEST_F(OverlayCli, UnknownMode) {
  const CliRun r = run(overlay_args("--mode xray --out " + dir_ + "/x.png"));
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: render mode 'xray' is not one of: wire, solid, hidden, ghost\n");
}

TEST_F(OverlayCli, BadObjectPoseFile) {
  std::ofstream(dir_ + "/bad_localize.json") << R"({"object": "oru", "rms_px": 0.3})";
  const CliRun r = run(overlay_args("--mode wire --object-pose " + dir_ + "/bad_localize.json --out " + dir_ + "/x.png"));
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: " + dir_ + "/bad_localize.json: no key 'base_T_object'\n");
}

// A GL context/framebuffer that cannot be made for the camera: exit 1, says why.
TEST_F(OverlayCli, ViewportBeyondTheGlLimit) {
  std::string yaml = slurp(dir_ + "/cameras.yaml");
  const std::string from = "viewport: [646, 486]";
  ASSERT_NE(yaml.find(from), std::string::npos);
  ASSERT_LT(yaml.find("oblique:"), yaml.find(from));  // the first camera (sorted) gets the huge viewport
  // Within the cameras file's bound (32768 px) and beyond the GL's (16384 for osmesa and llvmpipe).
  yaml.replace(yaml.find(from), from.size(), "viewport: [20000, 486]");
  std::ofstream(dir_ + "/huge.yaml") << yaml;
  const CliRun r = run("overlay --cameras " + dir_ + "/huge.yaml --camera oblique --image " + dir_ + "/frame.png --joints " +
                    joints(q_) + " --mode wire --out " + dir_ + "/x.png");
  EXPECT_EQ(r.rc, 1);
  EXPECT_EQ(r.err.rfind("foresight overlay: error: viewport 20000x486 cannot be rendered: the osmesa GL limit is ", 0), 0u)
      << r.err;
}

// The insert's go/no-go on the picture (overlay --check-insert): the ORU
// localized from seed 3's clicks in all four views (a go) and in the side view
// alone (a no_go), drawn over the side camera's frame. Where the picture
// differs from the same overlay without --check-insert, around the hole's
// projection, the marks are green for the go and red for the no_go.
TEST_F(OverlayCli, CheckInsertDrawsTheHolesEllipseGreenForGoRedForNoGo) {
  ASSERT_EQ(run("synth-clicks --calibration-out " + dir_ + "/arm.csv --object-out " + dir_ + "/oru.csv --seed 3").rc, 0);
  for (const std::string cam : {"side", "oblique", "overhead_wide", "overhead_zoom"}) {
    const CliRun c = run("calibrate " + dir_ + "/arm.csv --camera " + cam + " --out " + dir_ + "/cams_fit.yaml");
    ASSERT_EQ(c.rc, 0) << c.err;
  }
  for (const std::string views : {"", " --views side"}) {
    const CliRun l = run("localize " + dir_ + "/oru.csv --cameras " + dir_ + "/cams_fit.yaml" + views + " --json");
    ASSERT_EQ(l.rc, 0) << l.err;
    std::ofstream(dir_ + (views.empty() ? "/four.json" : "/side.json")) << l.out;
  }
  for (const bool go : {true, false}) {
    const std::string pose = dir_ + (go ? "/four.json" : "/side.json"), out = dir_ + (go ? "/check_go.png" : "/check_no_go.png");
    // The marks are where the picture differs from the plain overlay of this pose.
    const CliRun q = run(overlay_args("--mode wire --object-pose " + pose + " --out " + dir_ + "/check_ref.png"));
    ASSERT_EQ(q.rc, 0) << q.err;
    const CliRun r = run(overlay_args("--mode wire --object-pose " + pose + " --check-insert --out " + out + " --json"));
    ASSERT_EQ(r.rc, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out)["insert_check"];
    EXPECT_EQ(j["verdict"], go ? "go" : "no_go");
    EXPECT_EQ(go, j["p_success"].get<double>() >= 0.99);
    EXPECT_EQ(j["label"].get<std::string>().rfind(go ? "insert: go P=" : "insert: no_go P=", 0), 0u) << j["label"];
    ASSERT_TRUE(j["hole"]["in_view"].get<bool>());
    const auto& e = j["hole"]["ellipse95"];
    const double cu = e["centre_px"][0], cv_ = e["centre_px"][1], a = e["semi_major_px"], b = e["semi_minor_px"];
    std::printf("%s: P %.4f, hole's 95%% ellipse at (%.1f, %.1f) semi-axes %.2f x %.2f px at %.1f deg; tip's %.2f x %.2f px\n",
                go ? "four views" : "side view", j["p_success"].get<double>(), cu, cv_, a, b, e["angle_deg"].get<double>(),
                j["tip"]["ellipse95"]["semi_major_px"].get<double>(), j["tip"]["ellipse95"]["semi_minor_px"].get<double>());
    EXPECT_GE(a, b);
    EXPECT_GT(b, 0.0);
    const cv::Mat img = cv::imread(out), ref = cv::imread(dir_ + "/check_ref.png");
    ASSERT_FALSE(img.empty());
    ASSERT_EQ(img.size(), ref.size());
    // The changed pixels within the cross-hair's reach (semi-major + 11 px).
    const int h = static_cast<int>(std::ceil(std::max(a, 1.5) + 12.0));
    const cv::Rect box = cv::Rect(static_cast<int>(cu) - h, static_cast<int>(cv_) - h, 2 * h + 1, 2 * h + 1) &
                         cv::Rect(0, 0, img.cols, img.rows);
    int green = 0, red = 0, changed = 0;
    for (int y = box.y; y < box.y + box.height; ++y)
      for (int x = box.x; x < box.x + box.width; ++x) {
        const cv::Vec3b c = img.at<cv::Vec3b>(y, x), o = ref.at<cv::Vec3b>(y, x);
        if (c == o) continue;
        ++changed;
        // Pixels that turned green (red): the arm's wire-frame is green already.
        const auto is_green = [](const cv::Vec3b& p) { return p[1] >= 150 && p[1] - p[2] >= 80 && p[1] - p[0] >= 80; };
        const auto is_red = [](const cv::Vec3b& p) { return p[2] >= 150 && p[2] - p[1] >= 80 && p[2] - p[0] >= 80; };
        green += is_green(c) && !is_green(o);
        red += is_red(c) && !is_red(o);
      }
    std::printf("  %d changed pixels around the hole: %d green, %d red\n", changed, green, red);
    EXPECT_GT(go ? green : red, 25);
    EXPECT_EQ(go ? red : green, 0);
    // The ellipse itself: the pixels at its ends on the major axis are in the verdict's colour.
    const double ang = e["angle_deg"].get<double>() * M_PI / 180.0;
    for (const double s : {-1.0, 1.0}) {
      const double u = cu + s * std::max(a, 1.5) * std::cos(ang), v = cv_ + s * std::max(a, 1.5) * std::sin(ang);
      const cv::Vec3b c = img.at<cv::Vec3b>(static_cast<int>(std::floor(v)), static_cast<int>(std::floor(u)));
      if (go) EXPECT_GT(c[1] - std::max(c[0], c[2]), 60) << "(" << u << ", " << v << ")";
      else EXPECT_GT(c[2] - std::max(c[0], c[1]), 60) << "(" << u << ", " << v << ")";
    }
  }
}

// --check-insert needs a pose with its covariance, and a pose at all.
TEST_F(OverlayCli, CheckInsertWithoutACovarianceNamesTheFile) {
  CliRun r = run(overlay_args("--mode wire --object-pose " + dir_ + "/localize.json --check-insert --out " + dir_ + "/x.png"));
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: " + dir_ +
                       "/localize.json: the object pose has no covariance (localize --json or align --json write it)\n");
  r = run(overlay_args("--mode wire --check-insert --out " + dir_ + "/x.png"));
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "foresight overlay: error: --check-insert needs --object-pose (the object pose with its covariance)\n");
}

TEST_F(OverlayCli, PreviewWritesVideoAndContactSheet) {
  std::ofstream csv(dir_ + "/traj.csv");
  csv << "t,q1,q2,q3,q4,q5,q6,q7\n";
  for (int k = 0; k <= 2; ++k) {
    const Eigen::VectorXd q = mid_ + (q_ - mid_) * (k / 2.0);
    csv << k * 1.5;
    for (int i = 0; i < q.size(); ++i) csv << "," << q[i];
    csv << "\n";
  }
  csv.close();
  const CliRun r = run("preview " + dir_ + "/traj.csv --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ +
                    "/frame.png --out " + dir_ + "/preview.mp4 --contact-sheet " + dir_ +
                    "/sheet.png --speed 2 --fps 10 --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["frames"], 16);  // 3 s at speed 2: 1.5 s of video at 10 frames/s, both ends
  EXPECT_DOUBLE_EQ(j["trajectory_duration_s"].get<double>(), 3.0);
  EXPECT_FALSE(cv::imread(dir_ + "/sheet.png").empty());

  std::ofstream(dir_ + "/traj6.csv") << "t,q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0.1\n";
  const CliRun bad = run("preview " + dir_ + "/traj6.csv --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ +
                      "/frame.png --out " + dir_ + "/p6.mp4");
  EXPECT_EQ(bad.rc, 2);
  EXPECT_EQ(bad.err, "foresight preview: error: " + dir_ + "/traj6.csv: trajectory has 6 joints but the arm has 7\n");
}

TEST_F(OverlayCli, PredictiveFrame) {
  const CliRun r = run("predictive --cameras " + dir_ + "/cameras.yaml --camera side --image " + dir_ + "/frame.png --commanded " +
                    joints(q_) + " --actual " + joints(mid_) + " --delay-s 2.5 --out " + dir_ + "/pred.png --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_DOUBLE_EQ(j["delay_s"].get<double>(), 2.5);
  EXPECT_GT(j["tip_gap_m"].get<double>(), 0.05);
  EXPECT_FALSE(cv::imread(dir_ + "/pred.png").empty());
}
