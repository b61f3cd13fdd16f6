#pragma once
// The insert algorithm's parameters and the capture region they give: the
// set of tool-tip start errors (relative to the hole) from which the insert
// ends with the tool in the hole. One code for both sides: the remote's
// controller runs InsertParams (control::AlgorithmParams::insert,
// docs/control.md), the ground predicts from the same numbers whether the
// insert will succeed (`foresight check-insert`, `CHECK insert`;
// docs/estimation.md "Go/no-go before contact").
//
// Plain numbers, trivially copyable: usable from real-time code. The capture
// region is set-up code (it throws).

#include <stdexcept>

namespace foresight {

struct InsertParams {
  double depth_m = 0.06;               ///< success: tip advanced this far along the tool z axis from the start
  double depth_tolerance_m = 0.002;    ///< bottoming out within this of depth_m counts as success
  double speed_m_s = 0.005;            ///< axial reference speed when free
  double contact_force_n = 15.0;       ///< axial push while in contact (force-limited advance)
  double max_force_n = 80.0;           ///< failure (ForceLimit): |contact force| above this
  double lateral_stiffness_n_m = 400.0;   ///< admittance across the axis (x, y of the tool) once entered
  double search_stiffness_n_m = 5000.0;   ///< across the axis before entering (the spiral must not lag by friction)
  double rotational_stiffness_nm_rad = 20.0;  ///< admittance about x, y of the tool (tilt)
  double axial_stiffness_n_m = 2000.0;    ///< admittance along the axis
  /// Admittance damping across the axis (x, y) and about it (tilt); 0: the
  /// controller's (AdmittanceParams: 6000 N s/m, 20 N m s/rad). The loop stays
  /// stable against a contact up to about damping / delay times a constant
  /// (docs/hardware.md "Frame order and loop delay"): a long guide in a tight
  /// bore (the ORU in its slot) wants more than the tool's insertion.
  double lateral_damping_n_s_m = 0.0;
  double rotational_damping_nm_s_rad = 0.0;
  double stall_time_s = 0.3;           ///< pushing with < stall_progress_m progress this long: spiral search
  double stall_progress_m = 0.0003;
  double entered_progress_m = 0.002;   ///< past the contact depth by this: the tip has entered, spiral ends
  double spiral_pitch_m = 0.0008;      ///< radial growth per turn of the Archimedean spiral r = pitch * theta / 2 pi
  double spiral_speed_m_s = 0.004;     ///< tangential speed along the spiral
  double spiral_max_radius_m = 0.005;  ///< failure (Unreachable): searched this far without entering
  double timeout_s = 60.0;             ///< failure (Timeout)
};

/// The geometry the insert works in: the hole (the object model's
/// hole.diameter_m and depth_m), the tool's socket, and how deep the tip must
/// end for the step after the insert (the latch grips at this depth).
struct InsertGeometry {
  double hole_diameter_m = 0.030;
  double hole_depth_m = 0.080;
  double socket_diameter_m = 0.028;
  double required_depth_m = 0.05;
  /// The rim's lead-in: how far beyond the clearance an end face landing on
  /// the rim is still guided in by the lateral compliance (a chamfer's
  /// width; for the sharp rim of config/oru.yaml with the insert's default
  /// compliance, measured with `foresight-remote simulate-insertions`:
  /// 3.25 mm enter without a search, 7.5 mm with it, docs/control.md).
  double lead_in_m = 0.0015;
};

/// Tool-tip start errors, in the hole's frame (z along the hole axis into
/// the object, origin at the entrance), from which the insert succeeds:
///  - lateral: the tip's distance from the axis, at most lateral_m. Within
///    the clearance plus the rim's lead-in the socket enters directly;
///    beyond it the end face lands on the face, stalls, and the spiral
///    search (centred on the start, out to spiral_max_radius_m) enters
///    wherever it passes that close to the axis:
///    lateral_m = spiral_max_radius + clearance + lead_in.
///  - tilt: the tool axis within tilt_rad of the hole axis: the tilt at
///    which the socket's leading rim, centred, still clears the wall,
///    asin(clearance / socket radius); the rotational admittance aligns the
///    shaft once the rim is in.
///  - axial: the tip's start depth z in [axial_min_m, axial_max_m]: far
///    enough in that advancing depth_m reaches required_depth_m
///    (axial_min_m = required_depth - depth), and not past the face
///    (axial_max_m = 0: an approach that ends inside the face is a
///    collision) -- unless the tip is within the clearance of the axis: the
///    approach then ends in the hole, and the insert goes on to the bottom
///    (axial_max_in_hole_m = hole depth - depth_m + depth_tolerance).
struct InsertCapture {
  double lateral_m = 0.0;
  double tilt_rad = 0.0;
  double axial_min_m = 0.0;
  double axial_max_m = 0.0;
  double axial_max_in_hole_m = 0.0;  ///< the axial limit for a tip within the clearance of the axis
  double clearance_m = 0.0;  ///< radial: (hole - socket) / 2
};

/// The capture region of `params` in `geometry`. Throws std::invalid_argument
/// naming the setting: "<section>.<name> must be a positive number" (hole.,
/// insert., contact_check. sizes; lead_in_m non-negative), and "capture
/// region: ..." for a socket not narrower than the hole, a required depth
/// past the hole's bottom, a depth_m not beyond the required depth.
InsertCapture insert_capture(const InsertParams& params, const InsertGeometry& geometry);

}  // namespace foresight
