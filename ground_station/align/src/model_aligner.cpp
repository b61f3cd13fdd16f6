#include "foresight/align/model_aligner.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <map>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/render/mesh.hpp"
#include "foresight/render/renderer.hpp"

namespace foresight::align {

Refine parse_refine(const std::string& text) {
  if (text == "camera") return Refine::Camera;
  if (text == "object") return Refine::Object;
  if (text == "both") return Refine::Both;
  throw std::invalid_argument("--refine '" + text + "' is not one of: camera, object, both");
}

const char* to_string(Refine r) {
  switch (r) {
    case Refine::Camera: return "camera";
    case Refine::Object: return "object";
    case Refine::Both: return "both";
  }
  return "?";
}

const char* to_string(AlignStatus s) {
  switch (s) {
    case AlignStatus::Aligned: return "aligned";
    case AlignStatus::Refused: return "refused";
    case AlignStatus::NotInView: return "not_in_view";
  }
  return "?";
}

double reprojection_rms_px(const Camera& a, const Camera& b, const std::vector<Eigen::Vector3d>& pts) {
  double s = 0.0;
  int n = 0;
  for (const auto& p : pts) {
    if (a.to_camera(p).z() <= 1e-3 || b.to_camera(p).z() <= 1e-3) continue;
    s += (a.project(p) - b.project(p)).squaredNorm();
    ++n;
  }
  return n ? std::sqrt(s / n) : 0.0;
}

namespace {

constexpr double kCreaseCos = 0.9063;  // cos 25 deg
constexpr double kNear_m = 0.05;

struct Edge {
  Eigen::Vector3d a, b;    // primitive frame (link or object)
  Eigen::Vector3d n1, n2;  // outward face normals
  bool two_faces = true;
  bool crease = false;
};

// Primitive::link of the object's surroundings (ObjectModel::surroundings):
// drawn into the label image with the object's pose (they hide its parts),
// never sampled, never in the appearance render.
constexpr int kSurroundings = -2;

struct Primitive {
  int link = -1;  // link index; -1: the object; kSurroundings
  int body = -1;
  int shaded_body = -1;  // in the shaded (appearance) renderer
  int label = 0;  // 1..
  Eigen::Vector4d rgba = Eigen::Vector4d::Zero();
  std::vector<Edge> edges;
  int first_edge = 0;  // the index of edges[0] over all primitives' edges
};

// Mesh edges with their adjacent face normals (vertices are duplicated per
// face in the meshes, so adjacency goes by position). Coplanar edges (a face's
// diagonal, a cap's spokes) are dropped: they never show.
std::vector<Edge> mesh_edges(const render::Mesh& m) {
  using Key = std::array<long long, 3>;
  auto key = [&](std::uint32_t i) {
    const float* p = m.vertices[i].position;
    return Key{std::llround(p[0] * 1e5), std::llround(p[1] * 1e5), std::llround(p[2] * 1e5)};
  };
  auto pos = [&](std::uint32_t i) {
    const float* p = m.vertices[i].position;
    return Eigen::Vector3d(p[0], p[1], p[2]);
  };
  struct Entry {
    Eigen::Vector3d a, b;
    std::vector<Eigen::Vector3d> normals;
  };
  std::map<std::pair<Key, Key>, Entry> map;
  for (std::size_t t = 0; t + 2 < m.triangles.size(); t += 3) {
    const std::uint32_t v[3] = {m.triangles[t], m.triangles[t + 1], m.triangles[t + 2]};
    Eigen::Vector3d n = (pos(v[1]) - pos(v[0])).cross(pos(v[2]) - pos(v[0]));
    if (n.norm() < 1e-12) continue;
    n.normalize();
    Eigen::Vector3d vn = Eigen::Vector3d::Zero();
    for (auto i : v) vn += Eigen::Vector3d(m.vertices[i].normal[0], m.vertices[i].normal[1], m.vertices[i].normal[2]);
    if (n.dot(vn) < 0.0) n = -n;
    for (int e = 0; e < 3; ++e) {
      std::uint32_t i = v[e], j = v[(e + 1) % 3];
      Key ki = key(i), kj = key(j);
      if (ki == kj) continue;
      if (kj < ki) {
        std::swap(ki, kj);
        std::swap(i, j);
      }
      auto& entry = map[{ki, kj}];
      if (entry.normals.empty()) {
        entry.a = pos(i);
        entry.b = pos(j);
      }
      entry.normals.push_back(n);
    }
  }
  std::vector<Edge> out;
  for (const auto& [k, e] : map) {
    Edge edge;
    edge.a = e.a;
    edge.b = e.b;
    edge.n1 = e.normals[0];
    if (e.normals.size() >= 2) {
      edge.n2 = e.normals[1];
      if (edge.n1.dot(edge.n2) > 0.9999) continue;
      edge.crease = edge.n1.dot(edge.n2) < kCreaseCos;
    } else {
      edge.two_faces = false;
      edge.crease = true;
      edge.n2 = -edge.n1;
    }
    out.push_back(edge);
  }
  return out;
}

struct Level {
  double search_px;
  double blur_px;
};
constexpr std::array<Level, 4> kLevels{{{24.0, 4.0}, {10.0, 2.0}, {4.0, 1.0}, {2.5, 0.5}}};
constexpr Level kScoreLevel{8.0, 1.0};

// A model edge sample: a point fixed in its primitive.
struct Sample {
  int view = 0, frame = 0;
  bool on_object = false;
  bool silhouette = false;
  double length_px = 0.0;  // contour length it stands for
  // The model edge it lies on, whose samples share their errors: per frame
  // for the arm (it moves between frames), per view for the object (static:
  // the same image edge in every frame, seen through the same camera).
  int cluster = 0;
  double outward = 0.0;  // silhouettes: +1 when +n (the search direction) points out of the model, else -1; creases 0
  double bias_px = 0.0;  // the edge search's offset on the predicted (shaded) model image at this level
  Eigen::Vector3d p_local, dir_local;  // object frame when on_object, else base
  int link = -1;                       // arm samples: the link it is fixed in
  Eigen::Vector3d p_link, dir_link;    // arm samples: in that link's frame
};

constexpr int kMaxLinks = 16;  // refined link lengths (chain segments with an offset)

struct Gradient {
  cv::Mat gx, gy;  // CV_32F, grey levels per pixel
  bool valid = false;  // false: the buffers are a recycled frame's, to be recomputed
};

// Bilinear sample at continuous pixel coordinates (pixel centres at i + 0.5).
inline bool bilinear(const cv::Mat& m, double u, double v, float& out) {
  const double x = u - 0.5, y = v - 0.5;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= m.cols || y0 + 1 >= m.rows) return false;
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const float* r0 = m.ptr<float>(y0);
  const float* r1 = m.ptr<float>(y0 + 1);
  out = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
  return true;
}

// The nearest strong gradient maximum along n within +-R of uv; the signed
// offset along n (sub-pixel), or false when none.
bool search_edge(const Gradient& g, const Eigen::Vector2d& uv, const Eigen::Vector2d& n, double R, double threshold,
                 double& t_out, bool correct_ramp = false) {
  constexpr int kMax = 64;
  const int half = std::min(kMax / 2 - 1, static_cast<int>(std::ceil(R)));
  const int N = 2 * half + 1;
  std::array<float, kMax> mag{};
  for (int i = 0; i < N; ++i) {
    const double t = i - half;
    const double u = uv.x() + t * n.x(), v = uv.y() + t * n.y();
    float gx = 0, gy = 0;
    if (!bilinear(g.gx, u, v, gx) || !bilinear(g.gy, u, v, gy)) {
      mag[i] = 0.0f;
      continue;
    }
    mag[i] = std::abs(static_cast<float>(n.x()) * gx + static_cast<float>(n.y()) * gy);
  }
  float best_mag = 0.0f;
  for (int i = 1; i + 1 < N; ++i)
    if (mag[i] >= threshold && mag[i] >= mag[i - 1] && mag[i] > mag[i + 1]) best_mag = std::max(best_mag, mag[i]);
  if (best_mag <= 0.0f) return false;
  int best = -1;
  for (int i = 1; i + 1 < N; ++i) {
    if (!(mag[i] >= 0.5f * best_mag && mag[i] >= mag[i - 1] && mag[i] > mag[i + 1])) continue;
    if (best < 0 || std::abs(i - half) < std::abs(best - half)) best = i;
  }
  // Gaussian (log-parabola) interpolation: exact for a Gaussian-blurred step.
  const double a = std::log(std::max(1e-3f, mag[best - 1])), b = std::log(std::max(1e-3f, mag[best])),
               c = std::log(std::max(1e-3f, mag[best + 1]));
  const double den = a - 2.0 * b + c;
  double off = den < -1e-9 ? 0.5 * (a - c) / den : 0.0;
  off = std::clamp(off, -0.5, 0.5);
  t_out = best - half + off;
  if (correct_ramp) {
    // Shading ramps beside an edge (a cylinder darkening towards its
    // silhouette) shift the gradient peak by ~sigma^2 x slope / step: up to
    // 0.3 px here. The signed gradient G(t) = A phi(t - t0) + b- Phi(t0 - t)
    // + b+ Phi(t - t0) for a blurred step between two linear ramps; b-, b+
    // are read 3 sigma either side, their blurred sum subtracted, and the
    // peak of the remainder re-located (twice).
    const double sigma = den < -1e-9 ? std::clamp(std::sqrt(-1.0 / den), 0.6, 2.5) : 1.0;
    auto G = [&](double t, double& out) {
      float gx = 0, gy = 0;
      if (!bilinear(g.gx, uv.x() + t * n.x(), uv.y() + t * n.y(), gx) ||
          !bilinear(g.gy, uv.x() + t * n.x(), uv.y() + t * n.y(), gy))
        return false;
      out = n.x() * gx + n.y() * gy;
      return true;
    };
    double t0 = t_out;
    for (int pass = 0; pass < 2; ++pass) {
      double bm1, bm2, bp1, bp2, g0, gm, gp;
      const double d = 3.0 * sigma;
      if (!G(t0 - d, bm1) || !G(t0 - d - 0.5, bm2) || !G(t0 + d, bp1) || !G(t0 + d + 0.5, bp2) || !G(t0, g0) ||
          !G(t0 - 1.0, gm) || !G(t0 + 1.0, gp))
        break;
      const double bm = 0.5 * (bm1 + bm2), bp = 0.5 * (bp1 + bp2);
      auto ramp = [&](double dt) { return bm + (bp - bm) * 0.5 * std::erfc(-dt / (sigma * std::sqrt(2.0))); };
      const double sgn = g0 >= 0.0 ? 1.0 : -1.0;
      const double c0 = sgn * (g0 - ramp(t0 - t_out)), cm = sgn * (gm - ramp(t0 - 1.0 - t_out)),
                   cp = sgn * (gp - ramp(t0 + 1.0 - t_out));
      if (c0 <= 0.0 || cm <= 0.0 || cp <= 0.0) break;
      const double la = std::log(cm), lb = std::log(c0), lc = std::log(cp);
      const double dd = la - 2.0 * lb + lc;
      if (!(dd < -1e-9)) break;
      t0 += std::clamp(0.5 * (la - lc) / dd, -0.5, 0.5);
    }
    t_out = t0;
  }
  return std::abs(t_out) <= R;
}

Pose make_pose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

}  // namespace

