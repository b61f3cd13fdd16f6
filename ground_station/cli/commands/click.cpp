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

#include <opencv2/highgui.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "command.hpp"
#include "foresight/calibration/calibrate.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/display/click_session.hpp"
#include "foresight/display/display_frame.hpp"
#include "foresight/display/residual_plot.hpp"
#include "foresight/display/video_source.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/video_frame.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

using display::ClickSession;

struct ClickArgs {
  std::string camera, image, model, joints, joints_deg, out, cameras, snapshot, gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  int frame = 0;
  bool append = false, json = false;
};

constexpr const char* kModelWindow = "foresight click: model";
constexpr int kPickRadiusPx = 14;

struct Ui {
  ClickSession* session = nullptr;
  display::ZoomView* zoom = nullptr;
  const std::vector<Eigen::Vector2d>* model_px = nullptr;
  Eigen::Vector2d mouse_image_px{0, 0};
  bool dirty = true;
  std::string status;
};

void save_csv(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp);
    if (!(f << text) || !f.flush()) throw InputError(path, "cannot write the points file");
  }
  std::filesystem::rename(tmp, path);
}

void on_model_mouse(int event, int x, int y, int, void* data) {
  auto& ui = *static_cast<Ui*>(data);
  // Qt reports a quick second press near the first as a double click: a click all the same.
  if (event != cv::EVENT_LBUTTONDOWN && event != cv::EVENT_LBUTTONDBLCLK) return;
  const int i = display::nearest_point(*ui.model_px, Eigen::Vector2d(x + 0.5, y + 0.5), kPickRadiusPx);
  if (i >= 0) {
    ui.session->select_model_point(i);
    ui.status = "model point " + std::to_string(i + 1) + " (" + ui.session->model_points()[i].label +
                "): now click it in the image";
  } else {
    ui.status = "no model point there: click on a numbered point";
  }
  ui.dirty = true;
}

void on_image_mouse(int event, int x, int y, int flags, void* data) {
  auto& ui = *static_cast<Ui*>(data);
  const Eigen::Vector2d uv = ui.zoom->to_image(x, y);
  ui.mouse_image_px = uv;
  if (event == cv::EVENT_MOUSEWHEEL) {
    ui.zoom->zoom_at(uv, cv::getMouseWheelDelta(flags) > 0 ? 2.0 : 0.5);
    ui.dirty = true;
    return;
  }
  // Qt reports a quick second press near the first as a double click: a click all the same.
  if (event != cv::EVENT_LBUTTONDOWN && event != cv::EVENT_LBUTTONDBLCLK) return;
  switch (ui.session->click_image(uv)) {
    case ClickSession::Outcome::Added: {
      const auto& r = ui.session->session_rows().back();
      char buf[128];
      std::snprintf(buf, sizeof buf, "point %d at (%.1f, %.1f) px", r.n, r.uv_px.x(), r.uv_px.y());
      ui.status = buf;
      break;
    }
    case ClickSession::Outcome::NoModelPoint:
      ui.status = "pick a model point first (model window)";
      break;
    case ClickSession::Outcome::OutsideImage:
      ui.status = "outside the image: ignored";
      break;
  }
  ui.dirty = true;
}

