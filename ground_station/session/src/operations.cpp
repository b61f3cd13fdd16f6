// The ground's file-to-file operations (operations.hpp).
#include "foresight/session/operations.hpp"
#include "foresight/session/insert_check.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <optional>
#include <random>
#include <set>
#include <sstream>

#include "foresight/align/alignment_study.hpp"
#include "foresight/align/arm_links_file.hpp"
#include "foresight/align/model_aligner.hpp"
#include "foresight/calibration/robot_points.hpp"
#include "foresight/common/atomic_file.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/format.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"
#include "foresight/render/video_frame.hpp"
#include "go_no_go_marks.hpp"

namespace foresight::session {

namespace {

std::string utc_now() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

/// The information (J^T J, pixels; body rotation, position, f) of a camera's
/// calibration from what cameras.yaml keeps: covariance C in (roll, pitch,
/// yaw, x, y, z, f) = s^2 (J_rpy^T J_rpy)^-1, with s^2 = rms^2 m / (2 m - 7)
/// over the m inliers; J_rpy = J_body W(rpy).
Eigen::Matrix<double, 7, 7> calibration_information(const std::string& file, const std::string& name,
                                                    const camera::CameraRecord& rec) {
  if (!rec.calibration) throw std::invalid_argument(file + ": camera '" + name + "' has no calibration covariance (--camera-uncertainty)");
  const camera::CameraCalibrationInfo& c = *rec.calibration;
  const int m = c.n_points - static_cast<int>(c.outliers.size());
  if (m < 4 || !(c.rms_px > 0.0))
    throw std::invalid_argument(file + ": camera '" + name + "' calibration has no usable rms_px/n_points (--camera-uncertainty)");
  const double s2 = c.rms_px * c.rms_px * m / std::max(2 * m - 7, 1);
  const Eigen::LDLT<Eigen::Matrix<double, 7, 7>> ldlt(c.covariance);
  if (ldlt.info() != Eigen::Success || !(c.covariance.diagonal().array() > 0.0).all())
    throw std::invalid_argument(file + ": camera '" + name + "' covariance is not positive definite");
  const Eigen::Matrix<double, 7, 7> H_rpy = s2 * ldlt.solve(Eigen::Matrix<double, 7, 7>::Identity());
  Eigen::Matrix<double, 7, 7> T = Eigen::Matrix<double, 7, 7>::Identity();
  T.topLeftCorner<3, 3>() = calibration::rpy_rate_matrix(rpy_from_rotation(rec.camera.base_T_camera.linear())).inverse();
  return T.transpose() * H_rpy * T;
}

std::vector<std::string> split_views(const std::string& text) {
  std::vector<std::string> out;
  for (const std::string_view v : split_commas(text)) {
    if (v.empty()) throw std::invalid_argument("--views: empty view name in '" + text + "'");
    out.emplace_back(v);
  }
  return out;
}

/// The text of an output file, written atomically at the end (write_file_atomic).
std::ostringstream open_out(const std::string& path) {
  check_output_path(path);  // before any work
  std::ostringstream f;
  f.precision(15);
  return f;
}

constexpr double kDeg = M_PI / 180.0;

nlohmann::json stats_json(const localization::ErrorStats& s) {
  return {{"n", s.n},
          {"mean_cm", vec_json(s.mean.head<3>() * 100.0)},
          {"mean_deg", vec_json(s.mean.tail<3>() / kDeg)},
          {"sd_cm", vec_json(s.sd.head<3>() * 100.0)},
          {"sd_deg", vec_json(s.sd.tail<3>() / kDeg)},
          {"alignment95_cm", s.alignment95_m * 100.0},
          {"depth95_cm", s.depth95_m * 100.0},
          {"position_rmse_m", s.position_rmse_m},
          {"rotation_rmse_deg", s.rotation_rmse_rad / kDeg}};
}

nlohmann::json alignment_summary_json(const localization::ErrorStats& s) {
  return {{"n", s.n},
          {"position_rmse_m", s.position_rmse_m},
          {"rotation_rmse_deg", s.rotation_rmse_rad / kDeg},
          {"alignment95_m", s.alignment95_m},
          {"depth95_m", s.depth95_m},
          {"mean_m", vec_json(s.mean.head<3>())},
          {"sd_m", vec_json(s.sd.head<3>())}};
}

}  // namespace

nlohmann::json localization_spread_json(const std::vector<localization::StudyResult>& runs) {
  nlohmann::json out = nlohmann::json::array();
  for (std::size_t ci = 0; ci < runs.front().combos.size(); ++ci) {
    std::vector<double> p, r, jp, jr;
    for (const auto& run : runs) {
      const localization::ComboStats& c = run.combos[ci];
      p.push_back(c.ours.position_rmse_m * 1e3);
      r.push_back(c.ours.rotation_rmse_rad / kDeg);
      jp.push_back(c.ours_joint.position_rmse_m * 1e3);
      jr.push_back(c.ours_joint.rotation_rmse_rad / kDeg);
    }
    const localization::ComboStats& c0 = runs.front().combos[ci];
    auto js = [](const localization::Spread& s) { return nlohmann::json{{"mean", s.mean}, {"sd", s.sd}}; };
    out.push_back({{"views", c0.label},
                   {"position_rmse_mm", js(localization::spread_of(p))},
                   {"rotation_rmse_deg", js(localization::spread_of(r))},
                   {"joint_position_rmse_mm", js(localization::spread_of(jp))},
                   {"joint_rotation_rmse_deg", js(localization::spread_of(jr))},
                   {"crlb_position_mm", c0.crlb_position_m * 1e3},
                   {"crlb_rotation_deg", c0.crlb_rotation_rad / kDeg}});
  }
  return out;
}

LocalizationStudy study_localization(const LocalizationStudyRequest& a,
                                     const std::function<void(int done, int total)>& progress) {
  if (a.trials < 1) throw std::invalid_argument("--trials must be at least 1");
  if (a.seeds < 1) throw std::invalid_argument("--seeds must be at least 1");
  if (!(a.arm_error_mm >= 0.0) || !std::isfinite(a.arm_error_mm))
    throw std::invalid_argument("--arm-error-mm must be a non-negative number");
  if (!(a.noise_px > 0.0 && a.noise_px <= limits::kMaxPixelNoise_px))
    throw std::invalid_argument("--noise-px must be a number in (0, " +
                                std::to_string(static_cast<int>(limits::kMaxPixelNoise_px)) + "] px");
  if (a.trials > 1000000) throw std::invalid_argument("--trials must be at most 1000000");
  if (a.seeds > 1000) throw std::invalid_argument("--seeds must be at most 1000");
  if (!(a.arm_error_mm <= 1000.0)) throw std::invalid_argument("--arm-error-mm must be at most 1000");
  const Scene scene = Scene::from_file(a.scene);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const RobotModel robot = RobotModel::from_file(a.robot);
  localization::StudySetup setup = localization::make_study_setup(scene, object, {});
  localization::choose_calibration_points(setup, localization::arm_calibration_poses(robot));

  localization::StudyOptions opt;
  opt.trials = a.trials;
  opt.noise_px = a.noise_px;
  opt.seed = a.seed;
  opt.robot = &robot;
  const bool arm_error = a.arm_error_mm > 0.0;
  const int studies = a.seeds * (arm_error ? 2 : 1);
  int study = 0;
  if (progress)
    opt.progress = [&](int done_in_study, int total_in_study) {
      progress(study * total_in_study + done_in_study, studies * total_in_study);
    };
  const auto t0 = std::chrono::steady_clock::now();
  LocalizationStudy out;
  std::vector<localization::StudyResult>& runs = out.runs;
  std::vector<localization::StudyResult>& arm_runs = out.arm_runs;
  for (int k = 0; k < a.seeds; ++k, ++study) {
    localization::StudyOptions o = opt;
    o.seed = a.seed + static_cast<unsigned>(k);
    runs.push_back(localization::run_accuracy_study(setup, o));
  }
  if (arm_error)
    for (int k = 0; k < a.seeds; ++k, ++study) {
      localization::StudyOptions o = opt;
      o.seed = a.seed + static_cast<unsigned>(k);
      o.arm_link_error_m = a.arm_error_mm * 1e-3;
      arm_runs.push_back(localization::run_accuracy_study(setup, o));
    }
  for (const auto* set : {&runs, &arm_runs})
    for (const localization::StudyResult& run : *set)
      if (run.calibration_failures >= run.trials)  // tables of zeros would look like perfect accuracy
        throw ComputationError("every one of the " + std::to_string(run.trials) +
                               " trials failed its calibration: no accuracy to report; is --noise-px " +
                               std::to_string(a.noise_px) + " too large?");
  out.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

nlohmann::json localization_study_json(const LocalizationStudyRequest& a, const LocalizationStudy& study) {
  const std::vector<localization::StudyResult>& runs = study.runs;
  const std::vector<localization::StudyResult>& arm_runs = study.arm_runs;
  const bool arm_error = a.arm_error_mm > 0.0;
  const double elapsed_s = study.elapsed_s;
  const localization::StudyResult& r = runs.front();
  const localization::ComboStats& all = r.combos.back();
  const double pos_ratio = all.ours.position_rmse_m / all.crlb_position_m;
  const double rot_ratio = all.ours.rotation_rmse_rad / all.crlb_rotation_rad;
  const double jpos_ratio = all.ours_joint.position_rmse_m / all.crlb_position_m;
  const double jrot_ratio = all.ours_joint.rotation_rmse_rad / all.crlb_rotation_rad;
  nlohmann::json views = nlohmann::json::array();
  for (std::size_t v = 0; v < r.view_names.size(); ++v)
    views.push_back({{"index", v + 1},
                     {"name", r.view_names[v]},
                     {"calibration_points", r.calibration_points[v]},
                     {"object_points", r.object_points[v]},
                     {"calibration_rms_px", r.calibration_rms_px[v]}});
  nlohmann::json combos = nlohmann::json::array();
  for (const auto& c : r.combos) {
    const nlohmann::json crlb = {{"sd_cm", vec_json(c.crlb_sd.head<3>() * 100.0)},
                                 {"sd_deg", vec_json(c.crlb_sd.tail<3>() / kDeg)},
                                 {"alignment95_cm", c.crlb_alignment95_m * 100.0},
                                 {"depth95_cm", c.crlb_depth95_m * 100.0},
                                 {"position_m", c.crlb_position_m},
                                 {"rotation_deg", c.crlb_rotation_rad / kDeg}};
    combos.push_back({{"views", c.label},
                      {"failures", c.failures},
                      {"ours", stats_json(c.ours)},
                      {"ours_joint", stats_json(c.ours_joint)},
                      {"joint_failures", c.joint_failures},
                      {"crlb", crlb},
                      {"crlb_known_cameras",
                       {{"sd_cm", vec_json(c.crlb_known_cameras_sd.head<3>() * 100.0)},
                        {"sd_deg", vec_json(c.crlb_known_cameras_sd.tail<3>() / kDeg)},
                        {"position_m", c.crlb_known_cameras_sd.head<3>().norm()},
                        {"rotation_deg", c.crlb_known_cameras_sd.tail<3>().norm() / kDeg}}},
                      {"pnp_sqpnp", stats_json(c.pnp_sqpnp)},
                      {"pnp_iterative", stats_json(c.pnp_iterative)},
                      {"triangulation", stats_json(c.triangulation)}});
  }
  nlohmann::json j = {{"study", "localization"},
                            {"trials", r.trials},
                            {"noise_px", r.noise_px},
                            {"seed", a.seed},
                            {"seeds", a.seeds},
                            {"arm_model_error", "none: the calibration uses the exact arm model"},
                            {"calibration_failures", r.calibration_failures},
                            {"elapsed_s", elapsed_s},
                            {"frame", "oru (z along the hole axis)"},
                            {"views", views},
                            {"combos", combos},
                            {"four_view",
                             {{"position_rmse_m", all.ours.position_rmse_m},
                              {"crlb_position_m", all.crlb_position_m},
                              {"position_ratio", pos_ratio},
                              {"rotation_rmse_deg", all.ours.rotation_rmse_rad / kDeg},
                              {"crlb_rotation_deg", all.crlb_rotation_rad / kDeg},
                              {"rotation_ratio", rot_ratio},
                              {"within_10_percent", pos_ratio <= 1.1 && rot_ratio <= 1.1},
                              {"joint_position_rmse_m", all.ours_joint.position_rmse_m},
                              {"joint_position_ratio", jpos_ratio},
                              {"joint_rotation_rmse_deg", all.ours_joint.rotation_rmse_rad / kDeg},
                              {"joint_rotation_ratio", jrot_ratio},
                              {"joint_within_10_percent", jpos_ratio <= 1.1 && jrot_ratio <= 1.1}}}};
  j["over_seeds"] = localization_spread_json(runs);
  if (arm_error) {
    const localization::ComboStats& w = arm_runs.front().combos.back();
    j["with_arm_model_error"] = {{"link_length_sd_mm", a.arm_error_mm},
                                 {"calibration_failures", arm_runs.front().calibration_failures},
                                 {"four_view",
                                  {{"position_rmse_m", w.ours.position_rmse_m},
                                   {"rotation_rmse_deg", w.ours.rotation_rmse_rad / kDeg},
                                   {"joint_position_rmse_m", w.ours_joint.position_rmse_m},
                                   {"joint_rotation_rmse_deg", w.ours_joint.rotation_rmse_rad / kDeg},
                                   {"alignment95_cm", w.ours.alignment95_m * 100.0},
                                   {"depth95_cm", w.ours.depth95_m * 100.0}}},
                                 {"over_seeds", localization_spread_json(arm_runs)}};
  }
  return j;
}

AlignmentStudySummary study_alignment(const AlignmentStudyRequest& a,
                                      const std::function<void(int done, int total)>& progress) {
  if (a.trials < 1) throw std::invalid_argument("--trials must be at least 1");
  if (!(a.noise_px > 0.0) || !std::isfinite(a.noise_px)) throw std::invalid_argument("--noise-px must be a positive number");
  if (!(a.arm_error_mm >= 0.0) || !std::isfinite(a.arm_error_mm))
    throw std::invalid_argument("--arm-error-mm must be a non-negative number");
  if (!(a.arm_prior_mm >= 0.0) || !std::isfinite(a.arm_prior_mm))
    throw std::invalid_argument("--arm-prior-mm must be a non-negative number");
  if (!(a.sensor_noise_dn >= 0.0) || !std::isfinite(a.sensor_noise_dn))
    throw std::invalid_argument("--sensor-noise-dn must be a non-negative number");
  if (!(a.blur_px >= 0.0) || !std::isfinite(a.blur_px)) throw std::invalid_argument("--blur-px must be a non-negative number");
  const render::GlBackend backend = render::parse_gl_backend(a.gl);
  const Scene scene = Scene::from_file(a.scene);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const RobotModel robot = RobotModel::from_file(a.robot);
  auto context = render::GlContext::create(backend);

  align::AlignmentStudyOptions o;
  o.trials = a.trials;
  o.noise_px = a.noise_px;
  o.seed = a.seed;
  o.arm_link_error_m = a.arm_error_mm * 1e-3;
  o.arm_link_prior_m = a.arm_prior_mm * 1e-3;
  o.sensor_noise_dn = a.sensor_noise_dn;
  o.blur_px = a.blur_px;
  o.progress = progress;
  AlignmentStudySummary out;
  out.result = align::run_alignment_study(*context, robot, object, scene, o);
  const align::AlignmentStudyResult& r = out.result;
  const align::AlignmentComboStats& all = r.combos.back();
  double single_clicks_depth = 0.0, single_aligned_depth = 0.0, single_cam_only_depth = 0.0;
  int singles = 0;
  for (const auto& c : r.combos)
    if (c.views.size() == 1) {
      single_clicks_depth += c.clicks.depth95_m;
      single_aligned_depth += c.aligned.depth95_m;
      single_cam_only_depth += c.aligned_cameras_only.depth95_m;
      ++singles;
    }
  single_clicks_depth /= std::max(1, singles);
  single_aligned_depth /= std::max(1, singles);
  single_cam_only_depth /= std::max(1, singles);
  out.single_clicks_depth_m = single_clicks_depth;
  out.single_aligned_depth_m = single_aligned_depth;
  out.single_cameras_only_depth_m = single_cam_only_depth;
  out.four_view_ratio = all.aligned.alignment95_m > 0 ? all.clicks.alignment95_m / all.aligned.alignment95_m : 0.0;
  out.single_view_depth_ratio = single_aligned_depth > 0 ? single_clicks_depth / single_aligned_depth : 0.0;
  out.four_view_ratio_held_cameras = all.aligned_held_cameras.alignment95_m > 0
                                         ? all.clicks.alignment95_m / all.aligned_held_cameras.alignment95_m
                                         : 0.0;
  out.four_view_ratio_cameras_only = all.aligned_cameras_only.alignment95_m > 0
                                         ? all.clicks.alignment95_m / all.aligned_cameras_only.alignment95_m
                                         : 0.0;
  out.single_view_depth_ratio_cameras_only =
      single_cam_only_depth > 0 ? single_clicks_depth / single_cam_only_depth : 0.0;
  return out;
}


nlohmann::json alignment_study_json(const AlignmentStudyRequest& a, const AlignmentStudySummary& s) {
  const align::AlignmentStudyResult& r = s.result;
  nlohmann::json views = nlohmann::json::array();
  for (std::size_t v = 0; v < r.view_names.size(); ++v)
    views.push_back({{"index", v + 1},
                     {"name", r.view_names[v]},
                     {"frames", r.frames[v]},
                     {"camera_clicks_px", r.camera_clicks_px[v]},
                     {"camera_aligned_px", r.camera_aligned_px[v]},
                     {"camera_bundle_px", r.camera_bundle_px[v]},
                     {"camera_refused", r.camera_refused[v]}});
  nlohmann::json combos = nlohmann::json::array();
  for (const auto& c : r.combos)
    combos.push_back({{"views", c.label},
                      {"clicks", alignment_summary_json(c.clicks)},
                      {"aligned", alignment_summary_json(c.aligned)},
                      {"aligned_held_cameras", alignment_summary_json(c.aligned_held_cameras)},
                      {"aligned_cameras_only", alignment_summary_json(c.aligned_cameras_only)},
                      {"clicks_failures", c.clicks_failures},
                      {"aligned_refused", c.aligned_refused},
                      {"aligned_refused_disagreement", c.aligned_refused_disagreement},
                      {"aligned_cameras_only_refused", c.aligned_cameras_only_refused},
                      {"aligned_held_cameras_refused", c.aligned_held_cameras_refused},
                      {"aligned_accepted", c.aligned_accepted},
                      {"aligned_within_3_sigma", c.aligned_within_3_sigma},
                      {"aligned_mahalanobis2_mean", c.aligned_mahalanobis2_mean}});
  nlohmann::json links = nlohmann::json::array();
  for (std::size_t j = 0; j < r.link_segments.size(); ++j)
    links.push_back({{"segment", r.link_segments[j]},
                     {"true_rms_m", r.link_true_rms_m[j]},
                     {"estimate_error_rms_m", r.link_estimate_error_rms_m[j]},
                     {"sigma_mean_m", r.link_sigma_mean_m[j]}});
  nlohmann::json j = {{"study", "alignment"},
                            {"trials", r.trials},
                            {"noise_px", r.noise_px},
                            {"seed", a.seed},
                            {"arm_error_mm", a.arm_error_mm},
                            {"sensor_noise_dn", a.sensor_noise_dn},
                            {"blur_px", a.blur_px},
                            {"calibration_failures", r.calibration_failures},
                            {"elapsed_s", r.elapsed_s},
                            {"frame", "oru (z along the hole axis)"},
                            {"views", views},
                            {"combinations", combos},
                            {"arm_prior_mm", a.arm_prior_mm},
                            {"bundle_refused", r.bundle_refused},
                            {"arm_links", links},
                            {"arm_link_true_rms_m", r.link_true_rms_all_m},
                            {"arm_link_estimate_error_rms_m", r.link_estimate_error_rms_all_m},
                            {"four_view_alignment95_ratio", s.four_view_ratio},
                            {"single_view_depth95_ratio", s.single_view_depth_ratio},
                            {"four_view_alignment95_ratio_held_cameras", s.four_view_ratio_held_cameras},
                            {"four_view_alignment95_ratio_cameras_only", s.four_view_ratio_cameras_only},
                            {"single_view_depth95_ratio_cameras_only", s.single_view_depth_ratio_cameras_only}};
  return j;
}

SynthClicks synth_clicks(const SynthClicksRequest& a) {
  if (!(a.noise_px >= 0.0 && a.noise_px <= limits::kMaxPixelNoise_px))
    throw std::invalid_argument("--noise-px must be a number in [0, " +
                                std::to_string(static_cast<int>(limits::kMaxPixelNoise_px)) + "] px");
  if (a.per_pose < 1) throw std::invalid_argument("--per-pose must be at least 1");
  const Scene scene = Scene::from_file(a.scene);
  const RobotModel robot = RobotModel::from_file(a.robot);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const localization::StudySetup setup = localization::make_study_setup(scene, object, {});
  const std::vector<localization::ArmCalibrationPose> poses = localization::arm_calibration_poses(robot);

  std::mt19937 rng(a.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  auto click = [&](const camera::Camera& c, const Eigen::Vector3d& p_base) {
    return Eigen::Vector2d(c.project(p_base) + a.noise_px * Eigen::Vector2d(noise(rng), noise(rng)));
  };

  SynthClicks out;
  std::ostringstream cal, obj;
  if (!a.calibration_out.empty()) {
    cal = open_out(a.calibration_out);
    cal << "n,cam,link,lx,ly,lz";
    for (int j = 1; j <= robot.dof(); ++j) cal << ",q" << j;
    cal << ",u,v\n";
  }
  if (!a.object_out.empty()) {
    obj = open_out(a.object_out);
    obj << "n,cam,x,y,z,u,v\n";
  }
  int n_cal = 0, n_obj = 0;
  for (const localization::StudyView& v : setup.views) {
    int cal_here = 0, obj_here = 0;
    for (const localization::ArmCalibrationPose& pose : poses)
      for (const localization::ArmFeature& f : localization::visible_features(v.truth, pose, a.per_pose)) {
        const Eigen::Vector2d uv = click(v.truth, f.p_base);
        ++cal_here;
        if (a.calibration_out.empty()) continue;
        cal << ++n_cal << ',' << v.truth.name << ',' << robot.links()[f.link].name << ',' << f.p_link.x() << ','
            << f.p_link.y() << ',' << f.p_link.z();
        for (int j = 0; j < robot.dof(); ++j) cal << ',' << pose.q[j];
        cal << ',' << uv.x() << ',' << uv.y() << '\n';
      }
    for (const Eigen::Vector3d& p : v.object_points) {
      const Eigen::Vector2d uv = click(v.truth, setup.base_T_object * p);
      ++obj_here;
      if (!a.object_out.empty())
        obj << ++n_obj << ',' << v.truth.name << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ','
            << uv.y() << '\n';
    }
    out.views.push_back({v.truth.name, cal_here, obj_here});
  }
  if (!a.calibration_out.empty()) write_file_atomic(a.calibration_out, cal.str());
  if (!a.object_out.empty()) write_file_atomic(a.object_out, obj.str());
  if (!a.joints_out.empty()) {
    std::ostringstream j = open_out(a.joints_out);
    for (int i = 0; i < robot.dof(); ++i) j << (i ? "," : "") << poses.front().q[i];
    j << '\n';
    write_file_atomic(a.joints_out, j.str());
  }
  for (const auto& p : poses) out.arm_poses.push_back(p.q);
  out.true_base_T_object = setup.base_T_object;
  return out;
}

Calibrated calibrate_from_clicks(const CalibrateRequest& a) {
  Calibrated out;
  out.viewport = camera::parse_viewport(a.viewport);
  if (!a.out.empty()) check_output_path(a.out);  // before any work: a folder or a missing folder is bad input
  calibration::RobotLinkPoints robot(a.robot);
  const std::vector<calibration::Correspondence> all = calibration::read_correspondences_csv(a.points, &robot);
  out.points = calibration::select_camera(all, a.camera);
  if (out.points.empty()) {
    std::set<std::string> names;
    for (const auto& c : all) names.insert(c.cam);
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    throw InputError(a.points, "no points for camera '" + a.camera + "' (cameras in the file: " + list + ")");
  }
  if (a.max_iterations < 1) throw std::invalid_argument("--max-iterations must be at least 1");
  calibration::check_in_viewport(out.points, out.viewport, a.points);
  calibration::CalibrationOptions copt;
  copt.max_iterations = a.max_iterations;
  copt.arm_link_sigma_m = a.arm_link_sigma_m;
  out.result = calibration::calibrate_camera(out.points, out.viewport, a.camera, copt);
  return out;
}

nlohmann::json calibrated_json(const CalibrateRequest& a, const Calibrated& c) {
  constexpr double kDeg = M_PI / 180.0;
  const calibration::CalibrationResult& r = c.result;
  const Eigen::Matrix<double, 7, 1> arm_sigma = r.arm_model_covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  nlohmann::json residuals = nlohmann::json::array();
  for (const auto& p : r.residuals)
    residuals.push_back({{"n", p.n}, {"px", p.px}, {"du_px", p.r_px.x()}, {"dv_px", p.r_px.y()}, {"outlier", p.outlier},
                         {"line", p.line}});
  nlohmann::json j = {{"camera", a.camera},
                      {"viewport", {c.viewport.width_px, c.viewport.height_px}},
                      {"f_px", r.camera.f_px},
                      {"fovy_deg", r.camera.fovy_rad() / kDeg},
                      {"position_m", vec_json(r.position_m())},
                      {"rpy_deg", vec_json(r.rpy_rad() / kDeg)},
                      {"base_T_camera", localization::pose_json(r.camera.base_T_camera)},
                      {"rms_px", r.rms_px},
                      {"max_px", r.max_px},
                      {"linear_rms_px", r.linear_rms_px},
                      {"linear_cross_product", r.linear_cross_product},
                      {"residuals_px", residuals},
                      {"outliers", r.outliers},
                      {"sigma",
                       {{"f_px", r.sigma[6]},
                        {"position_m", vec_json(r.sigma.segment<3>(3))},
                        {"rpy_deg", vec_json(r.sigma.head<3>() / kDeg)}}},
                      {"covariance", matrix_rows(r.covariance)},
                      {"arm_model_sigma",
                       {{"arm_link_sigma_m", a.arm_link_sigma_m},
                        {"f_px", arm_sigma[6]},
                        {"position_m", vec_json(Eigen::Vector3d(arm_sigma.segment<3>(3)))},
                        {"rpy_deg", vec_json(Eigen::Vector3d(arm_sigma.head<3>() / kDeg))}}},
                      {"iterations", r.iterations},
                      {"n_points", r.n_points}};
  if (!a.out.empty()) j["out"] = a.out;
  return j;
}

void add_camera(const std::string& cameras_yaml, const std::string& camera, const Calibrated& c) {
  std::map<std::string, camera::CameraRecord> cams;
  if (std::filesystem::exists(cameras_yaml)) cams = camera::load_cameras(cameras_yaml);
  cams[camera] = camera::CameraRecord{c.result.camera, c.result.info(utc_now())};
  camera::save_cameras(cameras_yaml, cams);
}

Localized localize_from_clicks(const LocalizeRequest& a) {
  Localized out{ObjectModel::from_file(a.object), {}, {}, {}, 0.0, {}, {}};
  const auto records = camera::load_cameras(a.cameras);
  for (const auto& [name, rec] : records) out.cameras[name] = rec.camera;
  out.points = calibration::read_correspondences_csv(a.points);
  const std::vector<calibration::Correspondence>& pts = out.points;
  for (const auto& [name, camera] : out.cameras) calibration::check_in_viewport(calibration::select_camera(pts, name), camera.viewport, a.points);
  localization::LocalizationOptions opt;
  if (!a.views.empty()) opt.views = split_views(a.views);
  const auto in_use = [&](const std::string& name) {
    return std::any_of(pts.begin(), pts.end(), [&](const calibration::Correspondence& c) { return c.cam == name; }) &&
           (opt.views.empty() || std::find(opt.views.begin(), opt.views.end(), name) != opt.views.end());
  };
  if (a.camera_uncertainty)
    for (const auto& [name, rec] : records)
      if (in_use(name)) opt.camera_information[name] = calibration_information(a.cameras, name, rec);
  // The cameras held as calibrated are not exact, and cameras calibrated on
  // one arm share its link errors (cameras.yaml's arm_link_sensitivity):
  // both enter the pose's covariance; the pose is the same.
  std::string arm_first;
  for (const auto& [name, rec] : records) {
    if (!in_use(name) || !rec.calibration) continue;
    const camera::CameraCalibrationInfo& c = *rec.calibration;
    const Eigen::Matrix3d R = rec.camera.base_T_camera.linear();
    Eigen::Matrix<double, 7, 7> arm_rpy = Eigen::Matrix<double, 7, 7>::Zero();
    if (c.arm_link_sensitivity.size() > 0) {
      if (!arm_first.empty() && c.arm_link_sigma_m != opt.arm_link_sigma_m)
        throw std::invalid_argument(a.cameras + ": cameras '" + arm_first + "' and '" + name +
                                    "' were calibrated with different arm link sigmas (" + fixed(opt.arm_link_sigma_m * 1e3, 2) +
                                    " and " + fixed(c.arm_link_sigma_m * 1e3, 2) + " mm)");
      if (arm_first.empty()) arm_first = name;
      opt.arm_link_sigma_m = c.arm_link_sigma_m;
      arm_rpy = c.arm_link_sigma_m * c.arm_link_sigma_m * c.arm_link_sensitivity * c.arm_link_sensitivity.transpose();
      Eigen::MatrixXd K = c.arm_link_sensitivity;  // rpy rates -> body increments
      K.topRows<3>() = calibration::rpy_rate_matrix(rpy_from_rotation(R)) * c.arm_link_sensitivity.topRows<3>();
      opt.camera_link_sensitivity[name] = K;
    }
    if (opt.camera_information.count(name) || c.covariance.isZero(0.0)) continue;
    // The calibration's own (noise) part, kept positive semi-definite against
    // the file's rounding.
    const Eigen::Matrix<double, 7, 7> body = calibration::camera_covariance_body_from_rpy(c.covariance - arm_rpy, R);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 7, 7>> eig(0.5 * (body + body.transpose()));
    opt.camera_covariance[name] =
        eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() * eig.eigenvectors().transpose();
    out.held_cameras.push_back(name);
  }
  out.arm_link_sigma_m = opt.arm_link_sigma_m;
  out.result = localization::localize_object(pts, out.cameras, opt);
  contact_check::ContactCheckConfig check = contact_check::load_contact_check_config(a.ground);
  if (opt.arm_link_sigma_m > 0.0) check.arm_link_sigma_m = opt.arm_link_sigma_m;
  const std::optional<RobotModel> robot = a.robot.empty() ? std::nullopt : std::optional<RobotModel>(RobotModel::from_file(a.robot));
  out.tag_uncertainty =
      tag_uncertainty_json(out.object, out.result.base_T_object, out.result.covariance, robot ? &*robot : nullptr, check);
  return out;
}

nlohmann::json localized_json(const Localized& l) {
  const localization::LocalizationResult& r = l.result;
  nlohmann::json tags = nlohmann::json::object();
  for (const auto& [name, oru_T_tag] : l.object.tags) tags[name] = localization::pose_json(r.base_T_object * oru_T_tag);
  nlohmann::json residuals = nlohmann::json::array();
  nlohmann::json outlier_details = nlohmann::json::array();
  for (const auto& p : r.residuals) {
    residuals.push_back({{"n", p.n}, {"cam", p.cam}, {"px", p.px}, {"outlier", p.outlier}, {"line", p.line}});
    if (p.outlier) outlier_details.push_back({{"n", p.n}, {"cam", p.cam}, {"px", p.px}, {"line", p.line}});
  }
  constexpr double kDeg = M_PI / 180.0;
  nlohmann::json j = {{"object", l.object.name},
                      {"position_m", vec_json(r.position_m())},
                      {"rpy_deg", vec_json(r.rpy_rad() / kDeg)},
                      {"sigma", {{"position_m", vec_json(r.sigma_position_m)}, {"rpy_deg", vec_json(r.sigma_rpy_rad / kDeg)}}},
                      {"covariance", matrix_rows(r.covariance)},
                      {"rms_px", r.rms_px},
                      {"max_px", r.max_px},
                      {"linear_rms_px", r.linear_rms_px},
                      {"iterations", r.iterations},
                      {"n_points", r.n_points},
                      {"residuals_px", residuals},
                      {"outliers", r.outliers},
                      {"outlier_details", outlier_details},
                      {"views", r.views},
                      {"camera_uncertainty", r.camera_uncertainty},
                      {"held_camera_uncertainty", l.held_cameras},
                      {"arm_link_sigma_m", l.arm_link_sigma_m},
                      {"tags", tags},
                      {"tag_uncertainty", l.tag_uncertainty}};
  if (r.arm_link_sensitivity.size() > 0) j["arm_link_sensitivity"] = matrix_rows(r.arm_link_sensitivity);
  j.update(localization::object_pose_json(r.base_T_object));  // base_T_object: the object pose file's one writer
  return j;
}

Synthesized synth_frame(const SynthRequest& a) {
  using namespace foresight::render;
  Synthesized out;
  out.backend = parse_gl_backend(a.gl);
  if (!(a.noise_dn >= 0.0) || !(a.blur_px >= 0.0)) throw std::invalid_argument("--noise-dn and --blur-px must be >= 0");
  if (!a.joints.empty() && !a.joints_deg.empty()) throw std::invalid_argument("give only one of --joints, --joints-deg");
  const Scene scene = Scene::from_file(a.scene);
  out.camera = scene_camera(scene, a.camera, a.scene);
  const RobotModel nominal = RobotModel::from_file(a.robot);
  const RobotModel model =
      a.arm_links.empty() ? nominal : nominal.with_link_lengths_changed(align::load_arm_links(a.arm_links, nominal).delta_m);
  const ObjectModel object = ObjectModel::from_file(a.object);
  out.q = !a.joints.empty()       ? parse_joints(a.joints, "--joints", model)
          : !a.joints_deg.empty() ? parse_joints(a.joints_deg, "--joints-deg", model, true)
                                  : model.mid_configuration();
  if (!a.write_cameras.empty()) {
    std::map<std::string, camera::CameraRecord> cams;
    for (const auto& name : scene.camera_order) cams[name].camera = scene_camera(scene, name, a.scene);
    camera::save_cameras(a.write_cameras, cams);
  }
  auto context = GlContext::create(out.backend);
  SyntheticOptions o;
  o.noise_sigma_dn = a.noise_dn;
  o.blur_sigma_px = a.blur_px;
  o.seed = a.seed;
  SyntheticCamera synth(*context, model, object, scene, out.camera.viewport, o);
  const SyntheticFrame f = synth.render(out.camera, out.q);
  write_image(a.out, f.image_bgr);
  if (!a.arm_mask.empty()) write_image(a.arm_mask, f.arm_mask);
  out.arm_pixels = cv::countNonZero(f.arm_mask);
  out.object_pixels = cv::countNonZero(f.object_mask);
  return out;
}

Overlaid overlay_frame(const OverlayRequest& a) {
  using namespace foresight::render;
  const auto t_start = std::chrono::steady_clock::now();
  Overlaid out;
  out.mode = parse_render_mode(a.mode);
  out.backend = parse_gl_backend(a.gl);
  if (!(a.alpha >= 0.0 && a.alpha <= 1.0)) throw std::invalid_argument("--alpha must be in [0, 1]");
  if (a.joints.empty() == a.joints_deg.empty())
    throw std::invalid_argument("give the arm's joint angles with exactly one of --joints (rad) or --joints-deg");
  out.camera = load_camera(a.cameras, a.camera);
  const camera::Camera& camera = out.camera;
  const RobotModel model = RobotModel::from_file(a.robot);
  out.q = a.joints.empty() ? parse_joints(a.joints_deg, "--joints-deg", model, true)
                           : parse_joints(a.joints, "--joints", model);
  std::optional<ObjectModel> object;
  if (!a.object_pose.empty()) {
    out.base_T_object = localization::read_object_pose_json(a.object_pose);
    object = ObjectModel::from_file(a.object);
  } else if (a.tags) {
    throw std::invalid_argument("--tags needs --object-pose (the tags are frames of the object)");
  }
  std::optional<display::GoNoGoMarks> go_no_go;
  if (a.check_insert) {
    if (a.object_pose.empty())
      throw std::invalid_argument("--check-insert needs --object-pose (the object pose with its covariance)");
    go_no_go = load_go_no_go_marks(a.object_pose, a.object, a.robot, a.ground);
  }
  out.object_drawn = object.has_value();
  auto context = GlContext::create(out.backend);
  Renderer renderer(*context, camera.viewport);
  cv::Mat video = fit_to_viewport(read_video_frame(a.image, a.frame), a.image, camera, a.scale_image);
  ArmGeometry arm(renderer, model);
  DrawList list;
  arm.append(out.q, list);
  if (object) {
    list.bodies.push_back({add_object_body(renderer, *object), out.base_T_object, kObjectWireRgba, std::nullopt});
    if (a.tags)
      for (const auto& [name, oru_T_tag] : object->tags) append_triad(list, out.base_T_object * oru_T_tag, 0.08);
  }
  RenderSettings settings;
  settings.mode = out.mode;
  cv::Mat layer;
  const auto t_render = std::chrono::steady_clock::now();
  out.triangles = renderer.render(camera, list, settings, layer);
  out.opacity = mode_opacity(out.mode, a.alpha);
  composite(layer, out.opacity, video);
  if (go_no_go) out.insert_check = go_no_go_json(*go_no_go, display::draw_go_no_go(video, camera, *go_no_go));
  out.render_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_render).count();
  write_image(a.out, video);
  out.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start).count();
  out.tip_px = camera.project(arm.tip_pose(out.q).translation());
  return out;
}

namespace {

/// The ORU's block of an alignment's covariance (after the refined cameras'
/// blocks of 7), from its body rotation increment to the object pose file's
/// (roll, pitch, yaw, x, y, z); none when the object was not refined.
std::optional<Eigen::Matrix<double, 6, 6>> aligned_object_covariance(const align::AlignResult& r, bool cameras_refined) {
  if (!r.base_T_object) return std::nullopt;
  const Eigen::Index at = cameras_refined ? 7 * static_cast<Eigen::Index>(r.cameras.size()) : 0;
  if (r.covariance.rows() < at + 6 || r.covariance.cols() < at + 6) return std::nullopt;
  Eigen::Matrix<double, 6, 6> G = Eigen::Matrix<double, 6, 6>::Identity();
  G.topLeftCorner<3, 3>() = calibration::rpy_rate_matrix(rpy_from_rotation(r.base_T_object->linear())).inverse();
  return G * r.covariance.block<6, 6>(at, at) * G.transpose();
}

}  // namespace

AlignedViews align_views(const AlignRequest& a) {
  using namespace foresight::render;
  using namespace foresight::align;
  AlignedViews out;
  AlignOptions& options = out.options;
  const GlBackend backend = parse_gl_backend(a.gl);
  options.refine = parse_refine(a.refine);
  if (a.joints.empty() == a.joints_deg.empty())
    throw std::invalid_argument("give the arm's joint angles with exactly one of --joints (rad) or --joints-deg");
  const auto& joint_texts = a.joints.empty() ? a.joints_deg : a.joints;
  const std::string joint_option = a.joints.empty() ? "--joints-deg" : "--joints";
  if (a.camera.size() > 1 && a.camera.size() != a.image.size())
    throw std::invalid_argument("with several --camera give one --image per --camera (" +
                                std::to_string(a.camera.size()) + " cameras, " + std::to_string(a.image.size()) +
                                " images)");
  if (!(a.arm_prior_mm >= 0.0) || !std::isfinite(a.arm_prior_mm))
    throw std::invalid_argument("--arm-prior-mm must be a non-negative number");
  if (a.arm_prior_mm > 0.0 && options.refine == Refine::Object)
    throw std::invalid_argument("--arm-prior-mm refines the arm with the cameras: use --refine camera or both");
  if (!a.arm_out.empty() && a.arm_prior_mm == 0.0)
    throw std::invalid_argument("--arm-out writes the refined arm: give --arm-prior-mm");
  if (joint_texts.size() != 1 && joint_texts.size() != a.image.size())
    throw std::invalid_argument("give " + joint_option + " once or once per --image (" +
                                std::to_string(joint_texts.size()) + " given for " + std::to_string(a.image.size()) +
                                " images)");
  if (options.refine != Refine::Camera && a.object_pose.empty())
    throw std::invalid_argument("--refine " + a.refine + " needs --object-pose (the start pose of the object)");
  if (!a.object_out.empty() && options.refine == Refine::Camera)
    throw std::invalid_argument("--object-out needs --refine object or both");
  if (!a.out.empty() && options.refine == Refine::Object)
    throw std::invalid_argument("--out writes refined cameras: use --refine camera or both");
  for (const std::string* path : {&a.out, &a.object_out, &a.arm_out})
    if (!path->empty()) check_output_path(*path);

  std::map<std::string, camera::CameraRecord> records = camera::load_cameras(a.cameras);
  std::vector<AlignView> views;
  std::vector<int> view_of_image;  // per --image (several cameras): its view
  for (const auto& name : a.camera) {
    if (!records.count(name)) {
      std::string known;
      for (const auto& [n, r] : records) known += (known.empty() ? "" : ", ") + n;
      throw InputError(a.cameras, "no camera '" + name + "' (known: " + known + ")");
    }
    const auto seen = std::find_if(views.begin(), views.end(), [&](const AlignView& v) { return v.camera.name == name; });
    view_of_image.push_back(static_cast<int>(seen - views.begin()));
    if (seen != views.end()) continue;  // another frame of that camera
    const camera::CameraRecord& rec = records.at(name);
    AlignView view{rec.camera, {}};
    // The calibration's uncertainty: with --refine object the camera is held
    // but not exact, and its error enters the object's covariance.
    if (rec.calibration)
      view.camera_covariance = calibration::camera_covariance_body_from_rpy(rec.calibration->covariance, rec.camera.base_T_camera.linear());
    views.push_back(std::move(view));
  }
  const RobotModel model = RobotModel::from_file(a.robot);
  if (!a.arm_links.empty()) options.arm_link_delta_m = load_arm_links(a.arm_links, model).delta_m;
  options.arm_link_prior_m = a.arm_prior_mm * 1e-3;
  std::optional<ObjectModel> object;
  std::optional<Pose> base_T_object;
  if (!a.object_pose.empty()) {
    // The click solution's uncertainty (`localize --json` writes it beside
    // the pose): with it the aligner refuses an ORU that moved or turned
    // further from the clicks than both uncertainties allow.
    const localization::ObjectPoseFile pose = localization::read_object_pose_file(a.object_pose);
    base_T_object = pose.base_T_object;
    object = ObjectModel::from_file(a.object);
    if (pose.covariance) options.object_start_covariance = *pose.covariance;
  }
  for (std::size_t i = 0; i < a.image.size(); ++i) {
    AlignView& view = views[a.camera.size() == 1 ? 0 : view_of_image[i]];
    const std::string& jt = joint_texts[joint_texts.size() == 1 ? 0 : i];
    const Eigen::VectorXd q = parse_joints(jt, joint_option, model, !a.joints_deg.empty());
    const cv::Mat img = fit_to_viewport(read_video_frame(a.image[i], a.frame), a.image[i], view.camera, a.scale_image);
    view.frames.push_back({img, q});
  }
  for (const auto& v : views)
    if (!(v.camera.viewport == views[0].camera.viewport))
      throw std::invalid_argument("cameras '" + views[0].camera.name + "' and '" + v.camera.name +
                                  "' have different viewports");

  auto context = GlContext::create(backend);
  ModelAligner aligner(*context, model, object ? &*object : nullptr, views[0].camera.viewport);
  out.result = aligner.align(views, base_T_object, options);
  const AlignResult& r = out.result;
  out.offset_segments = model.offset_segments();
  if (r.status == AlignStatus::NotInView) throw InputError(a.image.front(), r.reason);

  out.cameras_refined = options.refine != Refine::Camera ? options.refine == Refine::Both : true;
  const bool cam_refined = out.cameras_refined;

  if (r.status == AlignStatus::Aligned) {
    if (!a.out.empty() && cam_refined) {
      std::map<std::string, camera::CameraRecord> out_records =
          std::filesystem::exists(a.out) ? camera::load_cameras(a.out) : std::map<std::string, camera::CameraRecord>{};
      if (a.out == a.cameras) out_records = records;
      for (std::size_t v = 0; v < r.cameras.size(); ++v) {
        camera::CameraCalibrationInfo info;
        // cameras.yaml keeps roll/pitch/yaw; the aligner's rotation is a
        // body increment (calibrate writes the same convention).
        info.covariance = calibration::camera_covariance_rpy_from_body(r.covariance.block<7, 7>(7 * v, 7 * v),
                                                          r.cameras[v].base_T_camera.linear());
        info.rms_px = r.residual_rms_px;
        info.max_px = 1.0;  // inliers are within 1 px by definition
        info.n_points = r.matched_samples;
        info.date = utc_now();
        out_records[r.cameras[v].name] = camera::CameraRecord{r.cameras[v], info};
      }
      camera::save_cameras(a.out, out_records);
    }
    if (!a.arm_out.empty() && !r.arm_link_sigma_m.empty())
      save_arm_links(a.arm_out, {r.arm_link_delta_m, r.arm_link_sigma_m}, a.robot, utc_now());
    if (!a.object_out.empty() && r.base_T_object) {
      nlohmann::json j = localization::object_pose_json(*r.base_T_object);
      j["source"] = "foresight align";
      if (const auto C = aligned_object_covariance(r, out.cameras_refined)) j["covariance"] = matrix_rows(*C);
      std::vector<std::string> views;
      for (const auto& cam : r.cameras) views.push_back(cam.name);
      j["views"] = views;
      write_file_atomic(a.object_out, j.dump(2) + "\n");
    }
  }
  return out;
}

nlohmann::json aligned_json(const AlignRequest& a, const AlignedViews& aligned) {
  using namespace foresight::align;
  const AlignResult& r = aligned.result;
  const AlignOptions& options = aligned.options;
  const bool cam_refined = aligned.cameras_refined;
  auto sigma = [&](int k) { return r.covariance.size() > 0 ? std::sqrt(std::max(0.0, r.covariance(k, k))) : 0.0; };
  nlohmann::json cams = nlohmann::json::array();
  for (std::size_t v = 0; v < r.cameras.size(); ++v) {
    const auto& d = r.camera_change[v];
    nlohmann::json c = {{"name", r.cameras[v].name},
                        {"f_px", r.cameras[v].f_px},
                        {"base_T_camera", localization::pose_json(r.cameras[v].base_T_camera)},
                        {"change",
                         {{"rotation_deg", vec_json(d.head<3>() * 180.0 / M_PI)},
                          {"position_m", vec_json(d.segment<3>(3))},
                          {"f_px", d[6]}}}};
    if (cam_refined) {
      std::vector<double> s;
      for (int k = 0; k < 7; ++k) s.push_back(sigma(7 * static_cast<int>(v) + k));
      c["sigma"] = s;  // rad x3, m x3, px
    }
    cams.push_back(c);
  }
  nlohmann::json j = {{"status", to_string(r.status)},
                      {"reason", r.reason},
                      {"refine", to_string(options.refine)},
                      {"cameras", cams},
                      {"start_score_px", r.start_score_px},
                      {"final_score_px", r.final_score_px},
                      {"residual_rms_px", r.residual_rms_px},
                      {"visible_samples", r.visible_samples},
                      {"matched_samples", r.matched_samples},
                      {"iterations", r.iterations},
                      {"start_disagreement_sigma", r.start_disagreement_sigma},
                      {"start_position_disagreement_sigma", r.start_position_disagreement_sigma},
                      {"time_ms", r.time_ms},
                      {"covariance", matrix_rows(r.covariance)}};
  if (r.base_T_object) {
    j["base_T_object"] = localization::pose_json(*r.base_T_object);
    j["object_change"] = {{"rotation_deg", vec_json(r.object_change.head<3>() * 180.0 / M_PI)},
                          {"position_m", vec_json(r.object_change.tail<3>())}};
  }
  if (const auto C = aligned_object_covariance(r, cam_refined)) {
    j["object_covariance"] = matrix_rows(*C);  // roll, pitch, yaw, x, y, z: the object pose file's
    const RobotModel robot = RobotModel::from_file(a.robot);
    j["tag_uncertainty"] = tag_uncertainty_json(ObjectModel::from_file(a.object), *r.base_T_object, *C, &robot,
                                                contact_check::load_contact_check_config(default_config("ground.yaml")));
  }
  if (!r.arm_link_delta_m.empty()) j["arm_link_delta_m"] = r.arm_link_delta_m;
  if (!r.arm_link_sigma_m.empty()) j["arm_link_sigma_m"] = r.arm_link_sigma_m;
  if (r.status == AlignStatus::Aligned && !a.out.empty()) j["out"] = a.out;
  return j;
}

Previewed preview_trajectory(const PreviewRequest& a) {
  using namespace foresight::render;
  const auto t_start = std::chrono::steady_clock::now();
  Previewed out;
  preview::PreviewOptions& o = out.options;
  o.mode = parse_render_mode(a.mode);
  o.speed = a.speed;
  o.fps = a.fps;
  o.ghost_alpha = a.alpha;
  o.tool_path = !a.no_path;
  o.interrupted = a.interrupted;
  if (!(a.speed > 0.0) || !std::isfinite(a.speed)) throw std::invalid_argument("--speed must be a positive number");
  if (!(a.fps > 0.0)) throw std::invalid_argument("--fps must be a positive number");
  if (!(a.fps <= 1000.0)) throw std::invalid_argument("--fps must be at most 1000");
  if (!(a.alpha >= 0.0 && a.alpha <= 1.0)) throw std::invalid_argument("--alpha must be in [0, 1]");
  out.backend = parse_gl_backend(a.gl);
  const Trajectory tr = read_trajectory_csv(a.trajectory);
  out.samples = tr.samples();
  out.joints = tr.joints();
  out.camera = load_camera(a.cameras, a.camera);
  const RobotModel model = RobotModel::from_file(a.robot);
  if (tr.joints() != model.dof())
    throw InputError(a.trajectory, "trajectory has " + std::to_string(tr.joints()) + " joints but the arm has " +
                                       std::to_string(model.dof()));
  if (a.tags && a.object_pose.empty())
    throw std::invalid_argument("--tags needs --object-pose (the tags are frames of the object)");
  out.violations = validate(tr, TrajectoryLimits::from_model(model), &out.violations_total);
  for (const auto& v : out.violations)
    if (v.rule == Violation::Rule::NonFinite || v.rule == Violation::Rule::TimeNotIncreasing ||
        v.rule == Violation::Rule::TooFewSamples)
      throw InputError(a.trajectory, v.message + ": cannot be previewed");
  // The frame count must fit before anything renders (--speed 1e-9 overflowed it).
  const std::optional<int> frames = limits::sample_count(tr.duration_s() / a.speed, a.fps);
  if (!frames || *frames > limits::kMaxVideoFrames)
    throw std::invalid_argument("--speed " + std::to_string(a.speed) + " and --fps " + std::to_string(a.fps) +
                                " give more than " + std::to_string(limits::kMaxVideoFrames) + " video frames for " +
                                std::to_string(tr.duration_s()) + " s of trajectory");

  auto context = GlContext::create(out.backend);
  Renderer renderer(*context, out.camera.viewport);
  const cv::Mat video = fit_to_viewport(read_video_frame(a.image, a.frame), a.image, out.camera, a.scale_image);
  ArmGeometry arm(renderer, model);
  preview::OverlayExtras extras;
  if (!a.object_pose.empty()) {
    const ObjectModel object = ObjectModel::from_file(a.object);
    extras.base_T_object = localization::read_object_pose_json(a.object_pose);
    extras.object_body = add_object_body(renderer, object);
    if (a.tags)
      for (const auto& [name, oru_T_tag] : object.tags) extras.base_T_tags.push_back(extras.base_T_object * oru_T_tag);
  }
  out.result = preview::render_preview(renderer, arm, out.camera, video, tr, extras, o, a.out, a.sheet);
  out.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return out;
}

}  // namespace foresight::session