struct ModelAligner::Impl {
  const RobotModel& arm;
  const ObjectModel* object;
  Viewport vp;
  render::Renderer renderer;
  render::Renderer shaded_renderer;  // the model's appearance (lit, anti-aliased): the edge bias prediction
  KinematicsWorkspace ws;
  std::vector<Primitive> prims;
  render::DrawList list;
  cv::Mat layer, shaded_layer;
  int next_cluster = 0;
  // Image buffers kept from one call to the next (align is called per
  // frame by the health check and many times by the study): a fresh
  // full-frame buffer is fresh pages, and faulting them in was over half of
  // an alignment's time (BM_AlignCamera 95 -> 45 ms wall with glibc told not
  // to return freed memory). The recycled frames' Mats are rewritten in
  // place (OpenCV reuses a destination of the same size and type).
  cv::Mat blurred;                                      // gradient(): the blurred level
  cv::Mat model_mask, bg_w, bg_v, predicted_grey;       // predict_bias()
  Gradient predicted;                                   // predict_bias()

  Impl(render::GlContext& ctx, const RobotModel& a, const ObjectModel* o, const Viewport& v)
      : arm(a), object(o), vp(v), renderer(ctx, v, 1), shaded_renderer(ctx, v, 4), ws(a) {
    spare_frames.reserve(kSpareFrames);  // recycle() never reallocates (it runs in a destructor)
    const auto& links = arm.links();
    for (int k = 0; k < static_cast<int>(links.size()); ++k)
      for (const auto& shape : links[k].visuals) add(k, render::make_shape(shape), shape.rgba);
    if (object) {
      add(-1, render::make_box(object->size_m, object->oru_T_box, object->rgba), object->rgba);
      for (const auto& shape : object->visuals) add(-1, render::make_shape(shape), shape.rgba);
      for (const auto& shape : object->surroundings) add(kSurroundings, render::make_shape(shape), shape.rgba);
    }
  }

  void add(int link, const render::Mesh& mesh, const Eigen::Vector4d& rgba) {
    Primitive p;
    p.link = link;
    p.body = renderer.add_body(mesh);
    p.shaded_body = shaded_renderer.add_body(mesh);
    p.label = static_cast<int>(prims.size()) + 1;
    p.rgba = rgba;
    p.edges = mesh_edges(mesh);
    p.first_edge = prims.empty() ? 0 : prims.back().first_edge + static_cast<int>(prims.back().edges.size());
    prims.push_back(std::move(p));
  }

  // Per frame: the link poses at its q, the grey image.
  struct FrameData {
    Eigen::VectorXd q;
    std::vector<Pose> link_poses;
    cv::Mat grey8, grey;
    std::map<int, Gradient> gradients;  // by level index (-1: score level)
  };
  // Frames of finished calls, their buffers reused by prepare(); at most
  // kSpareFrames (about 11 MB each at 646x486) are kept.
  static constexpr std::size_t kSpareFrames = 4;
  std::vector<FrameData> spare_frames;
  void recycle(FrameData&& f) {
    if (spare_frames.size() < kSpareFrames) spare_frames.push_back(std::move(f));
  }
  // Returns a call's frames to spare_frames however the call ends.
  struct FramesLease {
    Impl& impl;
    std::vector<std::vector<FrameData>>& frames;
    ~FramesLease() {
      for (auto& per_view : frames)
        for (auto& f : per_view) impl.recycle(std::move(f));
    }
  };

  class Alignment;  // one call of align()

  static Eigen::Vector4d label_rgba(int label) {
    return {(label & 0xFF) / 255.0, ((label >> 8) & 0xFF) / 255.0, 0.0, 1.0};
  }
  static int label_at(const cv::Mat& layer_bgra, const Eigen::Vector2d& uv) {
    const int x = static_cast<int>(std::floor(uv.x())), y = static_cast<int>(std::floor(uv.y()));
    if (x < 0 || y < 0 || x >= layer_bgra.cols || y >= layer_bgra.rows) return 0;
    const std::uint8_t* p = layer_bgra.ptr<std::uint8_t>(y) + 4 * x;
    return p[2] + 256 * p[1];
  }

