#pragma once
// The two peer methods the accuracy study compares against, on identical
// data: OpenCV solvePnP (a single view) and triangulate-then-align (points
// seen in two or more views triangulated by linear DLT, then the Arun /
// Umeyama 3-D to 3-D rigid fit). Not real-time code.

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/pose.hpp"

namespace foresight::localization {

enum class PnpMethod { Iterative, Sqpnp };

/// base_T_object from one view's clicks (object-frame points) with OpenCV
/// solvePnP and the camera's intrinsics (f_px, principal point at the centre,
/// no distortion). nullopt when OpenCV fails or reports no solution.
std::optional<Pose> solve_pnp_opencv(const std::vector<calibration::Correspondence>& points, const camera::Camera& camera, PnpMethod method);

/// The linear (DLT) triangulation of one point from two or more views.
Eigen::Vector3d triangulate_dlt(const std::vector<const camera::Camera*>& cameras, const std::vector<Eigen::Vector2d>& uv_px);

/// Triangulate every model point clicked in two or more views (points are
/// matched by their object-frame coordinates), then fit base_T_object with
/// Eigen::umeyama (rotation and translation, no scale). nullopt with fewer
/// than 3 such points.
std::optional<Pose> triangulate_and_align(const std::vector<calibration::Correspondence>& points,
                                          const std::map<std::string, camera::Camera>& cameras);

}  // namespace foresight::localization
