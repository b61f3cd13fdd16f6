// CLI-level tests: run the built `foresight` binary on generated files and
// check exit codes, stderr messages and the --json contract of calibrate,
// localize and eval localization.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/calibration/robot_points.hpp"
#include "foresight/test/cli.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/localize.hpp"

using namespace foresight;

namespace {

using test::CliRun;
using test::temp_path;
CliRun run(const std::string& args) { return test::run_foresight(args); }
std::string write_file(const std::string& text, const std::string& suffix = ".csv") {
  return test::write_temp_file(text, suffix);
}

std::map<std::string, camera::Camera> scene_cameras() {
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  std::map<std::string, camera::Camera> out;
  for (const auto& [name, c] : scene.cameras)
    out[name] = camera::Camera::look_at(name, {c.width_px, c.height_px}, c.f_px, c.position_m, c.look_at_m, c.up);
  return out;
}

/// Base-frame clicks for `cam`: workspace points it sees, noisy pixels.
std::string calibration_csv(const camera::Camera& cam, int count, double noise, unsigned seed, int outlier_n = -1) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> x(0.35, 0.95), y(-0.35, 0.55), z(0.2, 1.0);
  std::normal_distribution<double> g(0.0, noise);
  std::ostringstream s;
  s.precision(12);
  s << "n,cam,x,y,z,u,v\n";
  int n = 0;
  while (n < count) {
    const Eigen::Vector3d p(x(rng), y(rng), z(rng));
    if (!cam.in_front(p) || !cam.in_view(cam.project(p))) continue;
    ++n;
    Eigen::Vector2d uv = cam.project(p) + Eigen::Vector2d(g(rng), g(rng));
    if (n == outlier_n) uv += Eigen::Vector2d(30.0, -20.0);
    s << n << ',' << cam.name << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ',' << uv.y() << '\n';
  }
  return s.str();
}

}  // namespace

