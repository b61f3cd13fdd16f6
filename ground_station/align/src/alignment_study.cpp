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

/// One run of the study: the scene's set-up, the accumulators, and a trial
/// in steps (the clicks, the cameras aligned one by one, the bundle with the
/// arm, the ORU over every view combination).
class AlignmentStudy {
 public:
  AlignmentStudy(render::GlContext& ctx, const RobotModel& robot, const ObjectModel& object, const Scene& scene,
                 const AlignmentStudyOptions& opt)
      : ctx_(ctx),
        robot_(robot),
        object_(object),
        scene_(scene),
        opt_(opt),
        setup_(localization::make_study_setup(scene, object, {})),
        poses_(localization::arm_calibration_poses(robot)),
        rng_(opt.seed),
        noise_(0.0, opt.noise_px),
        arm_rng_(opt.seed ^ 0x9E3779B97F4A7C15ull),
        link_error_(0.0, opt.arm_link_error_m > 0.0 ? opt.arm_link_error_m : 1.0) {
    localization::choose_calibration_points(setup_, poses_);
    nv_ = static_cast<int>(setup_.views.size());
    vp_ = setup_.views.front().truth.viewport;
    for (const auto& v : setup_.views)
      if (!(v.truth.viewport == vp_)) throw InputError("eval alignment: every camera of the scene needs one viewport");
    res_.trials = opt.trials;
    res_.noise_px = opt.noise_px;
    res_.arm_link_error_m = opt.arm_link_error_m;
    // Per view, the calibration poses it sees the arm at (a frame each).
    view_poses_.resize(nv_);
    for (int v = 0; v < nv_; ++v) {
      res_.view_names.push_back(setup_.views[v].truth.name);
      for (const auto& f : setup_.views[v].calibration_features)
        if (view_poses_[v].empty() || view_poses_[v].back() != f.pose) view_poses_[v].push_back(f.pose);
      res_.frames.push_back(static_cast<int>(view_poses_[v].size()));
    }
    for (int size = 1; size <= nv_; ++size)
      for (int mask = 1; mask < (1 << nv_); ++mask) {
        if (__builtin_popcount(static_cast<unsigned>(mask)) != size) continue;
        AlignmentComboStats c;
        for (int v = 0; v < nv_; ++v)
          if (mask & (1 << v)) c.views.push_back(v);
        c.label = localization::view_combination_label(c.views);
        combos_.push_back(c);
      }
    acc_clicks_.resize(combos_.size());
    acc_aligned_.resize(combos_.size());
    acc_held_.resize(combos_.size());
    acc_cam_only_.resize(combos_.size());
    res_.link_segments = robot.offset_segments();
    nls_ = static_cast<int>(res_.link_segments.size());
    link_true2_.assign(nls_, 0.0);
    link_err2_.assign(nls_, 0.0);
    link_sig_.assign(nls_, 0.0);
    res_.camera_bundle_px.assign(nv_, 0.0);
    res_.camera_clicks_px.assign(nv_, 0.0);
    res_.camera_aligned_px.assign(nv_, 0.0);
    res_.camera_refused.assign(nv_, 0);
    // Reprojection metric points: the ORU's box corners and the link origins.
    KinematicsWorkspace ws(robot);
    for (const auto& p : poses_)
      for (int k = 0; k < static_cast<int>(robot.links().size()); ++k)
        metric_points_.push_back(forward_kinematics(robot, ws, p.q, k).translation());
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d h = object.size_m / 2.0;
      const Eigen::Vector3d c((k & 1) ? h.x() : -h.x(), (k & 2) ? h.y() : -h.y(), (k & 4) ? h.z() : -h.z());
      metric_points_.push_back(scene.base_T_object * (object.oru_T_box * c));
    }
    // The calibration points' sensitivity to the link lengths (the nominal
    // arm's; the same every trial): the click calibration's covariance
    // carries the arm model's uncertainty (arm_link_prior_m), which the
    // residuals cannot show.
    calibration_dp_dlinks_ = localization::calibration_link_sensitivities(setup_, robot);
    calibration_options_.arm_link_sigma_m = opt.arm_link_prior_m;
    aligner_ = std::make_unique<ModelAligner>(ctx, robot, &object, vp_);
  }

  AlignmentStudyResult run(std::chrono::steady_clock::time_point t0) {
    for (int t = 0; t < opt_.trials; ++t) {
      trial(t);
      if (opt_.progress) opt_.progress(t + 1, opt_.trials);
    }
    summarize();
    res_.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return std::move(res_);
  }

 private:
  /// A trial's click calibration of every camera (on the true arm, the
  /// believed points from the nominal arm) and the ORU's clicks.
  struct Clicks {
    std::map<std::string, camera::Camera> cams;
    std::map<std::string, Eigen::Matrix<double, 7, 7>> covariance, noise_covariance;
    std::map<std::string, Eigen::MatrixXd> link_sensitivity;
    std::vector<calibration::Correspondence> oru;
  };
  /// The ORU localized from the clicks per view combination.
  struct ClickPoses {
    std::vector<std::optional<Pose>> pose;
    std::vector<Eigen::Matrix<double, 6, 6>> covariance, arm_covariance;
  };
  /// The cameras of a trial after each step.
  struct TrialCameras {
    std::vector<AlignView> views;                       ///< the click cameras with the frames
    std::vector<camera::Camera> aligned;                        ///< step 4 (the start when refused)
    std::vector<Eigen::Matrix<double, 7, 7>> aligned_cov;
    std::vector<int> views_aligned;
    std::vector<camera::Camera> bundle;                         ///< step 5
    std::vector<Eigen::Matrix<double, 7, 7>> bundle_cov;
    std::vector<double> arm_delta;                      ///< step 5's links (empty: the nominal arm)
  };

  void trial(int t) {
    // The true arm (rendered and clicked); the ground believes `robot`.
    std::vector<double> delta(robot_.segment_count(), 0.0);
    if (opt_.arm_link_error_m > 0.0)
      for (const int k : res_.link_segments) delta[k] = link_error_(arm_rng_);
    const RobotModel truth_arm = robot_.with_link_lengths_changed(delta);
    Clicks clicks;
    if (!click_calibration(truth_arm, clicks)) {
      ++res_.calibration_failures;
      return;
    }
    const ClickPoses click_poses = localize_clicks(clicks);
    ++good_;
    // Synthetic frames of the true arm (the ORU at its true pose).
    render::SyntheticOptions so;
    so.noise_sigma_dn = opt_.sensor_noise_dn;
    so.blur_sigma_px = opt_.blur_px;
    so.seed = static_cast<unsigned>(opt_.seed * 7919u + static_cast<unsigned>(t));
    render::SyntheticCamera synth(ctx_, truth_arm, object_, scene_, vp_, so);
    const std::optional<Pose> occluder =
        click_poses.pose.back() ? click_poses.pose.back() : std::optional<Pose>(setup_.base_T_object);
    TrialCameras cams = align_cameras(clicks, synth, occluder);
    bundle(cams, occluder, delta);
    if (const char* dump = std::getenv("FORESIGHT_STUDY_DUMP"); dump && std::atoi(dump) == t)
      dump_trial(delta, cams, click_poses, so.seed);
    for (int v = 0; v < nv_; ++v)
      res_.camera_bundle_px[v] += reprojection_rms_px(cams.bundle[v], setup_.views[v].truth, metric_points_);
    for (std::size_t ci = 0; ci < combos_.size(); ++ci)
      if (click_poses.pose[ci]) align_oru(t, ci, cams, click_poses);
  }

  bool click_calibration(const RobotModel& truth_arm, Clicks& clicks) {
    std::vector<int> views(static_cast<std::size_t>(nv_));
    for (int v = 0; v < nv_; ++v) views[static_cast<std::size_t>(v)] = v;
    try {
      localization::ClickCalibration c = localization::calibrate_from_arm_clicks(
          setup_, views, truth_arm, calibration_dp_dlinks_, calibration_options_, [&] { return noise_(rng_); });
      clicks.cams = std::move(c.cameras);
      clicks.link_sensitivity = std::move(c.link_sensitivity);
      clicks.covariance = std::move(c.covariance);
      clicks.noise_covariance = std::move(c.noise_covariance);
      clicks.oru = std::move(c.object);
    } catch (const Error&) {
      return false;
    }
    return true;
  }

  /// The clicks' localization per combination. Its uncertainty serves the
  /// alignment's agreement check: the clicks' noise, the cameras'
  /// calibration noise and the arm model's error, which the cameras share;
  /// the pose is the paper's two-step one.
  ClickPoses localize_clicks(const Clicks& clicks) {
    ClickPoses out;
    out.pose.resize(combos_.size());
    out.covariance.assign(combos_.size(), Eigen::Matrix<double, 6, 6>::Zero());
    out.arm_covariance.assign(combos_.size(), Eigen::Matrix<double, 6, 6>::Zero());
    for (std::size_t ci = 0; ci < combos_.size(); ++ci) {
      localization::LocalizationOptions lo;
      std::vector<calibration::Correspondence> pts;
      for (const int v : combos_[ci].views) {
        lo.views.push_back(setup_.views[v].truth.name);
        for (const auto& c : clicks.oru)
          if (c.cam == setup_.views[v].truth.name) pts.push_back(c);
      }
      lo.camera_covariance = clicks.noise_covariance;
      lo.camera_link_sensitivity = clicks.link_sensitivity;
      lo.arm_link_sigma_m = opt_.arm_link_prior_m;
      try {
        const localization::LocalizationResult lr = localization::localize_object(pts, clicks.cams, lo);
        out.pose[ci] = lr.base_T_object;
        out.covariance[ci] = lr.covariance;
        out.arm_covariance[ci] = lr.arm_model_covariance;
      } catch (const Error&) {
        ++combos_[ci].clicks_failures;
      }
    }
    return out;
  }

  /// Step 4: each camera aligned on its own frames. Each camera's
  /// uncertainty (body rotation): its click calibration's (the arm model's
  /// part included), replaced by its alignment's block when aligned; held
  /// with it when the ORU is aligned (a refused camera keeps its clicks
  /// error, seen at 3% in f).
  TrialCameras align_cameras(const Clicks& clicks, render::SyntheticCamera& synth, const std::optional<Pose>& occluder) {
    TrialCameras c;
    c.views.resize(nv_);
    c.aligned.resize(nv_);
    c.aligned_cov.resize(nv_);
    for (int v = 0; v < nv_; ++v) c.aligned_cov[v] = clicks.covariance.at(setup_.views[v].truth.name);
    for (int v = 0; v < nv_; ++v) {
      const camera::Camera& truth = setup_.views[v].truth;
      c.views[v].camera = clicks.cams.at(truth.name);
      for (const int p : view_poses_[v])
        c.views[v].frames.push_back({synth.render(truth, setup_.arm_q[p]).image_bgr, setup_.arm_q[p]});
      AlignOptions ao;
      ao.refine = Refine::Camera;
      const AlignResult r = aligner_->align({c.views[v]}, occluder, ao);
      if (r.status != AlignStatus::Aligned) ++res_.camera_refused[v];
      c.aligned[v] = r.cameras[0];  // the start when refused
      if (r.status == AlignStatus::Aligned && r.covariance.rows() >= 7) c.aligned_cov[v] = r.covariance.topLeftCorner<7, 7>();
      if (r.status == AlignStatus::Aligned) c.views_aligned.push_back(v);
      res_.camera_clicks_px[v] += reprojection_rms_px(c.views[v].camera, truth, metric_points_);
      res_.camera_aligned_px[v] += reprojection_rms_px(c.aligned[v], truth, metric_points_);
    }
    return c;
  }

  /// Step 5: cameras + the arm's link lengths over every aligned camera's frames.
  void bundle(TrialCameras& c, const std::optional<Pose>& occluder, const std::vector<double>& delta) {
    c.bundle = c.aligned;
    c.bundle_cov = c.aligned_cov;
    if (!(opt_.arm_link_prior_m > 0.0) || c.views_aligned.empty()) return;
    std::vector<AlignView> all;
    for (const int v : c.views_aligned) all.push_back({c.aligned[v], c.views[v].frames});
    AlignOptions ao;
    ao.refine = Refine::Camera;
    ao.arm_link_prior_m = opt_.arm_link_prior_m;
    const AlignResult r = aligner_->align(all, occluder, ao);
    if (r.status != AlignStatus::Aligned) {
      ++res_.bundle_refused;
      return;
    }
    for (std::size_t i = 0; i < c.views_aligned.size(); ++i) {
      c.bundle[c.views_aligned[i]] = r.cameras[i];
      if (r.covariance.rows() >= 7 * static_cast<int>(i + 1))
        c.bundle_cov[c.views_aligned[i]] = r.covariance.block<7, 7>(7 * i, 7 * i);
    }
    c.arm_delta = r.arm_link_delta_m;
    for (int j = 0; j < nls_; ++j) {
      const int k = res_.link_segments[j];
      link_true2_[j] += delta[k] * delta[k];
      link_err2_[j] += (c.arm_delta[k] - delta[k]) * (c.arm_delta[k] - delta[k]);
      link_sig_[j] += r.arm_link_sigma_m.empty() ? 0.0 : r.arm_link_sigma_m[k];
    }
    ++link_trials_;
  }

  /// FORESIGHT_STUDY_DUMP=t: the trial's arm, cameras and click poses on
  /// stderr (a test rebuilds a trial from them).
  void dump_trial(const std::vector<double>& delta, const TrialCameras& c, const ClickPoses& click_poses,
                  unsigned synth_seed) const {
    auto vec = [](const char* name, const double* d, int n) {
      std::fprintf(stderr, "DUMP %s", name);
      for (int k = 0; k < n; ++k) std::fprintf(stderr, " %.17g", d[k]);
      std::fprintf(stderr, "\n");
    };
    vec("true_delta", delta.data(), static_cast<int>(delta.size()));
    vec("arm_delta", c.arm_delta.data(), static_cast<int>(c.arm_delta.size()));
    std::fprintf(stderr, "DUMP synth_seed %u\n", synth_seed);
    for (int v = 0; v < nv_; ++v) {
      const Eigen::Matrix4d M = c.bundle[v].base_T_camera.matrix();
      std::fprintf(stderr, "DUMP camera %d f %.17g", v, c.bundle[v].f_px);
      for (int k = 0; k < 16; ++k) std::fprintf(stderr, " %.17g", M(k % 4, k / 4));
      std::fprintf(stderr, " covariance");
      for (int k = 0; k < 49; ++k) std::fprintf(stderr, " %.17g", c.bundle_cov[v](k % 7, k / 7));
      std::fprintf(stderr, "\n");
    }
    for (std::size_t ci = 0; ci < combos_.size(); ++ci) {
      if (!click_poses.pose[ci]) continue;
      const Eigen::Matrix4d M = click_poses.pose[ci]->matrix();
      std::fprintf(stderr, "DUMP clicks %s", combos_[ci].label.c_str());
      for (int k = 0; k < 16; ++k) std::fprintf(stderr, " %.17g", M(k % 4, k / 4));
      std::fprintf(stderr, " covariance");
      for (int k = 0; k < 36; ++k) std::fprintf(stderr, " %.17g", click_poses.covariance[ci](k % 6, k / 6));
      std::fprintf(stderr, "\n");
    }
  }

  /// Step 6, the ORU over combination ci: refined with the step-5 cameras
  /// and arm; for comparison, with those cameras held and with the step-4
  /// cameras (nominal arm) held. The claim checked: the position error
  /// against the position covariance.
  void align_oru(int t, std::size_t ci, const TrialCameras& c, const ClickPoses& click_poses) {
    AlignmentComboStats& combo = combos_[ci];
    const Pose& clicks_pose = *click_poses.pose[ci];
    acc_clicks_[ci].add(localization::pose_error(clicks_pose, setup_.base_T_object));
    std::vector<AlignView> sub, sub_cam_only;
    for (const int v : combo.views) {
      sub.push_back({c.bundle[v], c.views[v].frames, c.bundle_cov[v]});
      sub_cam_only.push_back({c.aligned[v], c.views[v].frames, c.aligned_cov[v]});
    }
    AlignOptions ao;
    ao.refine = Refine::Object;
    ao.object_start_covariance = click_poses.covariance[ci];
    const AlignResult r0 = aligner_->align(sub_cam_only, clicks_pose, ao);
    if (r0.status != AlignStatus::Aligned) ++combo.aligned_cameras_only_refused;
    acc_cam_only_[ci].add(localization::pose_error(*r0.base_T_object, setup_.base_T_object));
    AlignResult r = r0;
    int object_col = 0;  // the object's block in r.covariance
    if (opt_.arm_link_prior_m > 0.0) {
      ao.arm_link_delta_m = c.arm_delta;
      const AlignResult held = aligner_->align(sub, clicks_pose, ao);
      if (held.status != AlignStatus::Aligned) ++combo.aligned_held_cameras_refused;
      acc_held_[ci].add(localization::pose_error(*held.base_T_object, setup_.base_T_object));
      // The ORU with the views' cameras and the arm's links (step 6).
      AlignOptions jo = ao;
      jo.refine = Refine::Both;
      jo.arm_link_prior_m = opt_.arm_link_prior_m;
      r = aligner_->align(sub, clicks_pose, jo);
      object_col = 7 * static_cast<int>(sub.size());
    } else {
      acc_held_[ci].add(localization::pose_error(*r0.base_T_object, setup_.base_T_object));
      if (r0.status != AlignStatus::Aligned) ++combo.aligned_held_cameras_refused;
    }
    if (r.status != AlignStatus::Aligned) ++combo.aligned_refused;
    if (refused_for_disagreement(r)) ++combo.aligned_refused_disagreement;
    acc_aligned_[ci].add(localization::pose_error(*r.base_T_object, setup_.base_T_object));
    const Eigen::Matrix3d Cp = r.covariance.rows() >= object_col + 6
                                   ? Eigen::Matrix3d(r.covariance.block<3, 3>(object_col + 3, object_col + 3))
                                   : Eigen::Matrix3d::Zero();
    const Eigen::Vector3d ep = r.base_T_object->translation() - setup_.base_T_object.translation();
    double worst_axis = 0.0, z2 = 0.0;
    if (r.status == AlignStatus::Aligned) {
      for (int k = 0; k < 3; ++k) worst_axis = std::max(worst_axis, std::abs(ep[k]) / std::sqrt(std::max(1e-30, Cp(k, k))));
      z2 = ep.dot(Cp.ldlt().solve(ep));
      ++combo.aligned_accepted;
      if (worst_axis <= 3.0) ++combo.aligned_within_3_sigma;
      combo.aligned_mahalanobis2_mean += z2;
    }
    if (std::getenv("FORESIGHT_STUDY_TRACE")) trace(t, ci, r, Cp, worst_axis, z2, click_poses);
  }

  /// FORESIGHT_STUDY_TRACE: the clicks' covariance's honesty and the ORU
  /// alignment's steps, per trial and combination, on stderr.
  void trace(int t, std::size_t ci, const AlignResult& r, const Eigen::Matrix3d& Cp, double worst_axis, double z2,
             const ClickPoses& click_poses) const {
    const AlignmentComboStats& combo = combos_[ci];
    const Pose& clicks_pose = *click_poses.pose[ci];
    const Eigen::Matrix<double, 6, 6>& clicks_cov = click_poses.covariance[ci];
    // the clicks covariance's honesty: the clicks' error in sigmas (6-DoF, rotation)
    const Eigen::AngleAxisd aa(setup_.base_T_object.linear().transpose() * clicks_pose.linear());
    Eigen::Matrix<double, 6, 1> e;
    e << aa.angle() * aa.axis(), clicks_pose.translation() - setup_.base_T_object.translation();
    Eigen::Matrix<double, 6, 6> T = Eigen::Matrix<double, 6, 6>::Identity();
    T.topLeftCorner<3, 3>() = calibration::rpy_rate_matrix(rpy_from_rotation(clicks_pose.linear()));
    const Eigen::Matrix<double, 6, 6> Cb = T * clicks_cov * T.transpose();
    const Eigen::Matrix<double, 6, 6> Ca = T * click_poses.arm_covariance[ci] * T.transpose();
    std::fprintf(stderr, "HONEST t%d %-8s clicks z6 %.2f zrot %.2f zpos %.2f | rot err %.2f deg sd %.2f %.2f %.2f deg (arm %.2f %.2f %.2f)\n", t,
                 combo.label.c_str(), std::sqrt(e.dot(Cb.ldlt().solve(e))),
                 std::sqrt(e.head<3>().dot(Cb.topLeftCorner<3, 3>().ldlt().solve(e.head<3>()))),
                 std::sqrt(e.tail<3>().dot(Cb.bottomRightCorner<3, 3>().ldlt().solve(e.tail<3>()))),
                 aa.angle() * 180 / M_PI, std::sqrt(Cb(0, 0)) * 180 / M_PI, std::sqrt(Cb(1, 1)) * 180 / M_PI,
                 std::sqrt(Cb(2, 2)) * 180 / M_PI, std::sqrt(Ca(0, 0)) * 180 / M_PI, std::sqrt(Ca(1, 1)) * 180 / M_PI,
                 std::sqrt(Ca(2, 2)) * 180 / M_PI);
    const auto ec = localization::pose_error(clicks_pose, setup_.base_T_object);
    const auto ea = localization::pose_error(*r.base_T_object, setup_.base_T_object);
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
                 std::sqrt(z2), std::sqrt(clicks_cov(3, 3)) * 1e3, std::sqrt(clicks_cov(4, 4)) * 1e3,
                 std::sqrt(clicks_cov(5, 5)) * 1e3);
  }

  void summarize() {
    for (std::size_t ci = 0; ci < combos_.size(); ++ci) {
      combos_[ci].clicks = acc_clicks_[ci].stats();
      combos_[ci].aligned = acc_aligned_[ci].stats();
      combos_[ci].aligned_cameras_only = acc_cam_only_[ci].stats();
      combos_[ci].aligned_held_cameras = acc_held_[ci].stats();
      if (combos_[ci].aligned_accepted > 0) combos_[ci].aligned_mahalanobis2_mean /= combos_[ci].aligned_accepted;
    }
    double t2 = 0.0, e2 = 0.0;
    for (int j = 0; j < nls_; ++j) {
      t2 += link_true2_[j];
      e2 += link_err2_[j];
      res_.link_true_rms_m.push_back(std::sqrt(link_true2_[j] / std::max(1, link_trials_)));
      res_.link_estimate_error_rms_m.push_back(std::sqrt(link_err2_[j] / std::max(1, link_trials_)));
      res_.link_sigma_mean_m.push_back(link_sig_[j] / std::max(1, link_trials_));
    }
    res_.link_true_rms_all_m = std::sqrt(t2 / std::max(1, link_trials_ * nls_));
    res_.link_estimate_error_rms_all_m = std::sqrt(e2 / std::max(1, link_trials_ * nls_));
    for (int v = 0; v < nv_; ++v) {
      res_.camera_clicks_px[v] /= std::max(1, good_);
      res_.camera_aligned_px[v] /= std::max(1, good_);
      res_.camera_bundle_px[v] /= std::max(1, good_);
    }
    res_.combos = std::move(combos_);
  }

  render::GlContext& ctx_;
  const RobotModel& robot_;
  const ObjectModel& object_;
  const Scene& scene_;
  const AlignmentStudyOptions& opt_;
  localization::StudySetup setup_;
  const std::vector<localization::ArmCalibrationPose> poses_;
  int nv_ = 0, nls_ = 0;
  camera::Viewport vp_;
  AlignmentStudyResult res_;
  std::vector<std::vector<int>> view_poses_;
  std::vector<AlignmentComboStats> combos_;
  std::vector<localization::ErrorAccumulator> acc_clicks_, acc_aligned_, acc_held_, acc_cam_only_;
  std::vector<double> link_true2_, link_err2_, link_sig_;
  int link_trials_ = 0, good_ = 0;
  std::vector<Eigen::Vector3d> metric_points_;
  std::vector<std::vector<Eigen::Matrix3Xd>> calibration_dp_dlinks_;
  calibration::CalibrationOptions calibration_options_;
  std::unique_ptr<ModelAligner> aligner_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> noise_;
  std::mt19937_64 arm_rng_;
  std::normal_distribution<double> link_error_;
};

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
  AlignmentStudy study(ctx, robot, object, scene, opt);
  return study.run(t0);
}

}  // namespace foresight::align
