#pragma once
// `overlay --check-insert` and `display --check-insert`: the insert's check of
// the object pose file (insert_check.hpp) in the terms of the drawing
// (display/go_no_go.hpp), and what was drawn as JSON. Session-internal.

#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "foresight/common/json_text.hpp"
#include "foresight/contact_check/insert_check.hpp"
#include "foresight/display/go_no_go.hpp"
#include "foresight/session/insert_check.hpp"

namespace foresight::session {

/// check_insert over the pose file (InputError "<file>: the object pose has
/// no covariance (...)" when it has none), the default step (the tool sent to
/// insert_start, the hole hole_entrance), ground.yaml's contact_check
/// settings (the socket's diameter for its rim).
inline display::GoNoGoMarks load_go_no_go_marks(const std::string& object_pose, const std::string& object,
                                                const std::string& robot, const std::string& ground) {
  CheckInsertRequest request;
  request.object_pose = object_pose;
  request.object = object;
  request.robot = robot;
  request.ground = ground;
  const InsertCheck c = check_insert(request);
  display::GoNoGoMarks m;
  m.base_T_hole = c.base_T_hole;
  m.base_T_tag = c.base_T_tag;
  m.hole_position_covariance = c.hole_position_covariance;
  m.tip_position_covariance = c.tip_position_covariance;
  m.socket_diameter_m = c.socket_diameter_m;
  m.go = c.prediction.go;
  m.p_success = c.prediction.p_success;
  return m;
}

inline nlohmann::json image_ellipse_json(const display::ImageEllipse& e) {
  return {{"centre_px", vec_json(e.centre_px)},
          {"semi_major_px", e.semi_major_px},
          {"semi_minor_px", e.semi_minor_px},
          {"angle_deg", e.angle_rad * 180.0 / std::numbers::pi}};
}

/// {verdict, p_success, label, hole{in_view, ellipse95}, tip{in_view, ellipse95}}
/// (ellipse95 null behind the camera).
inline nlohmann::json go_no_go_json(const display::GoNoGoMarks& m, const display::GoNoGoDrawn& d) {
  return {{"verdict", contact_check::verdict(m.go)},
          {"p_success", m.p_success},
          {"label", d.label},
          {"hole", {{"in_view", d.hole_in_view},
                    {"ellipse95", d.hole_in_front ? image_ellipse_json(d.hole) : nlohmann::json(nullptr)}}},
          {"tip", {{"in_view", d.tip_in_view},
                   {"ellipse95", d.tip_in_front ? image_ellipse_json(d.tip) : nlohmann::json(nullptr)}}}};
}

}  // namespace foresight::session