  const Gradient& gradient(FrameData& f, int level_index, double blur) {
    Gradient& g = f.gradients[level_index];
    if (g.valid) return g;
    // Coarse levels blur the 8-bit image (several times faster); the fine
    // levels blur in float so the sub-pixel edge is not quantized.
    if (blur >= 2.0) cv::GaussianBlur(f.grey8, blurred, cv::Size(0, 0), blur);
    else if (blur > 0.0) cv::GaussianBlur(f.grey, blurred, cv::Size(0, 0), blur);
    const cv::Mat& src = blur > 0.0 ? blurred : f.grey;
    cv::Sobel(src, g.gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
    cv::Sobel(src, g.gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
    g.valid = true;
    return g;
  }

  FrameData prepare(const AlignFrame& frame) {
    if (frame.image_bgr.empty() || frame.image_bgr.cols != vp.width_px || frame.image_bgr.rows != vp.height_px)
      throw std::invalid_argument("frame is " + std::to_string(frame.image_bgr.cols) + "x" +
                                  std::to_string(frame.image_bgr.rows) + " but the camera viewport is " +
                                  std::to_string(vp.width_px) + "x" + std::to_string(vp.height_px));
    if (frame.q.size() != arm.dof())
      throw std::invalid_argument("joint vector has " + std::to_string(frame.q.size()) + " values but the arm has " +
                                  std::to_string(arm.dof()) + " joints");
    if (frame.image_bgr.type() != CV_8UC3 && frame.image_bgr.type() != CV_8UC1)
      throw std::invalid_argument("frame must be an 8-bit BGR or grey image");
    FrameData f;
    if (!spare_frames.empty()) {
      f = std::move(spare_frames.back());
      spare_frames.pop_back();
      for (auto& [level, g] : f.gradients) g.valid = false;
    }
    // A grey input is copied, not shared: the buffer is rewritten when this
    // frame is recycled, and the caller's image is not ours to rewrite.
    if (frame.image_bgr.type() == CV_8UC3) cv::cvtColor(frame.image_bgr, f.grey8, cv::COLOR_BGR2GRAY);
    else frame.image_bgr.copyTo(f.grey8);
    f.grey8.convertTo(f.grey, CV_32F);
    f.q = frame.q;
    f.link_poses.resize(arm.links().size());
    for (int k = 0; k < static_cast<int>(arm.links().size()); ++k)
      f.link_poses[k] = forward_kinematics(arm, ws, frame.q, k);
    return f;
  }

  // The edge search's own bias on this model's appearance: the model rendered
  // as the camera would see it (lit, anti-aliased, the camera's optical blur,
  // on a flat background of the image's median where the model is not), the
  // same search run on it at every sample of out[begin..] whose true edge is
  // at 0. Shading ramps beside a silhouette (a cylinder darkening towards its
  // rim) and the background's contrast move the gradient peak by 0.1-0.3 px;
  // the residual is then the image's offset minus this predicted one. Uses
  // `layer` (the label image of the same camera and frame, just rendered).
  void predict_bias(const Camera& cam, const FrameData& f, const std::optional<Pose>& base_T_object, double blur,
                    double search_px, double threshold, const AlignOptions& o, std::vector<Sample>& out,
                    std::size_t begin) {
    if (begin >= out.size()) return;
    list.clear();
    for (const auto& p : prims) {
      if ((p.link < 0 && !base_T_object) || p.link == kSurroundings) continue;
      render::BodyInstance b;
      b.body = p.shaded_body;
      b.base_T_body = p.link >= 0 ? f.link_poses[p.link] : *base_T_object;
      list.bodies.push_back(b);
    }
    render::RenderSettings st;
    st.mode = render::RenderMode::Solid;
    st.lighting = true;
    st.near_m = kNear_m;
    st.clear_rgba = Eigen::Vector4d::Zero();
    shaded_renderer.render(cam, list, st, shaded_layer);
    // The background: the image's median grey where no model part is (the
    // surroundings are background here: the image shows them as they are).
    auto is_model = [&](const std::uint8_t* px) {
      const int label = px[2] + 256 * px[1];
      return label > 0 && prims[label - 1].link != kSurroundings;
    };
    std::array<int, 256> hist{};
    int nbg = 0;
    for (int y = 0; y < layer.rows; y += 2) {
      const std::uint8_t* lp = layer.ptr<std::uint8_t>(y);
      const std::uint8_t* gp = f.grey8.ptr<std::uint8_t>(y);
      for (int x = 0; x < layer.cols; x += 2)
        if (!is_model(lp + 4 * x)) {
          ++hist[gp[x]];
          ++nbg;
        }
    }
    float bg = 0.0f;
    for (int k = 0, acc = 0; k < 256; ++k) {
      acc += hist[k];
      if (2 * acc >= nbg) {
        bg = static_cast<float>(k);
        break;
      }
    }
    // The local background: the image where no model part is (3 px clear of
    // the model, so its blurred edges stay out), spread over the model by a
    // normalized Gaussian (floor behind one silhouette, sky behind another).
    model_mask.create(layer.rows, layer.cols, CV_8U);
    for (int y = 0; y < layer.rows; ++y) {
      const std::uint8_t* lp = layer.ptr<std::uint8_t>(y);
      std::uint8_t* m = model_mask.ptr<std::uint8_t>(y);
      for (int x = 0; x < layer.cols; ++x) m[x] = is_model(lp + 4 * x) ? 255 : 0;
    }
    cv::dilate(model_mask, model_mask, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(7, 7)));
    cv::bitwise_not(model_mask, model_mask);
    model_mask.convertTo(bg_w, CV_32F, 1.0 / 255.0);
    cv::multiply(f.grey, bg_w, bg_v);
    // At full resolution: spreading at a quarter of it (1.5 px there) saved
    // a few ms but moved the study's link estimates (eval alignment seeds 1
    // and 3: four-view gain 3.9x / 3.0x -> 2.2x / 0.8x).
    cv::GaussianBlur(bg_w, bg_w, cv::Size(0, 0), 6.0);
    cv::GaussianBlur(bg_v, bg_v, cv::Size(0, 0), 6.0);
    cv::Mat& grey = predicted_grey;
    grey.create(shaded_layer.rows, shaded_layer.cols, CV_32F);
    for (int y = 0; y < grey.rows; ++y) {
      const std::uint8_t* p = shaded_layer.ptr<std::uint8_t>(y);
      const float* w = bg_w.ptr<float>(y);
      const float* v = bg_v.ptr<float>(y);
      float* g = grey.ptr<float>(y);
      for (int x = 0; x < grey.cols; ++x, p += 4) {
        const float a = p[3] / 255.0f;
        // BGR -> grey as cv::COLOR_BGR2GRAY; the layer is premultiplied by coverage.
        const float model = 0.114f * p[0] + 0.587f * p[1] + 0.299f * p[2];
        const float b = w[x] > 0.02f ? v[x] / w[x] : bg;
        g[x] = model + (1.0f - a) * b;
      }
    }
    // The camera's blur and the level's in one pass (Gaussians compose).
    const double total_blur = std::sqrt(std::max(0.0, o.optical_blur_px) * std::max(0.0, o.optical_blur_px) +
                                        std::max(0.0, blur) * std::max(0.0, blur));
    if (total_blur > 0.0) cv::GaussianBlur(grey, grey, cv::Size(0, 0), total_blur);
    Gradient& g = predicted;
    cv::Sobel(grey, g.gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
    cv::Sobel(grey, g.gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
    for (std::size_t i = begin; i < out.size(); ++i) {
      Sample& s = out[i];
      const Eigen::Vector3d p = s.on_object ? Eigen::Vector3d(*base_T_object * s.p_local) : s.p_local;
      const Eigen::Vector3d dir = s.on_object ? Eigen::Vector3d(base_T_object->linear() * s.dir_local) : s.dir_local;
      const Projection pr = project_with_jacobians(cam, p);
      Eigen::Vector2d d2 = pr.d_point * dir;
      if (d2.norm() < 1e-9) continue;
      d2.normalize();
      const Eigen::Vector2d n(-d2.y(), d2.x());
      double t = 0.0;
      // A shading bias is 0.1-0.3 px; a larger offset is another model edge
      // close by (the tool's small parts), not this edge's bias.
      if (search_edge(g, pr.uv_px, n, std::min(search_px, 1.5), threshold, t, blur <= 1.0) && std::abs(t) <= 0.5)
        s.bias_px = t;
    }
  }

  // The visible model edge samples of one frame through `cam`.
  void sample(const Camera& cam, const FrameData& f, const std::optional<Pose>& base_T_object, int view, int frame_index,
              bool want_arm, bool want_object, const AlignOptions& o, std::vector<Sample>& out) {
    list.clear();
    for (const auto& p : prims) {
      if (p.link < 0 && !base_T_object) continue;
      render::BodyInstance b;
      b.body = p.body;
      b.base_T_body = p.link >= 0 ? f.link_poses[p.link] : *base_T_object;
      b.solid_rgba = label_rgba(p.label);
      list.bodies.push_back(b);
    }
    render::RenderSettings st;
    st.mode = render::RenderMode::Solid;
    st.lighting = false;
    st.near_m = kNear_m;
    renderer.render(cam, list, st, layer);

    const Eigen::Vector3d C = cam.base_T_camera.translation();
    struct Candidate {
      const Primitive* prim;
      Eigen::Vector3d a, b;
      Eigen::Vector2d ua, ub;
      bool silhouette;
      int edge;  // over all primitives' edges
    };
    std::vector<Candidate> cands;
    double total_len = 0.0;
    for (const auto& p : prims) {
      if (p.link == kSurroundings) continue;
      const bool is_object = p.link < 0;
      if (is_object && (!base_T_object || !want_object)) continue;
      if (!is_object && !want_arm) continue;
      const Pose& T = is_object ? *base_T_object : f.link_poses[p.link];
      for (const auto& e : p.edges) {
        const Eigen::Vector3d a = T * e.a, b = T * e.b, m = 0.5 * (a + b);
        const bool f1 = (T.linear() * e.n1).dot(C - m) > 0.0;
        const bool f2 = e.two_faces ? (T.linear() * e.n2).dot(C - m) > 0.0 : false;
        const bool silhouette = f1 != f2;
        if (!silhouette && !(e.crease && f1 && f2)) continue;
        if (cam.to_camera(a).z() <= kNear_m || cam.to_camera(b).z() <= kNear_m) continue;
        const Eigen::Vector2d ua = cam.project(a), ub = cam.project(b);
        const double len = (ub - ua).norm();
        if (len < 1.0) continue;
        cands.push_back({&p, a, b, ua, ub, silhouette, p.first_edge + static_cast<int>(&e - p.edges.data())});
        total_len += len;
      }
    }
    const double spacing = std::max(o.sample_spacing_px, total_len / std::max(1, o.max_samples_per_frame));
    const double margin = 3.0;
    const int total_edges = prims.back().first_edge + static_cast<int>(prims.back().edges.size());
    for (const auto& c : cands) {
      // Arm edges: a new cluster per frame (positive); object edges: one per
      // view and edge (negative, the same in every frame of the view).
      const int cluster = c.prim->link < 0 ? -(1 + view * total_edges + c.edge) : ++next_cluster;
      const Eigen::Vector2d d = (c.ub - c.ua).normalized();
      const Eigen::Vector2d n(-d.y(), d.x());
      const int ns = std::clamp(static_cast<int>((c.ub - c.ua).norm() / spacing), 1, 400);
      for (int k = 0; k < ns; ++k) {
        const double t = (k + 0.5) / ns;
        const Eigen::Vector3d p = c.a + t * (c.b - c.a);
        const Eigen::Vector2d uv = cam.project(p);
        if (uv.x() < margin || uv.y() < margin || uv.x() > vp.width_px - margin || uv.y() > vp.height_px - margin)
          continue;
        const int lp = label_at(layer, uv + 1.5 * n), lm = label_at(layer, uv - 1.5 * n);
        const int id = c.prim->label;
        bool visible;
        if (c.silhouette) {
          const int other = lp == id ? lm : lm == id ? lp : -1;
          visible = (lp == id) != (lm == id) && other >= 0;
          if (visible && other > 0 && (prims[other - 1].rgba - c.prim->rgba).norm() < 0.02) visible = false;
        } else {
          visible = lp == id && lm == id;
        }
        if (!visible) continue;
        Sample s;
        s.view = view;
        s.frame = frame_index;
        s.on_object = c.prim->link < 0;
        s.silhouette = c.silhouette;
        if (c.silhouette) s.outward = lp == id ? -1.0 : 1.0;
        s.cluster = cluster;
        s.length_px = (c.ub - c.ua).norm() / ns;
        const Eigen::Vector3d dir = (c.b - c.a).normalized();
        if (s.on_object) {
          s.p_local = base_T_object->inverse() * p;
          s.dir_local = base_T_object->linear().transpose() * dir;
        } else {
          s.p_local = p;
          s.dir_local = dir;
          s.link = c.prim->link;
          const Pose& T = f.link_poses[s.link];
          s.p_link = T.inverse() * p;
          s.dir_link = T.linear().transpose() * dir;
        }
        out.push_back(s);
      }
    }
  }
};

ModelAligner::ModelAligner(render::GlContext& context, const RobotModel& arm, const ObjectModel* object,
                           const Viewport& viewport)
    : impl_(std::make_unique<Impl>(context, arm, object, viewport)) {}

ModelAligner::~ModelAligner() = default;

namespace {

// One residual evaluation: the search result for each sample.
struct Eval {
  std::vector<double> r;       // signed distance along n, px
  std::vector<char> matched;
  std::vector<Eigen::Vector2d> n;  // the search direction (unit, image)
  std::vector<Eigen::Matrix<double, 1, 13>> J;  // camera 7, object 6
  std::vector<Eigen::Matrix<double, 1, kMaxLinks>> Jl;  // refined link lengths
};

// The prior weight of the link lengths in units of H (= sum w J^T J over
// samples): s^2 n / G / sd^2 is the prior information 1/sd^2 scaled by the
// data's per-sample variance s^2 and the n / G samples per model edge.
double link_prior_weight_impl(const std::vector<Sample>& samples, const Eval& e, double c, double s2, double prior_m) {
  std::vector<int> clusters;
  int n = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (!e.matched[i] || std::abs(e.r[i] / c) >= 1.0) continue;
    clusters.push_back(samples[i].cluster);
    ++n;
  }
  std::sort(clusters.begin(), clusters.end());
  const double G = static_cast<double>(std::unique(clusters.begin(), clusters.end()) - clusters.begin());
  return s2 * (n / std::max(1.0, G)) / (prior_m * prior_m);
}

}  // namespace

// One call of align(): the parameters it refines (the cameras' R, c, f; the
// object's R, t; the arm's link lengths), the frames' data, and its steps:
// the samples, their residuals, the robust Gauss-Newton of each level, the
// covariance, the verdict. ModelAligner::align runs them in order.
class ModelAligner::Impl::Alignment {
 public:
  Alignment(Impl& impl, const std::vector<AlignView>& views, const std::optional<Pose>& start, const AlignOptions& o)
      : I_(impl),
        views_(views),
        start_(start),
        o_(o),
        refine_camera_(o.refine != Refine::Object),
        refine_object_(o.refine != Refine::Camera),
        V_(static_cast<int>(views.size())),
        data_(views.size()),
        lease_{impl, data_} {
    if (refine_object_ && !start_) throw std::invalid_argument("refining the object needs its start pose (--object-pose)");
    if (refine_object_ && !I_.object) throw std::invalid_argument("refining the object needs the object model");
    for (int v = 0; v < V_; ++v) {
      if (views_[v].frames.empty()) throw std::invalid_argument("camera '" + views_[v].camera.name + "' has no frames");
      if (!(views_[v].camera.viewport == I_.vp))
        throw std::invalid_argument("camera '" + views_[v].camera.name + "' has another viewport than the aligner's");
      const auto& cc = views_[v].camera_covariance;
      if (!cc.allFinite() || (cc.diagonal().array() < 0.0).any() || !cc.isApprox(cc.transpose(), 1e-9))
        throw std::invalid_argument("camera '" + views_[v].camera.name +
                                    "': its covariance is not a finite symmetric matrix with a non-negative diagonal");
      for (const auto& fr : views_[v].frames) data_[v].push_back(I_.prepare(fr));
    }
    for (int v = 0; v < V_; ++v) {
      cam_R_.push_back(views_[v].camera.base_T_camera.linear());
      cam_c_.push_back(views_[v].camera.base_T_camera.translation());
      cam_f_.push_back(views_[v].camera.f_px);
    }
    obj_R_ = start_ ? Eigen::Matrix3d(start_->linear()) : Eigen::Matrix3d::Identity();
    obj_t_ = start_ ? Eigen::Vector3d(start_->translation()) : Eigen::Vector3d::Zero();
    init_links();
    P_ = (refine_camera_ ? 7 * V_ : 0) + (refine_object_ ? 6 : 0) + NL_;
    obj_col_ = refine_camera_ ? 7 * V_ : 0;
    link_col_ = P_ - NL_;
    for (int v = 0; v < V_; ++v) res_.cameras.push_back(views_[v].camera);
    res_.base_T_object = start_;
    res_.camera_change.assign(V_, Eigen::Matrix<double, 7, 1>::Zero());
  }

  AlignResult run(std::chrono::steady_clock::time_point t0) {
    t0_ = t0;
    // Start: visibility (the samples serve the first level too) and score.
    std::vector<int> per_view;
    collect(samples_, &per_view, 0);
    for (int v = 0; v < V_; ++v)
      if (per_view[v] == 0) {
        res_.status = AlignStatus::NotInView;
        res_.reason = std::string("the ") + (refine_camera_ ? "arm" : "object") + " model is not in view of camera '" +
                      views_[v].camera.name + "': none of its edges projects visibly into the image";
        return finish();
      }
    res_.start_score_px = score_of(samples_);
    for (int li = 0; li < static_cast<int>(kLevels.size()); ++li) {
      if (li > 0) collect(samples_, nullptr, li);
      if (static_cast<int>(samples_.size()) < o_.min_visible_samples) {
        res_.status = AlignStatus::Refused;
        res_.reason = "too few model edges in view: " + std::to_string(samples_.size()) + " samples (need " +
                      std::to_string(o_.min_visible_samples) + ")";
        res_.visible_samples = static_cast<int>(samples_.size());
        return finish();
      }
      for (int it = 0; it < o_.iterations_per_level; ++it)
        if (!gauss_newton_step(li)) break;
    }
    // Final residuals at the finest level, then the covariance.
    evaluate(samples_, static_cast<int>(kLevels.size()) - 1, kLevels.back(), e_, true);
    covariance();
    debug_image();
    summarize();
    verdict();
    return finish();
  }

 private:
  // --- the model's state ------------------------------------------------------

  /// The arm model's link-length corrections: given (rendered and sampled
  /// with) and/or refined with the cameras under a prior (a bundle
  /// adjustment over cameras + arm; the link offsets are observable over
  /// several poses).
  void init_links() {
    nseg_ = I_.arm.segment_count();
    if (!o_.arm_link_delta_m.empty() && static_cast<int>(o_.arm_link_delta_m.size()) != nseg_)
      throw std::invalid_argument("arm link corrections: " + std::to_string(o_.arm_link_delta_m.size()) +
                                  " values for " + std::to_string(nseg_) + " chain segments");
    if (!(o_.arm_link_prior_m >= 0.0) || !std::isfinite(o_.arm_link_prior_m))
      throw std::invalid_argument("arm link prior must be a non-negative number");
    link_start_ = o_.arm_link_delta_m.empty() ? std::vector<double>(nseg_, 0.0) : o_.arm_link_delta_m;
    link_delta_ = link_start_;
    if (refine_camera_ && o_.arm_link_prior_m > 0.0) link_segs_ = I_.arm.offset_segments();
    NL_ = static_cast<int>(link_segs_.size());
    if (NL_ > kMaxLinks) throw std::invalid_argument("arm link refinement: more than 16 link offsets");
    dposes_.resize(V_);
    if (!o_.arm_link_delta_m.empty() || NL_ > 0) update_arm();
  }

  /// The link poses of every frame with the current link lengths, and with
  /// each refined length stepped (dposes_[v][k][j][link]).
  void update_arm() {
    const RobotModel m = I_.arm.with_link_lengths_changed(link_delta_);
    KinematicsWorkspace mws(m);
    std::vector<RobotModel> stepped;
    for (int j = 0; j < NL_; ++j) {
      std::vector<double> d = link_delta_;
      d[link_segs_[j]] += kLinkStep_m;
      stepped.push_back(I_.arm.with_link_lengths_changed(d));
    }
    const int nl = static_cast<int>(I_.arm.links().size());
    for (int v = 0; v < V_; ++v) {
      dposes_[v].resize(data_[v].size());
      for (std::size_t k = 0; k < data_[v].size(); ++k) {
        auto& f = data_[v][k];
        for (int l = 0; l < nl; ++l) f.link_poses[l] = forward_kinematics(m, mws, f.q, l);
        dposes_[v][k].assign(NL_, std::vector<Pose>(nl));
        for (int j = 0; j < NL_; ++j) {
          KinematicsWorkspace sws(stepped[j]);
          for (int l = 0; l < nl; ++l) dposes_[v][k][j][l] = forward_kinematics(stepped[j], sws, f.q, l);
        }
      }
    }
  }

  Camera camera_of(int v) const {
    Camera c = views_[v].camera;
    c.base_T_camera = make_pose(cam_R_[v], cam_c_[v]);
    c.f_px = cam_f_[v];
    return c;
  }

  std::optional<Pose> object_pose() const {
    if (!start_) return std::nullopt;
    return make_pose(obj_R_, obj_t_);
  }

  // --- samples and residuals ---------------------------------------------------

  /// Samples at level `level` (-1: the score's); at the finest level with
  /// their predicted edge bias (Impl::predict_bias).
  void collect(std::vector<Sample>& samples, std::vector<int>* per_view, int level) {
    samples.clear();
    if (per_view) per_view->assign(V_, 0);
    const auto obj = object_pose();
    for (int v = 0; v < V_; ++v) {
      const Camera cam = camera_of(v);
      for (int k = 0; k < static_cast<int>(data_[v].size()); ++k) {
        const std::size_t before = samples.size();
        I_.sample(cam, data_[v][k], obj, v, k, refine_camera_, refine_object_, o_, samples);
        // The bias is predicted at the finest level only: it is 0.1-0.3 px,
        // below what the coarser levels resolve, and each prediction is a
        // 4x-MSAA render (about half of an alignment's time when done at
        // the two fine levels).
        if (level + 1 == static_cast<int>(kLevels.size()) && o_.predict_edge_bias) {
          const Level& L = kLevels[level];
          I_.predict_bias(cam, data_[v][k], obj, L.blur_px, L.search_px,
                          o_.gradient_threshold * 0.7 / std::max(0.7, L.blur_px), o_, samples, before);
        }
        if (per_view) (*per_view)[v] += static_cast<int>(samples.size() - before);
      }
    }
  }

  /// Residuals (and Jacobian rows) of the samples at the current parameters.
  void evaluate(const std::vector<Sample>& samples, int level_index, const Level& L, Eval& e, bool jac) {
    e.r.assign(samples.size(), 0.0);
    e.matched.assign(samples.size(), 0);
    e.n.assign(samples.size(), Eigen::Vector2d::Zero());
    if (jac) e.J.assign(samples.size(), Eigen::Matrix<double, 1, 13>::Zero());
    if (jac && NL_ > 0) e.Jl.assign(samples.size(), Eigen::Matrix<double, 1, kMaxLinks>::Zero());
    const double thr = o_.gradient_threshold * 0.7 / std::max(0.7, L.blur_px);
    std::vector<Camera> cams;
    for (int v = 0; v < V_; ++v) cams.push_back(camera_of(v));
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const Sample& s = samples[i];
      const Camera& cam = cams[s.view];
      Eigen::Vector3d p, dir;
      if (s.on_object) {
        p = obj_R_ * s.p_local + obj_t_;
        dir = obj_R_ * s.dir_local;
      } else {
        const Pose& T = data_[s.view][s.frame].link_poses[s.link];
        p = T * s.p_link;
        dir = T.linear() * s.dir_link;
      }
      if (cam.to_camera(p).z() <= kNear_m) continue;
      const Projection pr = project_with_jacobians(cam, p);
      Eigen::Vector2d d2 = pr.d_point * dir;
      if (d2.norm() < 1e-9) continue;
      d2.normalize();
      const Eigen::Vector2d n(-d2.y(), d2.x());
      double t = 0.0;
      const Gradient& g = I_.gradient(data_[s.view][s.frame], level_index, L.blur_px);
      if (!search_edge(g, pr.uv_px, n, L.search_px, thr, t, L.blur_px <= 1.0)) continue;
      e.r[i] = t - s.bias_px;
      e.matched[i] = 1;
      e.n[i] = n;
      if (jac) {
        // The camera's columns also when it is held (its covariance is
        // propagated into the object's below).
        e.J[i].leftCols<7>() = n.transpose() * pr.d_camera;
        if (refine_object_ && s.on_object)
          e.J[i].rightCols<6>() = n.transpose() * object_pose_jacobian(pr, obj_R_, s.p_local);
        if (NL_ > 0 && !s.on_object) {
          const Eigen::RowVector3d nd = n.transpose() * pr.d_point;
          for (int j = 0; j < NL_; ++j)
            e.Jl[i][j] = nd.dot(dposes_[s.view][s.frame][j][s.link] * s.p_link - p) / kLinkStep_m;
        }
      }
    }
  }

  /// The truncated edge distance (misses count as the cap) of `samples`.
  double score_of(const std::vector<Sample>& samples) {
    Eval e;
    evaluate(samples, -1, kScoreLevel, e, false);
    double s2 = 0.0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const double d = e.matched[i] ? std::min(std::abs(e.r[i]), o_.score_cap_px) : o_.score_cap_px;
      s2 += d * d;
    }
    return samples.empty() ? o_.score_cap_px : std::sqrt(s2 / samples.size());
  }

