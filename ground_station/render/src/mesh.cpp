#include "foresight/render/mesh.hpp"

#include <cmath>
#include <stdexcept>

namespace foresight::render {

namespace {

Vertex make_vertex(const Pose& T, const Eigen::Vector3d& p, const Eigen::Vector3d& n, const Eigen::Vector4d& rgba) {
  const Eigen::Vector3d pb = T * p;
  const Eigen::Vector3d nb = T.linear() * n;
  Vertex v{};
  for (int i = 0; i < 3; ++i) {
    v.position[i] = static_cast<float>(pb[i]);
    v.normal[i] = static_cast<float>(nb[i]);
  }
  for (int i = 0; i < 4; ++i) v.rgba[i] = static_cast<float>(rgba[i]);
  return v;
}

std::uint32_t add(Mesh& m, const Vertex& v) {
  m.vertices.push_back(v);
  return static_cast<std::uint32_t>(m.vertices.size() - 1);
}

}  // namespace

void Mesh::append(const Mesh& other) {
  const auto base = static_cast<std::uint32_t>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  for (auto i : other.triangles) triangles.push_back(base + i);
  for (auto i : other.edges) edges.push_back(base + i);
}

Mesh make_box(const Eigen::Vector3d& size_m, const Pose& T, const Eigen::Vector4d& rgba) {
  Mesh m;
  const Eigen::Vector3d h = size_m / 2.0;
  // Corner k has sign bits (x: bit 0, y: bit 1, z: bit 2).
  auto corner = [&](int k) {
    return Eigen::Vector3d((k & 1) ? h.x() : -h.x(), (k & 2) ? h.y() : -h.y(), (k & 4) ? h.z() : -h.z());
  };
  // Six faces, each with its own four vertices (flat normals), counter-clockwise seen from outside.
  const int faces[6][4] = {{0, 2, 6, 4}, {1, 5, 7, 3}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 6, 7, 5}};
  const Eigen::Vector3d normals[6] = {-Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY(),
                                      Eigen::Vector3d::UnitY(),  -Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitZ()};
  std::uint32_t corner_vertex[8];
  for (int f = 0; f < 6; ++f) {
    std::uint32_t idx[4];
    for (int i = 0; i < 4; ++i) {
      idx[i] = add(m, make_vertex(T, corner(faces[f][i]), normals[f], rgba));
      corner_vertex[faces[f][i]] = idx[i];
    }
    m.triangles.insert(m.triangles.end(), {idx[0], idx[1], idx[2], idx[0], idx[2], idx[3]});
  }
  // The 12 edges: corners differing in one bit.
  for (int a = 0; a < 8; ++a)
    for (int bit = 1; bit < 8; bit <<= 1)
      if (!(a & bit)) m.edges.insert(m.edges.end(), {corner_vertex[a], corner_vertex[a | bit]});
  return m;
}

Mesh make_cylinder(double r, double len, const Pose& T, const Eigen::Vector4d& rgba, int segments) {
  if (segments < 3) throw std::invalid_argument("cylinder needs at least 3 segments");
  Mesh m;
  const double hz = len / 2.0;
  std::vector<std::uint32_t> side_bottom, side_top;
  for (int i = 0; i < segments; ++i) {
    const double a = 2.0 * M_PI * i / segments;
    const Eigen::Vector3d radial(std::cos(a), std::sin(a), 0.0);
    side_bottom.push_back(add(m, make_vertex(T, r * radial - hz * Eigen::Vector3d::UnitZ(), radial, rgba)));
    side_top.push_back(add(m, make_vertex(T, r * radial + hz * Eigen::Vector3d::UnitZ(), radial, rgba)));
  }
  for (int i = 0; i < segments; ++i) {
    const int j = (i + 1) % segments;
    m.triangles.insert(m.triangles.end(), {side_bottom[i], side_bottom[j], side_top[j], side_bottom[i], side_top[j], side_top[i]});
  }
  for (int cap = 0; cap < 2; ++cap) {
    const double z = cap ? hz : -hz;
    const Eigen::Vector3d n(0.0, 0.0, cap ? 1.0 : -1.0);
    const std::uint32_t centre = add(m, make_vertex(T, Eigen::Vector3d(0, 0, z), n, rgba));
    std::vector<std::uint32_t> ring;
    for (int i = 0; i < segments; ++i) {
      const double a = 2.0 * M_PI * i / segments;
      ring.push_back(add(m, make_vertex(T, Eigen::Vector3d(r * std::cos(a), r * std::sin(a), z), n, rgba)));
    }
    for (int i = 0; i < segments; ++i) {
      const int j = (i + 1) % segments;
      if (cap) m.triangles.insert(m.triangles.end(), {centre, ring[i], ring[j]});
      else m.triangles.insert(m.triangles.end(), {centre, ring[j], ring[i]});
    }
  }
  // Wire-frame: both rims and eight generators.
  for (int i = 0; i < segments; ++i) {
    const int j = (i + 1) % segments;
    m.edges.insert(m.edges.end(), {side_bottom[i], side_bottom[j], side_top[i], side_top[j]});
  }
  const int step = std::max(1, segments / 8);
  for (int i = 0; i < segments; i += step) m.edges.insert(m.edges.end(), {side_bottom[i], side_top[i]});
  return m;
}

