#include "foresight/preview/preview.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <stdexcept>

#include "foresight/common/error.hpp"
#include "foresight/render/video_frame.hpp"

namespace foresight::preview {

Eigen::VectorXd sample_trajectory(const Trajectory& tr, double t) {
  if (tr.samples() == 0) throw std::invalid_argument("trajectory has no samples");
  const auto& ts = tr.time_s;
  if (t <= ts.front()) return tr.positions_rad.row(0).transpose();
  if (t >= ts.back()) return tr.positions_rad.row(tr.samples() - 1).transpose();
  const auto it = std::upper_bound(ts.begin(), ts.end(), t);
  const int i = static_cast<int>(it - ts.begin());  // ts[i-1] <= t < ts[i]
  const double s = (t - ts[i - 1]) / (ts[i] - ts[i - 1]);
  return ((1.0 - s) * tr.positions_rad.row(i - 1) + s * tr.positions_rad.row(i)).transpose();
}

void append_extras(const OverlayExtras& extras, render::DrawList& list) {
  if (extras.object_body >= 0)
    list.bodies.push_back({extras.object_body, extras.base_T_object, render::kObjectWireRgba, std::nullopt});
  for (const auto& T : extras.base_T_tags) render::append_triad(list, T, extras.triad_length_m);
}

namespace {

void put_label(cv::Mat& img, const std::string& text, cv::Point at, double scale = 0.5) {
  int base = 0;
  const cv::Size sz = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &base);
  cv::rectangle(img, cv::Rect(at.x - 3, at.y - sz.height - 4, sz.width + 6, sz.height + base + 6), cv::Scalar(0, 0, 0),
                cv::FILLED);
  cv::putText(img, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
}

std::string seconds_text(double t) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f s", t);
  return b;
}

}  // namespace

