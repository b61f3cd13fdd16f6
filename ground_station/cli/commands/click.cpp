// foresight click: the paper's operator-interactive data entry. Two windows:
// the model (the arm at the given joints, or the ORU) with its selectable
// model points numbered, and the video frame. Click a model point, then where
// it appears in the image; each pair is a row of the points CSV that
// `calibrate` (--model robot: base-frame points) and `localize` (--model oru:
// object-frame points) read. The CSV is rewritten after every change.
//
//   foresight click --camera NAME --image FRAME --model robot|oru
//                   [--joints q | --joints-deg q] --out POINTS.csv [--append]
//                   [--cameras cameras.yaml] [--frame K] [--snapshot PREFIX]
//                   [--robot robot.urdf] [--object oru.yaml] [--gl osmesa|egl] [--json]
//
// Keys (either window): u / Backspace delete last, c clear all, + / - zoom
// in / out at the mouse (or the mouse wheel), 0 reset the zoom, n / p select
// the next / previous model point, f fit (calibrate, or localize with
// --cameras) and show the residual arrows, q / Esc save and quit. A click
// outside the image is ignored. Needs a display (X); exit 2 without one.

#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/session/click_loop.hpp"

namespace foresight::cli {
namespace {

struct ClickArgs {
  session::ClickSettings settings;
  bool json = false;
};

int click(const ClickArgs& args) {
  const session::ClickSettings& a = args.settings;
  const session::ClickSummary s = session::run_click(a);
  if (args.json) {
    std::cout << nlohmann::json{{"out", a.out},
                                {"camera", a.camera},
                                {"model", a.model},
                                {"points", s.points},
                                {"rows_in_file", s.rows_in_file},
                                {"fit", s.fit}}
                     .dump()
              << "\n";
  } else {
    std::printf("click: %zu point(s) on camera %s (%s model); %zu row(s) in %s\n", s.points, a.camera.c_str(),
                a.model.c_str(), s.rows_in_file, a.out.c_str());
    if (!s.fit.empty()) std::printf("  %s\n", s.fit.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"click", "operator point entry: click model points and their image points, write the points CSV",
     [](Command& sub) -> std::function<int()> {
       auto args = std::make_shared<ClickArgs>();
       session::ClickSettings* a = &args->settings;
       sub.add_option("--camera", a->camera, "camera name (the cam column)")->required();
       sub.add_option("--image", a->image, "the video frame: an image, or a video file (see --frame)")->required();
       sub.add_option("--frame", a->frame, "frame index when --image is a video (0-based)")
           ->check(check::NonNegativeNumber);
       sub.add_option("--model", a->model, "robot (the arm at --joints; base-frame points) or oru (object frame)")
           ->required();
       sub.add_option("--joints", a->joints, "the arm's joint angles in the frame, q1,...,qN (rad)");
       sub.add_option("--joints-deg", a->joints_deg, "the arm's joint angles in degrees");
       sub.add_option("--out", a->out, "points CSV (n,cam,x,y,z,u,v), rewritten after every change")->required();
       sub.add_flag("--append", a->append, "keep the rows already in --out (several frames, cameras or poses)");
       sub.add_option("--cameras", a->cameras, "calibrated cameras, for the ORU fit (key f)");
       sub.add_option("--snapshot", a->snapshot, "at exit, write PREFIX_model.png and PREFIX_image.png (what was shown)");
       sub.add_option("--gl", a->gl, "GL back end: osmesa | egl")->capture_default_str();
       sub.add_option("--robot", a->robot, "robot URDF")->capture_default_str();
       sub.add_option("--object", a->object, "task object model")->capture_default_str();
       sub.add_flag("--json", args->json, "print one JSON object");
       return [args] { return click(*args); };
     }});

}  // namespace
}  // namespace foresight::cli
