#pragma once
// What the overlays and the synthetic camera draw: the arm from the URDF's
// visual geometry posed by forward kinematics, the task object, the
// satellite panel, a floor. Set-up allocates; append() computes FK with a
// preallocated workspace but fills a DrawList (not for a real-time loop).

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/render/renderer.hpp"

namespace foresight::render {

/// Default overlay colours (wire/hidden modes).
inline const Eigen::Vector4d kArmWireRgba{0.2, 1.0, 0.3, 1.0};     ///< green
inline const Eigen::Vector4d kObjectWireRgba{1.0, 0.85, 0.1, 1.0};  ///< yellow

/// The arm's links as bodies of one renderer.
class ArmGeometry {
 public:
  /// Uploads one body per link that has visuals. The model must outlive this.
  ArmGeometry(Renderer& renderer, const RobotModel& model);

  /// Appends the link bodies at joint angles q (radians). Throws
  /// std::invalid_argument when q does not have model().dof() values.
  void append(const Eigen::VectorXd& q, DrawList& list, const Eigen::Vector4d& wire_rgba = kArmWireRgba,
              const std::optional<Eigen::Vector4d>& solid_rgba = std::nullopt);
  /// base_T_tip at q (the tool tip).
  Pose tip_pose(const Eigen::VectorXd& q);
  /// Triangles of all link bodies.
  int triangles() const { return triangles_; }
  const RobotModel& model() const { return model_; }

  /// Checks a joint vector's size; the message names both counts.
  void check_joints(const Eigen::VectorXd& q) const;

 private:
  const RobotModel& model_;
  KinematicsWorkspace ws_;
  std::vector<std::pair<int, int>> link_body_;  // (link index, body id)
  int triangles_ = 0;
};

/// The task object (box and visuals, object frame) as a body; returns its id.
int add_object_body(Renderer& renderer, const ObjectModel& object);

/// The tool-tip path along joint-space samples (one row of q per sample), as a polyline.
LineSet tool_path(ArmGeometry& arm, const Eigen::MatrixXd& q_samples, const Eigen::Vector4d& rgba = {1.0, 0.3, 1.0, 1.0});

/// The true camera `name` of the scene (look-at form). Throws InputError
/// naming scene_source and the known cameras when there is no such camera.
camera::Camera scene_camera(const Scene& scene, const std::string& name, const std::string& scene_source = "scene");

}  // namespace foresight::render