TEST(CliCalibrate, JsonContractAndCamerasFile) {
  const auto cams = scene_cameras();
  const camera::Camera& side = cams.at("side");
  const std::string pts = write_file(calibration_csv(side, 30, 0.3, 1, 7) + calibration_csv(cams.at("oblique"), 25, 0.3, 2).substr(16));
  const std::string out = temp_path(".yaml");
  const CliRun r = run("calibrate " + pts + " --camera side --json --out " + out);
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  for (const char* key : {"camera", "f_px", "fovy_deg", "position_m", "rpy_deg", "base_T_camera", "rms_px", "max_px",
                          "linear_rms_px", "residuals_px", "outliers", "sigma", "iterations", "n_points"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["camera"], "side");
  EXPECT_EQ(j["n_points"], 30);
  EXPECT_EQ(j["outliers"], nlohmann::json::array({7}));
  EXPECT_EQ(j["residuals_px"].size(), 30u);
  EXPECT_EQ(j["residuals_px"][6]["n"], 7);
  EXPECT_GT(j["residuals_px"][6]["px"].get<double>(), 20.0);
  EXPECT_EQ(j["base_T_camera"].size(), 4u);
  EXPECT_EQ(j["base_T_camera"][0].size(), 4u);
  EXPECT_LT(j["rms_px"].get<double>(), 1.0);
  const double f = j["f_px"], sf = j["sigma"]["f_px"];
  EXPECT_LT(std::abs(f - side.f_px), 5.0 * sf);
  for (int i = 0; i < 3; ++i) {
    const double p = j["position_m"][i], sp = j["sigma"]["position_m"][i];
    EXPECT_LT(std::abs(p - side.base_T_camera.translation()[i]), 5.0 * sp) << i;
    EXPECT_GT(j["sigma"]["rpy_deg"][i].get<double>(), 0.0);
  }
  EXPECT_NEAR(j["fovy_deg"].get<double>(), 2.0 * std::atan(243.0 / f) * 180.0 / M_PI, 1e-9);
  // --out adds the camera and keeps the others.
  const CliRun r2 = run("calibrate " + pts + " --camera oblique --out " + out);
  ASSERT_EQ(r2.status, 0) << r2.err;
  EXPECT_NE(r2.out.find("camera oblique"), std::string::npos);
  const auto file = camera::load_cameras(out);
  ASSERT_EQ(file.size(), 2u);
  EXPECT_NEAR(file.at("side").camera.f_px, f, 1e-6);
  ASSERT_TRUE(file.at("side").calibration.has_value());
  EXPECT_EQ(file.at("side").calibration->outliers, std::vector<int>{7});
  EXPECT_GT(file.at("side").calibration->covariance(6, 6), 0.0);
  std::remove(pts.c_str());
  std::remove(out.c_str());
}

TEST(CliCalibrate, ArmAsFixtureRows) {
  // Points on the arm's links at three arm poses, through the URDF's FK.
  const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  const calibration::RobotLinkPoints robot(model);
  const camera::Camera side = scene_cameras().at("side");
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> off(-0.05, 0.05);
  std::ostringstream s;
  s.precision(12);
  s << "n,cam,link";
  s << ",lx,ly,lz";
  for (int i = 1; i <= model.dof(); ++i) s << ",q" << i;
  s << ",u,v\n";
  int n = 0;
  for (int pose = 0; pose < 3; ++pose) {
    Eigen::VectorXd q = model.mid_configuration();
    for (int i = 0; i < q.size(); ++i) q[i] += 0.25 * (pose - 1) * ((i % 2) ? 1.0 : -0.6);
    for (int k = 1; k < static_cast<int>(model.links().size()); ++k) {
      const Eigen::Vector3d pl(off(rng), off(rng), off(rng));
      const Eigen::Vector3d pb = robot.to_base(model.links()[k].name, pl, q);
      if (!side.in_front(pb) || !side.in_view(side.project(pb))) continue;
      const Eigen::Vector2d uv = side.project(pb);
      s << ++n << ",side," << model.links()[k].name << ',' << pl.x() << ',' << pl.y() << ',' << pl.z();
      for (int i = 0; i < q.size(); ++i) s << ',' << q[i];
      s << ',' << uv.x() << ',' << uv.y() << '\n';
    }
  }
  ASSERT_GE(n, 8);
  const std::string pts = write_file(s.str());
  const CliRun r = run("calibrate " + pts + " --camera side --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_NEAR(j["f_px"].get<double>(), side.f_px, 1e-4);
  EXPECT_LT(j["rms_px"].get<double>(), 1e-6);
  EXPECT_EQ(j["arm_model_sigma"]["f_px"].get<double>(), 0.0);
  // --arm-link-sigma: the arm model's link-length uncertainty enters the
  // camera's covariance (JSON and cameras.yaml) as the library computes it;
  // the camera is the same.
  const std::string yaml = temp_path(".yaml");
  const CliRun ra = run("calibrate " + pts + " --camera side --json --arm-link-sigma 0.002 --out " + yaml);
  ASSERT_EQ(ra.status, 0) << ra.err;
  const auto ja = nlohmann::json::parse(ra.out);
  EXPECT_EQ(ja["f_px"].get<double>(), j["f_px"].get<double>());
  calibration::CalibrationOptions arm_options;
  arm_options.arm_link_sigma_m = 0.002;
  const calibration::CalibrationResult lib =
      calibration::calibrate_camera(calibration::select_camera(calibration::read_correspondences_csv(pts, &robot), "side"), side.viewport, "side", arm_options);
  ASSERT_GT(lib.arm_model_covariance(6, 6), 0.0);
  EXPECT_NEAR(ja["arm_model_sigma"]["f_px"].get<double>(), std::sqrt(lib.arm_model_covariance(6, 6)),
              1e-9 * std::sqrt(lib.arm_model_covariance(6, 6)));
  EXPECT_EQ(ja["arm_model_sigma"]["arm_link_sigma_m"].get<double>(), 0.002);
  EXPECT_NEAR(ja["sigma"]["f_px"].get<double>(), lib.sigma[6], 1e-9 * lib.sigma[6]);
  const camera::CameraCalibrationInfo stored = *camera::load_cameras(yaml).at("side").calibration;
  EXPECT_NEAR(stored.covariance(6, 6), lib.covariance(6, 6), 1e-6 * lib.covariance(6, 6));
  // cameras.yaml keeps the camera's response to the links (rpy, as the
  // covariance), so localization can carry the arm's error on.
  EXPECT_EQ(stored.arm_link_sigma_m, 0.002);
  const Eigen::MatrixXd K_rpy = lib.info("").arm_link_sensitivity;
  ASSERT_EQ(stored.arm_link_sensitivity.rows(), 7);
  ASSERT_EQ(stored.arm_link_sensitivity.cols(), K_rpy.cols());
  EXPECT_LT((stored.arm_link_sensitivity - K_rpy).norm(), 1e-9 * K_rpy.norm());
  EXPECT_LT((0.002 * 0.002 * K_rpy * K_rpy.transpose() - lib.arm_model_covariance).norm(),
            1e-9 * lib.arm_model_covariance.norm());

  // The ORU clicked in this camera: `localize` holds the camera and its
  // sigma carries the camera's calibration noise and the arm's links, as the
  // library computes them from what the calibration gave.
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  std::ostringstream o;
  o.precision(12);
  o << "n,cam,x,y,z,u,v\n";
  for (std::size_t i = 0; i < oru.points.size(); ++i) {
    const Eigen::Vector3d p = oru.points[i].p_m;
    if (p.z() > 0.0) continue;  // the back of the ORU is inside the panel
    const Eigen::Vector2d uv = side.project(scene.base_T_object * p);
    o << i + 1 << ",side," << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ',' << uv.y() << '\n';
  }
  const std::string oru_pts = write_file(o.str());
  const CliRun rl = run("localize " + oru_pts + " --cameras " + yaml + " --json");
  ASSERT_EQ(rl.status, 0) << rl.err;
  const auto jl = nlohmann::json::parse(rl.out);
  EXPECT_EQ(jl["arm_link_sigma_m"].get<double>(), 0.002);
  EXPECT_EQ(jl["held_camera_uncertainty"], nlohmann::json::array({"side"}));
  localization::LocalizationOptions lo;
  const Eigen::Matrix3d R = lib.camera.base_T_camera.linear();
  lo.camera_covariance["side"] = calibration::camera_covariance_body_from_rpy(lib.covariance - lib.arm_model_covariance, R);
  lo.camera_link_sensitivity["side"] = lib.link_sensitivity;
  lo.arm_link_sigma_m = 0.002;
  const std::map<std::string, camera::Camera> cams = {{"side", lib.camera}};
  const auto oru_clicks = calibration::read_correspondences_csv(oru_pts);
  const localization::LocalizationResult with = localization::localize_object(oru_clicks, cams, lo), exact = localization::localize_object(oru_clicks, cams);
  for (int i = 0; i < 3; ++i) {
    const double sp = jl["sigma"]["position_m"][i];
    EXPECT_NEAR(sp, with.sigma_position_m[i], 1e-4 * sp) << i;
    const double srpy = with.sigma_rpy_rad[i] * 180.0 / M_PI;
    EXPECT_NEAR(jl["sigma"]["rpy_deg"][i].get<double>(), srpy, 1e-4 * srpy) << i;
    EXPECT_GT(sp, 3.0 * exact.sigma_position_m[i]) << i;  // the arm dominates: exact clicks
  }
  std::remove(oru_pts.c_str());
  std::remove(yaml.c_str());
  const CliRun bad_sigma = run("calibrate " + pts + " --camera side --arm-link-sigma -0.001");
  EXPECT_EQ(bad_sigma.status, 2);
  EXPECT_NE(bad_sigma.err.find("--arm-link-sigma"), std::string::npos) << bad_sigma.err;
  // A wrong joint count and an unknown link, with their line numbers.
  std::string text = s.str();
  const std::size_t second_line = text.find('\n') + 1;
  std::string bad_link = text;
  bad_link.replace(bad_link.find(",side,", second_line) + 6, 0, "no_such_");
  const std::string p2 = write_file(bad_link);
  const CliRun r2 = run("calibrate " + p2 + " --camera side");
  EXPECT_EQ(r2.status, 2);
  EXPECT_NE(r2.err.find(p2 + ":2: unknown link 'no_such_"), std::string::npos) << r2.err;
  std::string short_q = text.substr(0, second_line) + "1,side,lst_tip,0,0,0,0.1,0.2,100,200\n";
  const std::string p3 = write_file(short_q);
  const CliRun r3 = run("calibrate " + p3 + " --camera side");
  EXPECT_EQ(r3.status, 2);
  EXPECT_NE(r3.err.find(p3 + ":2: point on link 'lst_tip' needs " + std::to_string(model.dof()) + " joint angles"),
            std::string::npos)
      << r3.err;
  for (const auto& p : {pts, p2, p3}) std::remove(p.c_str());
}

TEST(CliCalibrate, AFailedComputationExitsOne) {
  // The fit cannot converge in one iteration on noisy clicks: a computation
  // failure (EstimationError, a ComputationError), exit 1, not bad input (2).
  const std::string pts = write_file(calibration_csv(scene_cameras().at("side"), 30, 1.0, 21));
  const CliRun r = run("calibrate " + pts + " --camera side --max-iterations 1");
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("foresight calibrate: error: camera 'side': the nonlinear fit did not converge after 1 iterations"),
            std::string::npos)
      << r.err;
  const CliRun ok = run("calibrate " + pts + " --camera side");
  EXPECT_EQ(ok.status, 0) << ok.err;
  std::remove(pts.c_str());
}

TEST(CliCalibrate, BadInputsExitTwoWithTheirMessage) {
  const camera::Camera side = scene_cameras().at("side");
  const CliRun missing = run("calibrate /nonexistent/pts.csv --camera side");
  EXPECT_EQ(missing.status, 2);
  EXPECT_NE(missing.err.find("/nonexistent/pts.csv: cannot open points file"), std::string::npos) << missing.err;

  const std::string good = calibration_csv(side, 10, 0.0, 4);
  const std::string bad_row = write_file(good.substr(0, good.find('\n', good.find('\n') + 1) + 1) + "2,side,1,2,3,x,5\n");
  const CliRun r1 = run("calibrate " + bad_row + " --camera side");
  EXPECT_EQ(r1.status, 2);
  EXPECT_NE(r1.err.find(bad_row + ":3: field 'u' is not a number: 'x'"), std::string::npos) << r1.err;

  const std::string nan_row = write_file("n,cam,x,y,z,u,v\n1,side,1,2,nan,4,5\n");
  const CliRun r2 = run("calibrate " + nan_row + " --camera side");
  EXPECT_EQ(r2.status, 2);
  EXPECT_NE(r2.err.find(nan_row + ":2: field 'z' is not finite: 'nan'"), std::string::npos) << r2.err;

  const std::string ten = write_file(good);
  const CliRun r3 = run("calibrate " + ten + " --camera top");
  EXPECT_EQ(r3.status, 2);
  EXPECT_NE(r3.err.find("no points for camera 'top' (cameras in the file: side)"), std::string::npos) << r3.err;

  const std::string five = write_file(calibration_csv(side, 5, 0.0, 5));
  const CliRun r4 = run("calibrate " + five + " --camera side --json");
  EXPECT_EQ(r4.status, 2);
  EXPECT_TRUE(r4.out.empty());
  EXPECT_NE(r4.err.find("camera 'side': 5 points; the linear calibration needs at least 6"), std::string::npos) << r4.err;

  // Coplanar points (all at z = 0.5).
  std::ostringstream s;
  s << "n,cam,x,y,z,u,v\n";
  for (int i = 0; i < 9; ++i) {
    const Eigen::Vector3d p(0.6 + 0.05 * (i % 3), 0.1 * (i / 3), 0.5);
    const Eigen::Vector2d uv = side.project(p);
    s << i + 1 << ",side," << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ',' << uv.y() << '\n';
  }
  const std::string plane = write_file(s.str());
  const CliRun r5 = run("calibrate " + plane + " --camera side");
  EXPECT_EQ(r5.status, 2);
  EXPECT_NE(r5.err.find("camera 'side': the 9 points are coplanar"), std::string::npos) << r5.err;

  const CliRun r6 = run("calibrate " + ten + " --camera side --viewport 646by486");
  EXPECT_EQ(r6.status, 2);
  EXPECT_NE(r6.err.find("viewport '646by486' is not WIDTHxHEIGHT"), std::string::npos) << r6.err;
  for (const auto& p : {bad_row, nan_row, ten, five, plane}) std::remove(p.c_str());
}

TEST(CliLocalize, JsonContractTagsViewsAndBadInputs) {
  const auto cams = scene_cameras();
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  std::map<std::string, camera::CameraRecord> recs;
  for (const auto& [name, c] : cams) recs[name] = camera::CameraRecord{c, std::nullopt};
  const std::string cam_file = temp_path(".yaml");
  camera::save_cameras(cam_file, recs);
  std::ostringstream s;
  s.precision(12);
  s << "n,cam,x,y,z,u,v\n";
  std::mt19937 rng(9);
  std::normal_distribution<double> g(0.0, 0.2);
  for (const auto& name : {"side", "oblique", "overhead_wide"})
    for (std::size_t i = 0; i < oru.points.size(); ++i) {
      const Eigen::Vector3d p = oru.points[i].p_m;
      if (p.z() > 0.0) continue;  // the back of the ORU is inside the panel
      const Eigen::Vector2d uv = cams.at(name).project(scene.base_T_object * p) + Eigen::Vector2d(g(rng), g(rng));
      s << i + 1 << ',' << name << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ',' << uv.y() << '\n';
    }
  const std::string pts = write_file(s.str());
  const CliRun r = run("localize " + pts + " --cameras " + cam_file + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  for (const char* key : {"object", "base_T_object", "position_m", "rpy_deg", "sigma", "rms_px", "outliers", "views", "tags"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["object"], "oru");
  EXPECT_EQ(j["views"], nlohmann::json::array({"oblique", "overhead_wide", "side"}));
  for (int i = 0; i < 3; ++i) {
    const double p = j["position_m"][i], sp = j["sigma"]["position_m"][i];
    EXPECT_LT(std::abs(p - scene.base_T_object.translation()[i]), 5.0 * sp + 1e-9) << i;
    EXPECT_GT(j["sigma"]["rpy_deg"][i].get<double>(), 0.0);
  }
  ASSERT_TRUE(j["tags"].contains("hole_entrance"));
  Eigen::Matrix4d T, H;
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) {
      T(a, b) = j["base_T_object"][a][b];
      H(a, b) = j["tags"]["approach_20cm"][a][b];
    }
  EXPECT_LT((H - T * oru.tags.at("approach_20cm").matrix()).norm(), 1e-9);
  EXPECT_EQ(j["tags"].size(), oru.tags.size());

  const CliRun two = run("localize " + pts + " --cameras " + cam_file + " --views side,oblique --json");
  ASSERT_EQ(two.status, 0) << two.err;
  EXPECT_EQ(nlohmann::json::parse(two.out)["views"], nlohmann::json::array({"oblique", "side"}));

  const CliRun noview = run("localize " + pts + " --cameras " + cam_file + " --views side,overhead_zoom");
  EXPECT_EQ(noview.status, 2);
  EXPECT_NE(noview.err.find("view 'overhead_zoom' has no points"), std::string::npos) << noview.err;

  const std::string unknown = write_file(s.str() + "99,top,0,0,0,100,100\n");
  const CliRun r2 = run("localize " + unknown + " --cameras " + cam_file);
  EXPECT_EQ(r2.status, 2);
  EXPECT_NE(r2.err.find("point n=99 (line"), std::string::npos) << r2.err;
  EXPECT_NE(r2.err.find("unknown camera 'top' (known cameras: oblique, overhead_wide, overhead_zoom, side)"),
            std::string::npos)
      << r2.err;

  const CliRun r4 = run("localize " + pts + " --cameras " + cam_file + " --camera-uncertainty");
  EXPECT_EQ(r4.status, 2);
  EXPECT_NE(r4.err.find(cam_file + ": camera 'oblique' has no calibration covariance (--camera-uncertainty)"),
            std::string::npos)
      << r4.err;

  const CliRun r3 = run("localize " + pts + " --cameras /nonexistent/cameras.yaml");
  EXPECT_EQ(r3.status, 2);
  EXPECT_NE(r3.err.find("/nonexistent/cameras.yaml: cannot open camera file"), std::string::npos) << r3.err;
  for (const auto& p : {pts, unknown, cam_file}) std::remove(p.c_str());
}

TEST(CliEval, LocalizationJsonAndProgressOnStderr) {
  const CliRun r = run("eval localization --trials 12 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);  // the progress bar stays off stdout
  EXPECT_EQ(j["trials"], 12);
  ASSERT_EQ(j["combos"].size(), 15u);
  EXPECT_EQ(j["combos"][14]["views"], "1+2+3+4");
  for (const char* key : {"ours", "ours_joint", "crlb", "crlb_known_cameras", "pnp_sqpnp", "pnp_iterative", "triangulation"})
    EXPECT_TRUE(j["combos"][0].contains(key)) << key;
  EXPECT_EQ(j["views"].size(), 4u);
  EXPECT_GT(j["four_view"]["crlb_position_m"].get<double>(), 0.0);
  EXPECT_GT(j["four_view"]["position_rmse_m"].get<double>(), 0.0);
  EXPECT_NE(r.err.find("100%"), std::string::npos);
  EXPECT_EQ(j["seeds"], 1);
  EXPECT_EQ(j["over_seeds"].size(), 15u);
  EXPECT_FALSE(j.contains("with_arm_model_error"));

  // Several seeds and the arm-model error: both studies, their spread.
  const CliRun both = run("eval localization --trials 3 --seeds 2 --arm-error-mm 2 --json");
  ASSERT_EQ(both.status, 0) << both.err;
  const auto k = nlohmann::json::parse(both.out);
  EXPECT_EQ(k["seeds"], 2);
  ASSERT_EQ(k["over_seeds"].size(), 15u);
  EXPECT_GT(k["over_seeds"][14]["position_rmse_mm"]["sd"].get<double>(), 0.0);
  EXPECT_EQ(k["with_arm_model_error"]["link_length_sd_mm"], 2.0);
  EXPECT_EQ(k["with_arm_model_error"]["over_seeds"].size(), 15u);
  EXPECT_GT(k["with_arm_model_error"]["four_view"]["position_rmse_m"].get<double>(), 0.0);
  const CliRun text = run("eval localization --trials 2 --seeds 2 --arm-error-mm 2");
  ASSERT_EQ(text.status, 0) << text.err;
  EXPECT_NE(text.out.find("Arm-model error (link lengths off by 2.0 mm sd): RMSE over 2 seeds x 2 trials"),
            std::string::npos)
      << text.out;
  const CliRun neg = run("eval localization --arm-error-mm -1");
  EXPECT_EQ(neg.status, 2);
  EXPECT_NE(neg.err.find("--arm-error-mm must be a non-negative number"), std::string::npos) << neg.err;

  const CliRun bad = run("eval localization --trials 0");
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE(bad.err.find("--trials must be at least 1"), std::string::npos) << bad.err;
  const CliRun none = run("eval");
  EXPECT_EQ(none.status, 2);
}

TEST(CliLocalize, CalibrateThenLocalizeWithCameraUncertainty) {
  // The whole chain through the binary: calibrate three cameras into one
  // cameras.yaml, then localize with and without their covariance.
  const auto cams = scene_cameras();
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const std::string cam_file = temp_path(".yaml");
  std::string cal = "n,cam,x,y,z,u,v\n";
  unsigned seed = 20;
  for (const auto& name : {"side", "oblique", "overhead_wide"})
    cal += calibration_csv(cams.at(name), 25, 0.5, ++seed).substr(16);
  const std::string cal_file = write_file(cal);
  for (const auto& name : {"side", "oblique", "overhead_wide"}) {
    const CliRun r = run("calibrate " + cal_file + " --camera " + name + " --out " + cam_file);
    ASSERT_EQ(r.status, 0) << r.err;
  }
  std::ostringstream s;
  s.precision(12);
  s << "n,cam,x,y,z,u,v\n";
  std::mt19937 rng(4);
  std::normal_distribution<double> g(0.0, 0.5);
  for (const auto& name : {"side", "oblique", "overhead_wide"})
    for (std::size_t i = 0; i < oru.points.size(); ++i) {
      const Eigen::Vector3d p = oru.points[i].p_m;
      if (p.z() > 0.0) continue;
      const Eigen::Vector2d uv = cams.at(name).project(scene.base_T_object * p) + Eigen::Vector2d(g(rng), g(rng));
      s << i + 1 << ',' << name << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ',' << uv.y() << '\n';
    }
  const std::string pts = write_file(s.str());
  const CliRun plain = run("localize " + pts + " --cameras " + cam_file + " --json");
  const CliRun joint = run("localize " + pts + " --cameras " + cam_file + " --camera-uncertainty --json");
  ASSERT_EQ(plain.status, 0) << plain.err;
  ASSERT_EQ(joint.status, 0) << joint.err;
  const auto jp = nlohmann::json::parse(plain.out), jj = nlohmann::json::parse(joint.out);
  EXPECT_EQ(jp["camera_uncertainty"], false);
  EXPECT_EQ(jj["camera_uncertainty"], true);
  // Without --camera-uncertainty the cameras are held as calibrated, and
  // their calibration covariance enters the sigma (the library's
  // camera_covariance, from cameras.yaml); the pose is the paper's two-step one.
  EXPECT_EQ(jp["held_camera_uncertainty"], nlohmann::json::array({"oblique", "overhead_wide", "side"}));
  EXPECT_EQ(jj["held_camera_uncertainty"], nlohmann::json::array());
  EXPECT_EQ(jp["arm_link_sigma_m"].get<double>(), 0.0);
  std::map<std::string, camera::Camera> calibrated;
  localization::LocalizationOptions held;
  for (const auto& [name, rec] : camera::load_cameras(cam_file)) {
    calibrated[name] = rec.camera;
    if (rec.calibration)
      held.camera_covariance[name] = calibration::camera_covariance_body_from_rpy(rec.calibration->covariance, rec.camera.base_T_camera.linear());
  }
  const auto clicks = calibration::read_correspondences_csv(pts);
  const localization::LocalizationResult exact = localization::localize_object(clicks, calibrated), lib = localization::localize_object(clicks, calibrated, held);
  for (int i = 0; i < 3; ++i) {
    const double sj = jj["sigma"]["position_m"][i], sp = jp["sigma"]["position_m"][i];
    EXPECT_NEAR(jp["position_m"][i].get<double>(), exact.position_m()[i], 1e-9) << i;
    EXPECT_NEAR(sp, lib.sigma_position_m[i], 1e-4 * sp) << i;
    // The calibration error is part of the uncertainty, both ways.
    EXPECT_GT(sp, 1.2 * exact.sigma_position_m[i]) << i;
    EXPECT_GT(sj, exact.sigma_position_m[i]) << i;
    EXPECT_LT(std::abs(jj["position_m"][i].get<double>() - scene.base_T_object.translation()[i]), 5.0 * sj) << i;
  }
  for (const auto& p : {pts, cal_file, cam_file}) std::remove(p.c_str());
}

TEST(CliLocalize, CamerasCalibratedWithDifferentArmSigmasAreRefused) {
  // The arm's links are one arm: two cameras that claim different link sds
  // for it cannot both be right, and localize says which.
  const auto cams = scene_cameras();
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  std::map<std::string, camera::CameraRecord> records;
  double sd = 0.001;
  for (const char* name : {"oblique", "side"}) {
    camera::CameraRecord& rec = records[name];
    rec.camera = cams.at(name);
    camera::CameraCalibrationInfo info;
    info.covariance = 1e-8 * Eigen::Matrix<double, 7, 7>::Identity();
    info.rms_px = 0.5;
    info.n_points = 20;
    info.arm_link_sigma_m = sd;
    sd *= 2.0;
    info.arm_link_sensitivity = Eigen::MatrixXd::Constant(7, 10, 0.01);
    rec.calibration = info;
  }
  const std::string cam_file = temp_path(".yaml");
  camera::save_cameras(cam_file, records);
  std::ostringstream s;
  s.precision(12);
  s << "n,cam,x,y,z,u,v\n";
  for (const char* name : {"oblique", "side"})
    for (std::size_t i = 0; i < oru.points.size(); ++i) {
      const Eigen::Vector3d p = oru.points[i].p_m;
      if (p.z() > 0.0) continue;
      const Eigen::Vector2d uv = cams.at(name).project(scene.base_T_object * p);
      s << i + 1 << ',' << name << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ',' << uv.y() << '\n';
    }
  const std::string pts = write_file(s.str());
  const CliRun r = run("localize " + pts + " --cameras " + cam_file + " --json");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.out, "");
  EXPECT_NE(r.err.find(cam_file + ": cameras 'oblique' and 'side' were calibrated with different arm link sigmas (1.00 and 2.00 mm)"),
            std::string::npos)
      << r.err;
  // One view alone is fine.
  const CliRun one = run("localize " + pts + " --cameras " + cam_file + " --views side --json");
  ASSERT_EQ(one.status, 0) << one.err;
  EXPECT_EQ(nlohmann::json::parse(one.out)["arm_link_sigma_m"].get<double>(), 0.002);
  for (const auto& p : {pts, cam_file}) std::remove(p.c_str());
}
