#pragma once
// Contact between the LST socket and the ORU (its front face and its hole),
// giving the wrist F/T sensor reading from the simulated tool pose.
//
// Geometry (object frame `oru`, object_model.hpp): the front face is the plane
// z = 0 (the box's near face, bounded by the box's x/y extents); the hole is a
// cylinder of radius R = hole_diameter/2 along +z from the entrance to the
// bottom at z = hole_depth. The tool is a cylinder of radius r =
// socket_diameter/2 whose flat end face is the tip frame's x-y plane (tip
// frame `lst_tip`: origin at the socket face centre, z along the tool axis out
// of the tool), extending tool_length_m back along -z of the tip frame.
//
// Contacts (penalty, no state):
//  - end face on the ORU face and on the hole bottom: the end disk is sampled
//    with equal-area points (face_rings x face_ring_points, weights 1/count);
//    a point inside the ORU material is a face contact when the face is its
//    nearest surface (penetration z, force along -z), a bottom contact when it
//    lies within the hole radius below the bottom (penetration z - depth).
//    Force = stiffness x weight x penetration: pressing the whole end face
//    flat d metres into the face gives exactly face_stiffness x d.
//  - shaft on the hole wall and rim: shaft_stations slices of length
//    ds = tool_length / stations along the axis; a slice whose centre lies in
//    the hole (0 <= z <= depth, radial offset rho < R) and whose circle
//    reaches past the wall by p = rho + r - R > 0, with p <= z (else the face
//    is the nearer way out of the material), pushes back towards the axis
//    with wall_stiffness x p x ds, applied on the wall.
//    (Circle cross-sections: exact for an untilted tool, fine for small tilts.)
//  - friction at every contact: regularised Coulomb,
//    f_t = -mu |f_n| v_t / sqrt(|v_t|^2 + v_s^2), v_t the sliding velocity of
//    the tool point along the surface (from the tip twist), v_s =
//    friction_velocity_m_s. Zero velocity gives zero friction (no stiction).
//  - normal damping (optional): + damping x penetration rate, never pulling.
//
// Output: the wrench the ORU exerts on the tool, expressed in the F/T sensor
// frame and taken about the sensor origin (tool weight and sensor bias not
// included): force_n, torque_nm = sum (p_i - o_sensor) x f_i. The sensor frame
// is given by tip_T_sensor (from the URDF: ft_sensor -> lst_tip is a pure
// translation of 0.295 m along z, so tip_T_sensor = translation (0, 0, -0.295)).
//
// compute() is const, noexcept and allocation-free (RT-safe; the probe
// points are laid out once in the constructor). The ORU pose is an argument,
// so a carried ORU (latched and pulled out) can move with the tool.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"

namespace foresight::sim {

struct ContactParams {
  double socket_diameter_m = 0.028;
  double tool_length_m = 0.10;              ///< shaft length behind the tip that can touch the hole
  double face_stiffness_n_per_m = 2.0e5;    ///< whole end face pressed flat on the ORU face
  double bottom_stiffness_n_per_m = 2.0e5;  ///< whole end face on the hole bottom
  double wall_stiffness_n_per_m2 = 5.0e6;   ///< N per m of penetration per m of shaft in contact
  double damping_n_s_per_m = 0.0;           ///< normal damping, whole face (wall: per m of shaft)
  double friction_coefficient = 0.3;
  double friction_velocity_m_s = 1.0e-3;    ///< regularisation speed v_s
  int face_rings = 4;
  int face_ring_points = 16;
  int shaft_stations = 50;
  Pose tip_T_sensor = Pose(Eigen::Translation3d(0.0, 0.0, -0.295));
};

/// Check the parameters against the object; throws std::invalid_argument
/// naming the field: non-positive sizes or stiffnesses, negative friction,
/// socket not smaller than the hole, hole axis not along the face normal
/// (+z of `oru`), hole entrance off the face plane.
void validate(const ContactParams& params, const ObjectModel& oru);

/// The `contact:` section of config/scene.yaml. tip_T_sensor comes from
/// `sensor_to_tip_m` [x, y, z] (+ optional `sensor_to_tip_rpy_deg`), the pose
/// of the tip in the sensor frame (sensor_T_tip). Throws InputError naming
/// file, line and key.
ContactParams load_contact_params(const std::string& scene_yaml_path);

/// Linear velocity of the tip origin and angular velocity, both in `base`.
struct Twist {
  Eigen::Vector3d v_m_s = Eigen::Vector3d::Zero();
  Eigen::Vector3d w_rad_s = Eigen::Vector3d::Zero();
};

struct Wrench {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();
};

struct ContactResult {
  Wrench sensor;                 ///< on the tool, in and about the sensor frame
  Eigen::Vector3d force_base_n = Eigen::Vector3d::Zero();  ///< the same force in `base`
  int face_contacts = 0;         ///< end-face probe points on the ORU face
  int bottom_contacts = 0;       ///< end-face probe points on the hole bottom
  int wall_contacts = 0;         ///< shaft slices on the hole wall
  double max_penetration_m = 0.0;
  // Where the tip is relative to the hole (for the plant: is the socket on
  // the bolt, may the latch close?).
  double insertion_depth_m = 0.0;    ///< tip depth along the hole axis (z of the tip in `oru`)
  double tip_radial_offset_m = 0.0;  ///< tip distance from the hole axis
  double tilt_rad = 0.0;             ///< angle between the tool axis and the hole axis
  bool tip_in_hole() const { return insertion_depth_m > 0.0 && tip_radial_offset_m < hole_radius_m; }
  double hole_radius_m = 0.0;
  bool in_contact() const { return face_contacts + bottom_contacts + wall_contacts > 0; }
};

class ContactModel {
 public:
  /// Validates (throws std::invalid_argument) and lays out the probe points.
  ContactModel(const ObjectModel& oru, const ContactParams& params);

  /// The reading for the tool at base_T_tip with the ORU at base_T_oru, the
  /// tip moving with `tip_velocity` (base frame). RT-safe.
  ContactResult compute(const Pose& base_T_tip, const Pose& base_T_oru,
                        const Twist& tip_velocity = Twist{}) const noexcept;

  const ContactParams& params() const { return params_; }
  double hole_radius_m() const { return hole_radius_m_; }
  /// Radial clearance between the socket and the hole wall.
  double clearance_m() const { return hole_radius_m_ - 0.5 * params_.socket_diameter_m; }

 private:
  ContactParams params_;
  double hole_radius_m_ = 0.0;
  double hole_depth_m_ = 0.0;
  Eigen::Vector2d face_min_m_ = Eigen::Vector2d::Zero();  ///< x, y extents of the front face
  Eigen::Vector2d face_max_m_ = Eigen::Vector2d::Zero();
  double box_depth_m_ = 0.0;
  Eigen::Vector2d hole_xy_m_ = Eigen::Vector2d::Zero();  ///< hole axis position on the face
  std::vector<Eigen::Vector3d> disk_tip_;  ///< end-face probe points, tip frame
  double disk_weight_ = 0.0;
  double station_ds_m_ = 0.0;
};

}  // namespace foresight::sim
