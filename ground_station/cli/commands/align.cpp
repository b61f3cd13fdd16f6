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
#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/session/operations.hpp"

namespace foresight::cli {
namespace {

struct AlignArgs {
  session::AlignRequest request;
  bool json = false;
};

int run_align(const AlignArgs& args) {
  using namespace foresight::align;
  const session::AlignRequest& a = args.request;
  const session::AlignedViews aligned = session::align_views(a);
  const AlignResult& r = aligned.result;
  const AlignOptions& options = aligned.options;
  const bool cam_refined = aligned.cameras_refined;
  // Per-camera parameter sigmas (diagonal of the covariance blocks).
  auto sigma = [&](int k) { return r.covariance.size() > 0 ? std::sqrt(std::max(0.0, r.covariance(k, k))) : 0.0; };
  if (args.json) {
    std::cout << session::aligned_json(a, aligned).dump() << "\n";
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
      for (const int k : aligned.offset_segments)
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
       auto args = std::make_shared<AlignArgs>();
       session::AlignRequest* a = &args->request;
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
       add_render_options(sub, a->gl, a->robot, a->object, args->json);
       return [args] { return run_align(*args); };
     }});

}  // namespace
}  // namespace foresight::cli
