#pragma once
// Model-to-image alignment (issue 16): refine a camera's 7 parameters and/or
// the task object's pose by pulling the projected model's visible edges onto
// the image's edges, using every edge pixel instead of a few clicks.
//
// The method, per frame and per coarse-to-fine level:
//  1. Visibility from the renderer: the arm and the object are rendered as a
//     label image (one flat colour per convex primitive, depth-tested), so an
//     edge behind another part never pulls.
//  2. Model edges: every mesh edge that is a silhouette from this camera (one
//     adjacent face towards the camera, one away) or a crease (dihedral angle
//     > 25 deg) with a face towards the camera, and the object's edges with
//     its surroundings (where its faces pass into theirs: the ORU's sides
//     entering the bay; no mesh has them) with both faces towards it;
//     sampled every ~4 px along its projection; a sample is kept when the
//     label image shows its primitive on the inner side (and something of
//     another colour on the outer side of a silhouette: the surroundings for
//     an edge with them; for the object's, the same for 4 px beyond, so
//     that no other boundary there takes the search).
//  3. Edge-normal search: along the projected edge normal, within +-R px, the
//     nearest strong maximum of the image gradient (Sobel of the blurred grey
//     image) with sub-pixel parabola; the residual is the signed distance.
//  4. Robust Gauss-Newton (Tukey weights, scale from the MAD), the Jacobians
//     of foresight/camera/projection.hpp (camera: body rotation, centre in
//     base, f_px; object: body rotation, origin in base).
//  Levels: search 24 px on a 4 px blur, 10 px on 2 px, 4 px on 1 px, 2.5 px on
//  0.5 px; the peak by Gaussian (log-parabola) interpolation.
//  Several frames (arm poses) per camera and several cameras combine into one
//  least-squares problem (the object pose shared by all views).
//
// Confidence: the result is refused (cameras and object unchanged, reason
// said) when too few model edges are visible, when too few of them found an
// image edge at the end, or when the truncated edge distance (the residual
// against every visible sample, misses counted as 8 px) is not lower than at
// the start. A model entirely out of view is reported separately (bad input).
//
// Not real-time code: set-up uploads meshes; align() renders. The aligner is
// split as pinocchio splits a robot (Model / Data): an immutable
// AlignmentModel (the models' primitives and mesh edges, the viewport) built
// once and shareable between threads, the buffers every call writes (images,
// frames, samples, Jacobians, normal equations) kept per aligner and reused
// by the next call, and the steps as free functions of (model, data, input)
// in model_aligner.cpp.

#include <Eigen/Core>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/render/gl_context.hpp"

