#include "foresight/display/display_frame.hpp"

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "foresight/render/scene_geometry.hpp"

namespace foresight::display {

int put_text_line(cv::Mat& img, const std::string& text, cv::Point at, const cv::Scalar& colour, double scale) {
  int base = 0;
  const cv::Size sz = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &base);
  const cv::Rect box(at.x - 3, at.y - 3, sz.width + 6, sz.height + base + 6);
  cv::Mat roi = img(box & cv::Rect(0, 0, img.cols, img.rows));
  roi *= 0.35;  // darken behind the text so it reads on any video
  cv::putText(img, text, cv::Point(at.x, at.y + sz.height), cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv::LINE_AA);
  return at.y + sz.height + base + 8;
}

namespace {
struct PerViewport {
  std::unique_ptr<render::Renderer> renderer;
  std::unique_ptr<render::ArmGeometry> arm;
  int object_body = -1;
};
}  // namespace

struct DisplayComposer::Impl {
  render::GlContext& context;
  const RobotModel& robot;
  const ObjectModel* object;
  std::optional<Pose> base_T_object;
  DisplayColours colours;
  std::map<std::pair<int, int>, PerViewport> per_viewport;
  render::DrawList list;
  cv::Mat layer;

  PerViewport& at(const camera::Viewport& vp) {
    auto& p = per_viewport[{vp.width_px, vp.height_px}];
    if (!p.renderer) {
      p.renderer = std::make_unique<render::Renderer>(context, vp);
      p.arm = std::make_unique<render::ArmGeometry>(*p.renderer, robot);
      if (object != nullptr && base_T_object) p.object_body = render::add_object_body(*p.renderer, *object);
    }
    return p;
  }
};

DisplayComposer::DisplayComposer(render::GlContext& context, const RobotModel& robot, const ObjectModel* object,
                                 std::optional<Pose> base_T_object, DisplayColours colours)
    : impl_(new Impl{context, robot, object, base_T_object, colours, {}, {}, {}}) {}

DisplayComposer::~DisplayComposer() = default;

cv::Mat DisplayComposer::arm_silhouette(const camera::Camera& camera, const Eigen::VectorXd& q) {
  PerViewport& p = impl_->at(camera.viewport);
  impl_->list.clear();
  p.arm->append(q, impl_->list);
  render::RenderSettings st;
  st.mode = render::RenderMode::Solid;
  st.lighting = false;
  p.renderer->render(camera, impl_->list, st, impl_->layer);
  cv::Mat alpha;
  cv::extractChannel(impl_->layer, alpha, 3);
  return alpha > 0;
}

cv::Mat DisplayComposer::compose(const camera::Camera& camera, const cv::Mat& video_bgr, const DisplayState& s) {
  const cv::Size size(camera.viewport.width_px, camera.viewport.height_px);
  cv::Mat out;
  if (video_bgr.empty()) {
    out = cv::Mat(size, CV_8UC3, cv::Scalar(0, 0, 0));
  } else {
    if (video_bgr.size() != size || video_bgr.type() != CV_8UC3)
      throw std::invalid_argument("display: the video frame must be 8-bit BGR of the camera's viewport");
    out = video_bgr.clone();
  }
  if (s.overlay) {
    PerViewport& p = impl_->at(camera.viewport);
    auto& list = impl_->list;
    render::RenderSettings st;
    // The delayed actual arm and the ORU with its tag frames, in the chosen mode.
    list.clear();
    const bool shaded = s.mode == render::RenderMode::Solid || s.mode == render::RenderMode::Ghost;
    p.arm->append(s.q_actual, list, impl_->colours.actual_wire_rgba,
                  shaded ? std::optional<Eigen::Vector4d>(impl_->colours.actual_rgba) : std::nullopt);
    if (p.object_body >= 0) {
      list.bodies.push_back({p.object_body, *impl_->base_T_object, render::kObjectWireRgba, std::nullopt});
      for (const auto& [name, oru_T_tag] : impl_->object->tags)
        render::append_triad(list, *impl_->base_T_object * oru_T_tag, 0.06);
    }
    st.mode = s.mode;
    p.renderer->render(camera, list, st, impl_->layer);
    render::composite(impl_->layer, render::mode_opacity(s.mode, s.ghost_alpha), out);
    // The commanded arm running ahead, a tinted ghost.
    if (s.q_commanded) {
      list.clear();
      p.arm->append(*s.q_commanded, list, render::kArmWireRgba, impl_->colours.commanded_rgba);
      st.mode = render::RenderMode::Ghost;
      p.renderer->render(camera, list, st, impl_->layer);
      render::composite(impl_->layer, s.ghost_alpha, out);
    }
    if (s.go_no_go) draw_go_no_go(out, camera, *s.go_no_go, s.text);  // its label is text
  }
  if (s.text) {
    const cv::Scalar white(255, 255, 255), red(60, 60, 255), cyan(255, 220, 90);
    int y = 6;
    std::string head = "camera " + camera.name + "  mode " + render::to_string(s.mode) + "  overlay " +
                       (s.overlay ? "on" : "off");
    y = put_text_line(out, head, {8, y}, white, 0.45);
    if (!s.delay_text.empty()) y = put_text_line(out, s.delay_text, {8, y}, white, 0.45);
    if (!s.controller_text.empty()) y = put_text_line(out, s.controller_text, {8, y}, white, 0.45);
    if (!s.health_text.empty())
      y = put_text_line(out, s.health_text, {8, y}, s.health_warning ? red : white, s.health_warning ? 0.5 : 0.45);
    if (!s.fault_text.empty()) y = put_text_line(out, "FAULT: " + s.fault_text, {8, y}, red, 0.5);
    if (s.overlay && s.q_commanded)
      put_text_line(out, "ghost: commanded (ahead)   solid: actual (delayed)", {8, y}, cyan, 0.42);
    if (!s.video_problem.empty()) {
      int base = 0;
      const cv::Size sz = cv::getTextSize(s.video_problem, cv::FONT_HERSHEY_SIMPLEX, 0.5, 1, &base);
      put_text_line(out, s.video_problem, {std::max(4, (out.cols - sz.width) / 2), out.rows / 2 - 10}, red, 0.5);
    }
    if (!s.footer.empty()) put_text_line(out, s.footer, {8, out.rows - 24}, white, 0.42);
  }
  return out;
}

}  // namespace foresight::display
