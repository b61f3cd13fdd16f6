// `foresight click`'s loop (click_loop.hpp).
#include "foresight/session/click_loop.hpp"

#include <opencv2/highgui.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

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

namespace foresight::session {

namespace {

using display::ClickSession;

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

/// The two windows over one click session: set-up, the fit, the drawing,
/// the keys.
class ClickLoop {
 public:
  explicit ClickLoop(const ClickSettings& a)
      : a_(a),
        arm_(a.model == "robot"),
        robot_(RobotModel::from_file(a.robot)),
        object_(ObjectModel::from_file(a.object)) {
    using namespace foresight::render;
    Eigen::VectorXd q = robot_.mid_configuration();
    if (!a.joints.empty()) q = parse_joints(a.joints, "--joints", robot_);
    if (!a.joints_deg.empty()) q = parse_joints(a.joints_deg, "--joints-deg", robot_, true);
    if (arm_ && a.joints.empty() && a.joints_deg.empty())
      throw std::invalid_argument("--model robot needs the arm's joint angles in the frame (--joints or --joints-deg)");
    image_ = read_video_frame(a.image, a.frame);
    vp_ = camera::Viewport{image_.cols, image_.rows};
    if (!a.cameras.empty())
      for (const auto& [name, rec] : camera::load_cameras(a.cameras)) cameras_[name] = rec.camera;
    std::vector<calibration::Correspondence> existing;
    if (a.append && std::filesystem::exists(a.out)) existing = calibration::read_correspondences_csv(a.out);
    if (!std::filesystem::exists(std::filesystem::absolute(a.out).parent_path()))
      throw InputError(a.out, "the folder does not exist");
    if (const std::string why = display::x_display_problem(); !why.empty())
      throw InputError("foresight click needs a display to show its windows (" + why +
                       "); run it on the operator's desktop or under Xvfb");
    points_ = arm_ ? display::arm_model_points(robot_, q) : display::object_model_points(object_);
    session_ = std::make_unique<ClickSession>(a.camera, points_, image_.size());
    session_->set_existing_rows(existing);
    zoom_ = std::make_unique<display::ZoomView>(image_.size());
    render_model(q);
    ui_.session = session_.get();
    ui_.zoom = zoom_.get();
    ui_.model_px = &model_px_;
    ui_.status = "click a numbered model point, then the same point in the image";
    image_window_ = "foresight click: image " + a.camera;
    cv::namedWindow(kModelWindow, cv::WINDOW_AUTOSIZE | cv::WINDOW_GUI_NORMAL);
    cv::namedWindow(image_window_, cv::WINDOW_AUTOSIZE | cv::WINDOW_GUI_NORMAL);
    cv::moveWindow(kModelWindow, 0, 0);
    cv::moveWindow(image_window_, image_.cols + 16, 0);
    cv::setMouseCallback(kModelWindow, on_model_mouse, &ui_);
    cv::setMouseCallback(image_window_, on_image_mouse, &ui_);
  }

  ClickSummary run() {
    std::size_t saved_rows = static_cast<std::size_t>(-1);
    for (;;) {
      if (session_->rows().size() != saved_rows) {
        save_csv(a_.out, session_->csv());
        saved_rows = session_->rows().size();
        fit_arrows_.clear();
      }
      if (ui_.dirty) {
        ui_.dirty = false;
        draw_model();
        draw_image();
        cv::imshow(kModelWindow, model_shown_);
        cv::imshow(image_window_, image_shown_);
      }
      const int key = cv::waitKey(30);
      if (key < 0) continue;
      ui_.dirty = true;
      if (!on_key(key & 0xff)) break;
    }
    save_csv(a_.out, session_->csv());
    if (!a_.snapshot.empty()) {
      render::write_image(a_.snapshot + "_model.png", model_shown_);
      render::write_image(a_.snapshot + "_image.png", image_shown_);
    }
    cv::destroyAllWindows();
    return {session_->session_rows().size(), session_->rows().size(), fit_summary_};
  }

