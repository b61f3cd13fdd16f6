// foresight align: refine a camera's 7 parameters (and/or the task object's
// pose) by aligning the rendered model's visible edges to the image edges
// (ground_station/align, issue 16).
//
//   foresight align --cameras cameras.yaml --camera NAME [--camera NAME2 ...]
//                   --image FRAME [--image FRAME2 ...] --joints q | --joints-deg q (once, or once per image)
//                   [--object-pose localize.json] [--refine camera|object|both]
//                   [--out cameras.yaml] [--object-out pose.json] [--frame K]
//                   [--arm-prior-mm P] [--arm-links arm_links.yaml] [--arm-out arm_links.yaml]
//                   [--gl osmesa|egl] [--robot robot.urdf] [--object oru.yaml] [--json]
// One camera: every image is a frame of it (several arm poses combine). Several
// cameras: one --camera per --image, in the same order; a camera named again
// gets that image as another frame (localization by alignment: --refine object
// moves the ORU over all views at once; --refine both refines the cameras
// with it, the ORU's edges tying them to each other where it stands).
// The arm model: --arm-prior-mm P refines the arm's link lengths with the
// cameras (a bundle adjustment over every frame, prior sd P mm around the
// model or --arm-links); --arm-out writes the estimate, --arm-links renders
// and samples the arm with earlier corrections (foresight/align/arm_links_file.hpp).
// Exit: 0 aligned (and written), 1 refused (not confident; the reason is said,
// nothing written) or GL failure, 2 bad input (wrong frame size, unknown
// camera, the model not in view of a camera, ...; nothing written).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "command.hpp"
#include "foresight/align/arm_links_file.hpp"
#include "foresight/align/model_aligner.hpp"
#include "foresight/calibration/calibrate.hpp"
#include "foresight/common/atomic_file.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/video_frame.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

struct AlignArgs {
  std::string cameras, object_pose, refine = "camera", out, object_out, gl = "osmesa", arm_links, arm_out;
  double arm_prior_mm = 0.0;
  std::vector<std::string> camera, image, joints, joints_deg;
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  int frame = 0;
  bool json = false, scale_image = false;
};

std::string utc_now_iso() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