  // --- the robust least squares ------------------------------------------------

  /// A sample's Tukey weight at scale c (0: unmatched or beyond c): the same
  /// in the Gauss-Newton steps, the step limit and the covariance.
  static double tukey_weight(const Eval& ev, std::size_t i, double c) {
    if (!ev.matched[i]) return 0.0;
    const double u = ev.r[i] / c;
    return std::abs(u) >= 1.0 ? 0.0 : (1 - u * u) * (1 - u * u);
  }

  /// A sample's row of the Jacobian over all refined parameters.
  void jacobian_row(const Eval& ev, std::size_t i, Eigen::VectorXd& row) const {
    row.setZero();
    if (refine_camera_) row.segment<7>(7 * samples_[i].view) = ev.J[i].leftCols<7>().transpose();
    if (refine_object_) row.segment<6>(obj_col_) = ev.J[i].rightCols<6>().transpose();
    if (NL_ > 0) row.segment(link_col_, NL_) = ev.Jl[i].head(NL_).transpose();
  }

  /// Tukey's scale from the matched residuals' MAD, within [0.5, search_px];
  /// nullopt with fewer than 10 matched.
  std::optional<double> tukey_scale(double search_px) const {
    std::vector<double> absr;
    for (std::size_t i = 0; i < samples_.size(); ++i)
      if (e_.matched[i]) absr.push_back(std::abs(e_.r[i]));
    if (absr.size() < 10) return std::nullopt;
    std::nth_element(absr.begin(), absr.begin() + absr.size() / 2, absr.end());
    const double sigma = std::max(1.4826 * absr[absr.size() / 2], 0.1);
    return std::clamp(4.685 * sigma, 0.5, search_px);
  }

