#pragma once
// Triangle meshes built from the visual primitives of the URDF and the ORU
// model (boxes, cylinders, spheres), each with its wire-frame: the feature
// edges an operator expects to see (a box's 12 edges, a cylinder's two rims
// and a few generators, a sphere's equator and two meridians), not every
// triangle edge. Set-up code (allocates); not for a real-time loop.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight::render {

struct Vertex {
  float position[3];  ///< body frame, metres
  float normal[3];    ///< unit, body frame
  float rgba[4];
};

struct Mesh {
  std::vector<Vertex> vertices;
  std::vector<std::uint32_t> triangles;  ///< 3 vertex indices each
  std::vector<std::uint32_t> edges;      ///< 2 vertex indices each: the wire-frame

  int triangle_count() const { return static_cast<int>(triangles.size() / 3); }
  int edge_count() const { return static_cast<int>(edges.size() / 2); }
  /// Append `other` (indices re-based).
  void append(const Mesh& other);
};

/// A box of full extents size_m centred at body_T_box.
Mesh make_box(const Eigen::Vector3d& size_m, const Pose& body_T_box, const Eigen::Vector4d& rgba);
/// A closed cylinder along the z axis of body_T_cylinder, centred there.
Mesh make_cylinder(double radius_m, double length_m, const Pose& body_T_cylinder, const Eigen::Vector4d& rgba,
                   int segments = 24);
Mesh make_sphere(double radius_m, const Pose& body_T_sphere, const Eigen::Vector4d& rgba, int slices = 20,
                 int stacks = 12);
/// One URDF visual primitive, placed by shape.link_T_shape in the link frame.
Mesh make_shape(const VisualShape& shape);
/// The task object in its own frame: the box and its extra visuals.
Mesh make_object_mesh(const ObjectModel& object);
/// A flat checkered floor in the plane z = z_m (a background for the
/// synthetic camera), tiles of tile_m, n x n tiles centred on (cx, cy).
Mesh make_floor(double cx_m, double cy_m, double z_m, double tile_m, int n, const Eigen::Vector4d& rgba_a,
                const Eigen::Vector4d& rgba_b);

}  // namespace foresight::render
