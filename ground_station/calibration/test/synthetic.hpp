#pragma once
// Synthetic ground truth for the estimation tests: random cameras looking at
// random point clouds, exact projections plus Gaussian pixel noise.

#include <Eigen/Core>
#include <random>
#include <vector>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"

namespace foresight::testing {

/// A camera at `distance_m` from `target` in a random direction, with a
/// random roll about its axis (up chosen at random, not parallel).
inline camera::Camera random_camera(std::mt19937& rng, const Eigen::Vector3d& target, double distance_m, double f_px,
                            const camera::Viewport& vp = {}) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Vector3d dir, up;
  do {
    dir = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    up = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
  } while (std::abs(dir.dot(up)) > 0.9);
  return camera::Camera::look_at("cam", vp, f_px, target + distance_m * dir, target, up);
}

/// Up to `count` points uniformly in a cube of half-size `half_m` about
/// `centre` that are in front of the camera and inside its view.
inline std::vector<calibration::Correspondence> random_points(std::mt19937& rng, const camera::Camera& cam, const Eigen::Vector3d& centre,
                                                 double half_m, int count, double noise_px) {
  std::uniform_real_distribution<double> u(-half_m, half_m);
  std::normal_distribution<double> g(0.0, noise_px);
  std::vector<calibration::Correspondence> out;
  for (int tries = 0; tries < 100000 && static_cast<int>(out.size()) < count; ++tries) {
    const Eigen::Vector3d p = centre + Eigen::Vector3d(u(rng), u(rng), u(rng));
    if (!cam.in_front(p)) continue;
    const Eigen::Vector2d uv = cam.project(p);
    if (!cam.in_view(uv)) continue;
    calibration::Correspondence c;
    c.n = static_cast<int>(out.size()) + 1;
    c.cam = cam.name;
    c.p_m = p;
    c.uv_px = uv;
    if (noise_px > 0.0) c.uv_px += Eigen::Vector2d(g(rng), g(rng));
    out.push_back(c);
  }
  return out;
}

/// Adds fresh Gaussian noise to exact projections.
inline std::vector<calibration::Correspondence> with_noise(std::mt19937& rng, std::vector<calibration::Correspondence> pts, double noise_px) {
  std::normal_distribution<double> g(0.0, noise_px);
  for (auto& c : pts) c.uv_px += Eigen::Vector2d(g(rng), g(rng));
  return pts;
}

}  // namespace foresight::testing
