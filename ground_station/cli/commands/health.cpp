// foresight health: calibration health per video frame (issue 16): how well
// the reported arm's model edges match the video through the calibrated
// camera, and a warning when the camera has moved or zoomed.
//
//   foresight health --cameras cameras.yaml --camera NAME --video SOURCE
//                    --joints-from FILE|telemetry [--object-pose localize.json]
//                    [--max-frames N] [--gl osmesa|egl] [--robot robot.urdf]
//                    [--object oru.yaml] [--json]
// SOURCE: a video file, an image sequence (OpenCV pattern, e.g. f_%03d.png),
// one image, or a live camera (a device index, a stream URL). FILE: one joint
// vector per line (radians, comma-separated; '#' comments), either one line
// for a still arm or one per frame. `telemetry`: the remote's latest joint
// report over the link ([--domain D] [--connect-timeout S]) at each frame's
// arrival; a frame whose report is older than --max-telemetry-age is not
// scored (counted in `stale_frames`): the arm's pose then is not known.
// Per frame (--json `frames[]`): matched_fraction, score_px, iou (the arm's
// silhouette IoU estimated from the edge offsets, ModelAligner::FrameScore),
// visible_samples, bad, warning.
// Exit: 0 (warnings are reported, not errors), 2 bad input, 1 GL failure.

#include <cstdio>
#include <fstream>
#include <iostream>
#include <opencv2/videoio.hpp>

#include "command.hpp"
#include "foresight/align/health.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/video_frame.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct HealthArgs {
  std::string cameras, camera, video, joints_from, object_pose, gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  int max_frames = 100000;
  double max_telemetry_age_s = 0.5;
  LinkOptions link;  // --joints-from telemetry
  bool json = false, scale_image = false;
};

// The remote's latest joint angles (--joints-from telemetry), and how old.
struct TelemetryJoints {
  Eigen::VectorXd q;
  double age_s = 0.0;
};

TelemetryJoints telemetry_joints(const ground_link::GroundLink& link, const RobotModel& model, double timeout_s) {
  const auto report = wait_joints(link, timeout_s);
  if (!report) {
    char why[96];
    std::snprintf(why, sizeof why, "no joint report from the remote within %.1f s", timeout_s);
    throw LinkFailure(why);
  }
  return {require_joints(report->value, model), report->age_s};
}

std::vector<Eigen::VectorXd> read_joint_lines(const std::string& path, const RobotModel& model) {
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot open joints file");
  std::vector<Eigen::VectorXd> out;
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    try {
      out.push_back(parse_joints(line, "joints", model));
    } catch (const std::exception& e) {
      throw InputError(path, n, e.what());
    }
  }
  if (out.empty()) throw InputError(path, "no joint vectors");
  return out;
}

