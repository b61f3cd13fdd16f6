#pragma once
// Off-screen renderer for the calibrated overlays (the paper's sec. 3): bodies
// (meshes in their own frame, placed by base_T_body) and line sets (tag
// triads, a tool path) drawn through a Camera into a framebuffer object of the
// camera's viewport, read back as a BGRA layer and composited on a video frame.
//
// One source of truth for the projection: the GL projection and view are
// Camera::gl_projection() and Camera::gl_view(); the only addition here is a
// flip of the window y axis (diag(1, -1, 1, 1) applied after the projection)
// so that GL row r is image row r counted from the top: the read-back layer is
// then top-down like every image, and pixel (i, j) covers [i, i+1) x [j, j+1)
// in Camera::project() coordinates.
//
// Render modes (the paper's): wire-frame, solid shaded, wire-frame with hidden
// lines removed (a depth-only pre-pass of the faces pushed back with polygon
// offset, then the edges depth-tested), and ghost: the shaded solid composited
// semi-transparently, out = alpha * model + (1 - alpha) * video.
//
// Not real-time code (it allocates on set-up); render() reuses its buffers
// and allocates only when the layer is not yet of the viewport's size.

#include <Eigen/Core>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/render/gl_context.hpp"
#include "foresight/render/mesh.hpp"

namespace foresight::render {

enum class RenderMode { Wire, Solid, Hidden, Ghost };

/// "wire", "solid", "hidden" or "ghost"; throws std::invalid_argument otherwise.
RenderMode parse_render_mode(const std::string& text);
const char* to_string(RenderMode mode);

struct BodyInstance {
  int body = -1;                                      ///< id from Renderer::add_body
  Pose base_T_body = Pose::Identity();
  Eigen::Vector4d wire_rgba{0.1, 1.0, 0.2, 1.0};      ///< edge colour in wire/hidden modes
  std::optional<Eigen::Vector4d> solid_rgba;          ///< overrides the mesh colours when set
};

struct LineSet {
  std::vector<Eigen::Vector3d> points_base;  ///< metres, base frame
  Eigen::Vector4d rgba{1.0, 1.0, 1.0, 1.0};
  bool strip = true;  ///< a polyline; false: independent segments (point pairs)
  float width_px = 2.0f;
};

struct DrawList {
  std::vector<BodyInstance> bodies;
  std::vector<LineSet> lines;  ///< drawn over everything (never hidden)
  void clear() {
    bodies.clear();
    lines.clear();
  }
};

/// Adds the axis triad of `base_T_frame` (x red, y green, z blue), axes of length_m.
void append_triad(DrawList& list, const Pose& base_T_frame, double length_m);

struct RenderSettings {
  RenderMode mode = RenderMode::Solid;
  bool lighting = true;                     ///< false: flat mesh colours (masks, labels)
  Eigen::Vector4d clear_rgba{0, 0, 0, 0};   ///< alpha 0: the layer is transparent where nothing is drawn
  double near_m = 0.05;
  double far_m = 50.0;
  float line_width_px = 1.0f;
};

class Renderer {
 public:
  /// Creates the framebuffer for `viewport`, with `samples` > 1 for
  /// multisample anti-aliasing (the synthetic camera; overlays use 1 so a
  /// pixel is either drawn or not). The context is made current. Throws
  /// std::runtime_error when the viewport exceeds the GL limits or the
  /// framebuffer cannot be created, naming the size.
  Renderer(GlContext& context, const camera::Viewport& viewport, int samples = 1);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// Uploads a mesh; returns its body id. Set-up only.
  int add_body(const Mesh& mesh);
  int body_triangles(int body) const;
  const camera::Viewport& viewport() const;
  GlContext& context();
  /// GL_RENDERER / GL_VERSION strings of the context.
  std::string gl_description() const;

  /// Draws `list` through `camera` (whose viewport must equal viewport())
  /// into `layer_bgra` (CV_8UC4, top row first; alpha 255 where the model is
  /// drawn, clear_rgba elsewhere). Returns the number of triangles drawn.
  /// Throws std::invalid_argument on a viewport mismatch or an unknown body.
  int render(const camera::Camera& camera, const DrawList& list, const RenderSettings& settings, cv::Mat& layer_bgra);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// video_bgr (CV_8UC3) <- opacity * layer + (1 - opacity) * video wherever
/// the layer's alpha is non-zero (scaled by alpha / 255). Sizes must match
/// (std::invalid_argument otherwise).
void composite(const cv::Mat& layer_bgra, double opacity, cv::Mat& video_bgr);

/// The opacity a mode composites with: ghost_alpha for Ghost, 1 otherwise.
inline double mode_opacity(RenderMode mode, double ghost_alpha) { return mode == RenderMode::Ghost ? ghost_alpha : 1.0; }

}  // namespace foresight::render
