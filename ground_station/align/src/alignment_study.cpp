#include "foresight/align/alignment_study.hpp"

#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <random>

#include "foresight/align/model_aligner.hpp"
#include "foresight/calibration/calibrate.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

namespace foresight::align {

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
  std::vector<ErrorAccumulator> acc_clicks(combos.size()), acc_aligned(combos.size()), acc_cam_only(combos.size());
  const int nseg = static_cast<int>(robot.chain().getNrOfSegments());
  for (int k = 0; k < nseg; ++k)
    if (robot.chain().getSegment(k).getFrameToTip().p.Norm() > 1e-9) res.link_segments.push_back(k);
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

  ModelAligner aligner(ctx, robot, &object, vp);
  std::mt19937_64 rng(opt.seed);
  std::normal_distribution<double> noise(0.0, opt.noise_px);
  std::mt19937_64 arm_rng(opt.seed ^ 0x9E3779B97F4A7C15ull);
  std::normal_distribution<double> link_error(0.0, opt.arm_link_error_m > 0.0 ? opt.arm_link_error_m : 1.0);
  int good = 0;
  for (int t = 0; t < opt.trials; ++t) {
    // The true arm (rendered and clicked); the ground believes `robot`.
    std::vector<double> delta(robot.chain().getNrOfSegments(), 0.0);
    if (opt.arm_link_error_m > 0.0)
      for (unsigned k = 0; k < delta.size(); ++k)
        if (robot.chain().getSegment(k).getFrameToTip().p.Norm() > 1e-9) delta[k] = link_error(arm_rng);
    const RobotModel truth_arm = robot.with_link_lengths_changed(delta);
    KinematicsWorkspace tws(truth_arm);

    // Clicks: calibration on the true arm, the believed points from the nominal arm.
    std::map<std::string, Camera> cams;
    std::vector<Correspondence> oru_clicks;
    bool ok = true;
    for (int v = 0; v < nv && ok; ++v) {
      const StudyView& view = setup.views[v];
      std::vector<Eigen::Vector3d> true_base;
      for (const ArmFeature& f : view.calibration_features)
        true_base.push_back(forward_kinematics(truth_arm, tws, setup.arm_q.at(f.pose), f.link) * f.p_link);
      ViewClicks vc = simulate_view_clicks(view, view.calibration_points_base, true_base, setup.base_T_object,
                                           [&] { return noise(rng); });
      try {
        cams[view.truth.name] = calibrate_camera(vc.calibration, vp, view.truth.name).camera;
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
    for (std::size_t ci = 0; ci < combos.size(); ++ci) {
      LocalizationOptions lo;
      std::vector<Correspondence> pts;
      for (const int v : combos[ci].views) {
        lo.views.push_back(setup.views[v].truth.name);
        for (const auto& c : oru_clicks)
          if (c.cam == setup.views[v].truth.name) pts.push_back(c);
      }
      try {
        clicks_pose[ci] = localize_object(pts, cams, lo).base_T_object;
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
      if (r.status == AlignStatus::Aligned) views_aligned.push_back(v);
      res.camera_clicks_px[v] += reprojection_rms_px(views[v].camera, truth, metric_points);
      res.camera_aligned_px[v] += reprojection_rms_px(aligned_cam[v], truth, metric_points);
    }
    // Step 5: cameras + the arm's link lengths over every aligned camera's frames.
    std::vector<Camera> bundle_cam = aligned_cam;
    std::vector<double> arm_delta;  // empty: the nominal arm
    if (opt.arm_link_prior_m > 0.0 && !views_aligned.empty()) {
      std::vector<AlignView> all;
      for (const int v : views_aligned) all.push_back({aligned_cam[v], views[v].frames});
      AlignOptions ao;
      ao.refine = Refine::Camera;
      ao.arm_link_prior_m = opt.arm_link_prior_m;
      const AlignResult r = aligner.align(all, occluder, ao);
      if (r.status == AlignStatus::Aligned) {
        for (std::size_t i = 0; i < views_aligned.size(); ++i) bundle_cam[views_aligned[i]] = r.cameras[i];
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
    for (int v = 0; v < nv; ++v) res.camera_bundle_px[v] += reprojection_rms_px(bundle_cam[v], setup.views[v].truth, metric_points);
    // The ORU over each combination: with the step-5 cameras and arm, and
    // with the step-4 cameras (nominal arm) for comparison.
    for (std::size_t ci = 0; ci < combos.size(); ++ci) {
      if (!clicks_pose[ci]) continue;
      acc_clicks[ci].add(pose_error(*clicks_pose[ci], setup.base_T_object));
      std::vector<AlignView> sub, sub_cam_only;
      for (const int v : combos[ci].views) {
        sub.push_back({bundle_cam[v], views[v].frames});
        sub_cam_only.push_back({aligned_cam[v], views[v].frames});
      }
      AlignOptions ao;
      ao.refine = Refine::Object;
      const AlignResult r0 = aligner.align(sub_cam_only, clicks_pose[ci], ao);
      if (r0.status != AlignStatus::Aligned) ++combos[ci].aligned_cameras_only_refused;
      acc_cam_only[ci].add(pose_error(*r0.base_T_object, setup.base_T_object));
      if (opt.arm_link_prior_m > 0.0) {
        ao.arm_link_delta_m = arm_delta;
        const AlignResult r = aligner.align(sub, clicks_pose[ci], ao);
        if (r.status != AlignStatus::Aligned) ++combos[ci].aligned_refused;
        acc_aligned[ci].add(pose_error(*r.base_T_object, setup.base_T_object));
      } else {
        if (r0.status != AlignStatus::Aligned) ++combos[ci].aligned_refused;
        acc_aligned[ci].add(pose_error(*r0.base_T_object, setup.base_T_object));
      }
    }
    if (opt.progress) opt.progress(t + 1, opt.trials);
  }
  for (std::size_t ci = 0; ci < combos.size(); ++ci) {
    combos[ci].clicks = acc_clicks[ci].stats();
    combos[ci].aligned = acc_aligned[ci].stats();
    combos[ci].aligned_cameras_only = acc_cam_only[ci].stats();
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