int run_health(const HealthArgs& a) {
  using namespace foresight::render;
  using namespace foresight::align;
  const GlBackend backend = parse_gl_backend(a.gl);
  const bool telemetry = a.joints_from == "telemetry";
  const camera::Camera camera = load_camera(a.cameras, a.camera);
  const RobotModel model = RobotModel::from_file(a.robot);
  const auto joints = telemetry ? std::vector<Eigen::VectorXd>{} : read_joint_lines(a.joints_from, model);
  std::optional<ObjectModel> object;
  std::optional<Pose> base_T_object;
  if (!a.object_pose.empty()) {
    base_T_object = localization::read_object_pose_json(a.object_pose);
    object = ObjectModel::from_file(a.object);
  }
  cv::VideoCapture cap(a.video);
  if (!cap.isOpened()) throw InputError(a.video, "cannot read video or image");

  const auto link = telemetry ? connect_remote(a.link) : nullptr;
  auto context = GlContext::create(backend);
  ModelAligner aligner(*context, model, object ? &*object : nullptr, camera.viewport);
  HealthMonitor monitor;
  nlohmann::json frames = nlohmann::json::array(), warnings = nlohmann::json::array();
  bool moved = false;
  int k = 0, stale = 0;
  cv::Mat img;
  for (; k < a.max_frames && cap.read(img); ++k) {
    if (joints.size() > 1 && k >= static_cast<int>(joints.size()))
      throw InputError(a.joints_from, "has " + std::to_string(joints.size()) + " joint vectors but the video has more frames");
    img = fit_to_viewport(img, a.video + " frame " + std::to_string(k), camera, a.scale_image);
    TelemetryJoints tj;
    if (link) {
      tj = telemetry_joints(*link, model, a.link.connect_timeout_s);
      if (tj.age_s > a.max_telemetry_age_s) {
        ++stale;
        frames.push_back({{"frame", k}, {"telemetry_age_s", tj.age_s}, {"stale", true}});
        if (!a.json)
          std::printf("frame %4d: not scored: the joint report is %.2f s old (--max-telemetry-age %.2f)\n", k, tj.age_s,
                      a.max_telemetry_age_s);
        continue;
      }
    }
    const Eigen::VectorXd& q = link ? tj.q : joints[joints.size() == 1 ? 0 : k];
    const auto s = aligner.score(camera, {img, q}, base_T_object);
    if (s.visible_samples == 0)
      throw InputError(a.video, "frame " + std::to_string(k) + ": the arm model is not in view of camera '" +
                                    camera.name + "'");
    const HealthVerdict v = monitor.update(s);
    frames.push_back({{"frame", k},
                      {"matched_fraction", s.matched_fraction},
                      {"score_px", s.score_px},
                      {"iou", s.iou},
                      {"visible_samples", s.visible_samples},
                      {"bad", v.bad},
                      {"warning", v.warning}});
    if (link) frames.back()["telemetry_age_s"] = tj.age_s;
    if (v.warning && !moved) warnings.push_back({{"frame", k}, {"reason", v.reason}});
    moved = moved || v.warning;
    if (!a.json)
      std::printf("frame %4d: %3.0f%% of the arm's edges within 1 px, edge distance %.2f px, IoU %.3f%s%s\n", k,
                  100.0 * s.matched_fraction, s.score_px, s.iou, v.in_baseline ? " (baseline)" : v.bad ? " BAD" : "",
                  v.warning ? "  WARNING" : "");
  }
  if (k == 0) throw InputError(a.video, "no frames");
  if (a.json) {
    std::cout << nlohmann::json{{"camera", camera.name},
                                {"frames", frames},
                                {"baseline_fraction", monitor.baseline_fraction()},
                                {"baseline_score_px", monitor.baseline_score_px()},
                                {"camera_moved", moved},
                                {"warnings", warnings},
                                {"joints_from", telemetry ? "telemetry" : "file"},
                                {"stale_frames", stale}}
                     .dump()
              << "\n";
  } else {
    std::printf("health: camera %s, %d frames, baseline %.0f%% matched / %.2f px\n", camera.name.c_str(), k,
                100.0 * monitor.baseline_fraction(), monitor.baseline_score_px());
    if (stale > 0) std::printf("  %d frames not scored (stale telemetry)\n", stale);
    for (const auto& w : warnings) std::printf("  WARNING at frame %d: %s\n", w["frame"].get<int>(), w["reason"].get<std::string>().c_str());
    if (!moved) std::printf("  calibration healthy\n");
  }
  return kExitOk;
}

const bool registered = register_command(
    {"health", "per-frame calibration health: the arm's silhouette against the video, camera-moved warning",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<HealthArgs>();
       sub.add_option("--cameras", a->cameras, "cameras.yaml")->required();
       sub.add_option("--camera", a->camera, "camera name in cameras.yaml")->required();
       sub.add_option("--video", a->video, "video file, image sequence pattern or image")->required();
       sub.add_option("--joints-from", a->joints_from,
                      "joints file (one q per line, rad) or telemetry (the remote's joint reports over the link)")
           ->required();
       sub.add_option("--max-telemetry-age", a->max_telemetry_age_s,
                      "with telemetry: a frame whose joint report is older is not scored (s)")
           ->check(check::PositiveNumber)
           ->capture_default_str();
       add_link_options(sub, a->link, false, false);
       sub.add_option("--object-pose", a->object_pose, "JSON with base_T_object (the object occludes the arm)");
       sub.add_option("--max-frames", a->max_frames, "stop after N frames")->check(check::PositiveNumber);
       sub.add_flag("--scale-image", a->scale_image, "resize frames whose size differs from the camera viewport");
       add_render_options(sub, a->gl, a->robot, a->object, a->json);
       return [a] { return run_health(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