 private:
  /// The model picture: rendered once, the numbers drawn per refresh.
  void render_model(const Eigen::VectorXd& q) {
    using namespace foresight::render;
    const camera::Camera view = display::default_model_view(points_, vp_, arm_);
    auto context = GlContext::create(parse_gl_backend(a_.gl));
    Renderer renderer(*context, vp_);
    DrawList list;
    if (arm_) {
      ArmGeometry geometry(renderer, robot_);
      geometry.append(q, list);
    } else {
      list.bodies.push_back({add_object_body(renderer, object_), Pose::Identity(), kObjectWireRgba, std::nullopt});
    }
    cv::Mat layer;
    RenderSettings st;
    st.mode = RenderMode::Solid;
    renderer.render(view, list, st, layer);
    model_base_ = cv::Mat(image_.size(), CV_8UC3, cv::Scalar(48, 40, 36));
    composite(layer, 1.0, model_base_);
    for (const auto& p : points_) model_px_.push_back(view.project(p.p_m));
  }

  /// Calibrate (robot) or localize (oru) from the rows so far; the residual
  /// arrows and a summary line.
  void fit() {
    const auto rows = calibration::select_camera(session_->rows(), a_.camera);
    try {
      if (arm_) {
        const calibration::CalibrationResult r = calibration::calibrate_camera(rows, vp_, a_.camera);
        fit_arrows_ = display::plot_points(rows, r.residuals, a_.camera);
        char b[160];
        std::snprintf(b, sizeof b, "fit: f %.1f px, rms %.2f px, %zu outlier(s)", r.camera.f_px, r.rms_px,
                      r.outliers.size());
        fit_summary_ = b;
      } else {
        if (cameras_.empty()) throw InputError("the ORU fit needs the calibrated cameras (--cameras)");
        const auto all = session_->rows();
        const localization::LocalizationResult r = localization::localize_object(all, cameras_);
        fit_arrows_ = display::plot_points(all, r.residuals, a_.camera);
        const Eigen::Vector3d t = r.base_T_object.translation();
        char b[160];
        std::snprintf(b, sizeof b, "fit: ORU at %.3f %.3f %.3f m, rms %.2f px", t.x(), t.y(), t.z(), r.rms_px);
        fit_summary_ = b;
      }
    } catch (const std::exception& e) {
      fit_arrows_.clear();
      fit_summary_ = std::string("fit failed: ") + e.what();
    }
    ui_.status = fit_summary_;
  }

