#include "foresight/align/model_aligner.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <map>
#include <memory>
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

double reprojection_rms_px(const camera::Camera& a, const camera::Camera& b, const std::vector<Eigen::Vector3d>& pts) {
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
constexpr double kClear_px = 4.0;  // an object silhouette's clear view beyond it (the fine levels' search range)

struct Edge {
  Eigen::Vector3d a, b;    // primitive frame (link or object)
  Eigen::Vector3d n1, n2;  // outward face normals (surroundings: n1 the object's face, n2 theirs)
  bool two_faces = true;
  bool crease = false;
  // Not a mesh edge: where the object's face n1 passes into a face n2 of
  // its surroundings (the ORU's side entering the bay). The image has an
  // edge there, the object on one side, the surroundings on the other.
  bool surroundings = false;
};

// Primitive::link of the object's surroundings (ObjectModel::surroundings):
// drawn into the label image with the object's pose (they hide its parts),
// never sampled, never in the appearance render.
constexpr int kSurroundings = -2;

struct Primitive {
  int link = -1;  // link index; -1: the object; kSurroundings
  int label = 0;  // 1..
  Eigen::Vector4d rgba = Eigen::Vector4d::Zero();
  std::vector<Edge> edges;
  int first_edge = 0;  // the index of edges[0] over all primitives' edges (set once all are in)
};

// A mesh's triangles with their outward normals (towards the vertex
// normals' side); degenerate ones left out.
struct Triangle {
  std::array<Eigen::Vector3d, 3> v;
  Eigen::Vector3d n;
};

std::vector<Triangle> mesh_triangles(const render::Mesh& m) {
  auto pos = [&](std::uint32_t i) {
    const float* p = m.vertices[i].position;
    return Eigen::Vector3d(p[0], p[1], p[2]);
  };
  std::vector<Triangle> out;
  for (std::size_t t = 0; t + 2 < m.triangles.size(); t += 3) {
    const std::uint32_t v[3] = {m.triangles[t], m.triangles[t + 1], m.triangles[t + 2]};
    Triangle tri{{pos(v[0]), pos(v[1]), pos(v[2])}, Eigen::Vector3d::Zero()};
    Eigen::Vector3d n = (tri.v[1] - tri.v[0]).cross(tri.v[2] - tri.v[0]);
    if (n.norm() < 1e-12) continue;
    n.normalize();
    Eigen::Vector3d vn = Eigen::Vector3d::Zero();
    for (auto i : v) vn += Eigen::Vector3d(m.vertices[i].normal[0], m.vertices[i].normal[1], m.vertices[i].normal[2]);
    tri.n = n.dot(vn) < 0.0 ? Eigen::Vector3d(-n) : n;
    out.push_back(tri);
  }
  return out;
}

// Mesh edges with their adjacent face normals (vertices are duplicated per
// face in the meshes, so adjacency goes by position). Coplanar edges (a face's
// diagonal, a cap's spokes) are dropped: they never show.
std::vector<Edge> mesh_edges(const render::Mesh& m) {
  using Key = std::array<long long, 3>;
  auto key = [](const Eigen::Vector3d& p) {
    return Key{std::llround(p[0] * 1e5), std::llround(p[1] * 1e5), std::llround(p[2] * 1e5)};
  };
  struct Entry {
    Eigen::Vector3d a, b;
    std::vector<Eigen::Vector3d> normals;
  };
  std::map<std::pair<Key, Key>, Entry> map;
  for (const Triangle& tri : mesh_triangles(m)) {
    for (int e = 0; e < 3; ++e) {
      const Eigen::Vector3d* pi = &tri.v[e];
      const Eigen::Vector3d* pj = &tri.v[(e + 1) % 3];
      Key ki = key(*pi), kj = key(*pj);
      if (ki == kj) continue;
      if (kj < ki) {
        std::swap(ki, kj);
        std::swap(pi, pj);
      }
      auto& entry = map[{ki, kj}];
      if (entry.normals.empty()) {
        entry.a = *pi;
        entry.b = *pj;
      }
      entry.normals.push_back(tri.n);
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

// Where triangle `t` crosses the plane of `o` (through o.v[0], normal o.n):
// its points on that plane as an interval [lo, hi] along `dir` from `p0`;
// false when it does not reach the plane.
bool crossing_interval(const Triangle& t, const Triangle& o, const Eigen::Vector3d& p0, const Eigen::Vector3d& dir,
                       double& lo, double& hi) {
  constexpr double kOn = 1e-9;  // m: a vertex this close is on the plane
  std::array<double, 3> dist;
  for (int i = 0; i < 3; ++i) dist[i] = o.n.dot(t.v[i] - o.v[0]);
  lo = std::numeric_limits<double>::infinity();
  hi = -lo;
  auto add = [&](const Eigen::Vector3d& p) {
    const double s = dir.dot(p - p0);
    lo = std::min(lo, s);
    hi = std::max(hi, s);
  };
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3;
    if (std::abs(dist[i]) <= kOn) add(t.v[i]);
    if ((dist[i] > kOn && dist[j] < -kOn) || (dist[i] < -kOn && dist[j] > kOn))
      add(t.v[i] + dist[i] / (dist[i] - dist[j]) * (t.v[j] - t.v[i]));
  }
  return lo <= hi;
}

// The intersection of an object primitive's surface with a surrounding
// one's (both in the object frame): the segments where a face of the
// object passes through a face of the surroundings, each with the object's
// face normal (n1) and the surroundings' (n2); the pieces a triangulation
// cuts one line into joined. Coplanar faces meet in no edge of their own.
std::vector<Edge> surroundings_edges(const render::Mesh& object, const render::Mesh& surroundings) {
  const std::vector<Triangle> os = mesh_triangles(object), ss = mesh_triangles(surroundings);
  std::vector<Edge> out;
  for (const Triangle& t : os)
    for (const Triangle& u : ss) {
      Eigen::Vector3d dir = t.n.cross(u.n);
      if (dir.norm() < 1e-6) continue;  // parallel or coplanar
      dir.normalize();
      // A point on both planes: the closest to t.v[0] on their line.
      const Eigen::Vector3d p0 =
          t.v[0] - u.n.dot(t.v[0] - u.v[0]) / u.n.dot(u.n - t.n * t.n.dot(u.n)) * (u.n - t.n * t.n.dot(u.n));
      double lo1, hi1, lo2, hi2;
      if (!crossing_interval(t, u, p0, dir, lo1, hi1) || !crossing_interval(u, t, p0, dir, lo2, hi2)) continue;
      const double lo = std::max(lo1, lo2), hi = std::min(hi1, hi2);
      if (hi - lo < 1e-6) continue;
      Edge e;
      e.a = p0 + lo * dir;
      e.b = p0 + hi * dir;
      e.n1 = t.n;
      e.n2 = u.n;
      e.surroundings = true;
      out.push_back(e);
    }
  // Join the collinear pieces of one line between the same two faces.
  for (bool joined = true; joined;) {
    joined = false;
    for (std::size_t i = 0; i < out.size() && !joined; ++i)
      for (std::size_t j = i + 1; j < out.size() && !joined; ++j) {
        Edge& a = out[i];
        const Edge& b = out[j];
        if (a.n1.dot(b.n1) < 1.0 - 1e-9 || a.n2.dot(b.n2) < 1.0 - 1e-9) continue;
        const Eigen::Vector3d d = (a.b - a.a).normalized();
        auto off_line = [&](const Eigen::Vector3d& p) { return ((p - a.a) - d * d.dot(p - a.a)).norm() > 1e-6; };
        if (off_line(b.a) || off_line(b.b)) continue;
        const double sa = 0.0, ea = d.dot(a.b - a.a), sb = d.dot(b.a - a.a), eb = d.dot(b.b - a.a);
        if (std::max(sb, eb) < sa - 1e-6 || std::min(sb, eb) > ea + 1e-6) continue;  // apart
        const double lo = std::min({sa, sb, eb}), hi = std::max({ea, sb, eb});
        const Eigen::Vector3d origin = a.a;
        a.a = origin + lo * d;
        a.b = origin + hi * d;
        out.erase(out.begin() + static_cast<std::ptrdiff_t>(j));
        joined = true;
      }
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

/// An edge point `p` (base frame) running along `dir` through `cam`: its
/// projection and the unit normal of its image, across which the edge is
/// searched; false when the edge is seen end-on (no direction in the image).
bool edge_normal(const camera::Camera& cam, const Eigen::Vector3d& p, const Eigen::Vector3d& dir,
                 camera::Projection& pr, Eigen::Vector2d& n) {
  pr = camera::project_with_jacobians(cam, p);
  Eigen::Vector2d d2 = pr.d_point * dir;
  if (d2.norm() < 1e-9) return false;
  d2.normalize();
  n = Eigen::Vector2d(-d2.y(), d2.x());
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

// One residual evaluation: the search result for each sample.
struct Eval {
  std::vector<double> r;       // signed distance along n, px
  std::vector<char> matched;
  std::vector<Eigen::Vector2d> n;  // the search direction (unit, image)
  std::vector<Eigen::Matrix<double, 1, 13>> J;  // camera 7, object 6
  std::vector<Eigen::Matrix<double, 1, kMaxLinks>> Jl;  // refined link lengths
};

// Per frame: the link poses at its q, the grey image, its gradients.
struct FrameData {
  Eigen::VectorXd q;
  std::vector<Pose> link_poses;
  cv::Mat grey8, grey;
  std::map<int, Gradient> gradients;  // by level index (-1: score level)
};

Pose make_pose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

// The prior weight of the link lengths in units of H (= sum w J^T J over
// samples): s^2 n / G / sd^2 is the prior information 1/sd^2 scaled by the
// data's per-sample variance s^2 and the n / G samples per model edge.
double link_prior_weight(const std::vector<Sample>& samples, const Eval& e, double c, double s2, double prior_m) {
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

// The aligner as pinocchio splits a robot: an immutable model built once
// (AlignmentModel), the buffers every call writes (AlignmentData, one per
// thread, kept by its owner from one call to the next), and the steps as
// free functions f(const AlignmentModel&, AlignmentData&, inputs).

/// What is fixed once built: the arm's and the object's primitives (their
/// meshes and mesh edges), the viewport. The steps only read it, so one is
/// shared by every call and by the aligners of several threads.
struct AlignmentModel {
  AlignmentModel(const RobotModel& a, const ObjectModel* o, const camera::Viewport& v) : arm(a), object(o), vp(v) {
    const auto& links = arm.links();
    for (int k = 0; k < static_cast<int>(links.size()); ++k)
      for (const auto& shape : links[k].visuals) add(k, render::make_shape(shape), shape.rgba);
    if (object) {
      add(-1, render::make_box(object->size_m, object->oru_T_box, object->rgba), object->rgba);
      for (const auto& shape : object->visuals) add(-1, render::make_shape(shape), shape.rgba);
      for (const auto& shape : object->surroundings) add(kSurroundings, render::make_shape(shape), shape.rgba);
      // The object's edges with its surroundings, each its primitive's.
      for (std::size_t i = 0; i < prims.size(); ++i)
        for (std::size_t j = 0; j < prims.size(); ++j)
          if (prims[i].link == -1 && prims[j].link == kSurroundings)
            for (Edge& e : surroundings_edges(meshes[i], meshes[j])) prims[i].edges.push_back(e);
    }
    for (auto& p : prims) {
      p.first_edge = total_edges;
      total_edges += static_cast<int>(p.edges.size());
    }
  }

  const RobotModel& arm;
  const ObjectModel* const object;
  const camera::Viewport vp;
  std::vector<Primitive> prims;      // prims[i].label == i + 1
  std::vector<render::Mesh> meshes;  // prims[i]'s, uploaded by each AlignmentData's renderers
  int total_edges = 0;               // over all primitives

 private:
  void add(int link, render::Mesh mesh, const Eigen::Vector4d& rgba) {
    Primitive p;
    p.link = link;
    p.label = static_cast<int>(prims.size()) + 1;
    p.rgba = rgba;
    p.edges = mesh_edges(mesh);
    prims.push_back(std::move(p));
    meshes.push_back(std::move(mesh));
  }
};

std::shared_ptr<const AlignmentModel> make_alignment_model(const RobotModel& arm, const ObjectModel* object,
                                                           const camera::Viewport& viewport) {
  return std::make_shared<const AlignmentModel>(arm, object, viewport);
}

/// Everything a call writes: the renderers (their framebuffers, on one
/// thread's GL context), the image buffers, the frames, the parameters being
/// refined, the samples, residuals, Jacobians and normal equations. Its
/// owner keeps it between calls and each call rewrites it in place: OpenCV
/// reuses a destination of the same size and type, std::vector::assign and
/// clear keep their capacity, Eigen keeps a same-size matrix. A fresh
/// full-frame buffer is fresh pages, and faulting them in was over half of
/// an alignment's time (BM_AlignCamera 95 -> 45 ms wall with glibc told not
/// to return freed memory; align is called per frame by the health check and
/// many times by the study).
struct AlignmentData {
  AlignmentData(render::GlContext& ctx, const AlignmentModel& m)
      : renderer(ctx, m.vp, 1), shaded_renderer(ctx, m.vp, 4), ws(m.arm) {
    for (const auto& mesh : m.meshes) {
      body.push_back(renderer.add_body(mesh));
      shaded_body.push_back(shaded_renderer.add_body(mesh));
    }
  }

  // The model's meshes on this thread's GL context (by primitive index).
  render::Renderer renderer;
  render::Renderer shaded_renderer;  // the model's appearance (lit, anti-aliased): the edge bias prediction
  std::vector<int> body, shaded_body;
  KinematicsWorkspace ws;
  render::DrawList list;
  cv::Mat layer, shaded_layer;                     // sample()'s label image, predict_bias()'s render
  cv::Mat blurred;                                 // gradient(): the blurred level
  cv::Mat model_mask, bg_w, bg_v, predicted_grey;  // predict_bias()
  Gradient predicted;                              // predict_bias()

  // The call's frames, view after view: frame k of view v is frames[
  // first_frame[v] + k]. Never shrunk: a call with fewer frames leaves the
  // others' buffers to the next (the study alternates one view and all).
  std::vector<FrameData> frames;
  std::vector<int> first_frame, frame_count;
  FrameData& frame(int v, int k) { return frames[first_frame[v] + k]; }

  // The call's layout: columns cameras 7 V, object 6, links NL.
  bool refine_camera = false, refine_object = false;
  int V = 0, P = 0, obj_col = 0, link_col = 0;
  int next_cluster = 0;  // the arm's clusters, numbered per call
  // The parameters: per view the camera (R, c, f), the object (R, t).
  std::vector<Eigen::Matrix3d> cam_R;
  std::vector<Eigen::Vector3d> cam_c;
  std::vector<double> cam_f;
  Eigen::Matrix3d obj_R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d obj_t = Eigen::Vector3d::Zero();
  // The arm's link lengths: the segments, the start, the current corrections.
  int nseg = 0, NL = 0;
  std::vector<double> link_start, link_delta;
  std::vector<int> link_segs;
  std::vector<std::vector<std::vector<std::vector<Pose>>>> dposes;  // [view][frame][refined link][link]
  // Samples and residuals.
  std::vector<Sample> samples, final_samples;
  std::vector<int> per_view;
  Eval e, score_eval;
  std::vector<camera::Camera> cams;    // evaluate(): the current cameras
  std::vector<double> abs_r;   // tukey_scale()
  // The Gauss-Newton step's normal equations (H is also the covariance's).
  Eigen::MatrixXd H, A;
  Eigen::VectorXd g, row, delta;
  Eigen::LDLT<Eigen::MatrixXd> ldlt;
  // What the covariance and the result keep from the last step.
  Eigen::MatrixXd H_last, sandwich;
  bool has_H_last = false, has_sandwich = false;
  double s2_last = 0.0;
  AlignResult res;
  std::chrono::steady_clock::time_point t0;
};

namespace {

// One call's inputs, as align() was given them.
struct AlignInput {
  const std::vector<AlignView>& views;
  const std::optional<Pose>& start;
  const AlignOptions& o;
};

constexpr double kLinkStep_m = 1e-3;  // FK is linear in the offsets at fixed q: the difference is exact

Eigen::Vector4d label_rgba(int label) { return {(label & 0xFF) / 255.0, ((label >> 8) & 0xFF) / 255.0, 0.0, 1.0}; }

int label_at(const cv::Mat& layer_bgra, const Eigen::Vector2d& uv) {
  const int x = static_cast<int>(std::floor(uv.x())), y = static_cast<int>(std::floor(uv.y()));
  if (x < 0 || y < 0 || x >= layer_bgra.cols || y >= layer_bgra.rows) return 0;
  const std::uint8_t* p = layer_bgra.ptr<std::uint8_t>(y) + 4 * x;
  return p[2] + 256 * p[1];
}

// --- per frame ----------------------------------------------------------------

const Gradient& gradient(AlignmentData& d, FrameData& f, int level_index, double blur) {
  Gradient& g = f.gradients[level_index];
  if (g.valid) return g;
  // Coarse levels blur the 8-bit image (several times faster); the fine
  // levels blur in float so the sub-pixel edge is not quantized.
  if (blur >= 2.0) cv::GaussianBlur(f.grey8, d.blurred, cv::Size(0, 0), blur);
  else if (blur > 0.0) cv::GaussianBlur(f.grey, d.blurred, cv::Size(0, 0), blur);
  const cv::Mat& src = blur > 0.0 ? d.blurred : f.grey;
  cv::Sobel(src, g.gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(src, g.gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  g.valid = true;
  return g;
}

/// `frame` checked and into `f` (its buffers rewritten in place).
void prepare(const AlignmentModel& m, AlignmentData& d, const AlignFrame& frame, FrameData& f) {
  if (frame.image_bgr.empty() || frame.image_bgr.cols != m.vp.width_px || frame.image_bgr.rows != m.vp.height_px)
    throw std::invalid_argument("frame is " + std::to_string(frame.image_bgr.cols) + "x" +
                                std::to_string(frame.image_bgr.rows) + " but the camera viewport is " +
                                std::to_string(m.vp.width_px) + "x" + std::to_string(m.vp.height_px));
  if (frame.q.size() != m.arm.dof())
    throw std::invalid_argument("joint vector has " + std::to_string(frame.q.size()) + " values but the arm has " +
                                std::to_string(m.arm.dof()) + " joints");
  if (frame.image_bgr.type() != CV_8UC3 && frame.image_bgr.type() != CV_8UC1)
    throw std::invalid_argument("frame must be an 8-bit BGR or grey image");
  for (auto& [level, g] : f.gradients) g.valid = false;
  // A grey input is copied, not shared: the buffer is rewritten by the next
  // call, and the caller's image is not ours to rewrite.
  if (frame.image_bgr.type() == CV_8UC3) cv::cvtColor(frame.image_bgr, f.grey8, cv::COLOR_BGR2GRAY);
  else frame.image_bgr.copyTo(f.grey8);
  f.grey8.convertTo(f.grey, CV_32F);
  f.q = frame.q;
  f.link_poses.resize(m.arm.links().size());
  for (int k = 0; k < static_cast<int>(m.arm.links().size()); ++k)
    f.link_poses[k] = forward_kinematics(m.arm, d.ws, frame.q, k);
}

// The edge search's own bias on this model's appearance: the model rendered
// as the camera would see it (lit, anti-aliased, the camera's optical blur,
// on a flat background of the image's median where the model is not), the
// same search run on it at every sample of out[begin..] whose true edge is
// at 0. Shading ramps beside a silhouette (a cylinder darkening towards its
// rim) and the background's contrast move the gradient peak by 0.1-0.3 px;
// the residual is then the image's offset minus this predicted one. Uses
// `d.layer` (the label image of the same camera and frame, just rendered).
void predict_bias(const AlignmentModel& m, AlignmentData& d, const camera::Camera& cam, const FrameData& f,
                  const std::optional<Pose>& base_T_object, double blur, double search_px, double threshold,
                  const AlignOptions& o, std::vector<Sample>& out, std::size_t begin) {
  if (begin >= out.size()) return;
  d.list.clear();
  for (std::size_t i = 0; i < m.prims.size(); ++i) {
    const Primitive& p = m.prims[i];
    if ((p.link < 0 && !base_T_object) || p.link == kSurroundings) continue;
    render::BodyInstance b;
    b.body = d.shaded_body[i];
    b.base_T_body = p.link >= 0 ? f.link_poses[p.link] : *base_T_object;
    d.list.bodies.push_back(b);
  }
  render::RenderSettings st;
  st.mode = render::RenderMode::Solid;
  st.lighting = true;
  st.near_m = kNear_m;
  st.clear_rgba = Eigen::Vector4d::Zero();
  d.shaded_renderer.render(cam, d.list, st, d.shaded_layer);
  // The background: the image's median grey where no model part is (the
  // surroundings are background here: the image shows them as they are).
  auto is_model = [&](const std::uint8_t* px) {
    const int label = px[2] + 256 * px[1];
    return label > 0 && m.prims[label - 1].link != kSurroundings;
  };
  std::array<int, 256> hist{};
  int nbg = 0;
  for (int y = 0; y < d.layer.rows; y += 2) {
    const std::uint8_t* lp = d.layer.ptr<std::uint8_t>(y);
    const std::uint8_t* gp = f.grey8.ptr<std::uint8_t>(y);
    for (int x = 0; x < d.layer.cols; x += 2)
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
  d.model_mask.create(d.layer.rows, d.layer.cols, CV_8U);
  for (int y = 0; y < d.layer.rows; ++y) {
    const std::uint8_t* lp = d.layer.ptr<std::uint8_t>(y);
    std::uint8_t* mask = d.model_mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < d.layer.cols; ++x) mask[x] = is_model(lp + 4 * x) ? 255 : 0;
  }
  cv::dilate(d.model_mask, d.model_mask, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(7, 7)));
  cv::bitwise_not(d.model_mask, d.model_mask);
  d.model_mask.convertTo(d.bg_w, CV_32F, 1.0 / 255.0);
  cv::multiply(f.grey, d.bg_w, d.bg_v);
  // At full resolution: spreading at a quarter of it (1.5 px there) saved
  // a few ms but moved the study's link estimates (eval alignment seeds 1
  // and 3: four-view gain 3.9x / 3.0x -> 2.2x / 0.8x).
  cv::GaussianBlur(d.bg_w, d.bg_w, cv::Size(0, 0), 6.0);
  cv::GaussianBlur(d.bg_v, d.bg_v, cv::Size(0, 0), 6.0);
  cv::Mat& grey = d.predicted_grey;
  grey.create(d.shaded_layer.rows, d.shaded_layer.cols, CV_32F);
  for (int y = 0; y < grey.rows; ++y) {
    const std::uint8_t* p = d.shaded_layer.ptr<std::uint8_t>(y);
    const float* w = d.bg_w.ptr<float>(y);
    const float* v = d.bg_v.ptr<float>(y);
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
  Gradient& g = d.predicted;
  cv::Sobel(grey, g.gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(grey, g.gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  for (std::size_t i = begin; i < out.size(); ++i) {
    Sample& s = out[i];
    const Eigen::Vector3d p = s.on_object ? Eigen::Vector3d(*base_T_object * s.p_local) : s.p_local;
    const Eigen::Vector3d dir = s.on_object ? Eigen::Vector3d(base_T_object->linear() * s.dir_local) : s.dir_local;
    camera::Projection pr;
    Eigen::Vector2d n;
    if (!edge_normal(cam, p, dir, pr, n)) continue;
    double t = 0.0;
    // A shading bias is 0.1-0.3 px; a larger offset is another model edge
    // close by (the tool's small parts), not this edge's bias.
    if (search_edge(g, pr.uv_px, n, std::min(search_px, 1.5), threshold, t, blur <= 1.0) && std::abs(t) <= 0.5)
      s.bias_px = t;
  }
}

// The visible model edge samples of one frame through `cam`.
void sample(const AlignmentModel& m, AlignmentData& d, const camera::Camera& cam, const FrameData& f,
            const std::optional<Pose>& base_T_object, int view, int frame_index, bool want_arm, bool want_object,
            const AlignOptions& o, std::vector<Sample>& out) {
  d.list.clear();
  for (std::size_t i = 0; i < m.prims.size(); ++i) {
    const Primitive& p = m.prims[i];
    if (p.link < 0 && !base_T_object) continue;
    render::BodyInstance b;
    b.body = d.body[i];
    b.base_T_body = p.link >= 0 ? f.link_poses[p.link] : *base_T_object;
    b.solid_rgba = label_rgba(p.label);
    d.list.bodies.push_back(b);
  }
  render::RenderSettings st;
  st.mode = render::RenderMode::Solid;
  st.lighting = false;
  st.near_m = kNear_m;
  d.renderer.render(cam, d.list, st, d.layer);

  const Eigen::Vector3d C = cam.base_T_camera.translation();
  struct Candidate {
    const Primitive* prim;
    Eigen::Vector3d a, b;
    Eigen::Vector2d ua, ub;
    bool silhouette;
    bool surroundings;  // Edge::surroundings
    int edge;  // over all primitives' edges
  };
  std::vector<Candidate> cands;
  double total_len = 0.0;
  for (const auto& p : m.prims) {
    if (p.link == kSurroundings) continue;
    const bool is_object = p.link < 0;
    if (is_object && (!base_T_object || !want_object)) continue;
    if (!is_object && !want_arm) continue;
    const Pose& T = is_object ? *base_T_object : f.link_poses[p.link];
    for (const auto& e : p.edges) {
      const Eigen::Vector3d a = T * e.a, b = T * e.b, m = 0.5 * (a + b);
      const bool f1 = (T.linear() * e.n1).dot(C - m) > 0.0;
      const bool f2 = e.two_faces ? (T.linear() * e.n2).dot(C - m) > 0.0 : false;
      // An edge with the surroundings is a boundary of the object's image
      // like a silhouette; it shows where both its faces do.
      const bool silhouette = e.surroundings || f1 != f2;
      if (e.surroundings ? !(f1 && f2) : !silhouette && !(e.crease && f1 && f2)) continue;
      if (cam.to_camera(a).z() <= kNear_m || cam.to_camera(b).z() <= kNear_m) continue;
      const Eigen::Vector2d ua = cam.project(a), ub = cam.project(b);
      const double len = (ub - ua).norm();
      if (len < 1.0) continue;
      cands.push_back({&p, a, b, ua, ub, silhouette, e.surroundings, p.first_edge + static_cast<int>(&e - p.edges.data())});
      total_len += len;
    }
  }
  const double spacing = std::max(o.sample_spacing_px, total_len / std::max(1, o.max_samples_per_frame));
  const double margin = 3.0;
  for (const auto& c : cands) {
    // Arm edges: a new cluster per frame (positive); object edges: one per
    // view and edge (negative, the same in every frame of the view).
    const int cluster = c.prim->link < 0 ? -(1 + view * m.total_edges + c.edge) : ++d.next_cluster;
    const Eigen::Vector2d along = (c.ub - c.ua).normalized();
    const Eigen::Vector2d n(-along.y(), along.x());
    const int ns = std::clamp(static_cast<int>((c.ub - c.ua).norm() / spacing), 1, 400);
    for (int k = 0; k < ns; ++k) {
      const double t = (k + 0.5) / ns;
      const Eigen::Vector3d p = c.a + t * (c.b - c.a);
      const Eigen::Vector2d uv = cam.project(p);
      if (uv.x() < margin || uv.y() < margin || uv.x() > m.vp.width_px - margin || uv.y() > m.vp.height_px - margin)
        continue;
      const int lp = label_at(d.layer, uv + 1.5 * n), lm = label_at(d.layer, uv - 1.5 * n);
      const int id = c.prim->label;
      bool visible;
      if (c.silhouette) {
        const int other = lp == id ? lm : lm == id ? lp : -1;
        visible = (lp == id) != (lm == id) && other >= 0;
        // An edge with the surroundings: the surroundings on its other side.
        if (visible && c.surroundings) visible = other > 0 && m.prims[other - 1].link == kSurroundings;
        if (visible && other > 0 && (m.prims[other - 1].rgba - c.prim->rgba).norm() < 0.02) visible = false;
        // The object's silhouette with what lies beyond it unchanged for
        // kClear_px: another boundary there (seen: the bay's far edge 2 px
        // beyond the side view's ORU, bay against sky, stronger than the
        // ORU's dark face against the bay) is the edge the search takes,
        // and the few edges that decide the object follow it (4 mm). The
        // arm's many edges over its frames outvote such a capture (the
        // rule on them too: noise-free camera recovery 0.028 -> 0.034 px).
        const Eigen::Vector2d beyond = lp == id ? Eigen::Vector2d(-n) : n;
        if (visible && c.prim->link < 0)
          for (double k = 2.0; k <= kClear_px && visible; k += 0.5) visible = label_at(d.layer, uv + k * beyond) == other;
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

// --- the model's state ------------------------------------------------------

/// The link poses of every frame with the current link lengths, and with
/// each refined length stepped (d.dposes[v][k][j][link]).
void update_arm(const AlignmentModel& m, AlignmentData& d) {
  const RobotModel changed = m.arm.with_link_lengths_changed(d.link_delta);
  KinematicsWorkspace mws(changed);
  std::vector<RobotModel> stepped;
  for (int j = 0; j < d.NL; ++j) {
    std::vector<double> delta = d.link_delta;
    delta[d.link_segs[j]] += kLinkStep_m;
    stepped.push_back(m.arm.with_link_lengths_changed(delta));
  }
  const int nl = static_cast<int>(m.arm.links().size());
  for (int v = 0; v < d.V; ++v) {
    d.dposes[v].resize(d.frame_count[v]);
    for (int k = 0; k < d.frame_count[v]; ++k) {
      auto& f = d.frame(v, k);
      for (int l = 0; l < nl; ++l) f.link_poses[l] = forward_kinematics(changed, mws, f.q, l);
      // Every pose is written below: resized, not refilled (the buffers stay).
      d.dposes[v][k].resize(d.NL);
      for (auto& poses : d.dposes[v][k]) poses.resize(nl);
      for (int j = 0; j < d.NL; ++j) {
        KinematicsWorkspace sws(stepped[j]);
        for (int l = 0; l < nl; ++l) d.dposes[v][k][j][l] = forward_kinematics(stepped[j], sws, f.q, l);
      }
    }
  }
}

/// The arm model's link-length corrections: given (rendered and sampled
/// with) and/or refined with the cameras under a prior (a bundle
/// adjustment over cameras + arm; the link offsets are observable over
/// several poses).
void init_links(const AlignmentModel& m, AlignmentData& d, const AlignInput& in) {
  d.nseg = m.arm.segment_count();
  if (!in.o.arm_link_delta_m.empty() && static_cast<int>(in.o.arm_link_delta_m.size()) != d.nseg)
    throw std::invalid_argument("arm link corrections: " + std::to_string(in.o.arm_link_delta_m.size()) +
                                " values for " + std::to_string(d.nseg) + " chain segments");
  if (!(in.o.arm_link_prior_m >= 0.0) || !std::isfinite(in.o.arm_link_prior_m))
    throw std::invalid_argument("arm link prior must be a non-negative number");
  d.link_start = in.o.arm_link_delta_m.empty() ? std::vector<double>(d.nseg, 0.0) : in.o.arm_link_delta_m;
  d.link_delta = d.link_start;
  d.link_segs.clear();
  if (d.refine_camera && in.o.arm_link_prior_m > 0.0) d.link_segs = m.arm.offset_segments();
  d.NL = static_cast<int>(d.link_segs.size());
  if (d.NL > kMaxLinks) throw std::invalid_argument("arm link refinement: more than 16 link offsets");
  d.dposes.resize(d.V);
  if (!in.o.arm_link_delta_m.empty() || d.NL > 0) update_arm(m, d);
}

camera::Camera camera_of(const AlignmentData& d, const AlignInput& in, int v) {
  camera::Camera c = in.views[v].camera;
  c.base_T_camera = make_pose(d.cam_R[v], d.cam_c[v]);
  c.f_px = d.cam_f[v];
  return c;
}

std::optional<Pose> object_pose(const AlignmentData& d, const AlignInput& in) {
  if (!in.start) return std::nullopt;
  return make_pose(d.obj_R, d.obj_t);
}

// --- samples and residuals ---------------------------------------------------

/// Samples at level `level` (-1: the score's); at the finest level with
/// their predicted edge bias (predict_bias).
void collect(const AlignmentModel& m, AlignmentData& d, const AlignInput& in, std::vector<Sample>& samples,
             std::vector<int>* per_view, int level) {
  samples.clear();
  if (per_view) per_view->assign(d.V, 0);
  const auto obj = object_pose(d, in);
  for (int v = 0; v < d.V; ++v) {
    const camera::Camera cam = camera_of(d, in, v);
    for (int k = 0; k < d.frame_count[v]; ++k) {
      const std::size_t before = samples.size();
      sample(m, d, cam, d.frame(v, k), obj, v, k, d.refine_camera, d.refine_object, in.o, samples);
      // The bias is predicted at the finest level only: it is 0.1-0.3 px,
      // below what the coarser levels resolve, and each prediction is a
      // 4x-MSAA render (about half of an alignment's time when done at
      // the two fine levels).
      if (level + 1 == static_cast<int>(kLevels.size()) && in.o.predict_edge_bias) {
        const Level& L = kLevels[level];
        predict_bias(m, d, cam, d.frame(v, k), obj, L.blur_px, L.search_px,
                   in.o.gradient_threshold * 0.7 / std::max(0.7, L.blur_px), in.o, samples, before);
      }
      if (per_view) (*per_view)[v] += static_cast<int>(samples.size() - before);
    }
  }
}

/// Residuals (and Jacobian rows) of the samples at the current parameters.
void evaluate(AlignmentData& d, const AlignInput& in, const std::vector<Sample>& samples, int level_index,
              const Level& L, Eval& e, bool jac) {
  e.r.assign(samples.size(), 0.0);
  e.matched.assign(samples.size(), 0);
  e.n.assign(samples.size(), Eigen::Vector2d::Zero());
  if (jac) e.J.assign(samples.size(), Eigen::Matrix<double, 1, 13>::Zero());
  if (jac && d.NL > 0) e.Jl.assign(samples.size(), Eigen::Matrix<double, 1, kMaxLinks>::Zero());
  const double thr = in.o.gradient_threshold * 0.7 / std::max(0.7, L.blur_px);
  d.cams.resize(d.V);
  for (int v = 0; v < d.V; ++v) d.cams[v] = camera_of(d, in, v);
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Sample& s = samples[i];
    const camera::Camera& cam = d.cams[s.view];
    Eigen::Vector3d p, dir;
    if (s.on_object) {
      p = d.obj_R * s.p_local + d.obj_t;
      dir = d.obj_R * s.dir_local;
    } else {
      const Pose& T = d.frame(s.view, s.frame).link_poses[s.link];
      p = T * s.p_link;
      dir = T.linear() * s.dir_link;
    }
    if (cam.to_camera(p).z() <= kNear_m) continue;
    camera::Projection pr;
    Eigen::Vector2d n;
    if (!edge_normal(cam, p, dir, pr, n)) continue;
    double t = 0.0;
    const Gradient& g = gradient(d, d.frame(s.view, s.frame), level_index, L.blur_px);
    if (!search_edge(g, pr.uv_px, n, L.search_px, thr, t, L.blur_px <= 1.0)) continue;
    e.r[i] = t - s.bias_px;
    e.matched[i] = 1;
    e.n[i] = n;
    if (jac) {
      // The camera's columns also when it is held (its covariance is
      // propagated into the object's below).
      e.J[i].leftCols<7>() = n.transpose() * pr.d_camera;
      if (d.refine_object && s.on_object)
        e.J[i].rightCols<6>() = n.transpose() * camera::object_pose_jacobian(pr, d.obj_R, s.p_local);
      if (d.NL > 0 && !s.on_object) {
        const Eigen::RowVector3d nd = n.transpose() * pr.d_point;
        for (int j = 0; j < d.NL; ++j)
          e.Jl[i][j] = nd.dot(d.dposes[s.view][s.frame][j][s.link] * s.p_link - p) / kLinkStep_m;
      }
    }
  }
}

/// The truncated edge distance (misses count as the cap) of `samples`.
double score_of(AlignmentData& d, const AlignInput& in, const std::vector<Sample>& samples) {
  Eval& e = d.score_eval;
  evaluate(d, in, samples, -1, kScoreLevel, e, false);
  double s2 = 0.0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const double dist = e.matched[i] ? std::min(std::abs(e.r[i]), in.o.score_cap_px) : in.o.score_cap_px;
    s2 += dist * dist;
  }
  return samples.empty() ? in.o.score_cap_px : std::sqrt(s2 / samples.size());
}

// --- the robust least squares ------------------------------------------------

/// A sample's Tukey weight at scale c (0: unmatched or beyond c): the same
/// in the Gauss-Newton steps, the step limit and the covariance.
double tukey_weight(const Eval& ev, std::size_t i, double c) {
  if (!ev.matched[i]) return 0.0;
  const double u = ev.r[i] / c;
  return std::abs(u) >= 1.0 ? 0.0 : (1 - u * u) * (1 - u * u);
}

/// A sample's row of the Jacobian over all refined parameters.
void jacobian_row(const AlignmentData& d, const Eval& ev, std::size_t i, Eigen::VectorXd& row) {
  row.setZero();
  if (d.refine_camera) row.segment<7>(7 * d.samples[i].view) = ev.J[i].leftCols<7>().transpose();
  if (d.refine_object) row.segment<6>(d.obj_col) = ev.J[i].rightCols<6>().transpose();
  if (d.NL > 0) row.segment(d.link_col, d.NL) = ev.Jl[i].head(d.NL).transpose();
}

/// Tukey's scale from the matched residuals' MAD, within [0.5, search_px];
/// nullopt with fewer than 10 matched.
std::optional<double> tukey_scale(AlignmentData& d, double search_px) {
  std::vector<double>& absr = d.abs_r;
  absr.clear();
  for (std::size_t i = 0; i < d.samples.size(); ++i)
    if (d.e.matched[i]) absr.push_back(std::abs(d.e.r[i]));
  if (absr.size() < 10) return std::nullopt;
  std::nth_element(absr.begin(), absr.begin() + absr.size() / 2, absr.end());
  const double sigma = std::max(1.4826 * absr[absr.size() / 2], 0.1);
  return std::clamp(4.685 * sigma, 0.5, search_px);
}

/// sum w r^2 / (sum w - P) over the weighted samples.
double weighted_variance(const AlignmentData& d, double c) {
  double wr2 = 0.0, wsum = 0.0;
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const double w = tukey_weight(d.e, i, c);
    if (w <= 0.0) continue;
    wr2 += w * d.e.r[i] * d.e.r[i];
    wsum += w;
  }
  return wr2 / std::max(1.0, wsum - d.P);
}

/// The prior on the link lengths, in the data's units: the data's
/// information is H / (s^2 n / G) (G model edges: independent errors per
/// edge, not per sample), the prior's 1 / sd^2.
double link_prior_weight(const AlignmentData& d, const AlignInput& in, double c, double s2) {
  return link_prior_weight(d.samples, d.e, c, s2, in.o.arm_link_prior_m);
}

void apply(const AlignmentModel& m, AlignmentData& d, const Eigen::VectorXd& delta) {
  if (d.refine_camera)
    for (int v = 0; v < d.V; ++v) {
      const Eigen::Matrix<double, 7, 1> step = delta.segment<7>(7 * v);
      d.cam_R[v] = d.cam_R[v] * camera::exp_so3(step.head<3>());
      d.cam_c[v] += step.segment<3>(3);
      d.cam_f[v] += step[6];
      d.res.camera_change[v] += step;
    }
  if (d.refine_object) {
    const Eigen::Matrix<double, 6, 1> step = delta.segment<6>(d.obj_col);
    d.obj_R = d.obj_R * camera::exp_so3(step.head<3>());
    d.obj_t += step.tail<3>();
    d.res.object_change += step;
  }
  if (d.NL > 0) {
    for (int j = 0; j < d.NL; ++j) d.link_delta[d.link_segs[j]] += delta[d.link_col + j];
    update_arm(m, d);
  }
}

/// One robust Gauss-Newton step at level li; false when the level is done
/// (converged, too few matches, or no finite step).
bool gauss_newton_step(const AlignmentModel& m, AlignmentData& d, const AlignInput& in, int li) {
  const Level& L = kLevels[li];
  evaluate(d, in, d.samples, li, L, d.e, true);
  const std::optional<double> scale = tukey_scale(d, L.search_px);
  if (!scale) return false;
  const double c = *scale;
  // The normal equations in the data's buffers (same size every step).
  Eigen::MatrixXd& H = d.H;
  Eigen::VectorXd& g = d.g;
  Eigen::VectorXd& row = d.row;
  H.setZero(d.P, d.P);
  g.setZero(d.P);
  row.resize(d.P);
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const double w = tukey_weight(d.e, i, c);
    if (w <= 0.0) continue;
    jacobian_row(d, d.e, i, row);
    H.selfadjointView<Eigen::Lower>().rankUpdate(row, w);
    g += w * d.e.r[i] * row;
  }
  H = H.selfadjointView<Eigen::Lower>();
  d.s2_last = weighted_variance(d, c);
  if (d.NL > 0) {
    const double lambda = link_prior_weight(d, in, c, d.s2_last);
    for (int j = 0; j < d.NL; ++j) {
      H(d.link_col + j, d.link_col + j) += lambda;
      g[d.link_col + j] -= lambda * (d.link_delta[d.link_segs[j]] - d.link_start[d.link_segs[j]]);
    }
  }
  d.H_last = H;
  d.has_H_last = true;
  Eigen::MatrixXd& A = d.A;
  A = H;
  for (int k = 0; k < d.P; ++k) A(k, k) += 1e-3 * H(k, k) + 1e-12;
  Eigen::VectorXd& delta = d.delta;
  delta = d.ldlt.compute(A).solve(g);
  if (!delta.allFinite()) return false;
  // Limit the step to the search range (predicted pixel motion), over
  // every sample: every 7th made the steps depend on where a frame's
  // samples start in the list (the same frame given twice stopped an
  // iteration apart).
  double max_move = 0.0;
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    jacobian_row(d, d.e, i, row);
    max_move = std::max(max_move, std::abs(row.dot(delta)));
  }
  if (max_move > L.search_px) delta *= L.search_px / max_move;
  apply(m, d, delta);
  ++d.res.iterations;
  return max_move >= (li + 1 == static_cast<int>(kLevels.size()) ? 0.005 : 0.05);
}

// --- the covariance ----------------------------------------------------------

/// An offset shared by every silhouette (the image's edges all a little
/// out of or into the model: appearance the prediction does not carry,
/// the lighting, the blur) looks like a change of scale (f, depth) and
/// leaves no trace in the residuals; its sd o.edge_offset_sd_px enters as
/// the parameters' response to it: (H^-1 a)(H^-1 a)^T sd^2, a the score of
/// a 1 px outward shift. Likewise a shift of the whole image (u and v: the
/// pixel grid's phase, a digitizer's line timing).
void add_shared_offsets(AlignmentData& d, const AlignInput& in, double c, const Eigen::MatrixXd& Hinv) {
  if (!(in.o.edge_offset_sd_px > 0.0)) return;
  Eigen::VectorXd a = Eigen::VectorXd::Zero(d.P), au = Eigen::VectorXd::Zero(d.P), av = Eigen::VectorXd::Zero(d.P);
  Eigen::VectorXd row(d.P);
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const double w = tukey_weight(d.e, i, c);
    if (w <= 0.0) continue;
    jacobian_row(d, d.e, i, row);
    a += w * d.samples[i].outward * row;
    au += w * d.e.n[i].x() * row;
    av += w * d.e.n[i].y() * row;
  }
  for (const Eigen::VectorXd* s : {&a, &au, &av}) {
    const Eigen::VectorXd dp = Hinv * *s;
    d.sandwich += in.o.edge_offset_sd_px * in.o.edge_offset_sd_px * dp * dp.transpose();
  }
}

/// Each model edge's own offset (o.edge_model_sd_px, independent between
/// edges): the model's and the appearance's error along one edge, which
/// the fit absorbs where few edges decide a parameter (the ORU from one
/// view: ~10 edges for 6 parameters) and the sandwich then cannot see. An
/// offset b on edge e moves the parameters by H^-1 a_e b, a_e the edge's
/// summed weighted Jacobian rows.
void add_edge_offsets(AlignmentData& d, const AlignInput& in, double c, const Eigen::MatrixXd& Hinv) {
  if (!(in.o.edge_model_sd_px > 0.0)) return;
  std::map<int, Eigen::VectorXd> per_edge;
  Eigen::VectorXd row(d.P);
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const double w = tukey_weight(d.e, i, c);
    if (w <= 0.0) continue;
    jacobian_row(d, d.e, i, row);
    per_edge.try_emplace(d.samples[i].cluster, Eigen::VectorXd::Zero(d.P)).first->second += w * row;
  }
  for (const auto& [k, a_e] : per_edge) {
    const Eigen::VectorXd dp = Hinv * a_e;
    d.sandwich += in.o.edge_model_sd_px * in.o.edge_model_sd_px * dp * dp.transpose();
  }
}

/// The held cameras' own uncertainty (AlignView::camera_covariance): a
/// camera error dc moves the object by -H^-1 H_oc dc, H_oc the
/// cross-information of the object's and that camera's columns.
void add_held_cameras(AlignmentData& d, const AlignInput& in, double c, const Eigen::MatrixXd& Hinv) {
  std::vector<Eigen::MatrixXd> H_oc(d.V, Eigen::MatrixXd::Zero(d.P, 7));
  Eigen::VectorXd row(d.P);
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const double w = tukey_weight(d.e, i, c);
    if (w <= 0.0 || in.views[d.samples[i].view].camera_covariance.isZero(0.0)) continue;
    jacobian_row(d, d.e, i, row);
    H_oc[d.samples[i].view].noalias() += w * row * d.e.J[i].leftCols<7>();
  }
  for (int v = 0; v < d.V; ++v) {
    if (in.views[v].camera_covariance.isZero(0.0)) continue;
    const Eigen::MatrixXd K = Hinv * H_oc[v];
    d.sandwich += K * in.views[v].camera_covariance * K.transpose();
  }
}

/// The covariance at the final residuals: a sandwich estimator H^-1 B H^-1
/// with B summed over model edges (clusters), since the samples of one edge
/// share their localisation error (appearance, blur, the edge's own noise);
/// s^2 H^-1 alone was 3-5x optimistic. Then the errors no residual shows.
void covariance(AlignmentData& d, const AlignInput& in) {
  const std::optional<double> scale = tukey_scale(d, kLevels.back().search_px);
  if (!scale || !d.has_H_last) return;
  const double c = *scale;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(d.P, d.P);
  std::map<int, Eigen::VectorXd> score;
  Eigen::VectorXd row(d.P);
  int n = 0;
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const double w = tukey_weight(d.e, i, c);
    if (w <= 0.0) continue;
    jacobian_row(d, d.e, i, row);
    H.selfadjointView<Eigen::Lower>().rankUpdate(row, w);
    auto it = score.try_emplace(d.samples[i].cluster, Eigen::VectorXd::Zero(d.P)).first;
    it->second += w * d.e.r[i] * row;
    ++n;
  }
  H = H.selfadjointView<Eigen::Lower>();
  double prior_lambda = 0.0;
  if (d.NL > 0) {
    prior_lambda = link_prior_weight(d, in, c, weighted_variance(d, c));
    for (int j = 0; j < d.NL; ++j) H(d.link_col + j, d.link_col + j) += prior_lambda;
  }
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(d.P, d.P);
  // The prior's score: lambda x (a link error of sd prior): a link no
  // edge sees keeps its prior sd.
  for (int j = 0; j < d.NL; ++j)
    B(d.link_col + j, d.link_col + j) += prior_lambda * prior_lambda * in.o.arm_link_prior_m * in.o.arm_link_prior_m;
  for (const auto& [k, g] : score) B.selfadjointView<Eigen::Lower>().rankUpdate(g);
  B = B.selfadjointView<Eigen::Lower>();
  const double G = static_cast<double>(score.size());
  const double correction = G > 1 ? G / (G - 1) * (n - 1.0) / std::max(1.0, n - 1.0 - d.P) : 1.0;
  const Eigen::MatrixXd Hinv = H.ldlt().solve(Eigen::MatrixXd::Identity(d.P, d.P));
  d.sandwich = correction * Hinv * B * Hinv;
  d.has_sandwich = true;
  d.sandwich = 0.5 * (d.sandwich + d.sandwich.transpose());
  // The second estimator: s^2 H^-1 with the samples counted as the
  // number of model edges (the effective number of independent samples,
  // n / G). The reported covariance is the larger of the two (by trace):
  // the sandwich misses a bias shared by most edges.
  const double s2 = weighted_variance(d, c);
  const Eigen::MatrixXd effective = s2 * (n / std::max(1.0, G - d.P > 1 ? G : 1.0)) * Hinv;
  if (effective.trace() > d.sandwich.trace()) d.sandwich = effective;
  add_shared_offsets(d, in, c, Hinv);
  add_edge_offsets(d, in, c, Hinv);
  if (!d.refine_camera) add_held_cameras(d, in, c, Hinv);
}

// --- the result --------------------------------------------------------------

/// Diagnostic (docs/estimation.md): FORESIGHT_ALIGN_DEBUG=PATH writes the
/// first view's first frame at 2x with every final sample at its
/// projection (green: matched within 1 px, yellow: matched further, red:
/// no edge found) and prints their mean signed residual (a shading bias
/// shows there).
void debug_image(const AlignmentData& d, const AlignInput& in) {
  const char* dbg = std::getenv("FORESIGHT_ALIGN_DEBUG");
  if (dbg == nullptr) return;
  cv::Mat img;
  cv::cvtColor(in.views[0].frames[0].image_bgr, img, cv::COLOR_BGR2GRAY);
  cv::cvtColor(img, img, cv::COLOR_GRAY2BGR);
  cv::resize(img, img, cv::Size(), 2.0, 2.0, cv::INTER_NEAREST);
  const camera::Camera cam = camera_of(d, in, 0);
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    if (d.samples[i].view != 0 || d.samples[i].frame != 0) continue;
    const Eigen::Vector3d p =
        d.samples[i].on_object ? Eigen::Vector3d(d.obj_R * d.samples[i].p_local + d.obj_t) : d.samples[i].p_local;
    const Eigen::Vector2d uv = cam.project(p) * 2.0;
    const cv::Scalar col = !d.e.matched[i]              ? cv::Scalar(0, 0, 255)
                           : std::abs(d.e.r[i]) < 1.0 ? cv::Scalar(0, 255, 0)
                                                      : cv::Scalar(0, 255, 255);
    cv::circle(img, cv::Point2d(uv.x(), uv.y()), 2, col, -1);
    if (d.e.matched[i]) {
      sum += d.e.r[i];
      ++n;
    }
  }
  std::fprintf(stderr, "debug: mean residual %.3f px over %d\n", n ? sum / n : 0.0, n);
  cv::imwrite(dbg, img);
}

/// The final residual, score, samples and covariance into the result.
void summarize(const AlignmentModel& m, AlignmentData& d, const AlignInput& in) {
  double r2 = 0.0;
  int n_in = 0;
  for (std::size_t i = 0; i < d.samples.size(); ++i)
    if (d.e.matched[i] && std::abs(d.e.r[i]) < 1.0) {
      r2 += d.e.r[i] * d.e.r[i];
      ++n_in;
    }
  d.res.residual_rms_px = n_in ? std::sqrt(r2 / n_in) : 0.0;
  std::vector<Sample>& final_samples = d.final_samples;
  collect(m, d, in, final_samples, nullptr, -1);
  d.res.final_score_px = score_of(d, in, final_samples);
  d.res.visible_samples = static_cast<int>(final_samples.size());
  d.res.matched_samples = n_in;
  if (d.has_sandwich) {
    d.res.covariance = d.sandwich;
  } else if (d.has_H_last) {
    d.res.covariance = d.s2_last * d.H_last.ldlt().solve(Eigen::MatrixXd::Identity(d.P, d.P));
  }
}

/// How far the model moved in the images from the start: beyond the
/// coarsest search range no edge evidence vouches for the result (seen: a
/// single wide view pulling the ORU 0.3 m onto the panel's edges).
double moved_px(AlignmentData& d, const AlignInput& in) {
  double moved = 0.0;
  const Pose start_obj = in.start ? *in.start : Pose::Identity();
  const auto end_obj = object_pose(d, in);
  for (const auto& s : d.samples) {
    const camera::Camera end_cam = camera_of(d, in, s.view);
    const camera::Camera& start_cam = in.views[s.view].camera;
    const Eigen::Vector3d p_end = s.on_object ? Eigen::Vector3d(*end_obj * s.p_local)
                                              : Eigen::Vector3d(d.frame(s.view, s.frame).link_poses[s.link] * s.p_link);
    const Eigen::Vector3d p_start = s.on_object ? Eigen::Vector3d(start_obj * s.p_local) : p_end;
    if (start_cam.to_camera(p_start).z() <= kNear_m || end_cam.to_camera(p_end).z() <= kNear_m) continue;
    moved = std::max(moved, (end_cam.project(p_end) - start_cam.project(p_start)).norm());
  }
  return moved;
}

/// The object's move against the start's own uncertainty (the clicks'): a
/// disagreement beyond both covariances means the edges or the clicks are
/// wrong, and nothing here says which. Returns the turn (deg).
double start_disagreement(AlignmentData& d, const AlignInput& in) {
  if (!(d.refine_object && in.o.object_start_covariance && in.start && d.res.covariance.rows() == d.P)) return 0.0;
  const Eigen::AngleAxisd turn(in.start->linear().transpose() * d.obj_R);
  Eigen::Matrix<double, 6, 1> moved;
  moved << turn.angle() * turn.axis(), d.obj_t - in.start->translation();
  // The start's rpy covariance in body rotation increments (the object's parameters here).
  Eigen::Matrix<double, 6, 6> T = Eigen::Matrix<double, 6, 6>::Identity();
  T.topLeftCorner<3, 3>() = calibration::rpy_rate_matrix(rpy_from_rotation(in.start->linear()));
  const Eigen::Matrix<double, 6, 6> C =
      T * *in.o.object_start_covariance * T.transpose() + d.res.covariance.block<6, 6>(d.obj_col, d.obj_col);
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(C);
  if (ldlt.info() == Eigen::Success && ldlt.isPositive())
    d.res.start_disagreement_sigma = std::sqrt(std::max(0.0, moved.dot(ldlt.solve(moved))));
  const Eigen::LDLT<Eigen::Matrix3d> ldlt_p(C.bottomRightCorner<3, 3>());
  if (ldlt_p.info() == Eigen::Success && ldlt_p.isPositive())
    d.res.start_position_disagreement_sigma =
        std::sqrt(std::max(0.0, moved.tail<3>().dot(ldlt_p.solve(moved.tail<3>()))));
  return turn.angle() * 180.0 / M_PI;
}

/// Aligned or refused (the first reason that applies), and what goes back.
void verdict(AlignmentData& d, const AlignInput& in) {
  const double matched_fraction =
      d.samples.empty() ? 0.0 : static_cast<double>(d.res.matched_samples) / d.samples.size();
  const double moved = moved_px(d, in);
  const double turned_deg = start_disagreement(d, in);
  char buf[320];
  // The disagreement first: it is the one that names a physical conflict
  // (seen: a single view's ORU 0.17 m off the clicks, also 29% matched).
  if (d.res.start_disagreement_sigma > in.o.max_start_disagreement_sigma) {
    std::snprintf(buf, sizeof buf,
                  "the object moved %.0f mm and turned %.1f deg from its start pose, %.1f sigma of the start's and the "
                  "alignment's pose uncertainty together (limit %.1f): the edges disagree with the start (the clicks)",
                  1e3 * (d.obj_t - in.start->translation()).norm(), turned_deg, d.res.start_disagreement_sigma,
                  in.o.max_start_disagreement_sigma);
    d.res.status = AlignStatus::Refused;
    d.res.reason = buf;
  } else if (d.res.final_score_px > d.res.start_score_px + 0.02) {
    std::snprintf(buf, sizeof buf, "the edge distance got worse: %.2f px at the start, %.2f px after alignment",
                  d.res.start_score_px, d.res.final_score_px);
    d.res.status = AlignStatus::Refused;
    d.res.reason = buf;
  } else if (matched_fraction < in.o.min_matched_fraction) {
    std::snprintf(buf, sizeof buf,
                  "only %.0f%% of the %zu visible model edge samples lie within 1 px of an image edge (need %.0f%%)",
                  100.0 * matched_fraction, d.samples.size(), 100.0 * in.o.min_matched_fraction);
    d.res.status = AlignStatus::Refused;
    d.res.reason = buf;
  } else if (moved > kLevels.front().search_px) {
    std::snprintf(buf, sizeof buf,
                  "the model moved %.0f px from the start, beyond the %.0f px search range that edges can vouch for",
                  moved, kLevels.front().search_px);
    d.res.status = AlignStatus::Refused;
    d.res.reason = buf;
  } else {
    d.res.status = AlignStatus::Aligned;
  }
  if (d.res.status == AlignStatus::Aligned) {
    for (int v = 0; v < d.V; ++v) d.res.cameras[v] = camera_of(d, in, v);
    if (d.refine_object) d.res.base_T_object = object_pose(d, in);
  }
  d.res.arm_link_delta_m = d.res.status == AlignStatus::Aligned ? d.link_delta : d.link_start;
  if (d.NL > 0) {
    d.res.arm_link_sigma_m.assign(d.nseg, 0.0);
    if (d.res.covariance.rows() == d.P)
      for (int j = 0; j < d.NL; ++j)
        d.res.arm_link_sigma_m[d.link_segs[j]] = std::sqrt(d.res.covariance(d.link_col + j, d.link_col + j));
  }
}

AlignResult finish(AlignmentData& d) {
  d.res.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - d.t0).count();
  return std::move(d.res);
}

/// The steps in order: the samples and start score, each level's robust
/// Gauss-Newton, the final residuals, the covariance, the verdict.
AlignResult run(const AlignmentModel& m, AlignmentData& d, const AlignInput& in) {
  // Start: visibility (the samples serve the first level too) and score.
  collect(m, d, in, d.samples, &d.per_view, 0);
  for (int v = 0; v < d.V; ++v)
    if (d.per_view[v] == 0) {
      d.res.status = AlignStatus::NotInView;
      d.res.reason = std::string("the ") + (d.refine_camera ? "arm" : "object") + " model is not in view of camera '" +
                    in.views[v].camera.name + "': none of its edges projects visibly into the image";
      return finish(d);
    }
  d.res.start_score_px = score_of(d, in, d.samples);
  for (int li = 0; li < static_cast<int>(kLevels.size()); ++li) {
    if (li > 0) collect(m, d, in, d.samples, nullptr, li);
    if (static_cast<int>(d.samples.size()) < in.o.min_visible_samples) {
      d.res.status = AlignStatus::Refused;
      d.res.reason = "too few model edges in view: " + std::to_string(d.samples.size()) + " samples (need " +
                    std::to_string(in.o.min_visible_samples) + ")";
      d.res.visible_samples = static_cast<int>(d.samples.size());
      return finish(d);
    }
    for (int it = 0; it < in.o.iterations_per_level; ++it)
      if (!gauss_newton_step(m, d, in, li)) break;
  }
  // Final residuals at the finest level, then the covariance.
  evaluate(d, in, d.samples, static_cast<int>(kLevels.size()) - 1, kLevels.back(), d.e, true);
  covariance(d, in);
  debug_image(d, in);
  summarize(m, d, in);
  verdict(d, in);
  return finish(d);
}


// --- one call -------------------------------------------------------------------

/// Checks the call's input, prepares its frames into d and sets the
/// parameters at their start: d becomes this call's (its buffers kept).
void begin(const AlignmentModel& m, AlignmentData& d, const AlignInput& in) {
  const auto& views = in.views;
  const AlignOptions& o = in.o;
  d.res = AlignResult{};
  d.next_cluster = 0;  // the clusters are this call's
  d.has_H_last = d.has_sandwich = false;
  d.s2_last = 0.0;
  d.refine_camera = o.refine != Refine::Object;
  d.refine_object = o.refine != Refine::Camera;
  d.V = static_cast<int>(views.size());
  if (d.refine_object && !in.start)
    throw std::invalid_argument("refining the object needs its start pose (--object-pose)");
  if (d.refine_object && !m.object) throw std::invalid_argument("refining the object needs the object model");
  d.first_frame.assign(d.V, 0);
  d.frame_count.assign(d.V, 0);
  int total = 0;
  for (int v = 0; v < d.V; ++v) {
    d.first_frame[v] = total;
    d.frame_count[v] = static_cast<int>(views[v].frames.size());
    total += d.frame_count[v];
  }
  if (static_cast<int>(d.frames.size()) < total) d.frames.resize(total);
  for (int v = 0; v < d.V; ++v) {
    if (views[v].frames.empty()) throw std::invalid_argument("camera '" + views[v].camera.name + "' has no frames");
    if (!(views[v].camera.viewport == m.vp))
      throw std::invalid_argument("camera '" + views[v].camera.name + "' has another viewport than the aligner's");
    const auto& cc = views[v].camera_covariance;
    if (!cc.allFinite() || (cc.diagonal().array() < 0.0).any() || !cc.isApprox(cc.transpose(), 1e-9))
      throw std::invalid_argument("camera '" + views[v].camera.name +
                                  "': its covariance is not a finite symmetric matrix with a non-negative diagonal");
    for (int k = 0; k < d.frame_count[v]; ++k) prepare(m, d, views[v].frames[k], d.frame(v, k));
  }
  d.cam_R.clear();
  d.cam_c.clear();
  d.cam_f.clear();
  for (int v = 0; v < d.V; ++v) {
    d.cam_R.push_back(views[v].camera.base_T_camera.linear());
    d.cam_c.push_back(views[v].camera.base_T_camera.translation());
    d.cam_f.push_back(views[v].camera.f_px);
  }
  d.obj_R = in.start ? Eigen::Matrix3d(in.start->linear()) : Eigen::Matrix3d::Identity();
  d.obj_t = in.start ? Eigen::Vector3d(in.start->translation()) : Eigen::Vector3d::Zero();
  init_links(m, d, in);
  d.P = (d.refine_camera ? 7 * d.V : 0) + (d.refine_object ? 6 : 0) + d.NL;
  d.obj_col = d.refine_camera ? 7 * d.V : 0;
  d.link_col = d.P - d.NL;
  for (int v = 0; v < d.V; ++v) d.res.cameras.push_back(views[v].camera);
  d.res.base_T_object = in.start;
  d.res.camera_change.assign(d.V, Eigen::Matrix<double, 7, 1>::Zero());
}

}  // namespace

// The facade: the model (built here or shared) and this aligner's data.
struct ModelAligner::Impl {
  Impl(render::GlContext& ctx, std::shared_ptr<const AlignmentModel> m) : model(std::move(m)), data(ctx, *model) {}
  std::shared_ptr<const AlignmentModel> model;
  AlignmentData data;
};

ModelAligner::ModelAligner(render::GlContext& context, const RobotModel& arm, const ObjectModel* object,
                           const camera::Viewport& viewport)
    : ModelAligner(context, make_alignment_model(arm, object, viewport)) {}

ModelAligner::ModelAligner(render::GlContext& context, std::shared_ptr<const AlignmentModel> model) {
  if (!model) throw std::invalid_argument("ModelAligner: no alignment model");
  impl_ = std::make_unique<Impl>(context, std::move(model));
}

ModelAligner::~ModelAligner() = default;

AlignResult ModelAligner::align(const std::vector<AlignView>& views, const std::optional<Pose>& base_T_object_start,
                                const AlignOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  if (views.empty()) throw std::invalid_argument("align: no views");
  const AlignmentModel& m = *impl_->model;
  AlignmentData& d = impl_->data;
  const AlignInput in{views, base_T_object_start, o};
  begin(m, d, in);
  d.t0 = t0;
  return run(m, d, in);
}

ModelAligner::FrameScore ModelAligner::score(const camera::Camera& camera, const AlignFrame& frame,
                                             const std::optional<Pose>& base_T_object, const AlignOptions& o) {
  const AlignmentModel& m = *impl_->model;
  AlignmentData& d = impl_->data;
  if (d.frames.empty()) d.frames.resize(1);
  FrameData& f = d.frames[0];
  prepare(m, d, frame, f);
  std::vector<Sample>& samples = d.samples;
  samples.clear();
  sample(m, d, camera, f, base_T_object, 0, 0, true, false, o, samples);
  FrameScore out;
  out.visible_samples = static_cast<int>(samples.size());
  if (samples.empty()) {
    out.score_px = o.score_cap_px;
    return out;
  }
  const Gradient& g = gradient(d, f, -1, kScoreLevel.blur_px);
  const double thr = o.gradient_threshold * 0.7 / std::max(0.7, kScoreLevel.blur_px);
  double s2 = 0.0;
  int m1 = 0;
  // The silhouette IoU: the arm's rendered area A (label image of this
  // frame), and the area between the model's silhouette and the image's
  // edges, D = sum over silhouette samples of |offset| x the contour length
  // each stands for (a miss counts as the cap): IoU = (A - D/2) / (A + D/2).
  double area = 0.0;
  for (int y = 0; y < d.layer.rows; ++y) {
    const std::uint8_t* p = d.layer.ptr<std::uint8_t>(y);
    for (int x = 0; x < d.layer.cols; ++x, p += 4) {
      const int label = p[2] + 256 * p[1];
      if (label > 0 && label <= static_cast<int>(m.prims.size()) && m.prims[label - 1].link >= 0) area += 1.0;
    }
  }
  double between = 0.0;
  for (const auto& s : samples) {
    const camera::Projection pr = camera::project_with_jacobians(camera, s.p_local);
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
