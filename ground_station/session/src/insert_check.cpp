#include "foresight/session/insert_check.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>
#include <stdexcept>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/format.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::session {

namespace {

using Matrix6 = Eigen::Matrix<double, 6, 6>;
constexpr double kDeg = std::numbers::pi / 180.0;

const Pose& tag_of(const ObjectModel& object, const std::string& tag) {
  const auto it = object.tags.find(tag);
  if (it != object.tags.end()) return it->second;
  std::string names;
  for (const auto& [name, pose] : object.tags) names += (names.empty() ? "" : ", ") + name;
  throw std::invalid_argument("tag '" + tag + "' is not in the object model '" + object.name + "' (its tags: " + names + ")");
}

/// The rpy-rate map G of the object's covariance: C = G C_body G^T.
Matrix6 rpy_map(const Pose& base_T_object) {
  Matrix6 G = Matrix6::Identity();
  G.topLeftCorner<3, 3>() = calibration::rpy_rate_matrix(rpy_from_rotation(base_T_object.linear())).inverse();
  return G;
}

/// The estimate's covariance had `camera` also seen the object's model
/// points (those in front of it, in its view, on the front of the object):
/// (C_body^-1 + J^T J / sigma^2)^-1. Empty when it sees fewer than 4.
std::optional<Matrix6> with_view(const contact_check::ObjectEstimate& est, const ObjectModel& object,
                                 const camera::Camera& camera, double sigma_px) {
  const Matrix6 G = rpy_map(est.base_T_object);
  const Matrix6 Gi = G.inverse();
  Matrix6 info = Matrix6::Zero();
  int seen = 0;
  for (const ObjectModel::Point& p : object.points) {
    if (p.p_m.z() > 0.0) continue;  // the object's back: hidden in its bay
    const Eigen::Vector3d pb = est.base_T_object * p.p_m;
    if (!camera.in_front(pb) || !camera.in_view(camera.project(pb))) continue;
    const camera::Projection pr = camera::project_with_jacobians(camera, pb);
    const Eigen::Matrix<double, 2, 6> J = camera::object_pose_jacobian(pr, est.base_T_object.linear(), p.p_m);
    info += J.transpose() * J / (sigma_px * sigma_px);
    ++seen;
  }
  if (seen < 4) return std::nullopt;
  const Matrix6 C_body = Gi * est.covariance * Gi.transpose();
  const Eigen::LDLT<Matrix6> ldlt(C_body + 1e-18 * Matrix6::Identity());
  const Matrix6 combined = (ldlt.solve(Matrix6::Identity()) + info).inverse();
  return G * combined * G.transpose();
}

/// The arm's uncertainty: the links' sigma the estimate's sensitivity was
/// computed for (the same error moves cameras and tool), else ground.yaml's.
contact_check::ArmUncertainty arm_of(const contact_check::ObjectEstimate& est, const InsertCheckContext& ctx) {
  return {est.arm_link_sensitivity.size() > 0 ? est.arm_link_sigma_m : ctx.config.arm_link_sigma_m,
          ctx.config.encoder_sigma_rad};
}

contact_check::InsertPrediction predict(const contact_check::ObjectEstimate& est, const InsertStep& step,
                                        const InsertCheckContext& ctx, contact_check::LocalCovariance* tip_out,
                                        const contact_check::ToolTip& tool, const contact_check::ArmUncertainty& arm) {
  const ObjectModel& object = *ctx.object;
  InsertGeometry geometry;
  geometry.hole_diameter_m = object.hole_diameter_m;
  geometry.hole_depth_m = object.hole_depth_m;
  geometry.socket_diameter_m = ctx.config.socket_diameter_m;
  geometry.required_depth_m = ctx.config.required_depth_m;
  geometry.lead_in_m = ctx.config.lead_in_m;
  const InsertCapture capture = insert_capture(step.params, geometry);
  const contact_check::LocalCovariance tip =
      contact_check::tip_error_at_hole(est, tag_of(object, step.hole_tag), tag_of(object, step.tag), tool, arm);
  if (tip_out) *tip_out = tip;
  return contact_check::predict_insert(tip, capture, ctx.config.min_p_success);
}

std::string percent(double p) { return fixed(100.0 * p, p > 0.999 || p < 0.001 ? 3 : 1) + "%"; }

}  // namespace