int run_align(const AlignArgs& a) {
  using namespace foresight::render;
  using namespace foresight::align;
  const GlBackend backend = parse_gl_backend(a.gl);
  AlignOptions options;
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

  std::map<std::string, CameraRecord> records = load_cameras(a.cameras);
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
    const CameraRecord& rec = records.at(name);
    AlignView view{rec.camera, {}};
    // The calibration's uncertainty: with --refine object the camera is held
    // but not exact, and its error enters the object's covariance.
    if (rec.calibration)
      view.camera_covariance = camera_covariance_body_from_rpy(rec.calibration->covariance, rec.camera.base_T_camera.linear());
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
    const ObjectPoseFile pose = read_object_pose_file(a.object_pose);
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
  const AlignResult r = aligner.align(views, base_T_object, options);
  if (r.status == AlignStatus::NotInView) throw InputError(a.image.front(), r.reason);

  // Per-camera parameter sigmas (diagonal of the covariance blocks).
  const bool cam_refined = options.refine != Refine::Camera ? options.refine == Refine::Both : true;
  auto sigma = [&](int k) { return r.covariance.size() > 0 ? std::sqrt(std::max(0.0, r.covariance(k, k))) : 0.0; };

  if (r.status == AlignStatus::Aligned) {
    if (!a.out.empty() && cam_refined) {
      std::map<std::string, CameraRecord> out_records =
          std::filesystem::exists(a.out) ? load_cameras(a.out) : std::map<std::string, CameraRecord>{};
      if (a.out == a.cameras) out_records = records;
      for (std::size_t v = 0; v < r.cameras.size(); ++v) {
        CameraCalibrationInfo info;
        // cameras.yaml keeps roll/pitch/yaw; the aligner's rotation is a
        // body increment (calibrate writes the same convention).
        info.covariance = camera_covariance_rpy_from_body(r.covariance.block<7, 7>(7 * v, 7 * v),
                                                          r.cameras[v].base_T_camera.linear());
        info.rms_px = r.residual_rms_px;
        info.max_px = 1.0;  // inliers are within 1 px by definition
        info.n_points = r.matched_samples;
        info.date = utc_now_iso();
        out_records[r.cameras[v].name] = CameraRecord{r.cameras[v], info};
      }
      save_cameras(a.out, out_records);
    }
    if (!a.arm_out.empty() && !r.arm_link_sigma_m.empty())
      save_arm_links(a.arm_out, {r.arm_link_delta_m, r.arm_link_sigma_m}, a.robot, utc_now_iso());
    if (!a.object_out.empty() && r.base_T_object) {
      nlohmann::json j = object_pose_json(*r.base_T_object);
      j["source"] = "foresight align";
      write_file_atomic(a.object_out, j.dump(2) + "\n");
    }
  }

  if (a.json) {
    nlohmann::json cams = nlohmann::json::array();
    for (std::size_t v = 0; v < r.cameras.size(); ++v) {
      const auto& d = r.camera_change[v];
      nlohmann::json c = {{"name", r.cameras[v].name},
                          {"f_px", r.cameras[v].f_px},
                          {"base_T_camera", pose_json(r.cameras[v].base_T_camera)},
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
      j["base_T_object"] = pose_json(*r.base_T_object);
      j["object_change"] = {{"rotation_deg", vec_json(r.object_change.head<3>() * 180.0 / M_PI)},
                            {"position_m", vec_json(r.object_change.tail<3>())}};
    }
    if (!r.arm_link_delta_m.empty()) j["arm_link_delta_m"] = r.arm_link_delta_m;
    if (!r.arm_link_sigma_m.empty()) j["arm_link_sigma_m"] = r.arm_link_sigma_m;
    if (r.status == AlignStatus::Aligned && !a.out.empty()) j["out"] = a.out;
    std::cout << j.dump() << "\n";
  } else {
    std::printf("align (%s): %s%s%s\n", to_string(options.refine), to_string(r.status), r.reason.empty() ? "" : ": ",
                r.reason.c_str());
    std::printf("  edge distance %.2f px -> %.2f px (misses count %.0f px); inlier residual %.3f px RMS\n",
                r.start_score_px, r.final_score_px, options.score_cap_px, r.residual_rms_px);
    std::printf("  %d of %d visible model edge samples within 1 px of an image edge; %d iterations, %.0f ms\n",
                r.matched_samples, r.visible_samples, r.iterations, r.time_ms);
    for (std::size_t v = 0; v < r.cameras.size() && cam_refined; ++v) {
      const auto& d = r.camera_change[v];
      const int b = 7 * static_cast<int>(v);
      std::printf("  %s: rotation %+.4f %+.4f %+.4f deg, position %+.1f %+.1f %+.1f mm, f %+.2f px (now %.2f)\n",
                  r.cameras[v].name.c_str(), d[0] * 180 / M_PI, d[1] * 180 / M_PI, d[2] * 180 / M_PI, d[3] * 1e3,
                  d[4] * 1e3, d[5] * 1e3, d[6], r.cameras[v].f_px);
      std::printf("    sigma: rotation %.4f %.4f %.4f deg, position %.1f %.1f %.1f mm, f %.2f px\n",
                  sigma(b) * 180 / M_PI, sigma(b + 1) * 180 / M_PI, sigma(b + 2) * 180 / M_PI, sigma(b + 3) * 1e3,
                  sigma(b + 4) * 1e3, sigma(b + 5) * 1e3, sigma(b + 6));
    }
    if (options.refine != Refine::Camera && r.base_T_object)
      std::printf("  object: rotation %+.4f %+.4f %+.4f deg, position %+.1f %+.1f %+.1f mm\n",
                  r.object_change[0] * 180 / M_PI, r.object_change[1] * 180 / M_PI, r.object_change[2] * 180 / M_PI,
                  r.object_change[3] * 1e3, r.object_change[4] * 1e3, r.object_change[5] * 1e3);
    if (r.status == AlignStatus::Aligned && !a.out.empty()) std::printf("  wrote %s\n", a.out.c_str());
    if (!r.arm_link_sigma_m.empty()) {
      std::printf("  arm link-length corrections (mm, sd), per chain segment with an offset:");
      for (const int k : model.offset_segments())
        std::printf(" %d: %+.2f (%.2f)", k, r.arm_link_delta_m[k] * 1e3, r.arm_link_sigma_m[k] * 1e3);
      std::printf("\n");
    }
    if (r.status == AlignStatus::Aligned && !a.object_out.empty()) std::printf("  wrote %s\n", a.object_out.c_str());
    if (r.status == AlignStatus::Aligned && !a.arm_out.empty()) std::printf("  wrote %s\n", a.arm_out.c_str());
    if (r.status != AlignStatus::Aligned) std::printf("  nothing written\n");
  }
  if (r.status != AlignStatus::Aligned) std::cerr << "foresight align: refused: " << r.reason << "\n";
  return r.status == AlignStatus::Aligned ? kExitOk : kExitFailure;
}

const bool registered = register_command(
    {"align", "refine a camera (and/or the object pose) by aligning the model's edges to the image",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<AlignArgs>();
       sub.add_option("--cameras", a->cameras, "cameras.yaml from `foresight calibrate`")->required();
       sub.add_option("--camera", a->camera, "camera name in cameras.yaml (repeat for several views)")->required();
       sub.add_option("--image", a->image, "video frame of the camera: image or video file (repeatable)")->required();
       sub.add_option("--frame", a->frame, "frame index when --image is a video (0-based)")->check(check::NonNegativeNumber);
       sub.add_flag("--scale-image", a->scale_image, "resize an image whose size differs from the camera viewport");
       sub.add_option("--joints", a->joints, "arm joint angles q1,...,qN in radians (once, or once per image)");
       sub.add_option("--joints-deg", a->joints_deg, "arm joint angles in degrees (instead of --joints)");
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json` (key base_T_object)");
       sub.add_option("--refine", a->refine, "camera | object | both")->capture_default_str();
       sub.add_option("--out", a->out, "write the refined camera(s) into this cameras.yaml");
       sub.add_option("--object-out", a->object_out, "write the refined object pose (JSON, key base_T_object)");
       sub.add_option("--arm-prior-mm", a->arm_prior_mm,
                      "refine the arm's link lengths with the cameras, prior sd (mm); 0: the arm model is exact")
           ->capture_default_str();
       sub.add_option("--arm-links", a->arm_links, "the arm's link-length corrections (arm_links.yaml from --arm-out)");
       sub.add_option("--arm-out", a->arm_out, "write the refined link-length corrections (arm_links.yaml)");
       add_render_options(sub, a->gl, a->robot, a->object, a->json);
       return [a] { return run_align(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