  /// The model window: numbered points; the selected one ringed, clicked ones ticked.
  void draw_model() {
    model_shown_ = model_base_.clone();
    std::vector<bool> done(points_.size(), false);
    for (const int i : session_->session_model_index()) done[i] = true;
    for (std::size_t i = 0; i < points_.size(); ++i) {
      const cv::Point p(cvRound(model_px_[i].x() - 0.5), cvRound(model_px_[i].y() - 0.5));
      const bool sel = static_cast<int>(i) == session_->selected();
      const cv::Scalar c = sel ? cv::Scalar(0, 255, 255) : done[i] ? cv::Scalar(80, 220, 80) : cv::Scalar(255, 200, 80);
      cv::circle(model_shown_, p, sel ? 7 : 4, c, sel ? 2 : cv::FILLED, cv::LINE_AA);
      cv::putText(model_shown_, std::to_string(i + 1), p + cv::Point(6, -5), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                  cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
      cv::putText(model_shown_, std::to_string(i + 1), p + cv::Point(6, -5), cv::FONT_HERSHEY_SIMPLEX, 0.45, c, 1,
                  cv::LINE_AA);
    }
    display::put_text_line(model_shown_, std::string("model: ") + (arm_ ? "robot arm (base frame)" : object_.name) +
                                             ", " + std::to_string(points_.size()) + " points",
                           {8, 6}, cv::Scalar(255, 255, 255), 0.45);
    display::put_text_line(model_shown_,
                           session_->state() == ClickSession::State::AwaitModelPoint
                               ? "click a model point"
                               : "now click point " + std::to_string(session_->selected() + 1) + " in the image",
                           {8, model_shown_.rows - 24}, cv::Scalar(0, 255, 255), 0.45);
  }

  /// The image window: the clicks so far (and the fit's arrows), zoomed.
  void draw_image() {
    cv::Mat marked = fit_arrows_.empty() ? image_.clone()
                                         : display::draw_residual_plot(image_, vp_, fit_arrows_, {0.0, fit_summary_});
    for (const auto& r : session_->rows()) {
      if (r.cam != a_.camera) continue;
      const cv::Point p(cvRound(r.uv_px.x() - 0.5), cvRound(r.uv_px.y() - 0.5));
      cv::drawMarker(marked, p, cv::Scalar(80, 255, 80), cv::MARKER_CROSS, 9, 1);
    }
    image_shown_ = zoom_->render(marked);
    for (const auto& r : session_->rows()) {
      if (r.cam != a_.camera) continue;
      const Eigen::Vector2d w = zoom_->to_window(r.uv_px);
      cv::putText(image_shown_, std::to_string(r.n), cv::Point(cvRound(w.x()) + 5, cvRound(w.y()) - 5),
                  cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(80, 255, 80), 1, cv::LINE_AA);
    }
    char zoom_text[48];
    std::snprintf(zoom_text, sizeof zoom_text, "zoom x%g", zoom_->zoom());
    display::put_text_line(image_shown_,
                           std::to_string(session_->rows().size()) + " points  " + zoom_text +
                               "   u undo  c clear  +/- zoom  f fit  q quit",
                           {8, image_shown_.rows - 44}, cv::Scalar(255, 255, 255), 0.42);
    display::put_text_line(image_shown_, ui_.status, {8, image_shown_.rows - 24}, cv::Scalar(0, 255, 255), 0.42);
  }

  /// A key in either window; false to quit.
  bool on_key(int k) {
    if (k == 'q' || k == 27) return false;
    if (k == 'u' || k == 8) {
      ui_.status = session_->delete_last() ? "deleted the last point" : "nothing to delete";
    } else if (k == 'c') {
      session_->clear();
      ui_.status = "cleared";
    } else if (k == '+' || k == '=') {
      zoom_->zoom_at(ui_.mouse_image_px, 2.0);
    } else if (k == '-') {
      zoom_->zoom_at(ui_.mouse_image_px, 0.5);
    } else if (k == '0') {
      zoom_->reset();
    } else if (k == 'n' || k == 'p') {
      const int m = static_cast<int>(points_.size());
      const int i =
          session_->selected() < 0 ? (k == 'n' ? 0 : m - 1) : (session_->selected() + (k == 'n' ? 1 : m - 1)) % m;
      session_->select_model_point(i);
      ui_.status = "model point " + std::to_string(i + 1) + " (" + points_[i].label + "): now click it in the image";
    } else if (k == 'f') {
      fit();
    }
    return true;
  }

  const ClickSettings& a_;
  const bool arm_;
  const RobotModel robot_;
  const ObjectModel object_;
  cv::Mat image_;
  camera::Viewport vp_;
  std::map<std::string, camera::Camera> cameras_;
  std::vector<display::ModelPoint> points_;
  std::unique_ptr<ClickSession> session_;
  std::unique_ptr<display::ZoomView> zoom_;
  cv::Mat model_base_, model_shown_, image_shown_;
  std::vector<Eigen::Vector2d> model_px_;
  Ui ui_;
  std::string image_window_;
  std::vector<display::PlotPoint> fit_arrows_;
  std::string fit_summary_;
};

}  // namespace

ClickSummary run_click(const ClickSettings& settings) {
  if (settings.model != "robot" && settings.model != "oru") throw std::invalid_argument("--model must be robot or oru");
  if (!settings.joints.empty() && !settings.joints_deg.empty())
    throw std::invalid_argument("give only one of --joints, --joints-deg");
  ClickLoop loop(settings);
  return loop.run();
}

}  // namespace foresight::session