namespace foresight::align {

enum class Refine { Camera, Object, Both };

/// "camera", "object" or "both"; throws std::invalid_argument otherwise.
Refine parse_refine(const std::string& text);
const char* to_string(Refine refine);

struct AlignOptions {
  Refine refine = Refine::Camera;
  double sample_spacing_px = 4.0;    ///< along each projected model edge
  int max_samples_per_frame = 4000;  ///< spacing grows when exceeded
  int iterations_per_level = 8;
  int min_visible_samples = 80;      ///< fewer: refused, "too few model edges"
  double min_matched_fraction = 0.3; ///< final inliers within 1 px / visible samples
  double gradient_threshold = 6.0;   ///< grey levels per pixel (Sobel / 8)
  double score_cap_px = 8.0;         ///< truncation of the confidence score
  /// The edge search's bias predicted from the model's own appearance (the
  /// model rendered lit and anti-aliased through the current camera, the
  /// search run on it where the true edge is known) and subtracted at the
  /// finest level: shading ramps beside silhouettes moved the gradient peaks
  /// 0.1-0.3 px inwards (docs/estimation.md). `optical_blur_px`: the
  /// camera's blur (Gaussian sd, px) applied to that prediction.
  bool predict_edge_bias = true;
  double optical_blur_px = 0.6;
  /// The sd (px) of an edge offset shared by all silhouettes that the
  /// residuals cannot show (it trades against f and depth): added to the
  /// covariance as the parameters' response to it.
  double edge_offset_sd_px = 0.1;
  /// The sd (px) of each model edge's own offset, independent between
  /// edges (the model's and the appearance's error along one edge: seen,
  /// the side view's ORU 4 mm off along its line of sight claiming 0.3 mm,
  /// before its edge with the satellite's bay was sampled): added to the
  /// covariance as the parameters' response to it. 0: none.
  double edge_model_sd_px = 0.2;
  /// Arm-model self-calibration (a bundle adjustment over the cameras and
  /// the arm's link lengths): when > 0 and the cameras are refined, the
  /// length of every non-zero link offset (RobotModel::
  /// with_link_lengths_changed, one value per chain segment) is refined with
  /// the cameras, under a Gaussian prior of this sd (m) around
  /// `arm_link_delta_m`'s start. Observable over several arm poses seen by
  /// several cameras; 0: the arm model is taken as exact (the default).
  double arm_link_prior_m = 0.0;
  /// Link-length corrections of the arm model (m, one per chain segment;
  /// empty: none): the model that is rendered, sampled and (with
  /// arm_link_prior_m) the start of their refinement.
  std::vector<double> arm_link_delta_m;
  /// The uncertainty of the object's start pose, as LocalizationResult::
  /// covariance gives it (roll, pitch, yaw rad, position m; base frame), e.g.
  /// the click solution's. When given, an object alignment that ends
  /// further from the start than `max_start_disagreement_sigma` in the
  /// metric of the start's and the alignment's pose covariances together
  /// (rotation and position) is refused: the edges and the clicks disagree
  /// beyond both their uncertainties, and one view cannot say which is wrong
  /// (seen: a single oblique view whose ORU slid 0.17 m along its line of
  /// sight onto other edges, reporting a 2.5 mm sd; a side view's ORU turned
  /// 5.6 deg and slid 33 mm along its hole axis).
  std::optional<Eigen::Matrix<double, 6, 6>> object_start_covariance;
  double max_start_disagreement_sigma = 5.0;
};

/// One image of a camera with the arm at joint angles q.
struct AlignFrame {
  cv::Mat image_bgr;  ///< CV_8UC3 of the camera's viewport size
  Eigen::VectorXd q;  ///< radians
};

/// One camera and its frames.
struct AlignView {
  camera::Camera camera;
  std::vector<AlignFrame> frames;
  /// The camera's uncertainty in the alignment's camera parameters (body
  /// rotation increment rad, centre in base m, f_px; zero: taken as exact).
  /// When only the object is refined, the camera is held where it is but
  /// not believed exact: its error moves the object as much as the edges
  /// do (one view's depth trades against the camera's f and distance), so
  /// this enters the object's covariance as K C K^T, K the object's
  /// response to a camera change (a "consider" covariance).
  Eigen::Matrix<double, 7, 7> camera_covariance = Eigen::Matrix<double, 7, 7>::Zero();
};

enum class AlignStatus {
  Aligned,   ///< refined and confident: use the result
  Refused,   ///< not confident: `reason` says why; cameras/object are the start
  NotInView  ///< the model projects nowhere into a view: bad input
};
const char* to_string(AlignStatus status);

struct AlignResult {
  AlignStatus status = AlignStatus::Refused;
  std::string reason;                 ///< why refused / not in view; empty when aligned
  std::vector<camera::Camera> cameras;        ///< refined (or the start, when not aligned)
  std::optional<Pose> base_T_object;  ///< refined (or the start), when an object was given
  double start_score_px = 0.0;        ///< truncated RMS edge distance at the start
  double final_score_px = 0.0;        ///< same measure at the end
  double residual_rms_px = 0.0;       ///< RMS of the final inlier residuals (weights > 0)
  int visible_samples = 0;            ///< model edge samples visible at the end (all frames)
  int matched_samples = 0;            ///< of which found an image edge within 1 px
  int iterations = 0;
  /// With AlignOptions::object_start_covariance: the object's move from the
  /// start (body rotation, position) in sigmas of (start + alignment) pose
  /// covariance (the Mahalanobis distance; the refusal rule); the position
  /// part alone in the position blocks' metric; else 0.
  double start_disagreement_sigma = 0.0;
  double start_position_disagreement_sigma = 0.0;
  /// Parameter change, per camera (roll,pitch,yaw rad body increment; x,y,z
  /// m; f_px), then the object (rotation vector rad, translation m).
  std::vector<Eigen::Matrix<double, 7, 1>> camera_change;
  Eigen::Matrix<double, 6, 1> object_change = Eigen::Matrix<double, 6, 1>::Zero();
  /// Covariance of the refined parameters in the same order (cameras'
  /// blocks of 7 when refined, then the object's 6, then the refined link
  /// lengths): a cluster sandwich
  /// estimator H^-1 B H^-1 at the final residuals, the scores summed per
  /// model edge (the samples of one edge share their errors; the plain
  /// s^2 H^-1 was 3-5x optimistic). See docs/estimation.md.
  Eigen::MatrixXd covariance;
  double time_ms = 0.0;
  /// With arm_link_prior_m > 0: the refined link-length corrections (m, one
  /// per chain segment; 0 for segments without an offset) and their sds
  /// (from the covariance's link block); else the given ones / empty.
  std::vector<double> arm_link_delta_m, arm_link_sigma_m;
};

/// What an aligner keeps fixed (the arm's and the object's primitives with
/// their mesh edges, the viewport): read-only once built, so one may be
/// shared by the aligners of several threads. Defined in model_aligner.cpp.
struct AlignmentModel;
/// `object` may be null (arm only). The models must outlive the result.
std::shared_ptr<const AlignmentModel> make_alignment_model(const RobotModel& arm, const ObjectModel* object,
                                                           const camera::Viewport& viewport);

/// The aligner for one viewport: an AlignmentModel and this aligner's own
/// buffers (GL renderers with the model's meshes, images, samples), reused
/// from one call to the next. One per thread. Set-up may throw
/// std::runtime_error (GL).
class ModelAligner {
 public:
  /// `object` may be null (arm only). The models must outlive this.
  ModelAligner(render::GlContext& context, const RobotModel& arm, const ObjectModel* object, const camera::Viewport& viewport);
  /// On a model built once (make_alignment_model), e.g. shared with the
  /// aligners of other threads; throws std::invalid_argument when null.
  ModelAligner(render::GlContext& context, std::shared_ptr<const AlignmentModel> model);
  ~ModelAligner();
  ModelAligner(const ModelAligner&) = delete;
  ModelAligner& operator=(const ModelAligner&) = delete;

