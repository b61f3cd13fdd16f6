#include "foresight/align/alignment_study.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <map>
#include <memory>
#include <random>

#include "foresight/align/model_aligner.hpp"
#include "foresight/calibration/calibrate.hpp"
#include "foresight/calibration/robot_points.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

namespace foresight::align {

namespace {

bool refused_for_disagreement(const AlignResult& r) {
  return r.status == AlignStatus::Refused && r.reason.rfind("the object moved", 0) == 0;
}

}  // namespace

AlignmentStudyResult run_alignment_study(render::GlContext& ctx, const RobotModel& robot, const ObjectModel& object,
                                         const Scene& scene, const AlignmentStudyOptions& opt) {
  if (opt.trials < 1) throw InputError("--trials must be at least 1");
  if (!(opt.noise_px > 0.0) || !std::isfinite(opt.noise_px)) throw InputError("--noise-px must be a positive number");
  if (!(opt.arm_link_error_m >= 0.0) || !std::isfinite(opt.arm_link_error_m))
    throw InputError("--arm-error-mm must be a non-negative number");
  if (!(opt.arm_link_prior_m >= 0.0) || !std::isfinite(opt.arm_link_prior_m))
    throw InputError("--arm-prior-mm must be a non-negative number");
  const auto t0 = std::chrono::steady_clock::now();
  StudySetup setup = make_study_setup(scene, object, {});
  const std::vector<ArmCalibrationPose> poses = arm_calibration_poses(robot);
  choose_calibration_points(setup, poses);
  const int nv = static_cast<int>(setup.views.size());
  const Viewport vp = setup.views.front().truth.viewport;
  for (const auto& v : setup.views)
    if (!(v.truth.viewport == vp)) throw InputError("eval alignment: every camera of the scene needs one viewport");

  AlignmentStudyResult res;
  res.trials = opt.trials;
  res.noise_px = opt.noise_px;
  res.arm_link_error_m = opt.arm_link_error_m;
  // Per view, the calibration poses it sees the arm at (a frame each).
  std::vector<std::vector<int>> view_poses(nv);
  for (int v = 0; v < nv; ++v) {
    res.view_names.push_back(setup.views[v].truth.name);
    for (const auto& f : setup.views[v].calibration_features)
      if (view_poses[v].empty() || view_poses[v].back() != f.pose) view_poses[v].push_back(f.pose);
    res.frames.push_back(static_cast<int>(view_poses[v].size()));
  }
  std::vector<AlignmentComboStats> combos;
  for (int size = 1; size <= nv; ++size)
    for (int mask = 1; mask < (1 << nv); ++mask) {
      if (__builtin_popcount(static_cast<unsigned>(mask)) != size) continue;
      AlignmentComboStats c;
      for (int v = 0; v < nv; ++v)
        if (mask & (1 << v)) c.views.push_back(v);
      c.label = view_combination_label(c.views);
      combos.push_back(c);
    }
  std::vector<ErrorAccumulator> acc_clicks(combos.size()), acc_aligned(combos.size()), acc_held(combos.size()),
      acc_cam_only(combos.size());
  res.link_segments = robot.offset_segments();
  const int nls = static_cast<int>(res.link_segments.size());
  std::vector<double> link_true2(nls, 0.0), link_err2(nls, 0.0), link_sig(nls, 0.0);
  int link_trials = 0;
  res.camera_bundle_px.assign(nv, 0.0);
  res.camera_clicks_px.assign(nv, 0.0);
  res.camera_aligned_px.assign(nv, 0.0);
  res.camera_refused.assign(nv, 0);

  // Reprojection metric points: the ORU's box corners and the link origins.
  std::vector<Eigen::Vector3d> metric_points;
  {
    KinematicsWorkspace ws(robot);
    for (const auto& p : poses)
      for (int k = 0; k < static_cast<int>(robot.links().size()); ++k)
        metric_points.push_back(forward_kinematics(robot, ws, p.q, k).translation());
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d h = object.size_m / 2.0;
      const Eigen::Vector3d c((k & 1) ? h.x() : -h.x(), (k & 2) ? h.y() : -h.y(), (k & 4) ? h.z() : -h.z());
      metric_points.push_back(scene.base_T_object * (object.oru_T_box * c));
    }
  }

