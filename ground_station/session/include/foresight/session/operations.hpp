#pragma once
// The ground's file-to-file operations, one function each: what `foresight
// calibrate`, `localize`, `synth` and `preview` do, and what `foresight run`
// and `demo` do in-process for CALIBRATE, LOCALIZE and every preview. The
// commands bind options to a request and print the outcome; the runner fills
// the same request, so a run does exactly what the command does. Bad input
// throws InputError / std::invalid_argument naming the file or option, a
// failed fit ComputationError. Not real-time code.

#include <Eigen/Core>
#include <cstddef>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "foresight/align/alignment_study.hpp"
#include "foresight/align/model_aligner.hpp"
#include "foresight/calibration/calibrate.hpp"
#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/preview/preview.hpp"
#include "foresight/render/gl_context.hpp"
#include "foresight/render/renderer.hpp"
#include "foresight/session/config_path.hpp"

namespace foresight::session {

// --- synth-clicks (the simulated operator) ---------------------------------

struct SynthClicksRequest {
  std::string scene = default_config("scene.yaml");
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double noise_px = 1.0;
  unsigned seed = 1;
  int per_pose = 8;
  std::string calibration_out;        ///< arm clicks CSV ("": not written)
  std::string object_out;             ///< ORU clicks CSV ("": not written)
  std::string joints_out;             ///< arm pose 1 as q1,...,qN ("": not written)
};

struct ClickedView {
  std::string camera;
  int calibration_clicks = 0, object_clicks = 0;
};

struct SynthClicks {
  std::vector<ClickedView> views;
  std::vector<Eigen::VectorXd> arm_poses;  ///< the calibration poses (rad)
  Pose true_base_T_object;
};

/// Noisy clicks with a known ground truth: the arm's features in every
/// camera over the calibration poses, the ORU's model points; each output
/// written atomically (all paths checked before any work).
SynthClicks synth_clicks(const SynthClicksRequest& request);

// --- eval localization (the paper's Tables 1-3) ------------------------------

struct LocalizationStudyRequest {
  int trials = 1000;
  double noise_px = 1.0;
  unsigned seed = 1;
  int seeds = 1;                      ///< the study repeated with seeds seed..seed+seeds-1
  double arm_error_mm = 0.0;          ///< > 0: also with every link length off by this sd
  std::string scene = default_config("scene.yaml");
  std::string object = default_config("oru.yaml");
  std::string robot = default_config("robot.urdf");
};

struct LocalizationStudy {
  std::vector<localization::StudyResult> runs;      ///< per seed, the exact arm model
  std::vector<localization::StudyResult> arm_runs;  ///< per seed, with the arm-model error (empty without it)
  double elapsed_s = 0.0;
};

/// Monte Carlo over the synthetic four-camera scene: calibration from noisy
/// arm clicks, then localization with every combination of views, beside the
/// Cramer-Rao bound and the peers. `progress(done, total)` over all the
/// studies. ComputationError when every trial's calibration failed.
LocalizationStudy study_localization(const LocalizationStudyRequest& request,
                                     const std::function<void(int done, int total)>& progress = {});
/// Per view combination, the spread over the seeds of the RMSEs (mean, sd)
/// beside the bound (the --json "over_seeds").
nlohmann::json localization_spread_json(const std::vector<localization::StudyResult>& runs);
/// `foresight eval localization --json`'s object.
nlohmann::json localization_study_json(const LocalizationStudyRequest& request, const LocalizationStudy& study);

// --- eval alignment (clicks alone vs clicks + alignment) ---------------------

struct AlignmentStudyRequest {
  int trials = 20;
  double noise_px = 1.0;
  unsigned seed = 1;
  double arm_error_mm = 2.0;          ///< the rendered true arm's link-length error (sd)
  double arm_prior_mm = 2.0;          ///< the links refined with the cameras under this prior (0: nominal arm)
  double sensor_noise_dn = 2.0;
  double blur_px = 0.6;
  std::string gl = "osmesa";
  std::string scene = default_config("scene.yaml");
  std::string object = default_config("oru.yaml");
  std::string robot = default_config("robot.urdf");
};

/// The study and the figures its summary gives (the single views' mean
/// 95% depth, the ratios of clicks to alignment).
struct AlignmentStudySummary {
  align::AlignmentStudyResult result;
  double single_clicks_depth_m = 0.0, single_aligned_depth_m = 0.0, single_cameras_only_depth_m = 0.0;
  double four_view_ratio = 0.0, single_view_depth_ratio = 0.0;
  double four_view_ratio_held_cameras = 0.0, four_view_ratio_cameras_only = 0.0, single_view_depth_ratio_cameras_only = 0.0;
};

AlignmentStudySummary study_alignment(const AlignmentStudyRequest& request,
                                      const std::function<void(int done, int total)>& progress = {});
/// `foresight eval alignment --json`'s object.
nlohmann::json alignment_study_json(const AlignmentStudyRequest& request, const AlignmentStudySummary& summary);

// --- calibrate -------------------------------------------------------------

struct CalibrateRequest {
  std::string points;                 ///< clicked points CSV
  std::string camera;                 ///< its cam column
  std::string viewport = "646x486";
  std::string robot = default_config("robot.urdf");
  std::string out;                    ///< cameras.yaml the camera will go to (checked first; add_camera writes it)
  int max_iterations = 100;
  double arm_link_sigma_m = 0.0;
};

struct Calibrated {
  camera::Viewport viewport;
  std::vector<calibration::Correspondence> points;  ///< the camera's rows
  calibration::CalibrationResult result;
};

/// The camera's calibration from its rows of the points file. Nothing is
/// written: `out` is only checked to be writable before the fit.
Calibrated calibrate_from_clicks(const CalibrateRequest& request);
/// `foresight calibrate --json`'s object.
nlohmann::json calibrated_json(const CalibrateRequest& request, const Calibrated& calibrated);
/// Adds (or replaces) the calibrated camera in `cameras_yaml`; the other
/// cameras there are kept.
void add_camera(const std::string& cameras_yaml, const std::string& camera, const Calibrated& calibrated);

// --- localize --------------------------------------------------------------

struct LocalizeRequest {
  std::string points;                 ///< clicked model points CSV
  std::string cameras;                ///< cameras.yaml
  std::string object = default_config("oru.yaml");
  std::string views;                  ///< comma-separated camera names ("": every camera in the file)
  bool camera_uncertainty = false;    ///< refine the cameras under their calibration covariance
  /// For each tag's tool-tip uncertainty ("": none): the arm model and
  /// ground.yaml (contact_check: encoder and link sigmas).
  std::string robot = default_config("robot.urdf");
  std::string ground = default_config("ground.yaml");
};

struct Localized {
  ObjectModel object;
  std::map<std::string, camera::Camera> cameras;
  std::vector<calibration::Correspondence> points;
  std::vector<std::string> held_cameras;  ///< cameras whose calibration covariance entered the pose's
  double arm_link_sigma_m = 0.0;          ///< the arm model's link sigma that entered it
  localization::LocalizationResult result;
  /// Per tag: its pose's covariance in base and the tool tip's positioning
  /// uncertainty there (session::tag_uncertainty_json).
  nlohmann::json tag_uncertainty;
};

Localized localize_from_clicks(const LocalizeRequest& request);
/// `foresight localize --json`'s object, the object pose file `run` reads
/// (base_T_object with its covariance, the tag frames, the residuals).
nlohmann::json localized_json(const Localized& localized);

// --- synth -----------------------------------------------------------------

struct SynthRequest {
  std::string camera;                 ///< a camera of the scene
  std::string joints, joints_deg;     ///< "q1,...,qN" (at most one; none: the middle of the ranges)
  std::string out;                    ///< the frame (PNG)
  std::string arm_mask;               ///< "": not written
  std::string write_cameras;          ///< "": the true cameras not written
  std::string arm_links;              ///< "": the nominal arm
  std::string gl = "osmesa";
  std::string scene = default_config("scene.yaml");
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double noise_dn = 2.0, blur_px = 0.6;
  unsigned seed = 1;
};

struct Synthesized {
  camera::Camera camera;
  render::GlBackend backend = render::GlBackend::OSMesa;
  Eigen::VectorXd q;
  int arm_pixels = 0, object_pixels = 0;
};

/// One frame of the synthetic camera (the true work site) written to `out`.
Synthesized synth_frame(const SynthRequest& request);

// --- overlay ---------------------------------------------------------------

struct OverlayRequest {
  std::string cameras, camera;        ///< cameras.yaml and the camera in it
  std::string image;                  ///< the video frame (an image or a video, see frame)
  int frame = 0;
  std::string joints, joints_deg;     ///< exactly one
  std::string object_pose;            ///< localize JSON ("": no object drawn)
  std::string mode = "wire", gl = "osmesa";
  std::string out;                    ///< PNG
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  std::string ground = default_config("ground.yaml");  ///< its contact_check section (check_insert)
  double alpha = 0.5;
  bool scale_image = false, tags = false;
  /// The insert's go/no-go on the picture (display/go_no_go.hpp): the hole's
  /// 95% ellipse and the tool tip at insert_start, green go / red no_go. Needs
  /// object_pose with its covariance.
  bool check_insert = false;
};

struct Overlaid {
  camera::Camera camera;
  render::RenderMode mode = render::RenderMode::Wire;
  render::GlBackend backend = render::GlBackend::OSMesa;
  double opacity = 1.0;
  Eigen::VectorXd q;
  bool object_drawn = false;
  Pose base_T_object = Pose::Identity();
  int triangles = 0;
  Eigen::Vector2d tip_px = Eigen::Vector2d::Zero();
  double render_ms = 0.0, total_ms = 0.0;
  /// With check_insert: {verdict, p_success, label, hole{in_view, ellipse95{centre_px,
  /// semi_major_px, semi_minor_px, angle_deg}}, tip{...}}; null otherwise.
  nlohmann::json insert_check;
};

/// The arm (and the localized object) through the calibrated camera over the
/// video frame, written to `out`.
Overlaid overlay_frame(const OverlayRequest& request);

// --- align (model-to-image) -------------------------------------------------

struct AlignRequest {
  std::string cameras;                        ///< cameras.yaml
  std::vector<std::string> camera, image;     ///< one camera for every image, or one --camera per --image
  std::vector<std::string> joints, joints_deg;  ///< once, or once per image (exactly one of the two)
  std::string object_pose;                    ///< the object's start pose (localize JSON)
  std::string refine = "camera";              ///< camera | object | both
  std::string out, object_out;                ///< refined cameras.yaml; refined object pose JSON
  std::string arm_links, arm_out;             ///< link-length corrections in; the refined ones out
  double arm_prior_mm = 0.0;                  ///< > 0: the arm's link lengths refined with this prior sd
  std::string gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  int frame = 0;
  bool scale_image = false;
};

struct AlignedViews {
  align::AlignOptions options;
  align::AlignResult result;
  bool cameras_refined = false;
  std::vector<int> offset_segments;  ///< the arm's chain segments with a link offset
};

/// The model's visible edges aligned to the images' edges; when aligned, the
/// outputs asked for are written (nothing is when refused). Bad input
/// (options, files, the model not in view of a camera): InputError /
/// std::invalid_argument before anything is written.
AlignedViews align_views(const AlignRequest& request);
/// `foresight align --json`'s object.
nlohmann::json aligned_json(const AlignRequest& request, const AlignedViews& aligned);

// --- preview ---------------------------------------------------------------

struct PreviewRequest {
  std::string trajectory;             ///< t,q1,...,qN CSV
  std::string cameras, camera;        ///< cameras.yaml and the camera in it
  std::string image;                  ///< the video frame (an image or a video, see frame)
  int frame = 0;
  std::string out, sheet;             ///< the video; the contact sheet ("": none)
  std::string object_pose;            ///< localize JSON ("": no object drawn)
  std::string mode = "ghost", gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double speed = 1.0, fps = 30.0, alpha = 0.6;
  bool no_path = false, tags = false, scale_image = false;
  std::function<bool()> interrupted;  ///< asked every frame: true stops it (preview::Interrupted)
};

struct Previewed {
  camera::Camera camera;
  preview::PreviewOptions options;
  render::GlBackend backend = render::GlBackend::OSMesa;
  int samples = 0, joints = 0;
  /// The arm's limits the trajectory breaks (it is still previewed: that is
  /// what a preview is for), the first ones and how many in all.
  std::vector<Violation> violations;
  std::size_t violations_total = 0;
  preview::PreviewResult result;
  double wall_time_s = 0.0;
};

/// A trajectory that is malformed (non-finite, time not increasing, too few
/// samples) is refused: InputError "<file>: ...: cannot be previewed".
Previewed preview_trajectory(const PreviewRequest& request);

}  // namespace foresight::session
