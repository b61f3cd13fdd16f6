#include "foresight/localization/accuracy_study.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <map>
#include <random>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/calibration/robot_points.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/localization/peers.hpp"

namespace foresight::localization {

Eigen::Matrix<double, 6, 1> pose_error(const Pose& est, const Pose& truth) {
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = truth.linear().transpose() * (est.translation() - truth.translation());
  const Eigen::AngleAxisd aa(truth.linear().transpose() * est.linear());
  e.tail<3>() = aa.angle() * aa.axis();
  return e;
}

void ErrorAccumulator::add(const Eigen::Matrix<double, 6, 1>& e) {
  ++n;
  sum += e;
  sum_sq += e.cwiseAbs2();
}

ErrorStats ErrorAccumulator::stats() const {
  ErrorStats s;
  s.n = n;
  if (n == 0) return s;
  s.mean = sum / n;
  s.rms = (sum_sq / n).cwiseSqrt();
  const double bessel = n > 1 ? static_cast<double>(n) / (n - 1) : 1.0;
  s.sd = ((sum_sq / n - s.mean.cwiseAbs2()) * bessel).cwiseMax(0.0).cwiseSqrt();
  s.alignment95_m = s.mean.head<2>().norm() + 2.0 * s.sd.head<2>().norm();
  s.depth95_m = std::abs(s.mean[2]) + 2.0 * s.sd[2];
  s.position_rmse_m = s.rms.head<3>().norm();
  s.rotation_rmse_rad = s.rms.tail<3>().norm();
  return s;
}

ViewClicks simulate_view_clicks(const StudyView& view, const std::vector<Eigen::Vector3d>& believed_base,
                                const std::vector<Eigen::Vector3d>& true_base, const Pose& base_T_object,
                                const std::function<double()>& noise) {
  ViewClicks out;
  for (std::size_t i = 0; i < believed_base.size(); ++i) {
    calibration::Correspondence c;
    c.n = static_cast<int>(i) + 1;
    c.cam = view.truth.name;
    c.p_m = believed_base[i];
    c.uv_px = view.truth.project(true_base[i]) + Eigen::Vector2d(noise(), noise());
    out.calibration.push_back(c);
  }
  for (std::size_t i = 0; i < view.object_points.size(); ++i) {
    calibration::Correspondence c;
    c.n = static_cast<int>(i) + 1;
    c.cam = view.truth.name;
    c.p_m = view.object_points[i];
    c.uv_px = view.truth.project(base_T_object * c.p_m) + Eigen::Vector2d(noise(), noise());
    out.object.push_back(c);
  }
  return out;
}

std::vector<std::vector<Eigen::Matrix3Xd>> calibration_link_sensitivities(const StudySetup& setup, const RobotModel& robot) {
  std::vector<std::vector<Eigen::Matrix3Xd>> out(setup.views.size());
  calibration::LinkLengthSensitivity sensitivity(robot);
  for (std::size_t v = 0; v < setup.views.size(); ++v)
    for (const ArmFeature& f : setup.views[v].calibration_features)
      out[v].push_back(sensitivity.at(setup.arm_q.at(f.pose), f.link, f.p_link));
  return out;
}

ClickCalibration calibrate_from_arm_clicks(const StudySetup& setup, const std::vector<int>& views, const RobotModel& true_arm,
                                           const std::vector<std::vector<Eigen::Matrix3Xd>>& dp_dlinks,
                                           const calibration::CalibrationOptions& options,
                                           const std::function<double()>& noise) {
  KinematicsWorkspace ws(true_arm);
  ClickCalibration out;
  for (const int v : views) {
    const StudyView& view = setup.views.at(static_cast<std::size_t>(v));
    std::vector<Eigen::Vector3d> true_base;
    for (const ArmFeature& f : view.calibration_features)
      true_base.push_back(forward_kinematics(true_arm, ws, setup.arm_q.at(f.pose), f.link) * f.p_link);
    ViewClicks vc = simulate_view_clicks(view, view.calibration_points_base, true_base, setup.base_T_object, noise);
    if (!dp_dlinks.empty())
      for (std::size_t i = 0; i < vc.calibration.size(); ++i) vc.calibration[i].dp_dlinks = dp_dlinks.at(v).at(i);
    const calibration::CalibrationResult cr =
        calibration::calibrate_camera(vc.calibration, view.truth.viewport, view.truth.name, options);
    const std::string& name = view.truth.name;
    const Eigen::Matrix3d R = cr.camera.base_T_camera.linear();
    out.cameras[name] = cr.camera;
    out.covariance[name] = calibration::camera_covariance_body_from_rpy(cr.covariance, R);
    out.noise_covariance[name] = calibration::camera_covariance_body_from_rpy(cr.covariance - cr.arm_model_covariance, R);
    out.information[name] = cr.information;
    out.link_sensitivity[name] = cr.link_sensitivity;
    out.rms_px[name] = cr.rms_px;
    out.object.insert(out.object.end(), vc.object.begin(), vc.object.end());
  }
  return out;
}

std::string view_combination_label(const std::vector<int>& views) {
  std::string s;
  for (const int v : views) s += (s.empty() ? "" : "+") + std::to_string(v + 1);
  return s;
}

std::vector<ArmCalibrationPose> arm_calibration_poses(const RobotModel& m) {
  KinematicsWorkspace ws(m);
  const Eigen::Vector3d tool_along_x(0.0, M_PI / 2, 0.0);  // tip z (tool axis) along base +x
  const std::vector<Pose> targets = {
      make_pose({0.55, -0.20, 0.40}, tool_along_x),
      make_pose({0.60, 0.35, 0.75}, tool_along_x + Eigen::Vector3d(0.0, -0.3, 0.2)),
      make_pose({0.45, 0.05, 0.95}, tool_along_x + Eigen::Vector3d(0.3, 0.2, -0.2)),
      make_pose({0.70, 0.20, 0.55}, tool_along_x),
  };
  std::vector<ArmCalibrationPose> out;
  const Eigen::VectorXd seed = m.mid_configuration();
  for (const Pose& target : targets) {
    const IkResult ik = inverse_kinematics(m, ws, target, seed);
    if (!ik.success) continue;
    ArmCalibrationPose pose;
    pose.q = ik.q;
    for (int k = 1; k < static_cast<int>(m.links().size()); ++k) {
      const Pose T = forward_kinematics(m, ws, ik.q, k);
      std::vector<Eigen::Vector3d> local = {Eigen::Vector3d::Zero()};
      for (const auto& v : m.links()[k].visuals) local.push_back(v.link_T_shape.translation());
      for (const auto& p : local) {
        const Eigen::Vector3d pb = T * p;
        bool dup = false;
        for (const auto& f : pose.features) dup = dup || (f.p_base - pb).norm() < 0.03;  // distinct features only
        if (!dup) pose.features.push_back({k, p, pb, static_cast<int>(out.size())});
      }
    }
    out.push_back(std::move(pose));
  }
  if (out.size() < 2) throw std::runtime_error("inverse kinematics reached fewer than 2 calibration arm poses");
  return out;
}

std::vector<ArmFeature> visible_features(const camera::Camera& camera, const ArmCalibrationPose& pose, int max_count) {
  std::vector<ArmFeature> seen;
  for (const auto& f : pose.features)
    if (camera.in_front(f.p_base) && camera.in_view(camera.project(f.p_base))) seen.push_back(f);
  const std::size_t take = std::min<std::size_t>(static_cast<std::size_t>(std::max(max_count, 0)), seen.size());
  std::vector<ArmFeature> out;
  for (std::size_t i = 0; i < take; ++i) out.push_back(seen[i * seen.size() / take]);
  return out;
}

void choose_calibration_points(StudySetup& setup, const std::vector<ArmCalibrationPose>& poses) {
  setup.arm_q.clear();
  for (const auto& pose : poses) setup.arm_q.push_back(pose.q);
  for (auto& v : setup.views) {
    v.calibration_points_base.clear();
    v.calibration_features.clear();
    for (const auto& pose : poses)
      for (const auto& f : visible_features(v.truth, pose)) {
        v.calibration_points_base.push_back(f.p_base);
        v.calibration_features.push_back(f);
      }
  }
}

Spread spread_of(const std::vector<double>& values) {
  Spread s;
  s.n = static_cast<int>(values.size());
  if (s.n == 0) return s;
  for (const double v : values) s.mean += v;
  s.mean /= s.n;
  double ss = 0.0;
  for (const double v : values) ss += (v - s.mean) * (v - s.mean);
  s.sd = s.n > 1 ? std::sqrt(ss / (s.n - 1)) : 0.0;
  return s;
}

std::vector<StudyResult> run_accuracy_study_seeds(const StudySetup& setup, const StudyOptions& options, int seeds) {
  if (seeds < 1) throw InputError("accuracy study: seeds must be at least 1, got " + std::to_string(seeds));
  std::vector<StudyResult> out;
  for (int k = 0; k < seeds; ++k) {
    StudyOptions o = options;
    o.seed = options.seed + static_cast<unsigned>(k);
    if (options.progress)
      o.progress = [&options, k, seeds](int done, int total) { options.progress(k * total + done, seeds * total); };
    out.push_back(run_accuracy_study(setup, o));
  }
  return out;
}

StudySetup make_study_setup(const Scene& scene, const ObjectModel& object,
                            const std::vector<Eigen::Vector3d>& arm_points_base) {
  StudySetup s;
  s.base_T_object = scene.base_T_object;
  for (const auto& name : scene.camera_order) {
    const SceneCamera& sc = scene.cameras.at(name);
    StudyView v;
    v.truth = camera::Camera::look_at(name, camera::Viewport{sc.width_px, sc.height_px}, sc.f_px, sc.position_m, sc.look_at_m, sc.up);
    for (const auto& p : arm_points_base)
      if (v.truth.in_front(p) && v.truth.in_view(v.truth.project(p))) v.calibration_points_base.push_back(p);
    const Eigen::Vector3d cam_in_object = s.base_T_object.inverse() * sc.position_m;
    for (const auto& mp : object.points) {
      const Eigen::Vector3d pb = s.base_T_object * mp.p_m;
      if (mp.p_m.z() <= 1e-9 && cam_in_object.z() < mp.p_m.z() && v.truth.in_front(pb) &&
          v.truth.in_view(v.truth.project(pb)))
        v.object_points.push_back(mp.p_m);
    }
    s.views.push_back(std::move(v));
  }
  return s;
}

void cramer_rao_bound(const StudySetup& setup, const std::vector<int>& views, double noise_px,
                      Eigen::Matrix<double, 6, 6>& joint, Eigen::Matrix<double, 6, 6>& known_cameras) {
  const int k_views = static_cast<int>(views.size());
  const int np = 6 + 7 * k_views;
  int rows = 0;
  for (const int v : views)
    rows += 2 * static_cast<int>(setup.views[v].calibration_points_base.size() + setup.views[v].object_points.size());
  // d pixels / d parameters at the truth: pose (body rotation, base
  // translation), then per camera (body rotation, position, f), the
  // estimators' own parameterization (camera/projection.hpp).
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(rows, np);
  const Pose& T = setup.base_T_object;
  int r = 0;
  for (int k = 0; k < k_views; ++k) {
    const StudyView& view = setup.views[views[k]];
    for (const auto& p : view.calibration_points_base) {
      J.block<2, 7>(r, 6 + 7 * k) = camera::project_with_jacobians(view.truth, p).d_camera;
      r += 2;
    }
    for (const auto& p : view.object_points) {
      const camera::Projection pr = camera::project_with_jacobians(view.truth, T * p);
      J.block<2, 6>(r, 0) = camera::object_pose_jacobian(pr, T.linear(), p);
      J.block<2, 7>(r, 6 + 7 * k) = pr.d_camera;
      r += 2;
    }
  }
  const Eigen::MatrixXd F = J.transpose() * J / (noise_px * noise_px);
  const Eigen::MatrixXd C = F.inverse();
  // (omega, dt_base) -> (dp_object, theta).
  Eigen::Matrix<double, 6, 6> G = Eigen::Matrix<double, 6, 6>::Zero();
  G.block<3, 3>(0, 3) = setup.base_T_object.linear().transpose();
  G.block<3, 3>(3, 0) = Eigen::Matrix3d::Identity();
  joint = G * C.topLeftCorner<6, 6>() * G.transpose();
  const Eigen::Matrix<double, 6, 6> Cp = F.topLeftCorner<6, 6>().inverse();
  known_cameras = G * Cp * G.transpose();
}

StudyResult run_accuracy_study(const StudySetup& setup, const StudyOptions& opt) {
  const int nv = static_cast<int>(setup.views.size());
  StudyResult res;
  res.trials = opt.trials;
  res.noise_px = opt.noise_px;
  res.arm_link_error_m = opt.arm_link_error_m;
  const bool arm_error = opt.arm_link_error_m > 0.0;
  if (arm_error) {
    if (opt.robot == nullptr) throw InputError("accuracy study: an arm-model error needs the robot model");
    for (const auto& v : setup.views)
      if (v.calibration_features.size() != v.calibration_points_base.size() || setup.arm_q.empty())
        throw InputError("accuracy study: an arm-model error needs the arm's calibration features (view '" +
                         v.truth.name + "' has none; use choose_calibration_points)");
  }
  for (const auto& v : setup.views) {
    if (v.calibration_points_base.size() < 6)
      throw calibration::EstimationInputError("view '" + v.truth.name + "' sees " + std::to_string(v.calibration_points_base.size()) +
                            " arm points; calibration needs at least 6");
    res.view_names.push_back(v.truth.name);
    res.calibration_points.push_back(static_cast<int>(v.calibration_points_base.size()));
    res.object_points.push_back(static_cast<int>(v.object_points.size()));
  }
  // Every non-empty subset, by size then by index.
  for (int size = 1; size <= nv; ++size)
    for (int mask = 1; mask < (1 << nv); ++mask) {
      if (__builtin_popcount(static_cast<unsigned>(mask)) != size) continue;
      ComboStats c;
      for (int v = 0; v < nv; ++v)
        if (mask & (1 << v)) c.views.push_back(v);
      c.label = view_combination_label(c.views);
      Eigen::Matrix<double, 6, 6> joint, known;
      cramer_rao_bound(setup, c.views, opt.noise_px, joint, known);
      c.crlb_sd = joint.diagonal().cwiseMax(0.0).cwiseSqrt();
      c.crlb_known_cameras_sd = known.diagonal().cwiseMax(0.0).cwiseSqrt();
      c.crlb_position_m = std::sqrt(joint.topLeftCorner<3, 3>().trace());
      c.crlb_rotation_rad = std::sqrt(joint.bottomRightCorner<3, 3>().trace());
      c.crlb_alignment95_m = 2.0 * std::sqrt(joint(0, 0) + joint(1, 1));
      c.crlb_depth95_m = 2.0 * std::sqrt(joint(2, 2));
      res.combos.push_back(c);
    }
  std::vector<ErrorAccumulator> ours(res.combos.size()), ours_joint(res.combos.size()), pnp_it(res.combos.size()), pnp_sq(res.combos.size()),
      tri(res.combos.size());
  std::vector<double> calib_rms_sum(nv, 0.0);
  int good_trials = 0;
  std::mt19937_64 rng(opt.seed);
  std::normal_distribution<double> noise(0.0, opt.noise_px);
  // The arm-model error has its own stream: the clicks are the same with and without it.
  std::mt19937_64 arm_rng(opt.seed ^ 0x9E3779B97F4A7C15ull);
  std::normal_distribution<double> link_error(0.0, arm_error ? opt.arm_link_error_m : 1.0);
  for (int t = 0; t < opt.trials; ++t) {
    // Where the calibration believes each arm point is (the arm model's FK).
    std::vector<std::vector<Eigen::Vector3d>> believed(nv);
    for (int v = 0; v < nv; ++v) believed[v] = setup.views[v].calibration_points_base;
    if (arm_error) {
      const RobotModel& robot = *opt.robot;
      std::vector<double> delta(robot.segment_count(), 0.0);
      for (const int k : robot.offset_segments()) delta[k] = link_error(arm_rng);
      const RobotModel model = robot.with_link_lengths_changed(delta);
      KinematicsWorkspace ws(model);
      for (int v = 0; v < nv; ++v)
        for (std::size_t i = 0; i < believed[v].size(); ++i) {
          const ArmFeature& f = setup.views[v].calibration_features[i];
          believed[v][i] = forward_kinematics(model, ws, setup.arm_q.at(f.pose), f.link) * f.p_link;
        }
    }
    std::map<std::string, camera::Camera> cams;
    std::map<std::string, Eigen::Matrix<double, 7, 7>> information;
    std::vector<calibration::Correspondence> clicks;
    bool ok = true;
    for (int v = 0; v < nv && ok; ++v) {
      const StudyView& view = setup.views[v];
      ViewClicks vc = simulate_view_clicks(view, believed[v], view.calibration_points_base, setup.base_T_object,
                                           [&] { return noise(rng); });
      try {
        const calibration::CalibrationResult r = calibration::calibrate_camera(vc.calibration, view.truth.viewport, view.truth.name);
        cams[view.truth.name] = r.camera;
        information[view.truth.name] = r.information;
        calib_rms_sum[v] += r.rms_px;
      } catch (const Error&) {  // an estimation that failed (input or computation)
        ok = false;
      }
      clicks.insert(clicks.end(), vc.object.begin(), vc.object.end());
    }
    if (!ok) {
      ++res.calibration_failures;
      if (opt.progress) opt.progress(t + 1, opt.trials);
      continue;
    }
    ++good_trials;
    for (std::size_t ci = 0; ci < res.combos.size(); ++ci) {
      ComboStats& combo = res.combos[ci];
      LocalizationOptions lo;
      std::vector<calibration::Correspondence> pts;
      for (const int v : combo.views) {
        lo.views.push_back(setup.views[v].truth.name);
        for (const auto& c : clicks)
          if (c.cam == setup.views[v].truth.name) pts.push_back(c);
      }
      try {
        ours[ci].add(pose_error(localize_object(pts, cams, lo).base_T_object, setup.base_T_object));
      } catch (const Error&) {  // an estimation that failed (input or computation)
        ++combo.failures;
      }
      try {
        LocalizationOptions lj = lo;
        lj.camera_information = information;
        ours_joint[ci].add(pose_error(localize_object(pts, cams, lj).base_T_object, setup.base_T_object));
      } catch (const Error&) {  // an estimation that failed (input or computation)
        ++combo.joint_failures;
      }
      if (combo.views.size() == 1) {
        const camera::Camera& cam = cams.at(lo.views[0]);
        if (const auto T = solve_pnp_opencv(pts, cam, PnpMethod::Iterative))
          pnp_it[ci].add(pose_error(*T, setup.base_T_object));
        if (const auto T = solve_pnp_opencv(pts, cam, PnpMethod::Sqpnp))
          pnp_sq[ci].add(pose_error(*T, setup.base_T_object));
      } else if (const auto T = triangulate_and_align(pts, cams)) {
        tri[ci].add(pose_error(*T, setup.base_T_object));
      }
    }
    if (opt.progress) opt.progress(t + 1, opt.trials);
  }
  for (std::size_t ci = 0; ci < res.combos.size(); ++ci) {
    res.combos[ci].ours = ours[ci].stats();
    res.combos[ci].ours_joint = ours_joint[ci].stats();
    res.combos[ci].pnp_iterative = pnp_it[ci].stats();
    res.combos[ci].pnp_sqpnp = pnp_sq[ci].stats();
    res.combos[ci].triangulation = tri[ci].stats();
  }
  for (int v = 0; v < nv; ++v) res.calibration_rms_px.push_back(good_trials ? calib_rms_sum[v] / good_trials : 0.0);
  return res;
}

}  // namespace foresight::localization
