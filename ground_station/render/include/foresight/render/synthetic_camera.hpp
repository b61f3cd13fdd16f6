#pragma once
// The synthetic camera: the "true" work site (shaded arm, the ORU in the
// satellite mock-up panel, a floor and a dark sky) rendered through a true
// camera with anti-aliasing, slight blur and sensor noise. It stands in for
// live video in the tests and the demo, and gives the ground truth an
// estimator or an overlay is checked against: which pixels the arm and the
// object truly cover.
//
// Set-up code and per-frame rendering allocate; not for a real-time loop.

#include <Eigen/Core>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>

#include "foresight/camera/camera.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/render/gl_context.hpp"
#include "foresight/render/renderer.hpp"
#include "foresight/render/scene_geometry.hpp"

namespace foresight::render {

struct SyntheticOptions {
  double noise_sigma_dn = 2.0;   ///< Gaussian sensor noise, digital numbers (0..255)
  double blur_sigma_px = 0.6;    ///< Gaussian optical blur; 0 for none
  unsigned seed = 1;             ///< noise is deterministic per seed and frame
  int samples = 4;               ///< multisample anti-aliasing
  bool floor = true;             ///< a checkered floor at z = 0 around the arm
  Eigen::Vector4d sky_rgba{0.03, 0.04, 0.08, 1.0};
};

struct SyntheticFrame {
  cv::Mat image_bgr;    ///< CV_8UC3: what the camera "sees"
  cv::Mat arm_mask;     ///< CV_8U, 255 where the arm is the visible surface (before blur and noise)
  cv::Mat object_mask;  ///< CV_8U, 255 where the task object is visible
};

class SyntheticCamera {
 public:
  /// Uploads the scene for cameras of `viewport`. The models must outlive this.
  SyntheticCamera(GlContext& context, const RobotModel& arm, const ObjectModel& object, const Scene& scene,
                  const camera::Viewport& viewport, const SyntheticOptions& options = {});
  ~SyntheticCamera();

  /// The frame through `true_camera` with the arm at q and the object at
  /// base_T_object (default: the scene's). Throws std::invalid_argument on a
  /// wrong joint count or a camera of another viewport.
  SyntheticFrame render(const camera::Camera& true_camera, const Eigen::VectorXd& q,
                        const std::optional<Pose>& base_T_object = std::nullopt);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace foresight::render