  /// sum w r^2 / (sum w - P) over the weighted samples.
  double weighted_variance(double c) const {
    double wr2 = 0.0, wsum = 0.0;
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const double w = tukey_weight(e_, i, c);
      if (w <= 0.0) continue;
      wr2 += w * e_.r[i] * e_.r[i];
      wsum += w;
    }
    return wr2 / std::max(1.0, wsum - P_);
  }

  /// The prior on the link lengths, in the data's units: the data's
  /// information is H / (s^2 n / G) (G model edges: independent errors per
  /// edge, not per sample), the prior's 1 / sd^2.
  double link_prior_weight(double c, double s2) const {
    return link_prior_weight_impl(samples_, e_, c, s2, o_.arm_link_prior_m);
  }

  /// One robust Gauss-Newton step at level li; false when the level is done
  /// (converged, too few matches, or no finite step).
  bool gauss_newton_step(int li) {
    const Level& L = kLevels[li];
    evaluate(samples_, li, L, e_, true);
    const std::optional<double> scale = tukey_scale(L.search_px);
    if (!scale) return false;
    const double c = *scale;
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(P_, P_);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(P_);
    Eigen::VectorXd row(P_);
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const double w = tukey_weight(e_, i, c);
      if (w <= 0.0) continue;
      jacobian_row(e_, i, row);
      H.selfadjointView<Eigen::Lower>().rankUpdate(row, w);
      g += w * e_.r[i] * row;
    }
    H = H.selfadjointView<Eigen::Lower>();
    s2_last_ = weighted_variance(c);
    if (NL_ > 0) {
      const double lambda = link_prior_weight(c, s2_last_);
      for (int j = 0; j < NL_; ++j) {
        H(link_col_ + j, link_col_ + j) += lambda;
        g[link_col_ + j] -= lambda * (link_delta_[link_segs_[j]] - link_start_[link_segs_[j]]);
      }
    }
    H_last_ = H;
    Eigen::MatrixXd A = H;
    for (int k = 0; k < P_; ++k) A(k, k) += 1e-3 * H(k, k) + 1e-12;
    Eigen::VectorXd delta = A.ldlt().solve(g);
    if (!delta.allFinite()) return false;
    // Limit the step to the search range (predicted pixel motion).
    double max_move = 0.0;
    for (std::size_t i = 0; i < samples_.size(); i += 7) {
      jacobian_row(e_, i, row);
      max_move = std::max(max_move, std::abs(row.dot(delta)));
    }
    if (max_move > L.search_px) delta *= L.search_px / max_move;
    apply(delta);
    ++res_.iterations;
    return max_move >= (li + 1 == static_cast<int>(kLevels.size()) ? 0.005 : 0.05);
  }

  void apply(const Eigen::VectorXd& delta) {
    if (refine_camera_)
      for (int v = 0; v < V_; ++v) {
        const Eigen::Matrix<double, 7, 1> d = delta.segment<7>(7 * v);
        cam_R_[v] = cam_R_[v] * exp_so3(d.head<3>());
        cam_c_[v] += d.segment<3>(3);
        cam_f_[v] += d[6];
        res_.camera_change[v] += d;
      }
    if (refine_object_) {
      const Eigen::Matrix<double, 6, 1> d = delta.segment<6>(obj_col_);
      obj_R_ = obj_R_ * exp_so3(d.head<3>());
      obj_t_ += d.tail<3>();
      res_.object_change += d;
    }
    if (NL_ > 0) {
      for (int j = 0; j < NL_; ++j) link_delta_[link_segs_[j]] += delta[link_col_ + j];
      update_arm();
    }
  }

  // --- the covariance ----------------------------------------------------------

  /// The covariance at the final residuals: a sandwich estimator H^-1 B H^-1
  /// with B summed over model edges (clusters), since the samples of one edge
  /// share their localisation error (appearance, blur, the edge's own noise);
  /// s^2 H^-1 alone was 3-5x optimistic. Then the errors no residual shows.
  void covariance() {
    const std::optional<double> scale = tukey_scale(kLevels.back().search_px);
    if (!scale || H_last_.size() == 0) return;
    const double c = *scale;
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(P_, P_);
    std::map<int, Eigen::VectorXd> score;
    Eigen::VectorXd row(P_);
    int n = 0;
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const double w = tukey_weight(e_, i, c);
      if (w <= 0.0) continue;
      jacobian_row(e_, i, row);
      H.selfadjointView<Eigen::Lower>().rankUpdate(row, w);
      auto it = score.try_emplace(samples_[i].cluster, Eigen::VectorXd::Zero(P_)).first;
      it->second += w * e_.r[i] * row;
      ++n;
    }
    H = H.selfadjointView<Eigen::Lower>();
    double prior_lambda = 0.0;
    if (NL_ > 0) {
      prior_lambda = link_prior_weight(c, weighted_variance(c));
      for (int j = 0; j < NL_; ++j) H(link_col_ + j, link_col_ + j) += prior_lambda;
    }
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(P_, P_);
    // The prior's score: lambda x (a link error of sd prior): a link no
    // edge sees keeps its prior sd.
    for (int j = 0; j < NL_; ++j)
      B(link_col_ + j, link_col_ + j) += prior_lambda * prior_lambda * o_.arm_link_prior_m * o_.arm_link_prior_m;
    for (const auto& [k, g] : score) B.selfadjointView<Eigen::Lower>().rankUpdate(g);
    B = B.selfadjointView<Eigen::Lower>();
    const double G = static_cast<double>(score.size());
    const double correction = G > 1 ? G / (G - 1) * (n - 1.0) / std::max(1.0, n - 1.0 - P_) : 1.0;
    const Eigen::MatrixXd Hinv = H.ldlt().solve(Eigen::MatrixXd::Identity(P_, P_));
    sandwich_ = correction * Hinv * B * Hinv;
    sandwich_ = 0.5 * (sandwich_ + sandwich_.transpose());
    // The second estimator: s^2 H^-1 with the samples counted as the
    // number of model edges (the effective number of independent samples,
    // n / G). The reported covariance is the larger of the two (by trace):
    // the sandwich misses a bias shared by most edges.
    const double s2 = weighted_variance(c);
    const Eigen::MatrixXd effective = s2 * (n / std::max(1.0, G - P_ > 1 ? G : 1.0)) * Hinv;
    if (effective.trace() > sandwich_.trace()) sandwich_ = effective;
    add_shared_offsets(c, Hinv);
    add_edge_offsets(c, Hinv);
    if (!refine_camera_) add_held_cameras(c, Hinv);
  }

  /// An offset shared by every silhouette (the image's edges all a little
  /// out of or into the model: appearance the prediction does not carry,
  /// the lighting, the blur) looks like a change of scale (f, depth) and
  /// leaves no trace in the residuals; its sd o.edge_offset_sd_px enters as
  /// the parameters' response to it: (H^-1 a)(H^-1 a)^T sd^2, a the score of
  /// a 1 px outward shift. Likewise a shift of the whole image (u and v: the
  /// pixel grid's phase, a digitizer's line timing).
  void add_shared_offsets(double c, const Eigen::MatrixXd& Hinv) {
    if (!(o_.edge_offset_sd_px > 0.0)) return;
    Eigen::VectorXd a = Eigen::VectorXd::Zero(P_), au = Eigen::VectorXd::Zero(P_), av = Eigen::VectorXd::Zero(P_);
    Eigen::VectorXd row(P_);
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const double w = tukey_weight(e_, i, c);
      if (w <= 0.0) continue;
      jacobian_row(e_, i, row);
      a += w * samples_[i].outward * row;
      au += w * e_.n[i].x() * row;
      av += w * e_.n[i].y() * row;
    }
    for (const Eigen::VectorXd* s : {&a, &au, &av}) {
      const Eigen::VectorXd d = Hinv * *s;
      sandwich_ += o_.edge_offset_sd_px * o_.edge_offset_sd_px * d * d.transpose();
    }
  }

  /// Each model edge's own offset (o.edge_model_sd_px, independent between
  /// edges): the model's and the appearance's error along one edge, which
  /// the fit absorbs where few edges decide a parameter (the ORU from one
  /// view: ~10 edges for 6 parameters) and the sandwich then cannot see. An
  /// offset b on edge e moves the parameters by H^-1 a_e b, a_e the edge's
  /// summed weighted Jacobian rows.
  void add_edge_offsets(double c, const Eigen::MatrixXd& Hinv) {
    if (!(o_.edge_model_sd_px > 0.0)) return;
    std::map<int, Eigen::VectorXd> per_edge;
    Eigen::VectorXd row(P_);
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const double w = tukey_weight(e_, i, c);
      if (w <= 0.0) continue;
      jacobian_row(e_, i, row);
      per_edge.try_emplace(samples_[i].cluster, Eigen::VectorXd::Zero(P_)).first->second += w * row;
    }
    for (const auto& [k, a_e] : per_edge) {
      const Eigen::VectorXd d = Hinv * a_e;
      sandwich_ += o_.edge_model_sd_px * o_.edge_model_sd_px * d * d.transpose();
    }
  }

  /// The held cameras' own uncertainty (AlignView::camera_covariance): a
  /// camera error dc moves the object by -H^-1 H_oc dc, H_oc the
  /// cross-information of the object's and that camera's columns.
  void add_held_cameras(double c, const Eigen::MatrixXd& Hinv) {
    std::vector<Eigen::MatrixXd> H_oc(V_, Eigen::MatrixXd::Zero(P_, 7));
    Eigen::VectorXd row(P_);
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const double w = tukey_weight(e_, i, c);
      if (w <= 0.0 || views_[samples_[i].view].camera_covariance.isZero(0.0)) continue;
      jacobian_row(e_, i, row);
      H_oc[samples_[i].view].noalias() += w * row * e_.J[i].leftCols<7>();
    }
    for (int v = 0; v < V_; ++v) {
      if (views_[v].camera_covariance.isZero(0.0)) continue;
      const Eigen::MatrixXd K = Hinv * H_oc[v];
      sandwich_ += K * views_[v].camera_covariance * K.transpose();
    }
  }

  // --- the result --------------------------------------------------------------

  /// Diagnostic (docs/estimation.md): FORESIGHT_ALIGN_DEBUG=PATH writes the
  /// first view's first frame at 2x with every final sample at its
  /// projection (green: matched within 1 px, yellow: matched further, red:
  /// no edge found) and prints their mean signed residual (a shading bias
  /// shows there).
  void debug_image() const {
    const char* dbg = std::getenv("FORESIGHT_ALIGN_DEBUG");
    if (dbg == nullptr) return;
    cv::Mat img;
    cv::cvtColor(views_[0].frames[0].image_bgr, img, cv::COLOR_BGR2GRAY);
    cv::cvtColor(img, img, cv::COLOR_GRAY2BGR);
    cv::resize(img, img, cv::Size(), 2.0, 2.0, cv::INTER_NEAREST);
    const Camera cam = camera_of(0);
    double sum = 0;
    int n = 0;
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      if (samples_[i].view != 0 || samples_[i].frame != 0) continue;
      const Eigen::Vector3d p =
          samples_[i].on_object ? Eigen::Vector3d(obj_R_ * samples_[i].p_local + obj_t_) : samples_[i].p_local;
      const Eigen::Vector2d uv = cam.project(p) * 2.0;
      const cv::Scalar col = !e_.matched[i]              ? cv::Scalar(0, 0, 255)
                             : std::abs(e_.r[i]) < 1.0 ? cv::Scalar(0, 255, 0)
                                                        : cv::Scalar(0, 255, 255);
      cv::circle(img, cv::Point2d(uv.x(), uv.y()), 2, col, -1);
      if (e_.matched[i]) {
        sum += e_.r[i];
        ++n;
      }
    }
    std::fprintf(stderr, "debug: mean residual %.3f px over %d\n", n ? sum / n : 0.0, n);
    cv::imwrite(dbg, img);
  }

  /// The final residual, score, samples and covariance into the result.
  void summarize() {
    double r2 = 0.0;
    int n_in = 0;
    for (std::size_t i = 0; i < samples_.size(); ++i)
      if (e_.matched[i] && std::abs(e_.r[i]) < 1.0) {
        r2 += e_.r[i] * e_.r[i];
        ++n_in;
      }
    res_.residual_rms_px = n_in ? std::sqrt(r2 / n_in) : 0.0;
    std::vector<Sample> final_samples;
    collect(final_samples, nullptr, -1);
    res_.final_score_px = score_of(final_samples);
    res_.visible_samples = static_cast<int>(final_samples.size());
    res_.matched_samples = n_in;
    if (sandwich_.size() > 0) {
      res_.covariance = sandwich_;
    } else if (H_last_.size() > 0) {
      res_.covariance = s2_last_ * H_last_.ldlt().solve(Eigen::MatrixXd::Identity(P_, P_));
    }
  }

  /// How far the model moved in the images from the start: beyond the
  /// coarsest search range no edge evidence vouches for the result (seen: a
  /// single wide view pulling the ORU 0.3 m onto the panel's edges).
  double moved_px() const {
    double moved = 0.0;
    const Pose start_obj = start_ ? *start_ : Pose::Identity();
    const auto end_obj = object_pose();
    for (const auto& s : samples_) {
      const Camera end_cam = camera_of(s.view);
      const Camera& start_cam = views_[s.view].camera;
      const Eigen::Vector3d p_end = s.on_object ? Eigen::Vector3d(*end_obj * s.p_local)
                                                : Eigen::Vector3d(data_[s.view][s.frame].link_poses[s.link] * s.p_link);
      const Eigen::Vector3d p_start = s.on_object ? Eigen::Vector3d(start_obj * s.p_local) : p_end;
      if (start_cam.to_camera(p_start).z() <= kNear_m || end_cam.to_camera(p_end).z() <= kNear_m) continue;
      moved = std::max(moved, (end_cam.project(p_end) - start_cam.project(p_start)).norm());
    }
    return moved;
  }

  /// The object's move against the start's own uncertainty (the clicks'): a
  /// disagreement beyond both covariances means the edges or the clicks are
  /// wrong, and nothing here says which. Returns the turn (deg).
  double start_disagreement() {
    if (!(refine_object_ && o_.object_start_covariance && start_ && res_.covariance.rows() == P_)) return 0.0;
    const Eigen::AngleAxisd turn(start_->linear().transpose() * obj_R_);
    Eigen::Matrix<double, 6, 1> moved;
    moved << turn.angle() * turn.axis(), obj_t_ - start_->translation();
    // The start's rpy covariance in body rotation increments (the object's parameters here).
    Eigen::Matrix<double, 6, 6> T = Eigen::Matrix<double, 6, 6>::Identity();
    T.topLeftCorner<3, 3>() = rpy_rate_matrix(rpy_from_rotation(start_->linear()));
    const Eigen::Matrix<double, 6, 6> C =
        T * *o_.object_start_covariance * T.transpose() + res_.covariance.block<6, 6>(obj_col_, obj_col_);
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(C);
    if (ldlt.info() == Eigen::Success && ldlt.isPositive())
      res_.start_disagreement_sigma = std::sqrt(std::max(0.0, moved.dot(ldlt.solve(moved))));
    const Eigen::LDLT<Eigen::Matrix3d> ldlt_p(C.bottomRightCorner<3, 3>());
    if (ldlt_p.info() == Eigen::Success && ldlt_p.isPositive())
      res_.start_position_disagreement_sigma =
          std::sqrt(std::max(0.0, moved.tail<3>().dot(ldlt_p.solve(moved.tail<3>()))));
    return turn.angle() * 180.0 / M_PI;
  }

  /// Aligned or refused (the first reason that applies), and what goes back.
  void verdict() {
    const double matched_fraction =
        samples_.empty() ? 0.0 : static_cast<double>(res_.matched_samples) / samples_.size();
    const double moved = moved_px();
    const double turned_deg = start_disagreement();
    char buf[320];
    // The disagreement first: it is the one that names a physical conflict
    // (seen: a single view's ORU 0.17 m off the clicks, also 29% matched).
    if (res_.start_disagreement_sigma > o_.max_start_disagreement_sigma) {
      std::snprintf(buf, sizeof buf,
                    "the object moved %.0f mm and turned %.1f deg from its start pose, %.1f sigma of the start's and the "
                    "alignment's pose uncertainty together (limit %.1f): the edges disagree with the start (the clicks)",
                    1e3 * (obj_t_ - start_->translation()).norm(), turned_deg, res_.start_disagreement_sigma,
                    o_.max_start_disagreement_sigma);
      res_.status = AlignStatus::Refused;
      res_.reason = buf;
    } else if (res_.final_score_px > res_.start_score_px + 0.02) {
      std::snprintf(buf, sizeof buf, "the edge distance got worse: %.2f px at the start, %.2f px after alignment",
                    res_.start_score_px, res_.final_score_px);
      res_.status = AlignStatus::Refused;
      res_.reason = buf;
    } else if (matched_fraction < o_.min_matched_fraction) {
      std::snprintf(buf, sizeof buf,
                    "only %.0f%% of the %zu visible model edge samples lie within 1 px of an image edge (need %.0f%%)",
                    100.0 * matched_fraction, samples_.size(), 100.0 * o_.min_matched_fraction);
      res_.status = AlignStatus::Refused;
      res_.reason = buf;
    } else if (moved > kLevels.front().search_px) {
      std::snprintf(buf, sizeof buf,
                    "the model moved %.0f px from the start, beyond the %.0f px search range that edges can vouch for",
                    moved, kLevels.front().search_px);
      res_.status = AlignStatus::Refused;
      res_.reason = buf;
    } else {
      res_.status = AlignStatus::Aligned;
    }
    if (res_.status == AlignStatus::Aligned) {
      for (int v = 0; v < V_; ++v) res_.cameras[v] = camera_of(v);
      if (refine_object_) res_.base_T_object = object_pose();
    }
    res_.arm_link_delta_m = res_.status == AlignStatus::Aligned ? link_delta_ : link_start_;
    if (NL_ > 0) {
      res_.arm_link_sigma_m.assign(nseg_, 0.0);
      if (res_.covariance.rows() == P_)
        for (int j = 0; j < NL_; ++j)
          res_.arm_link_sigma_m[link_segs_[j]] = std::sqrt(res_.covariance(link_col_ + j, link_col_ + j));
    }
  }

  AlignResult finish() {
    res_.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0_).count();
    return std::move(res_);
  }

  static constexpr double kLinkStep_m = 1e-3;  // FK is linear in the offsets at fixed q: the difference is exact

  Impl& I_;
  const std::vector<AlignView>& views_;
  const std::optional<Pose>& start_;
  const AlignOptions& o_;
  const bool refine_camera_, refine_object_;
  const int V_;
  std::vector<std::vector<FrameData>> data_;
  const FramesLease lease_;  // after data_: returns its buffers first
  // The parameters: per view the camera (R, c, f), the object (R, t).
  std::vector<Eigen::Matrix3d> cam_R_;
  std::vector<Eigen::Vector3d> cam_c_;
  std::vector<double> cam_f_;
  Eigen::Matrix3d obj_R_;
  Eigen::Vector3d obj_t_;
  // The arm's link lengths: the segments, the start, the current corrections.
  int nseg_ = 0, NL_ = 0;
  std::vector<double> link_start_, link_delta_;
  std::vector<int> link_segs_;
  std::vector<std::vector<std::vector<std::vector<Pose>>>> dposes_;
  int P_ = 0, obj_col_ = 0, link_col_ = 0;  // columns: cameras 7 V, object 6, links NL
  std::vector<Sample> samples_;
  Eval e_;
  Eigen::MatrixXd H_last_, sandwich_;
  double s2_last_ = 0.0;
  AlignResult res_;
  std::chrono::steady_clock::time_point t0_;
};

