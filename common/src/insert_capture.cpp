#include "foresight/common/insert_capture.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "foresight/common/param_checks.hpp"

namespace foresight {

InsertCapture insert_capture(const InsertParams& p, const InsertGeometry& g) {
  require_positive(g.hole_diameter_m, "hole", "diameter_m");
  require_positive(g.hole_depth_m, "hole", "depth_m");
  require_positive(g.socket_diameter_m, "contact_check", "socket_diameter_m");
  require_positive(g.required_depth_m, "contact_check", "required_depth_m");
  require_non_negative(g.lead_in_m, "contact_check", "lead_in_m");
  require_positive(p.depth_m, "insert", "depth_m");
  require_positive(p.spiral_max_radius_m, "insert", "spiral_max_radius_m");
  InsertCapture c;
  c.clearance_m = 0.5 * (g.hole_diameter_m - g.socket_diameter_m);
  if (!(c.clearance_m > 0.0))
    throw std::invalid_argument("capture region: the socket (" + std::to_string(g.socket_diameter_m) +
                                " m) must be narrower than the hole (" + std::to_string(g.hole_diameter_m) + " m)");
  if (g.required_depth_m > g.hole_depth_m)
    throw std::invalid_argument("capture region: required_depth_m " + std::to_string(g.required_depth_m) +
                                " is deeper than the hole (" + std::to_string(g.hole_depth_m) + " m)");
  c.lateral_m = p.spiral_max_radius_m + c.clearance_m + g.lead_in_m;
  c.tilt_rad = std::asin(c.clearance_m / (0.5 * g.socket_diameter_m));
  c.axial_min_m = g.required_depth_m - p.depth_m;
  c.axial_max_m = 0.0;
  c.axial_max_in_hole_m = std::max(0.0, g.hole_depth_m - p.depth_m + p.depth_tolerance_m);
  if (!(c.axial_max_m - c.axial_min_m > 0.0))
    throw std::invalid_argument("capture region: insert.depth_m (" + std::to_string(p.depth_m) +
                                " m) must exceed contact_check.required_depth_m (" + std::to_string(g.required_depth_m) + " m)");
  return c;
}

}  // namespace foresight
