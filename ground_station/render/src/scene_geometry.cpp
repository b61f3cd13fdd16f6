#include "foresight/render/scene_geometry.hpp"

#include <stdexcept>

#include "foresight/common/error.hpp"

namespace foresight::render {

ArmGeometry::ArmGeometry(Renderer& renderer, const RobotModel& model) : model_(model), ws_(model) {
  const auto& links = model.links();
  for (int k = 0; k < static_cast<int>(links.size()); ++k) {
    if (links[k].visuals.empty()) continue;
    Mesh m;
    for (const auto& v : links[k].visuals) m.append(make_shape(v));
    link_body_.emplace_back(k, renderer.add_body(m));
    triangles_ += m.triangle_count();
  }
}

void ArmGeometry::check_joints(const Eigen::VectorXd& q) const {
  if (q.size() != model_.dof())
    throw std::invalid_argument("joint vector has " + std::to_string(q.size()) + " values but the arm has " +
                                std::to_string(model_.dof()) + " joints");
}

void ArmGeometry::append(const Eigen::VectorXd& q, DrawList& list, const Eigen::Vector4d& wire_rgba,
                         const std::optional<Eigen::Vector4d>& solid_rgba) {
  check_joints(q);
  for (const auto& [link, body] : link_body_) {
    BodyInstance b;
    b.body = body;
    b.base_T_body = forward_kinematics(model_, ws_, q, link);
    b.wire_rgba = wire_rgba;
    b.solid_rgba = solid_rgba;
    list.bodies.push_back(b);
  }
}

Pose ArmGeometry::tip_pose(const Eigen::VectorXd& q) {
  check_joints(q);
  return forward_kinematics(model_, ws_, q, model_.tip_index());
}

int add_object_body(Renderer& renderer, const ObjectModel& object) { return renderer.add_body(make_object_mesh(object)); }

LineSet tool_path(ArmGeometry& arm, const Eigen::MatrixXd& q_samples, const Eigen::Vector4d& rgba) {
  LineSet s;
  s.rgba = rgba;
  s.strip = true;
  for (Eigen::Index i = 0; i < q_samples.rows(); ++i)
    s.points_base.push_back(arm.tip_pose(q_samples.row(i).transpose()).translation());
  return s;
}

camera::Camera scene_camera(const Scene& scene, const std::string& name, const std::string& source) {
  const auto it = scene.cameras.find(name);
  if (it == scene.cameras.end()) {
    std::string known;
    for (const auto& [n, c] : scene.cameras) known += (known.empty() ? "" : ", ") + n;
    throw InputError(source, "no camera '" + name + "' (known: " + known + ")");
  }
  const SceneCamera& c = it->second;
  return camera::Camera::look_at(name, {c.width_px, c.height_px}, c.f_px, c.position_m, c.look_at_m, c.up);
}

}  // namespace foresight::render