AlignResult ModelAligner::align(const std::vector<AlignView>& views, const std::optional<Pose>& base_T_object_start,
                                const AlignOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  if (views.empty()) throw std::invalid_argument("align: no views");
  impl_->next_cluster = 0;  // the clusters are this call's
  Impl::Alignment alignment(*impl_, views, base_T_object_start, o);
  return alignment.run(t0);
}

ModelAligner::FrameScore ModelAligner::score(const Camera& camera, const AlignFrame& frame,
                                             const std::optional<Pose>& base_T_object, const AlignOptions& o) {
  auto& I = *impl_;
  std::vector<std::vector<Impl::FrameData>> data(1);
  const Impl::FramesLease lease{I, data};
  data[0].push_back(I.prepare(frame));
  Impl::FrameData& f = data[0][0];
  std::vector<Sample> samples;
  I.sample(camera, f, base_T_object, 0, 0, true, false, o, samples);
  FrameScore out;
  out.visible_samples = static_cast<int>(samples.size());
  if (samples.empty()) {
    out.score_px = o.score_cap_px;
    return out;
  }
  const Gradient& g = I.gradient(f, -1, kScoreLevel.blur_px);
  const double thr = o.gradient_threshold * 0.7 / std::max(0.7, kScoreLevel.blur_px);
  double s2 = 0.0;
  int m1 = 0;
  // The silhouette IoU: the arm's rendered area A (label image of this
  // frame), and the area between the model's silhouette and the image's
  // edges, D = sum over silhouette samples of |offset| x the contour length
  // each stands for (a miss counts as the cap): IoU = (A - D/2) / (A + D/2).
  double area = 0.0;
  for (int y = 0; y < I.layer.rows; ++y) {
    const std::uint8_t* p = I.layer.ptr<std::uint8_t>(y);
    for (int x = 0; x < I.layer.cols; ++x, p += 4) {
      const int label = p[2] + 256 * p[1];
      if (label > 0 && label <= static_cast<int>(I.prims.size()) && I.prims[label - 1].link >= 0) area += 1.0;
    }
  }
  double between = 0.0;
  for (const auto& s : samples) {
    const Projection pr = project_with_jacobians(camera, s.p_local);
    Eigen::Vector2d d2 = (pr.d_point * s.dir_local).normalized();
    const Eigen::Vector2d n(-d2.y(), d2.x());
    double t = 0.0;
    double d = o.score_cap_px;
    if (search_edge(g, pr.uv_px, n, kScoreLevel.search_px, thr, t)) {
      d = std::min(std::abs(t), o.score_cap_px);
      if (std::abs(t) < 1.0) ++m1;
    }
    s2 += d * d;
    if (s.silhouette) between += d * s.length_px;
  }
  out.score_px = std::sqrt(s2 / samples.size());
  out.matched_fraction = static_cast<double>(m1) / samples.size();
  out.iou = area > 0.0 ? std::clamp((area - 0.5 * between) / (area + 0.5 * between), 0.0, 1.0) : 0.0;
  return out;
}

}  // namespace foresight::align
