#include "foresight/common/insert_capture.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace foresight {

namespace {

void require_positive(double v, const char* name) {
  if (!(std::isfinite(v) && v > 0.0))
    throw std::invalid_argument(std::string("capture region: ") + name + " must be > 0 (got " + std::to_string(v) + ")");
}

}  // namespace

InsertCapture insert_capture(const InsertParams& p, const InsertGeometry& g) {
  require_positive(g.hole_diameter_m, "hole diameter_m");
  require_positive(g.hole_depth_m, "hole depth_m");
  require_positive(g.socket_diameter_m, "socket_diameter_m");
  require_positive(g.required_depth_m, "required_depth_m");
  require_positive(p.depth_m, "insert depth_m");
  require_positive(p.spiral_max_radius_m, "insert spiral_max_radius_m");
  InsertCapture c;
  c.clearance_m = 0.5 * (g.hole_diameter_m - g.socket_diameter_m);
  require_positive(c.clearance_m, "radial clearance (hole diameter_m - socket_diameter_m) / 2");
  if (g.required_depth_m > g.hole_depth_m)
    throw std::invalid_argument("capture region: required_depth_m " + std::to_string(g.required_depth_m) +
                                " is deeper than the hole (" + std::to_string(g.hole_depth_m) + " m)");
  if (!(std::isfinite(g.lead_in_m) && g.lead_in_m >= 0.0))
    throw std::invalid_argument("capture region: lead_in_m must be >= 0 (got " + std::to_string(g.lead_in_m) + ")");
  c.lateral_m = p.spiral_max_radius_m + c.clearance_m + g.lead_in_m;
  c.tilt_rad = std::asin(c.clearance_m / (0.5 * g.socket_diameter_m));
  c.axial_min_m = g.required_depth_m - p.depth_m;
  c.axial_max_m = 0.0;
  c.axial_max_in_hole_m = std::max(0.0, g.hole_depth_m - p.depth_m + p.depth_tolerance_m);
  require_positive(c.axial_max_m - c.axial_min_m, "axial window (insert depth_m - required_depth_m)");
  return c;
}

}  // namespace foresight