int run_click(const ClickArgs& a) {
  using namespace foresight::render;
  if (a.model != "robot" && a.model != "oru") throw std::invalid_argument("--model must be robot or oru");
  if (!a.joints.empty() && !a.joints_deg.empty()) throw std::invalid_argument("give only one of --joints, --joints-deg");
  const bool arm = a.model == "robot";
  const RobotModel robot = RobotModel::from_file(a.robot);
  const ObjectModel object = ObjectModel::from_file(a.object);
  Eigen::VectorXd q = robot.mid_configuration();
  if (!a.joints.empty()) q = parse_joints(a.joints, "--joints", robot);
  if (!a.joints_deg.empty()) q = parse_joints(a.joints_deg, "--joints-deg", robot, true);
  if (arm && a.joints.empty() && a.joints_deg.empty())
    throw std::invalid_argument("--model robot needs the arm's joint angles in the frame (--joints or --joints-deg)");
  const cv::Mat image = read_video_frame(a.image, a.frame);
  const Viewport vp{image.cols, image.rows};
  std::map<std::string, Camera> cameras;
  if (!a.cameras.empty())
    for (const auto& [name, rec] : load_cameras(a.cameras)) cameras[name] = rec.camera;
  std::vector<Correspondence> existing;
  if (a.append && std::filesystem::exists(a.out)) existing = read_correspondences_csv(a.out);
  if (!std::filesystem::exists(std::filesystem::absolute(a.out).parent_path()))
    throw InputError(a.out, "the folder does not exist");

  if (const std::string why = display::x_display_problem(); !why.empty())
    throw InputError("foresight click needs a display to show its windows (" + why +
                     "); run it on the operator's desktop or under Xvfb");

  const std::vector<display::ModelPoint> points =
      arm ? display::arm_model_points(robot, q) : display::object_model_points(object);
  ClickSession session(a.camera, points, image.size());
  session.set_existing_rows(existing);
  display::ZoomView zoom(image.size());

  // The model picture: rendered once, the numbers drawn per refresh.
  const Camera view = display::default_model_view(points, vp, arm);
  auto context = GlContext::create(parse_gl_backend(a.gl));
  Renderer renderer(*context, vp);
  DrawList list;
  if (arm) {
    ArmGeometry geometry(renderer, robot);
    geometry.append(q, list);
  } else {
    list.bodies.push_back({add_object_body(renderer, object), Pose::Identity(), kObjectWireRgba, std::nullopt});
  }
  cv::Mat layer;
  RenderSettings st;
  st.mode = RenderMode::Solid;
  renderer.render(view, list, st, layer);
  cv::Mat model_base(image.size(), CV_8UC3, cv::Scalar(48, 40, 36));
  composite(layer, 1.0, model_base);
  std::vector<Eigen::Vector2d> model_px;
  for (const auto& p : points) model_px.push_back(view.project(p.p_m));

  Ui ui;
  ui.session = &session;
  ui.zoom = &zoom;
  ui.model_px = &model_px;
  ui.status = "click a numbered model point, then the same point in the image";
  const std::string image_window = "foresight click: image " + a.camera;
  cv::namedWindow(kModelWindow, cv::WINDOW_AUTOSIZE | cv::WINDOW_GUI_NORMAL);
  cv::namedWindow(image_window, cv::WINDOW_AUTOSIZE | cv::WINDOW_GUI_NORMAL);
  cv::moveWindow(kModelWindow, 0, 0);
  cv::moveWindow(image_window, image.cols + 16, 0);
  cv::setMouseCallback(kModelWindow, on_model_mouse, &ui);
  cv::setMouseCallback(image_window, on_image_mouse, &ui);

  std::vector<display::PlotPoint> fit_arrows;
  std::string fit_summary;
  std::size_t saved_rows = static_cast<std::size_t>(-1);
  cv::Mat model_shown, image_shown;
  auto fit = [&] {
    const auto rows = select_camera(session.rows(), a.camera);
    try {
      if (arm) {
        const CalibrationResult r = calibrate_camera(rows, vp, a.camera);
        fit_arrows = display::plot_points(rows, r.residuals, a.camera);
        char b[160];
        std::snprintf(b, sizeof b, "fit: f %.1f px, rms %.2f px, %zu outlier(s)", r.camera.f_px, r.rms_px,
                      r.outliers.size());
        fit_summary = b;
      } else {
        if (cameras.empty()) throw InputError("the ORU fit needs the calibrated cameras (--cameras)");
        const auto all = session.rows();
        const LocalizationResult r = localize_object(all, cameras);
        fit_arrows = display::plot_points(all, r.residuals, a.camera);
        const Eigen::Vector3d t = r.base_T_object.translation();
        char b[160];
        std::snprintf(b, sizeof b, "fit: ORU at %.3f %.3f %.3f m, rms %.2f px", t.x(), t.y(), t.z(), r.rms_px);
        fit_summary = b;
      }
    } catch (const std::exception& e) {
      fit_arrows.clear();
      fit_summary = std::string("fit failed: ") + e.what();
    }
    ui.status = fit_summary;
  };

  for (;;) {
    if (session.rows().size() != saved_rows) {
      save_csv(a.out, session.csv());
      saved_rows = session.rows().size();
      fit_arrows.clear();
    }
    if (ui.dirty) {
      ui.dirty = false;
      // The model window: numbered points; the selected one ringed, clicked ones ticked.
      model_shown = model_base.clone();
      std::vector<bool> done(points.size(), false);
      for (const int i : session.session_model_index()) done[i] = true;
      for (std::size_t i = 0; i < points.size(); ++i) {
        const cv::Point p(cvRound(model_px[i].x() - 0.5), cvRound(model_px[i].y() - 0.5));
        const bool sel = static_cast<int>(i) == session.selected();
        const cv::Scalar c = sel ? cv::Scalar(0, 255, 255) : done[i] ? cv::Scalar(80, 220, 80) : cv::Scalar(255, 200, 80);
        cv::circle(model_shown, p, sel ? 7 : 4, c, sel ? 2 : cv::FILLED, cv::LINE_AA);
        cv::putText(model_shown, std::to_string(i + 1), p + cv::Point(6, -5), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                    cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
        cv::putText(model_shown, std::to_string(i + 1), p + cv::Point(6, -5), cv::FONT_HERSHEY_SIMPLEX, 0.45, c, 1,
                    cv::LINE_AA);
      }
      display::put_text_line(model_shown, std::string("model: ") + (arm ? "robot arm (base frame)" : object.name) +
                                              ", " + std::to_string(points.size()) + " points",
                             {8, 6}, cv::Scalar(255, 255, 255), 0.45);
      display::put_text_line(model_shown,
                             session.state() == ClickSession::State::AwaitModelPoint
                                 ? "click a model point"
                                 : "now click point " + std::to_string(session.selected() + 1) + " in the image",
                             {8, model_shown.rows - 24}, cv::Scalar(0, 255, 255), 0.45);
      // The image window: the clicks so far (and the fit's arrows), zoomed.
      cv::Mat marked = fit_arrows.empty() ? image.clone()
                                          : display::draw_residual_plot(image, vp, fit_arrows, {0.0, fit_summary});
      for (const auto& r : session.rows()) {
        if (r.cam != a.camera) continue;
        const cv::Point p(cvRound(r.uv_px.x() - 0.5), cvRound(r.uv_px.y() - 0.5));
        cv::drawMarker(marked, p, cv::Scalar(80, 255, 80), cv::MARKER_CROSS, 9, 1);
      }
      image_shown = zoom.render(marked);
      for (const auto& r : session.rows()) {
        if (r.cam != a.camera) continue;
        const Eigen::Vector2d w = zoom.to_window(r.uv_px);
        cv::putText(image_shown, std::to_string(r.n), cv::Point(cvRound(w.x()) + 5, cvRound(w.y()) - 5),
                    cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(80, 255, 80), 1, cv::LINE_AA);
      }
      char zoom_text[48];
      std::snprintf(zoom_text, sizeof zoom_text, "zoom x%g", zoom.zoom());
      display::put_text_line(image_shown,
                             std::to_string(session.rows().size()) + " points  " + zoom_text +
                                 "   u undo  c clear  +/- zoom  f fit  q quit",
                             {8, image_shown.rows - 44}, cv::Scalar(255, 255, 255), 0.42);
      display::put_text_line(image_shown, ui.status, {8, image_shown.rows - 24}, cv::Scalar(0, 255, 255), 0.42);
      cv::imshow(kModelWindow, model_shown);
      cv::imshow(image_window, image_shown);
    }
    const int key = cv::waitKey(30);
    if (key < 0) continue;
    const int k = key & 0xff;
    ui.dirty = true;
    if (k == 'q' || k == 27) break;
    if (k == 'u' || k == 8) {
      ui.status = session.delete_last() ? "deleted the last point" : "nothing to delete";
    } else if (k == 'c') {
      session.clear();
      ui.status = "cleared";
    } else if (k == '+' || k == '=') {
      zoom.zoom_at(ui.mouse_image_px, 2.0);
    } else if (k == '-') {
      zoom.zoom_at(ui.mouse_image_px, 0.5);
    } else if (k == '0') {
      zoom.reset();
    } else if (k == 'n' || k == 'p') {
      const int m = static_cast<int>(points.size());
      const int i = session.selected() < 0 ? (k == 'n' ? 0 : m - 1) : (session.selected() + (k == 'n' ? 1 : m - 1)) % m;
      session.select_model_point(i);
      ui.status = "model point " + std::to_string(i + 1) + " (" + points[i].label + "): now click it in the image";
    } else if (k == 'f') {
      fit();
    }
  }
  save_csv(a.out, session.csv());
  if (!a.snapshot.empty()) {
    write_image(a.snapshot + "_model.png", model_shown);
    write_image(a.snapshot + "_image.png", image_shown);
  }
  cv::destroyAllWindows();
  const auto rows = session.session_rows();
  if (a.json) {
    std::cout << nlohmann::json{{"out", a.out},
                                {"camera", a.camera},
                                {"model", a.model},
                                {"points", rows.size()},
                                {"rows_in_file", session.rows().size()},
                                {"fit", fit_summary}}
                     .dump()
              << "\n";
  } else {
    std::printf("click: %zu point(s) on camera %s (%s model); %zu row(s) in %s\n", rows.size(), a.camera.c_str(),
                a.model.c_str(), session.rows().size(), a.out.c_str());
    if (!fit_summary.empty()) std::printf("  %s\n", fit_summary.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"click", "operator point entry: click model points and their image points, write the points CSV",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<ClickArgs>();
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
       sub.add_flag("--json", a->json, "print one JSON object");
       return [a] { return run_click(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
