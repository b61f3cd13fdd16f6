#pragma once
// Poses and rotations. A pose "A_T_B" maps coordinates in frame B to frame A.
// Roll/pitch/yaw follow the paper (eq. 23) and URDF: R = Rz(yaw) Ry(pitch) Rx(roll).

#include <Eigen/Geometry>

namespace foresight {

using Pose = Eigen::Isometry3d;

/// R = Rz(rpy[2]) * Ry(rpy[1]) * Rx(rpy[0]), angles in radians.
Eigen::Matrix3d rotation_from_rpy(const Eigen::Vector3d& rpy_rad);

/// Inverse of rotation_from_rpy; pitch in [-pi/2, pi/2]. At the singularity
/// (|pitch| = pi/2) roll is set to 0 and yaw absorbs the rest.
Eigen::Vector3d rpy_from_rotation(const Eigen::Matrix3d& R);

/// Pose from a translation (m) and roll/pitch/yaw (rad).
Pose make_pose(const Eigen::Vector3d& xyz_m, const Eigen::Vector3d& rpy_rad);

/// Rotation angle (rad, in [0, pi]) of R_a^T R_b: the angular distance.
double rotation_distance(const Eigen::Matrix3d& R_a, const Eigen::Matrix3d& R_b);

/// Closest rotation matrix (SVD, det +1) to an approximately orthonormal M.
Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& M);

}  // namespace foresight