int video_fourcc(const std::string& path, const std::string& for_what) {
  std::string lower = path;
  for (auto& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (lower.ends_with(".mp4")) return cv::VideoWriter::fourcc('m', 'p', '4', 'v');
  if (lower.ends_with(".avi")) return cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  if (lower.ends_with(".webm")) return cv::VideoWriter::fourcc('V', 'P', '8', '0');
  throw InputError(path, "unsupported video extension" + for_what + " (use .mp4, .avi or .webm)");
}

PreviewResult render_preview(render::Renderer& renderer, render::ArmGeometry& arm, const camera::Camera& camera,
                             const cv::Mat& background, const Trajectory& tr, const OverlayExtras& extras,
                             const PreviewOptions& o, const std::string& video_path, const std::string& sheet_path) {
  if (!(o.speed > 0.0) || !std::isfinite(o.speed))
    throw std::invalid_argument("--speed must be a positive number");
  if (!(o.fps > 0.0)) throw std::invalid_argument("frame rate must be positive");
  if (o.sheet_frames < 2) throw std::invalid_argument("a contact sheet needs at least 2 frames");
  if (tr.samples() < 1) throw std::invalid_argument("trajectory has no samples");
  if (tr.joints() != arm.model().dof())
    throw std::invalid_argument("trajectory has " + std::to_string(tr.joints()) + " joints but the arm has " +
                                std::to_string(arm.model().dof()));
  if (background.size() != cv::Size(camera.viewport.width_px, camera.viewport.height_px) ||
      background.type() != CV_8UC3)
    throw std::invalid_argument("background frame must be 8-bit BGR of the camera's viewport");

  const int fourcc = video_fourcc(video_path);
  cv::VideoWriter writer(video_path, fourcc, o.fps, background.size());
  if (!writer.isOpened()) throw InputError(video_path, "cannot write video");

  PreviewResult result;
  result.duration_s = tr.duration_s();
  const double t0 = tr.time_s.front();
  const render::LineSet path = o.tool_path ? render::tool_path(arm, tr.positions_rad) : render::LineSet{};
  render::RenderSettings st;
  st.mode = o.mode;
  render::DrawList list;
  cv::Mat layer, frame;
  auto draw_at = [&](double t) {
    list.clear();
    arm.append(sample_trajectory(tr, t), list, render::kArmWireRgba, o.arm_rgba);
    append_extras(extras, list);
    if (o.tool_path) list.lines.push_back(path);
    result.triangles_per_frame = renderer.render(camera, list, st, layer);
    background.copyTo(frame);
    render::composite(layer, render::mode_opacity(o.mode, o.ghost_alpha), frame);
    return frame;
  };

  const double video_span_s = result.duration_s / o.speed;
  const int n_frames = static_cast<int>(std::floor(video_span_s * o.fps + 1e-9)) + 1;
  for (int k = 0; k < n_frames; ++k) {
    if (o.interrupted && o.interrupted()) throw Interrupted();
    const double t = std::min(t0 + k * o.speed / o.fps, tr.time_s.back());
    writer.write(draw_at(t));
  }
  // The final pose, held for one frame when the span is not a whole number of frames.
  if (t0 + (n_frames - 1) * o.speed / o.fps < tr.time_s.back() - 1e-9) {
    writer.write(draw_at(tr.time_s.back()));
    result.frames = n_frames + 1;
  } else {
    result.frames = n_frames;
  }
  writer.release();
  result.video_duration_s = result.frames / o.fps;

  for (int i = 0; i < o.sheet_frames; ++i)
    result.sheet_times_s.push_back(t0 + result.duration_s * i / (o.sheet_frames - 1));
  if (!sheet_path.empty()) {
    const int tw = std::max(1, static_cast<int>(std::lround(background.cols * o.sheet_scale)));
    const int th = std::max(1, static_cast<int>(std::lround(background.rows * o.sheet_scale)));
    const int cols = std::max(1, std::min(o.sheet_columns, o.sheet_frames));
    const int rows = (o.sheet_frames + cols - 1) / cols;
    cv::Mat sheet(rows * th, cols * tw, CV_8UC3, cv::Scalar(0, 0, 0));
    for (int i = 0; i < o.sheet_frames; ++i) {
      cv::Mat tile;
      cv::resize(draw_at(result.sheet_times_s[i]), tile, cv::Size(tw, th), 0, 0, cv::INTER_AREA);
      put_label(tile, "t = " + seconds_text(result.sheet_times_s[i] - t0), cv::Point(6, 18));
      tile.copyTo(sheet(cv::Rect((i % cols) * tw, (i / cols) * th, tw, th)));
    }
    render::write_image(sheet_path, sheet, "cannot write contact sheet");
  }
  return result;
}

cv::Mat predictive_frame(render::Renderer& renderer, render::ArmGeometry& arm, const camera::Camera& camera,
                         const cv::Mat& background, const Eigen::VectorXd& q_commanded,
                         const Eigen::VectorXd& q_actual, double delay_s, const OverlayExtras& extras,
                         const PredictiveOptions& o) {
  if (!std::isfinite(delay_s) || delay_s < 0.0) throw std::invalid_argument("delay must be a non-negative number of seconds");
  arm.check_joints(q_commanded);
  arm.check_joints(q_actual);
  cv::Mat out = background.clone();
  cv::Mat layer;
  render::DrawList list;
  render::RenderSettings st;
  // The delayed actual arm, solid, with the task object.
  st.mode = render::RenderMode::Solid;
  arm.append(q_actual, list);
  append_extras(extras, list);
  renderer.render(camera, list, st, layer);
  render::composite(layer, 1.0, out);
  // The commanded arm, a tinted ghost over it.
  list.clear();
  arm.append(q_commanded, list, render::kArmWireRgba, o.commanded_rgba);
  st.mode = render::RenderMode::Ghost;
  renderer.render(camera, list, st, layer);
  render::composite(layer, o.ghost_alpha, out);
  if (o.label) {
    put_label(out, "ghost: commanded (now)", cv::Point(8, 20));
    put_label(out, "solid: actual, delayed " + seconds_text(delay_s), cv::Point(8, 42));
  }
  return out;
}

}  // namespace foresight::preview