InsertCheck check_insert(const contact_check::ObjectEstimate& est, const InsertStep& step, const InsertCheckContext& ctx) {
  if (!ctx.object || !ctx.robot) throw std::logic_error("check_insert: no object or robot model");
  InsertCheck out;
  out.step = step;
  out.socket_diameter_m = ctx.config.socket_diameter_m;
  const ObjectModel& object = *ctx.object;
  out.base_T_hole = est.base_T_object * tag_of(object, step.hole_tag);
  out.base_T_tag = est.base_T_object * tag_of(object, step.tag);
  const contact_check::ArmUncertainty arm = arm_of(est, ctx);
  const contact_check::ToolTip tool = contact_check::tool_tip_uncertainty(*ctx.robot, out.base_T_tag, arm);
  out.prediction = predict(est, step, ctx, &out.tip_error, tool, arm);
  const Eigen::Matrix3d R = out.base_T_hole.linear();
  out.hole_position_covariance = contact_check::tag_covariance_base(est.base_T_object, est.covariance, tag_of(object, step.hole_tag))
                                     .bottomRightCorner<3, 3>();
  out.tip_position_covariance = R * out.tip_error.covariance.bottomRightCorner<3, 3>() * R.transpose();

  // Advice: what limits it, and what would raise it.
  const contact_check::InsertPrediction& p = out.prediction;
  if (p.go) return out;
  struct Term {
    double p;
    std::string text;
  };
  std::vector<Term> terms = {
      {p.p_lateral, "lateral: 95% of the tip within " + fixed(p.lateral95_m * 1e3, 1) + " mm of its aim, the insert captures " +
                        fixed(p.capture.lateral_m * 1e3, 1) + " mm (P " + percent(p.p_lateral) + ")"},
      {p.p_axial, "axial: 95% within " + fixed(p.axial95_m * 1e3, 1) + " mm, the start must be " +
                      fixed(-out.tip_error.mean[5] * 1e3, 1) + " mm in front of the face and no more than " +
                      fixed((p.capture.axial_max_m - p.capture.axial_min_m) * 1e3, 1) + " mm back (P " + percent(p.p_axial) + ")"},
      {p.p_tilt, "tilt: 95% within " + fixed(p.tilt95_deg, 2) + " deg, the insert takes " + fixed(p.capture.tilt_rad / kDeg, 2) +
                     " deg (P " + percent(p.p_tilt) + ")"}};
  std::sort(terms.begin(), terms.end(), [](const Term& a, const Term& b) { return a.p < b.p; });
  for (const Term& t : terms)
    if (t.p < 0.9999) out.advice.push_back("limited by the " + t.text);
  // The view that would help most.
  std::string best;
  double best_p = p.p_success;
  for (const auto& [name, cam] : ctx.cameras) {
    if (std::find(ctx.views_used.begin(), ctx.views_used.end(), name) != ctx.views_used.end()) continue;
    const std::optional<Matrix6> C = with_view(est, object, cam, ctx.click_sigma_px);
    if (!C) continue;
    contact_check::ObjectEstimate more = est;
    more.covariance = *C;
    if (more.arm_link_sensitivity.size() > 0) {
      // The arm's part stays what it was, at most the new total.
      const Matrix6 arm_part = more.arm_link_sigma_m * more.arm_link_sigma_m * more.arm_link_sensitivity * more.arm_link_sensitivity.transpose();
      const double shrink = std::min(1.0, std::sqrt(C->trace() / std::max(arm_part.trace(), 1e-300)));
      more.arm_link_sensitivity *= shrink;
    }
    const double pv = predict(more, step, ctx, nullptr, tool, arm).p_success;
    if (pv > best_p) best_p = pv, best = name;
  }
  if (!best.empty())
    out.advice.push_back("add the view '" + best + "' to the localization (its clicks on the ORU): P(success) " + percent(p.p_success) +
                         " -> about " + percent(best_p));
  if (!ctx.aligned)
    out.advice.push_back("refine the pose with `foresight align` (the ORU's edges in every view) and check again");
  out.advice.push_back("approach closer and localize again from nearer views (the error grows with the distance)");
  return out;
}

