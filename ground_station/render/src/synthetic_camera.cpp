#include "foresight/render/synthetic_camera.hpp"

#include <opencv2/imgproc.hpp>

namespace foresight::render {

struct SyntheticCamera::Impl {
  SyntheticOptions options;
  const Scene& scene;
  Renderer renderer;
  ArmGeometry arm;
  int object_body = -1, panel_body = -1, floor_body = -1;
  unsigned frame_counter = 0;
  DrawList list;
  cv::Mat layer;

  Impl(GlContext& ctx, const RobotModel& model, const ObjectModel& object, const Scene& s, const camera::Viewport& vp,
       const SyntheticOptions& o)
      : options(o), scene(s), renderer(ctx, vp, o.samples), arm(renderer, model) {
    object_body = add_object_body(renderer, object);
    panel_body = renderer.add_body(make_box(s.panel.size_m, Pose::Identity(), s.panel.rgba));
    if (o.floor)
      floor_body = renderer.add_body(make_floor(0.5, 0.0, 0.0, 0.25, 16, {0.30, 0.30, 0.33, 1.0}, {0.22, 0.22, 0.25, 1.0}));
  }

  // The scene's draw list; `highlight` 0 = natural colours, 1 = arm white and
  // the rest black, 2 = object white and the rest black.
  void build(const Eigen::VectorXd& q, const Pose& base_T_object, int highlight) {
    list.clear();
    const Eigen::Vector4d white(1, 1, 1, 1), black(0, 0, 0, 1);
    auto colour = [&](int who) -> std::optional<Eigen::Vector4d> {
      if (highlight == 0) return std::nullopt;
      return highlight == who ? white : black;
    };
    arm.append(q, list, kArmWireRgba, colour(1));
    list.bodies.push_back({object_body, base_T_object, kObjectWireRgba, colour(2)});
    list.bodies.push_back({panel_body, scene.panel.base_T_panel, kObjectWireRgba, colour(3)});
    if (floor_body >= 0) list.bodies.push_back({floor_body, Pose::Identity(), kObjectWireRgba, colour(3)});
  }

  cv::Mat mask(const camera::Camera& cam, const Eigen::VectorXd& q, const Pose& base_T_object, int who) {
    build(q, base_T_object, who);
    RenderSettings st;
    st.mode = RenderMode::Solid;
    st.lighting = false;
    renderer.render(cam, list, st, layer);
    cv::Mat m;
    cv::extractChannel(layer, m, 2);  // red: white where `who` is the front surface
    cv::threshold(m, m, 127, 255, cv::THRESH_BINARY);
    return m;
  }
};

SyntheticCamera::SyntheticCamera(GlContext& context, const RobotModel& arm, const ObjectModel& object,
                                 const Scene& scene, const camera::Viewport& viewport, const SyntheticOptions& options)
    : impl_(std::make_unique<Impl>(context, arm, object, scene, viewport, options)) {}

SyntheticCamera::~SyntheticCamera() = default;

SyntheticFrame SyntheticCamera::render(const camera::Camera& cam, const Eigen::VectorXd& q,
                                       const std::optional<Pose>& base_T_object_opt) {
  auto& I = *impl_;
  I.arm.check_joints(q);
  const Pose base_T_object = base_T_object_opt ? *base_T_object_opt : I.scene.base_T_object;
  SyntheticFrame f;
  I.build(q, base_T_object, 0);
  RenderSettings st;
  st.mode = RenderMode::Solid;
  st.clear_rgba = I.options.sky_rgba;
  I.renderer.render(cam, I.list, st, I.layer);
  cv::cvtColor(I.layer, f.image_bgr, cv::COLOR_BGRA2BGR);
  if (I.options.blur_sigma_px > 0.0)
    cv::GaussianBlur(f.image_bgr, f.image_bgr, cv::Size(0, 0), I.options.blur_sigma_px);
  if (I.options.noise_sigma_dn > 0.0) {
    cv::RNG rng(static_cast<std::uint64_t>(I.options.seed) * 7919u + I.frame_counter++);
    cv::Mat noise(f.image_bgr.size(), CV_32FC3);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, I.options.noise_sigma_dn);
    cv::Mat img;
    f.image_bgr.convertTo(img, CV_32FC3);
    img += noise;
    img.convertTo(f.image_bgr, CV_8UC3);  // saturating
  }
  f.arm_mask = I.mask(cam, q, base_T_object, 1);
  f.object_mask = I.mask(cam, q, base_T_object, 2);
  return f;
}

}  // namespace foresight::render
