#pragma once
// The go/no-go before the insert, the application's part (issue 30): from an
// object pose with its covariance (localize/align --json), the ground's arm
// model and ground.yaml's contact_check section to the prediction, its
// numbers and the advice that would raise it. `foresight check-insert`, the
// scripts' CHECK insert, the display's go/no-go drawing and localize/align's
// per-tag uncertainty all come through here. Set-up code.

#include <Eigen/Core>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"
#include "foresight/common/insert_capture.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/contact_check/config.hpp"
#include "foresight/contact_check/insert_check.hpp"
#include "foresight/contact_check/tip_error.hpp"
#include "foresight/session/config_path.hpp"

namespace foresight::session {

/// Where the insert starts and what it is given.
struct InsertStep {
  std::string tag = "insert_start";       ///< the approach's end (the tool tip is sent there)
  std::string hole_tag = "hole_entrance"; ///< the hole's frame (z along its axis)
  InsertParams params = default_insert_step_params();
  /// The changeout's insert: 6.5 cm from the 5 mm stand-off, 6 cm deep.
  static InsertParams default_insert_step_params() {
    InsertParams p;
    p.depth_m = 0.065;
    return p;
  }
};

/// What the check knows: the models, the settings, and where the views are
/// (for advice: the camera that would help most).
struct InsertCheckContext {
  const ObjectModel* object = nullptr;
  const RobotModel* robot = nullptr;
  contact_check::ContactCheckConfig config;
  std::map<std::string, camera::Camera> cameras;  ///< every camera there is (empty: no view advice)
  std::vector<std::string> views_used;            ///< the cameras the pose came from
  bool aligned = false;                           ///< the pose came from `align` (no align advice)
  double click_sigma_px = 1.0;                    ///< the clicks' noise for a view not yet used
};

struct InsertCheck {
  InsertStep step;
  contact_check::InsertPrediction prediction;
  contact_check::LocalCovariance tip_error;  ///< e of hole_T_tip
  Pose base_T_hole = Pose::Identity(), base_T_tag = Pose::Identity();
  Eigen::Matrix3d hole_position_covariance = Eigen::Matrix3d::Zero();  ///< of the hole's position, in base
  Eigen::Matrix3d tip_position_covariance = Eigen::Matrix3d::Zero();   ///< of the tip relative to the hole, in base
  std::vector<std::string> advice;
  double socket_diameter_m = 0.0;  ///< the tool's socket (ground.yaml contact_check), for drawing its rim
};

/// The prediction for `step` with the object at `estimate`. Throws InputError
/// / std::invalid_argument naming the input: a tag not in the object model
/// ("tag 'x' is not in the object model 'oru' (its tags: ...)"), a capture
/// region with a non-positive size, a threshold outside (0, 1); and
/// std::runtime_error when the arm cannot reach the tag.
InsertCheck check_insert(const contact_check::ObjectEstimate& estimate, const InsertStep& step, const InsertCheckContext& context);

/// The estimate an object pose file holds (pose, covariance, the arm links'
/// sensitivity), and where it came from (its views, aligned or not) into
/// `context`. InputError "<file>: the object pose has no covariance
/// (localize --json or align --json write it)" when it has none.
contact_check::ObjectEstimate estimate_of(const std::string& object_pose_file, InsertCheckContext& context);

/// `foresight check-insert`'s inputs.
struct CheckInsertRequest {
  std::string object_pose;  ///< localize/align --json (with "covariance")
  std::string cameras;      ///< cameras.yaml ("": no view advice)
  std::string object = default_config("oru.yaml");
  std::string robot = default_config("robot.urdf");
  std::string ground = default_config("ground.yaml");
  InsertStep step;
  std::optional<double> min_p_success;  ///< over ground.yaml's
};
/// Reads the files and checks. InputError "<file>: the object pose has no
/// covariance (localize --json or align --json write it)" when it has none.
InsertCheck check_insert(const CheckInsertRequest& request);

/// {p_success, lateral95_m, axial95_m, tilt95_deg, capture, verdict, advice, ...}.
nlohmann::json insert_check_json(const InsertCheck& check);

/// Per tag of `object`: the covariance of base_T_tag (roll, pitch, yaw, x,
/// y, z) and its sigmas, and, where `robot` is given and reaches the tag,
/// the tool tip's positioning uncertainty there (its frame): localize and
/// align --json's "tag_uncertainty".
nlohmann::json tag_uncertainty_json(const ObjectModel& object, const Pose& base_T_object,
                                    const Eigen::Matrix<double, 6, 6>& covariance, const RobotModel* robot,
                                    const contact_check::ContactCheckConfig& config);

}  // namespace foresight::session