contact_check::ObjectEstimate estimate_of(const std::string& object_pose_file, InsertCheckContext& ctx) {
  const localization::ObjectPoseFile file = localization::read_object_pose_file(object_pose_file);
  if (!file.covariance)
    throw InputError(object_pose_file, "the object pose has no covariance (localize --json or align --json write it)");
  ctx.views_used = file.views;
  ctx.aligned = file.aligned;
  contact_check::ObjectEstimate est;
  est.base_T_object = file.base_T_object;
  est.covariance = *file.covariance;
  est.arm_link_sensitivity = file.arm_link_sensitivity;
  est.arm_link_sigma_m = file.arm_link_sigma_m;
  return est;
}

InsertCheck check_insert(const CheckInsertRequest& r) {
  InsertCheckContext ctx;
  const contact_check::ObjectEstimate est = estimate_of(r.object_pose, ctx);
  const ObjectModel object = ObjectModel::from_file(r.object);
  const RobotModel robot = RobotModel::from_file(r.robot);
  ctx.object = &object;
  ctx.robot = &robot;
  ctx.config = contact_check::load_contact_check_config(r.ground);
  if (r.min_p_success) ctx.config.min_p_success = *r.min_p_success;
  if (!r.cameras.empty())
    for (const auto& [name, rec] : camera::load_cameras(r.cameras)) ctx.cameras[name] = rec.camera;
  return check_insert(est, r.step, ctx);
}

nlohmann::json insert_check_json(const InsertCheck& c) {
  const contact_check::InsertPrediction& p = c.prediction;
  const Eigen::Matrix<double, 6, 1> sd = c.tip_error.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  return {{"p_success", p.p_success},
          {"lateral95_m", p.lateral95_m},
          {"axial95_m", p.axial95_m},
          {"tilt95_deg", p.tilt95_deg},
          {"capture",
           {{"lateral_m", p.capture.lateral_m},
            {"tilt_deg", p.capture.tilt_rad / kDeg},
            {"axial_min_m", p.capture.axial_min_m},
            {"axial_max_m", p.capture.axial_max_m},
            {"clearance_m", p.capture.clearance_m}}},
          {"verdict", contact_check::verdict(p)},
          {"advice", c.advice},
          {"min_p_success", p.min_p_success},
          {"p_lateral", p.p_lateral},
          {"p_axial", p.p_axial},
          {"p_tilt", p.p_tilt},
          {"tag", c.step.tag},
          {"hole_tag", c.step.hole_tag},
          {"tip_error", {{"mean", vec_json(c.tip_error.mean)},
                         {"sigma", vec_json(sd)},
                         {"covariance", matrix_rows(c.tip_error.covariance)}}},
          {"base_T_hole", localization::pose_json(c.base_T_hole)},
          {"base_T_tag", localization::pose_json(c.base_T_tag)}};
}

nlohmann::json tag_uncertainty_json(const ObjectModel& object, const Pose& base_T_object, const Matrix6& covariance,
                                    const RobotModel* robot, const contact_check::ContactCheckConfig& config) {
  nlohmann::json out = nlohmann::json::object();
  for (const auto& [name, object_T_tag] : object.tags) {
    const Matrix6 C = contact_check::tag_covariance_base(base_T_object, covariance, object_T_tag);
    const Eigen::Matrix<double, 6, 1> sd = C.diagonal().cwiseMax(0.0).cwiseSqrt();
    nlohmann::json t = {{"covariance", matrix_rows(C)},
                        {"sigma_position_m", vec_json(sd.tail<3>())},
                        {"sigma_rpy_deg", vec_json(sd.head<3>() / kDeg)}};
    if (robot) {
      try {
        const contact_check::ToolTip tip =
            contact_check::tool_tip_uncertainty(*robot, base_T_object * object_T_tag, {config.arm_link_sigma_m, config.encoder_sigma_rad});
        const Eigen::Matrix<double, 6, 1> ts = tip.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
        t["tool_tip"] = {{"sigma_position_m", vec_json(ts.tail<3>())},
                         {"sigma_rotation_deg", vec_json(ts.head<3>() / kDeg)},
                         {"frame", "tag"}};
      } catch (const std::runtime_error&) {
        t["tool_tip"] = nullptr;  // the arm does not reach this tag
      }
    }
    out[name] = t;
  }
  return out;
}

}  // namespace foresight::session