  /// Refines the views' cameras and/or the object (`base_T_object` required
  /// for Refine::Object/Both and when the object should occlude/pull).
  /// Throws std::invalid_argument on a frame of the wrong size or type, a
  /// wrong joint count, a camera of another viewport, Refine::Object without
  /// an object pose, or no frames.
  AlignResult align(const std::vector<AlignView>& views, const std::optional<Pose>& base_T_object,
                    const AlignOptions& options = {});

  /// The truncated RMS edge distance of the model through `camera` on one
  /// frame (the confidence score; px) and the fraction of visible samples
  /// within 1 px of an image edge, the silhouette check of `health`.
  struct FrameScore {
    double score_px = 0.0;
    double matched_fraction = 0.0;
    int visible_samples = 0;
    /// Silhouette IoU of the model arm and the image's arm, estimated from
    /// the edge offsets along the silhouette: (A - D/2) / (A + D/2), A the
    /// rendered arm area, D the area between the model silhouette and the
    /// image edges found along its normals (a miss counts as the cap).
    double iou = 0.0;
  };
  FrameScore score(const camera::Camera& camera, const AlignFrame& frame, const std::optional<Pose>& base_T_object,
                   const AlignOptions& options = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// RMS pixel distance between two cameras' projections of `points_base`
/// (points behind either camera skipped): the reprojection difference.
double reprojection_rms_px(const camera::Camera& a, const camera::Camera& b, const std::vector<Eigen::Vector3d>& points_base);

}  // namespace foresight::align
