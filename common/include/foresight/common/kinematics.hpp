#pragma once
// Kinematics and statics of a RobotModel as free functions of
// (model, workspace, q). The workspace holds every solver and buffer, sized
// once at construction; after that, forward_kinematics, jacobian and
// gravity_torques are real-time safe: no allocation, no locks, noexcept.
// inverse_kinematics is not for the control loop (iterative, ~0.1 ms).
// One workspace per thread; the model may be shared. (Each workspace holds its
// own copy of the KDL chain: KDL::Joint caches its last pose in mutable
// members, so the solvers of two threads must never share one chain.)
// The real-time functions cannot throw: a q of the wrong size, a link index
// out of range, or a workspace built for another model gives NaN outputs.
//
// A workspace is tied to the model it was built from (RobotModel::id(); a
// copy of the model is the same model). As Pinocchio's model.check(data),
// check(model, ws) says whether they belong together; call it at set-up
// (the real-time functions test the same identity, one integer compare, and
// answer NaN on a mismatch rather than another robot's kinematics).
// inverse_kinematics, not real-time, throws std::invalid_argument on a
// mismatch (a programming error, as Pinocchio's argument checks).

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "foresight/common/joints.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight {

using Vector6 = Eigen::Matrix<double, 6, 1>;
/// Joint-space vectors and 6 x n Jacobians with inline storage (no heap) for
/// up to kMaxJoints: what the real-time code may hold on its stack.
using JointVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, static_cast<int>(kMaxJoints), 1>;
using Jacobian = Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, static_cast<int>(kMaxJoints)>;

class KinematicsWorkspace {
 public:
  explicit KinematicsWorkspace(const RobotModel& model);  // allocates; not RT
  ~KinematicsWorkspace();
  KinematicsWorkspace(KinematicsWorkspace&&) noexcept;
  KinematicsWorkspace& operator=(KinematicsWorkspace&&) noexcept;
  KinematicsWorkspace(const KinematicsWorkspace&) = delete;
  KinematicsWorkspace& operator=(const KinematicsWorkspace&) = delete;

  /// RobotModel::id() of the model this workspace was built for.
  std::uint64_t model_id() const noexcept;

  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

/// True when `ws` was built for `model` (or a copy of it). RT-safe.
bool check(const RobotModel& model, const KinematicsWorkspace& ws) noexcept;

/// base_T_link for link index `link` (RobotModel::links(); default the tool
/// tip). q must have model.dof() entries. RT-safe.
Pose forward_kinematics(const RobotModel& model, KinematicsWorkspace& ws,
                        const Eigen::Ref<const Eigen::VectorXd>& q, int link = -1) noexcept;

/// Geometric Jacobian (6 x dof; rows vx vy vz wx wy wz, in the base frame,
/// reference point at the origin of `link`, default the tool tip). J must be
/// sized 6 x dof beforehand. RT-safe.
void jacobian(const RobotModel& model, KinematicsWorkspace& ws,
              const Eigen::Ref<const Eigen::VectorXd>& q,
              Eigen::Ref<Eigen::Matrix<double, 6, Eigen::Dynamic>> J, int link = -1) noexcept;

/// Joint torques (N m) that hold the arm still against gravity. tau sized dof.
void gravity_torques(const RobotModel& model, KinematicsWorkspace& ws,
                     const Eigen::Ref<const Eigen::VectorXd>& q,
                     Eigen::Ref<Eigen::VectorXd> tau) noexcept;

struct IkOptions {
  double position_tolerance_m = 1e-4;
  double rotation_tolerance_rad = 1e-4;
  int max_restarts = 50;          ///< random restarts after the seeded attempt
  unsigned random_seed = 12345;   ///< restarts are deterministic
  /// Prefer configurations far from the joint limits: up to
  /// centre_candidates solutions (the seeded one, then random restarts) are
  /// each moved along the arm's self-motion (null space, pose held) away from
  /// the limits, and the one with the largest smallest margin is returned.
  /// For planning moves to task frames; ~10x slower, and the answer no longer
  /// stays near the seed.
  bool centre_joints = false;
  int centre_candidates = 8;
};

struct IkResult {
  bool success = false;
  Eigen::VectorXd q;                ///< best solution found, within joint limits
  double position_error_m = 0.0;    ///< residual of q
  double rotation_error_rad = 0.0;  ///< residual of q
  int attempts = 0;
};

/// Full-pose IK for the tip (or `link`): seeded from `seed`, solution within
/// joint limits. On failure success=false and q/residuals describe the best
/// attempt. Not RT-safe. Throws std::invalid_argument when ws was built for
/// another model.
IkResult inverse_kinematics(const RobotModel& model, KinematicsWorkspace& ws, const Pose& base_T_target,
                            const Eigen::Ref<const Eigen::VectorXd>& seed, const IkOptions& options = {},
                            int link = -1);

/// Damped least squares: dq = J^T (J J^T + lambda^2 I)^-1 e, lambda^2 =
/// lambda_max^2 (1 - (w / w0)^2) when the manipulability w = sqrt(det J J^T)
/// is below w0, else 0 (plus a floor of 1e-6). The remote's compliance and
/// the ground's teleoperation take their joint steps from here. RT-safe.
void dls_step(const Jacobian& J, const Vector6& e, JointVector& dq, double lambda_max = 0.05,
              double w0 = 0.01) noexcept;

}  // namespace foresight