  // The calibration points' sensitivity to the link lengths (the nominal
  // arm's; the same every trial): the click calibration's covariance
  // carries the arm model's uncertainty (arm_link_prior_m), which the
  // residuals cannot show.
  std::vector<std::vector<Eigen::Matrix3Xd>> calibration_dp_dlinks(nv);
  {
    LinkLengthSensitivity sensitivity(robot);
    for (int v = 0; v < nv; ++v)
      for (const ArmFeature& f : setup.views[v].calibration_features)
        calibration_dp_dlinks[v].push_back(sensitivity.at(setup.arm_q.at(f.pose), f.link, f.p_link));
  }
  CalibrationOptions calibration_options;
  calibration_options.arm_link_sigma_m = opt.arm_link_prior_m;

  ModelAligner aligner(ctx, robot, &object, vp);
  std::mt19937_64 rng(opt.seed);
  std::normal_distribution<double> noise(0.0, opt.noise_px);
  std::mt19937_64 arm_rng(opt.seed ^ 0x9E3779B97F4A7C15ull);
  std::normal_distribution<double> link_error(0.0, opt.arm_link_error_m > 0.0 ? opt.arm_link_error_m : 1.0);
  int good = 0;
  for (int t = 0; t < opt.trials; ++t) {
    // The true arm (rendered and clicked); the ground believes `robot`.
    std::vector<double> delta(robot.segment_count(), 0.0);
    if (opt.arm_link_error_m > 0.0)
      for (const int k : res.link_segments) delta[k] = link_error(arm_rng);
    const RobotModel truth_arm = robot.with_link_lengths_changed(delta);
    KinematicsWorkspace tws(truth_arm);

    // Clicks: calibration on the true arm, the believed points from the nominal arm.
    std::map<std::string, Camera> cams;
    std::map<std::string, Eigen::Matrix<double, 7, 7>> cam_covariance, cam_noise_covariance;
    std::map<std::string, Eigen::MatrixXd> cam_link_sensitivity;
    std::vector<Correspondence> oru_clicks;
    bool ok = true;
    for (int v = 0; v < nv && ok; ++v) {
      const StudyView& view = setup.views[v];
      std::vector<Eigen::Vector3d> true_base;
      for (const ArmFeature& f : view.calibration_features)
        true_base.push_back(forward_kinematics(truth_arm, tws, setup.arm_q.at(f.pose), f.link) * f.p_link);
      ViewClicks vc = simulate_view_clicks(view, view.calibration_points_base, true_base, setup.base_T_object,
                                           [&] { return noise(rng); });
      for (std::size_t i = 0; i < vc.calibration.size(); ++i) vc.calibration[i].dp_dlinks = calibration_dp_dlinks[v][i];
      try {
        const CalibrationResult cr = calibrate_camera(vc.calibration, vp, view.truth.name, calibration_options);
        cams[view.truth.name] = cr.camera;
        cam_link_sensitivity[view.truth.name] = cr.link_sensitivity;
        cam_covariance[view.truth.name] = camera_covariance_body_from_rpy(cr.covariance, cr.camera.base_T_camera.linear());
        cam_noise_covariance[view.truth.name] =
            camera_covariance_body_from_rpy(cr.covariance - cr.arm_model_covariance, cr.camera.base_T_camera.linear());
      } catch (const Error&) {
        ok = false;
      }
      oru_clicks.insert(oru_clicks.end(), vc.object.begin(), vc.object.end());
    }
    if (!ok) {
      ++res.calibration_failures;
      if (opt.progress) opt.progress(t + 1, opt.trials);
      continue;
    }
    // Clicks localization per combination.
    std::vector<std::optional<Pose>> clicks_pose(combos.size());
    std::vector<Eigen::Matrix<double, 6, 6>> clicks_cov(combos.size(), Eigen::Matrix<double, 6, 6>::Zero());
    std::vector<Eigen::Matrix<double, 6, 6>> clicks_arm_cov(combos.size(), Eigen::Matrix<double, 6, 6>::Zero());
    for (std::size_t ci = 0; ci < combos.size(); ++ci) {
      LocalizationOptions lo;
      std::vector<Correspondence> pts;
      for (const int v : combos[ci].views) {
        lo.views.push_back(setup.views[v].truth.name);
        for (const auto& c : oru_clicks)
          if (c.cam == setup.views[v].truth.name) pts.push_back(c);
      }
      // The clicks' uncertainty for the alignment's agreement check: the
      // clicks' noise, the cameras' calibration noise and the arm model's
      // error, which the cameras share; the pose is the paper's two-step one.
      lo.camera_covariance = cam_noise_covariance;
      lo.camera_link_sensitivity = cam_link_sensitivity;
      lo.arm_link_sigma_m = opt.arm_link_prior_m;
      try {
        const LocalizationResult lr = localize_object(pts, cams, lo);
        clicks_pose[ci] = lr.base_T_object;
        clicks_cov[ci] = lr.covariance;
        clicks_arm_cov[ci] = lr.arm_model_covariance;
      } catch (const Error&) {
        ++combos[ci].clicks_failures;
      }
    }
    ++good;

    // Synthetic frames of the true arm (the ORU at its true pose).
    render::SyntheticOptions so;
    so.noise_sigma_dn = opt.sensor_noise_dn;
    so.blur_sigma_px = opt.blur_px;
    so.seed = static_cast<unsigned>(opt.seed * 7919u + static_cast<unsigned>(t));
    render::SyntheticCamera synth(ctx, truth_arm, object, scene, vp, so);
    std::vector<AlignView> views(nv);
    const std::optional<Pose> occluder = clicks_pose.back() ? clicks_pose.back() : std::optional<Pose>(setup.base_T_object);
    std::vector<Camera> aligned_cam(nv);
    // Each camera's uncertainty (body rotation): its click calibration's
    // (the arm model's part included), replaced by its alignment's block when aligned; held with it when the
    // ORU is aligned (a refused camera keeps its clicks error, seen at 3% in f).
    std::vector<Eigen::Matrix<double, 7, 7>> aligned_cov(nv);
    for (int v = 0; v < nv; ++v) aligned_cov[v] = cam_covariance.at(setup.views[v].truth.name);
    std::vector<int> views_aligned;
    for (int v = 0; v < nv; ++v) {
      const Camera& truth = setup.views[v].truth;
      views[v].camera = cams.at(truth.name);
      for (const int p : view_poses[v]) views[v].frames.push_back({synth.render(truth, setup.arm_q[p]).image_bgr, setup.arm_q[p]});
      AlignOptions ao;
      ao.refine = Refine::Camera;
      const AlignResult r = aligner.align({views[v]}, occluder, ao);
      if (r.status != AlignStatus::Aligned) ++res.camera_refused[v];
      aligned_cam[v] = r.cameras[0];  // the start when refused
      if (r.status == AlignStatus::Aligned && r.covariance.rows() >= 7) aligned_cov[v] = r.covariance.topLeftCorner<7, 7>();
      if (r.status == AlignStatus::Aligned) views_aligned.push_back(v);
      res.camera_clicks_px[v] += reprojection_rms_px(views[v].camera, truth, metric_points);
      res.camera_aligned_px[v] += reprojection_rms_px(aligned_cam[v], truth, metric_points);
    }
    // Step 5: cameras + the arm's link lengths over every aligned camera's frames.
    std::vector<Camera> bundle_cam = aligned_cam;
    std::vector<Eigen::Matrix<double, 7, 7>> bundle_cov = aligned_cov;
    std::vector<double> arm_delta;  // empty: the nominal arm
    if (opt.arm_link_prior_m > 0.0 && !views_aligned.empty()) {
      std::vector<AlignView> all;
      for (const int v : views_aligned) all.push_back({aligned_cam[v], views[v].frames});
      AlignOptions ao;
      ao.refine = Refine::Camera;
      ao.arm_link_prior_m = opt.arm_link_prior_m;
      const AlignResult r = aligner.align(all, occluder, ao);
      if (r.status == AlignStatus::Aligned) {
        for (std::size_t i = 0; i < views_aligned.size(); ++i) {
          bundle_cam[views_aligned[i]] = r.cameras[i];
          if (r.covariance.rows() >= 7 * static_cast<int>(i + 1))
            bundle_cov[views_aligned[i]] = r.covariance.block<7, 7>(7 * i, 7 * i);
        }
        arm_delta = r.arm_link_delta_m;
        for (int j = 0; j < nls; ++j) {
          const int k = res.link_segments[j];
          link_true2[j] += delta[k] * delta[k];
          link_err2[j] += (arm_delta[k] - delta[k]) * (arm_delta[k] - delta[k]);
          link_sig[j] += r.arm_link_sigma_m.empty() ? 0.0 : r.arm_link_sigma_m[k];
        }
        ++link_trials;
      } else {
        ++res.bundle_refused;
      }
    }
    if (const char* dump = std::getenv("FORESIGHT_STUDY_DUMP"); dump && std::atoi(dump) == t) {
      auto vec = [](const char* name, const double* d, int n) {
        std::fprintf(stderr, "DUMP %s", name);
        for (int k = 0; k < n; ++k) std::fprintf(stderr, " %.17g", d[k]);
        std::fprintf(stderr, "\n");
      };
      vec("true_delta", delta.data(), static_cast<int>(delta.size()));
      vec("arm_delta", arm_delta.data(), static_cast<int>(arm_delta.size()));
      std::fprintf(stderr, "DUMP synth_seed %u\n", so.seed);
      for (int v = 0; v < nv; ++v) {
        const Eigen::Matrix4d M = bundle_cam[v].base_T_camera.matrix();
        std::fprintf(stderr, "DUMP camera %d f %.17g", v, bundle_cam[v].f_px);
        for (int k = 0; k < 16; ++k) std::fprintf(stderr, " %.17g", M(k % 4, k / 4));
        std::fprintf(stderr, " covariance");
        for (int k = 0; k < 49; ++k) std::fprintf(stderr, " %.17g", bundle_cov[v](k % 7, k / 7));
        std::fprintf(stderr, "\n");
      }
      for (std::size_t ci = 0; ci < combos.size(); ++ci) {
        if (!clicks_pose[ci]) continue;
        const Eigen::Matrix4d M = clicks_pose[ci]->matrix();
        std::fprintf(stderr, "DUMP clicks %s", combos[ci].label.c_str());
        for (int k = 0; k < 16; ++k) std::fprintf(stderr, " %.17g", M(k % 4, k / 4));
        std::fprintf(stderr, " covariance");
        for (int k = 0; k < 36; ++k) std::fprintf(stderr, " %.17g", clicks_cov[ci](k % 6, k / 6));
        std::fprintf(stderr, "\n");
      }
    }
    for (int v = 0; v < nv; ++v) res.camera_bundle_px[v] += reprojection_rms_px(bundle_cam[v], setup.views[v].truth, metric_points);
    // The ORU over each combination (step 6): refined with the step-5
    // cameras and arm; for comparison, with those cameras held and with the
    // step-4 cameras (nominal arm) held.
    for (std::size_t ci = 0; ci < combos.size(); ++ci) {
      if (!clicks_pose[ci]) continue;
      AlignmentComboStats& combo = combos[ci];
      acc_clicks[ci].add(pose_error(*clicks_pose[ci], setup.base_T_object));
      std::vector<AlignView> sub, sub_cam_only;
      for (const int v : combo.views) {
        sub.push_back({bundle_cam[v], views[v].frames, bundle_cov[v]});
        sub_cam_only.push_back({aligned_cam[v], views[v].frames, aligned_cov[v]});
      }
      AlignOptions ao;
      ao.refine = Refine::Object;
      ao.object_start_covariance = clicks_cov[ci];
      const AlignResult r0 = aligner.align(sub_cam_only, clicks_pose[ci], ao);
      if (r0.status != AlignStatus::Aligned) ++combo.aligned_cameras_only_refused;
      acc_cam_only[ci].add(pose_error(*r0.base_T_object, setup.base_T_object));
      AlignResult r = r0;
      int object_col = 0;  // the object's block in r.covariance
      if (opt.arm_link_prior_m > 0.0) {
        ao.arm_link_delta_m = arm_delta;
        const AlignResult held = aligner.align(sub, clicks_pose[ci], ao);
        if (held.status != AlignStatus::Aligned) ++combo.aligned_held_cameras_refused;
        acc_held[ci].add(pose_error(*held.base_T_object, setup.base_T_object));
        // The ORU with the views' cameras and the arm's links (step 6).
        AlignOptions jo = ao;
        jo.refine = Refine::Both;
        jo.arm_link_prior_m = opt.arm_link_prior_m;
        r = aligner.align(sub, clicks_pose[ci], jo);
        object_col = 7 * static_cast<int>(sub.size());
      } else {
        acc_held[ci].add(pose_error(*r0.base_T_object, setup.base_T_object));
        if (r0.status != AlignStatus::Aligned) ++combo.aligned_held_cameras_refused;
      }
      if (r.status != AlignStatus::Aligned) ++combo.aligned_refused;
      if (refused_for_disagreement(r)) ++combo.aligned_refused_disagreement;
      acc_aligned[ci].add(pose_error(*r.base_T_object, setup.base_T_object));
      // The claim: the position error against the position covariance.
      const Eigen::Matrix3d Cp = r.covariance.rows() >= object_col + 6
                                     ? Eigen::Matrix3d(r.covariance.block<3, 3>(object_col + 3, object_col + 3))
                                     : Eigen::Matrix3d::Zero();
      const Eigen::Vector3d ep = r.base_T_object->translation() - setup.base_T_object.translation();
      double worst_axis = 0.0, z2 = 0.0;
      if (r.status == AlignStatus::Aligned) {
        for (int k = 0; k < 3; ++k) worst_axis = std::max(worst_axis, std::abs(ep[k]) / std::sqrt(std::max(1e-30, Cp(k, k))));
        z2 = ep.dot(Cp.ldlt().solve(ep));
        ++combo.aligned_accepted;
        if (worst_axis <= 3.0) ++combo.aligned_within_3_sigma;
        combo.aligned_mahalanobis2_mean += z2;
      }
      if (std::getenv("FORESIGHT_STUDY_TRACE")) {
        // the clicks covariance's honesty: the clicks' error in sigmas (6-DoF, rotation)
        const Eigen::AngleAxisd aa(setup.base_T_object.linear().transpose() * clicks_pose[ci]->linear());
        Eigen::Matrix<double, 6, 1> e;
        e << aa.angle() * aa.axis(), clicks_pose[ci]->translation() - setup.base_T_object.translation();
        Eigen::Matrix<double, 6, 6> T = Eigen::Matrix<double, 6, 6>::Identity();
        T.topLeftCorner<3, 3>() = rpy_rate_matrix(rpy_from_rotation(clicks_pose[ci]->linear()));
        const Eigen::Matrix<double, 6, 6> Cb = T * clicks_cov[ci] * T.transpose();
        const Eigen::Matrix<double, 6, 6> Ca = T * clicks_arm_cov[ci] * T.transpose();
        std::fprintf(stderr, "HONEST t%d %-8s clicks z6 %.2f zrot %.2f zpos %.2f | rot err %.2f deg sd %.2f %.2f %.2f deg (arm %.2f %.2f %.2f)\n", t,
                     combo.label.c_str(), std::sqrt(e.dot(Cb.ldlt().solve(e))),
                     std::sqrt(e.head<3>().dot(Cb.topLeftCorner<3, 3>().ldlt().solve(e.head<3>()))),
                     std::sqrt(e.tail<3>().dot(Cb.bottomRightCorner<3, 3>().ldlt().solve(e.tail<3>()))),
                     aa.angle() * 180 / M_PI, std::sqrt(Cb(0, 0)) * 180 / M_PI, std::sqrt(Cb(1, 1)) * 180 / M_PI,
                     std::sqrt(Cb(2, 2)) * 180 / M_PI, std::sqrt(Ca(0, 0)) * 180 / M_PI, std::sqrt(Ca(1, 1)) * 180 / M_PI,
                     std::sqrt(Ca(2, 2)) * 180 / M_PI);
        const auto ec = pose_error(*clicks_pose[ci], setup.base_T_object);
        const auto ea = pose_error(*r.base_T_object, setup.base_T_object);
        std::fprintf(stderr,
                     "TRACE t%d %-8s %s '%s' clicks_err %.1f %.1f %.1f mm -> %.1f %.1f %.1f mm | score %.2f->%.2f res %.2f vis %d match %d it %d "
                     "| m %.1f p %.1f | change rot %.3f %.3f %.3f t %.1f %.1f %.1f mm | align sd t %.2f %.2f %.2f mm | worst axis %.2f z3 %.2f "
                     "| clicks sd t %.1f %.1f %.1f mm\n",
                     t, combo.label.c_str(), to_string(r.status), r.reason.c_str(), ec[0] * 1e3, ec[1] * 1e3, ec[2] * 1e3,
                     ea[0] * 1e3, ea[1] * 1e3, ea[2] * 1e3, r.start_score_px, r.final_score_px, r.residual_rms_px,
                     r.visible_samples, r.matched_samples, r.iterations, r.start_disagreement_sigma,
                     r.start_position_disagreement_sigma, r.object_change[0], r.object_change[1], r.object_change[2],
                     r.object_change[3] * 1e3, r.object_change[4] * 1e3, r.object_change[5] * 1e3,
                     std::sqrt(Cp(0, 0)) * 1e3, std::sqrt(Cp(1, 1)) * 1e3, std::sqrt(Cp(2, 2)) * 1e3, worst_axis,
                     std::sqrt(z2), std::sqrt(clicks_cov[ci](3, 3)) * 1e3, std::sqrt(clicks_cov[ci](4, 4)) * 1e3,
                     std::sqrt(clicks_cov[ci](5, 5)) * 1e3);
      }
    }
    if (opt.progress) opt.progress(t + 1, opt.trials);
  }
  for (std::size_t ci = 0; ci < combos.size(); ++ci) {
    combos[ci].clicks = acc_clicks[ci].stats();
    combos[ci].aligned = acc_aligned[ci].stats();
    combos[ci].aligned_cameras_only = acc_cam_only[ci].stats();
    combos[ci].aligned_held_cameras = acc_held[ci].stats();
    if (combos[ci].aligned_accepted > 0) combos[ci].aligned_mahalanobis2_mean /= combos[ci].aligned_accepted;
  }
  double t2 = 0.0, e2 = 0.0;
  for (int j = 0; j < nls; ++j) {
    t2 += link_true2[j];
    e2 += link_err2[j];
    res.link_true_rms_m.push_back(std::sqrt(link_true2[j] / std::max(1, link_trials)));
    res.link_estimate_error_rms_m.push_back(std::sqrt(link_err2[j] / std::max(1, link_trials)));
    res.link_sigma_mean_m.push_back(link_sig[j] / std::max(1, link_trials));
  }
  res.link_true_rms_all_m = std::sqrt(t2 / std::max(1, link_trials * nls));
  res.link_estimate_error_rms_all_m = std::sqrt(e2 / std::max(1, link_trials * nls));
  for (int v = 0; v < nv; ++v) {
    res.camera_clicks_px[v] /= std::max(1, good);
    res.camera_aligned_px[v] /= std::max(1, good);
    res.camera_bundle_px[v] /= std::max(1, good);
  }
  res.combos = std::move(combos);
  res.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace foresight::align