Mesh make_sphere(double r, const Pose& T, const Eigen::Vector4d& rgba, int slices, int stacks) {
  if (slices < 4 || stacks < 2) throw std::invalid_argument("sphere needs at least 4 slices and 2 stacks");
  Mesh m;
  // (stacks + 1) rings of (slices) vertices, poles included as degenerate rings.
  auto at = [&](int i, int j) { return static_cast<std::uint32_t>(i * slices + (j % slices)); };
  for (int i = 0; i <= stacks; ++i) {
    const double theta = M_PI * i / stacks;  // from +z
    for (int j = 0; j < slices; ++j) {
      const double phi = 2.0 * M_PI * j / slices;
      const Eigen::Vector3d n(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
      add(m, make_vertex(T, r * n, n, rgba));
    }
  }
  for (int i = 0; i < stacks; ++i)
    for (int j = 0; j < slices; ++j)
      m.triangles.insert(m.triangles.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i, j + 1)});
  // Equator (nearest ring) and two meridians.
  const int eq = stacks / 2;
  for (int j = 0; j < slices; ++j) m.edges.insert(m.edges.end(), {at(eq, j), at(eq, j + 1)});
  for (int j : {0, slices / 4})
    for (int i = 0; i < stacks; ++i) {
      m.edges.insert(m.edges.end(), {at(i, j), at(i + 1, j)});
      m.edges.insert(m.edges.end(), {at(i, j + slices / 2), at(i + 1, j + slices / 2)});
    }
  return m;
}

Mesh make_shape(const VisualShape& s) {
  switch (s.type) {
    case VisualShape::Type::Box: return make_box(s.size_m, s.link_T_shape, s.rgba);
    case VisualShape::Type::Cylinder: return make_cylinder(s.size_m.x(), s.size_m.y(), s.link_T_shape, s.rgba);
    case VisualShape::Type::Sphere: return make_sphere(s.size_m.x(), s.link_T_shape, s.rgba);
  }
  throw std::invalid_argument("unknown visual shape type");
}

Mesh make_object_mesh(const ObjectModel& object) {
  Mesh m = make_box(object.size_m, object.oru_T_box, object.rgba);
  for (const auto& v : object.visuals) m.append(make_shape(v));
  return m;
}

Mesh make_floor(double cx, double cy, double z, double tile, int n, const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  Mesh m;
  const double x0 = cx - tile * n / 2.0, y0 = cy - tile * n / 2.0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const Eigen::Vector4d& c = ((i + j) % 2) ? a : b;
      Mesh t;
      const double x = x0 + i * tile, y = y0 + j * tile;
      const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
      const Pose I = Pose::Identity();
      const std::uint32_t v0 = add(t, make_vertex(I, {x, y, z}, up, c));
      const std::uint32_t v1 = add(t, make_vertex(I, {x + tile, y, z}, up, c));
      const std::uint32_t v2 = add(t, make_vertex(I, {x + tile, y + tile, z}, up, c));
      const std::uint32_t v3 = add(t, make_vertex(I, {x, y + tile, z}, up, c));
      t.triangles = {v0, v1, v2, v0, v2, v3};
      t.edges = {v0, v1, v1, v2, v2, v3, v3, v0};
      m.append(t);
    }
  return m;
}

}  // namespace foresight::render
