#pragma once
// The robot model: built once from the URDF (urdfdom -> our own conversion to
// a KDL chain; not Debian's ROS1 kdl_parser), immutable afterwards and shared
// by every thread. Per-thread scratch memory lives in KinematicsWorkspace
// (kinematics.hpp). Both the ground (simulated arm, previews) and the remote
// (control loop) use this same code.
//
// Links are numbered along the serial chain: 0 is the root (`base`), k >= 1 is
// the child link of the k-th segment. Fixed joints (the F/T sensor mount, the
// tool) are segments too, so every link of the chain has an index.

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "foresight/common/pose.hpp"

namespace KDL {
class Chain;  // <kdl/chain.hpp>: only the files that walk the chain include it
}

namespace foresight {

/// Limits of one actuated joint, SI units. URDF gives position, velocity and
/// effort; acceleration comes from the `acceleration` attribute of the joint's
/// <limit> element (a Foresight extension urdfdom ignores), required.
struct JointLimits {
  double lower_rad = 0.0;
  double upper_rad = 0.0;
  double velocity_rad_s = 0.0;
  double acceleration_rad_s2 = 0.0;
  double effort_nm = 0.0;
};

/// One visual primitive of a link, from the URDF <visual> elements.
struct VisualShape {
  enum class Type { Box, Cylinder, Sphere };
  Type type = Type::Box;
  /// Box: full extents x, y, z. Cylinder (axis along z): radius, length, 0.
  /// Sphere: radius, 0, 0. Metres.
  Eigen::Vector3d size_m = Eigen::Vector3d::Zero();
  Pose link_T_shape = Pose::Identity();
  Eigen::Vector4d rgba = Eigen::Vector4d(0.7, 0.7, 0.7, 1.0);
};

struct LinkInfo {
  std::string name;
  std::vector<VisualShape> visuals;
  double mass_kg = 0.0;
};

struct RobotModelOptions {
  std::string base_link = "base";
  std::string tip_link = "lst_tip";
};

class RobotModel {
 public:
  /// Parse and convert a URDF file. Throws InputError naming the file and the
  /// offending element: unreadable file, XML/URDF syntax, base or tip missing,
  /// a non-serial chain (a link on the chain with more than one child), a
  /// movable joint without limits or with lower > upper, an unsupported joint
  /// type (only revolute and fixed).
  static RobotModel from_file(const std::string& urdf_path, const RobotModelOptions& options = {});
  /// As from_file, from XML text; `source_name` is used in error messages.
  static RobotModel from_xml(const std::string& urdf_xml, const std::string& source_name,
                             const RobotModelOptions& options = {});

  /// Number of actuated (revolute) joints.
  int dof() const { return static_cast<int>(joint_names_.size()); }
  const std::vector<std::string>& joint_names() const { return joint_names_; }
  const std::vector<JointLimits>& limits() const { return limits_; }

  /// Links along the chain, index 0 = base.
  const std::vector<LinkInfo>& links() const { return links_; }
  /// Index of a link by name, -1 when it is not on the chain.
  int link_index(const std::string& name) const;
  /// Index of the tool tip link (options.tip_link).
  int tip_index() const { return static_cast<int>(links_.size()) - 1; }

  /// The KDL chain (include <kdl/chain.hpp> to use it).
  const KDL::Chain& chain() const { return *chain_; }
  /// Number of chain segments (joints, the F/T mount, the tool, the tip).
  int segment_count() const { return segment_count_; }
  /// Gravity in the base frame (m/s^2), default (0, 0, -9.81).
  const Eigen::Vector3d& gravity() const { return gravity_; }

  /// True when every q_i is finite and within [lower, upper] (+tol).
  bool within_limits(const Eigen::Ref<const Eigen::VectorXd>& q, double tol_rad = 0.0) const;
  /// A configuration in the middle of the joint ranges (a reasonable seed).
  Eigen::VectorXd mid_configuration() const;

  const std::string& source() const { return source_; }

  /// Identity of this model, for tying a KinematicsWorkspace to it: unique to
  /// each model built (from_file, from_xml, with_link_lengths_changed); a copy
  /// has its original's id (a RobotModel is immutable, so a copy is the same model).
  std::uint64_t id() const noexcept { return id_; }

  /// This model with the length of every link offset changed: the origin of
  /// chain segment k (the joint origin in its parent) moves by delta_m[k]
  /// along its own direction (segments with a zero offset keep it). For
  /// studies of arm-model error. Throws std::invalid_argument when delta_m
  /// does not have one value per chain segment (segment_count()).
  RobotModel with_link_lengths_changed(const std::vector<double>& delta_m) const;
  /// The chain segments whose origin has a length offset (longer than
  /// kMinOffset_m), in chain order: the links whose lengths
  /// with_link_lengths_changed changes and arm-model studies perturb.
  std::vector<int> offset_segments() const;
  static constexpr double kMinOffset_m = 1e-9;

 private:
  RobotModel() = default;
  std::uint64_t id_ = 0;
  std::string source_;
  std::shared_ptr<const KDL::Chain> chain_;  // immutable: copies share it
  int segment_count_ = 0;
  std::vector<std::string> joint_names_;
  std::vector<JointLimits> limits_;
  std::vector<LinkInfo> links_;
  Eigen::Vector3d gravity_{0.0, 0.0, -9.81};
};

}  // namespace foresight
