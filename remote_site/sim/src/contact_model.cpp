#include "foresight/sim/contact_model.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "foresight/common/error.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/common/param_checks.hpp"

namespace foresight::sim {

namespace {

void check_fields(const ContactParams& p) {
  auto positive = [](double v, const char* name) { require_positive(v, "contact", name); };
  auto non_negative = [](double v, const char* name) { require_non_negative(v, "contact", name); };
  positive(p.socket_diameter_m, "socket_diameter_m");
  positive(p.tool_length_m, "tool_length_m");
  positive(p.face_stiffness_n_per_m, "face_stiffness_n_per_m");
  positive(p.bottom_stiffness_n_per_m, "bottom_stiffness_n_per_m");
  positive(p.wall_stiffness_n_per_m2, "wall_stiffness_n_per_m2");
  non_negative(p.damping_n_s_per_m, "damping_n_s_per_m");
  non_negative(p.friction_coefficient, "friction_coefficient");
  positive(p.friction_velocity_m_s, "friction_velocity_m_s");
  if (p.face_rings < 1 || p.face_rings > 64) throw std::invalid_argument("contact.face_rings must lie in 1..64");
  if (p.face_ring_points < 3 || p.face_ring_points > 256)
    throw std::invalid_argument("contact.face_ring_points must lie in 3..256");
  if (p.shaft_stations < 1 || p.shaft_stations > 10000)
    throw std::invalid_argument("contact.shaft_stations must lie in 1..10000");
  if (!p.tip_T_sensor.matrix().allFinite()) throw std::invalid_argument("contact.sensor_to_tip has non-finite numbers");
}

}  // namespace

void validate(const ContactParams& p, const ObjectModel& oru) {
  check_fields(p);
  if (!(oru.hole_diameter_m > 0.0) || !(oru.hole_depth_m > 0.0))
    throw std::invalid_argument("contact: the object's hole needs a positive diameter and depth");
  if (!(p.socket_diameter_m < oru.hole_diameter_m))
    throw std::invalid_argument("contact.socket_diameter_m (" + std::to_string(p.socket_diameter_m) +
                                ") must be smaller than the hole diameter (" + std::to_string(oru.hole_diameter_m) +
                                ")");
  if (oru.hole_axis.dot(Eigen::Vector3d::UnitZ()) < 1.0 - 1e-9)
    throw std::invalid_argument("contact: the hole axis must be +z of the object frame (the face normal, inwards)");
  if (std::abs(oru.hole_entrance_m.z()) > 1e-9)
    throw std::invalid_argument("contact: the hole entrance must lie on the face plane z = 0");
  if (!oru.oru_T_box.linear().isIdentity(1e-9))
    throw std::invalid_argument("contact: the box must be axis-aligned with the object frame");
  const double front = oru.oru_T_box.translation().z() - 0.5 * oru.size_m.z();
  if (std::abs(front) > 1e-6)
    throw std::invalid_argument("contact: the box's front face must be the plane z = 0 of the object frame");
}

ContactModel::ContactModel(const ObjectModel& oru, const ContactParams& params) : params_(params) {
  validate(params_, oru);
  hole_radius_m_ = 0.5 * oru.hole_diameter_m;
  hole_depth_m_ = oru.hole_depth_m;
  const Eigen::Vector3d c = oru.oru_T_box.translation();
  face_min_m_ = c.head<2>() - 0.5 * oru.size_m.head<2>();
  face_max_m_ = c.head<2>() + 0.5 * oru.size_m.head<2>();
  box_depth_m_ = oru.size_m.z();
  // Hole centre offset within the face: entrance x, y.
  hole_xy_m_ = oru.hole_entrance_m.head<2>();
  // Equal-area rings: ring j at the area-median radius of its annulus.
  const double r = 0.5 * params_.socket_diameter_m;
  const int n = params_.face_rings;
  const int k = params_.face_ring_points;
  disk_tip_.reserve(static_cast<std::size_t>(n * k));
  for (int j = 0; j < n; ++j) {
    const double rho = r * std::sqrt((j + 0.5) / n);
    for (int i = 0; i < k; ++i) {
      const double phi = 2.0 * std::numbers::pi * (i + 0.5 * (j % 2)) / k;
      disk_tip_.emplace_back(rho * std::cos(phi), rho * std::sin(phi), 0.0);
    }
  }
  disk_weight_ = 1.0 / static_cast<double>(n * k);
  station_ds_m_ = params_.tool_length_m / params_.shaft_stations;
}

ContactResult ContactModel::compute(const Pose& base_T_tip, const Pose& base_T_oru,
                                    const Twist& tip_velocity) const noexcept {
  ContactResult out;
  const Pose oru_T_tip = base_T_oru.inverse(Eigen::Isometry) * base_T_tip;
  const Eigen::Matrix3d R_ot = oru_T_tip.linear();
  const Eigen::Vector3d p_tip = oru_T_tip.translation();
  const Eigen::Vector3d axis = R_ot.col(2);
  const Eigen::Matrix3d R_bo = base_T_oru.linear();
  const Eigen::Vector3d v_tip = R_bo.transpose() * tip_velocity.v_m_s;
  const Eigen::Vector3d w = R_bo.transpose() * tip_velocity.w_rad_s;
  const Pose oru_T_sensor = oru_T_tip * params_.tip_T_sensor;
  const Eigen::Vector3d o_sensor = oru_T_sensor.translation();

  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();  // about o_sensor, oru frame
  const double mu = params_.friction_coefficient;
  const double vs2 = params_.friction_velocity_m_s * params_.friction_velocity_m_s;
  // One penalty contact: point p (oru), unit normal n pushing the tool out,
  // stiffness k_eff (N/m), damping c_eff (N s/m), penetration pen (m).
  auto contact = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& n, double k_eff, double c_eff, double pen) {
    const Eigen::Vector3d v_p = v_tip + w.cross(p - p_tip);
    const double v_n = v_p.dot(n);  // > 0: leaving the surface
    const double f_n = std::max(0.0, k_eff * pen - c_eff * v_n);
    const Eigen::Vector3d v_t = v_p - v_n * n;
    const Eigen::Vector3d f = f_n * n - (mu * f_n / std::sqrt(v_t.squaredNorm() + vs2)) * v_t;
    force += f;
    torque += (p - o_sensor).cross(f);
    out.max_penetration_m = std::max(out.max_penetration_m, pen);
  };

  const double R = hole_radius_m_;
  const double D = hole_depth_m_;
  const Eigen::Vector3d out_of_face(0.0, 0.0, -1.0);

  // End face: ORU face and hole bottom.
  const double kf = params_.face_stiffness_n_per_m * disk_weight_;
  const double kb = params_.bottom_stiffness_n_per_m * disk_weight_;
  const double cf = params_.damping_n_s_per_m * disk_weight_;
  for (const Eigen::Vector3d& d : disk_tip_) {
    const Eigen::Vector3d q = p_tip + R_ot * d;
    const double z = q.z();
    if (z <= 0.0 || z >= box_depth_m_ || q.x() < face_min_m_.x() || q.x() > face_max_m_.x() ||
        q.y() < face_min_m_.y() || q.y() > face_max_m_.y())
      continue;
    const double rho = std::hypot(q.x() - hole_xy_m_.x(), q.y() - hole_xy_m_.y());
    if (rho < R && z <= D) continue;  // in the hole's free space
    const double dr = std::max(rho - R, 0.0);
    const double dz = std::max(z - D, 0.0);
    const double to_hole = std::hypot(dr, dz);
    if (z <= to_hole) {
      contact(q, out_of_face, kf, cf, z);
      ++out.face_contacts;
    } else if (dr == 0.0) {
      contact(q, out_of_face, kb, cf, dz);
      ++out.bottom_contacts;
    }
    // else nearest to the wall: the shaft slices carry wall contact
  }

  // Shaft: hole wall and rim.
  const double ds = station_ds_m_;
  const double r = 0.5 * params_.socket_diameter_m;
  const double kw = params_.wall_stiffness_n_per_m2 * ds;
  const double cw = params_.damping_n_s_per_m * ds;
  for (int j = 0; j < params_.shaft_stations; ++j) {
    const Eigen::Vector3d c = p_tip - ((j + 0.5) * ds) * axis;
    if (c.z() < 0.0 || c.z() > D) continue;
    const Eigen::Vector3d radial(c.x() - hole_xy_m_.x(), c.y() - hole_xy_m_.y(), 0.0);
    const double rho = radial.norm();
    if (rho >= R || rho < 1e-12) continue;  // axis in the material (end face handles it) / centred
    const double pen = rho + r - R;
    if (pen <= 0.0) continue;
    // Overlap deeper sideways than the slice is below the face: the material
    // is nearer through the face, which the end face already pushes against
    // (a socket landing across the rim is pushed out, not sideways).
    if (c.z() < pen) continue;
    const Eigen::Vector3d u = radial / rho;
    const Eigen::Vector3d p(hole_xy_m_.x() + R * u.x(), hole_xy_m_.y() + R * u.y(), c.z());
    contact(p, -u, kw, cw, pen);
    ++out.wall_contacts;
  }

  out.insertion_depth_m = p_tip.z();
  out.tip_radial_offset_m = std::hypot(p_tip.x() - hole_xy_m_.x(), p_tip.y() - hole_xy_m_.y());
  out.tilt_rad = std::acos(std::clamp(axis.z(), -1.0, 1.0));
  out.hole_radius_m = R;

  const Eigen::Matrix3d R_os = oru_T_sensor.linear();
  out.sensor.force_n = R_os.transpose() * force;
  out.sensor.torque_nm = R_os.transpose() * torque;
  out.force_base_n = R_bo * force;
  return out;
}

// ---- config --------------------------------------------------------------------

ContactParams load_contact_params(const std::string& path) {
  using yaml::line_of;
  const YAML::Node root = yaml::load_file(path, "cannot open the scene file");
  const YAML::Node sec = yaml::section(root, "contact", path, "tool/ORU contact model");
  ContactParams p;
  auto number = [&](const char* key, double& v) { v = yaml::number_or(sec, key, v, path, "contact."); };
  auto integer = [&](const char* key, int& v) { v = yaml::integer_or(sec, key, v, path, "contact."); };
  auto vec3 = [&](const char* key, Eigen::Vector3d& v) {
    const YAML::Node n = sec[key];
    if (!n) return false;
    if (!n.IsSequence() || n.size() != 3)
      throw InputError(path, line_of(n), std::string("contact.") + key + ": expected a list of 3 numbers");
    for (int i = 0; i < 3; ++i) {
      try {
        v[i] = n[i].as<double>();
      } catch (const YAML::Exception&) {
        throw InputError(path, line_of(n),
                         std::string("contact.") + key + ": element " + std::to_string(i + 1) + " is not a number");
      }
    }
    return true;
  };
  static constexpr const char* kKeys[] = {
      "socket_diameter_m", "tool_length_m",        "face_stiffness_n_per_m", "bottom_stiffness_n_per_m",
      "wall_stiffness_n_per_m2", "damping_n_s_per_m", "friction_coefficient", "friction_velocity_m_s",
      "face_rings",        "face_ring_points",     "shaft_stations",         "sensor_to_tip_m",
      "sensor_to_tip_rpy_deg"};
  if (const auto key = yaml::unknown_key(sec, kKeys))
    throw InputError(path, line_of(*key), "contact." + key->as<std::string>() + ": unknown key");
  number("socket_diameter_m", p.socket_diameter_m);
  number("tool_length_m", p.tool_length_m);
  number("face_stiffness_n_per_m", p.face_stiffness_n_per_m);
  number("bottom_stiffness_n_per_m", p.bottom_stiffness_n_per_m);
  number("wall_stiffness_n_per_m2", p.wall_stiffness_n_per_m2);
  number("damping_n_s_per_m", p.damping_n_s_per_m);
  number("friction_coefficient", p.friction_coefficient);
  number("friction_velocity_m_s", p.friction_velocity_m_s);
  integer("face_rings", p.face_rings);
  integer("face_ring_points", p.face_ring_points);
  integer("shaft_stations", p.shaft_stations);
  Eigen::Vector3d xyz = -p.tip_T_sensor.translation();
  Eigen::Vector3d rpy_deg = Eigen::Vector3d::Zero();
  vec3("sensor_to_tip_m", xyz);
  vec3("sensor_to_tip_rpy_deg", rpy_deg);
  p.tip_T_sensor = make_pose(xyz, rpy_deg * (std::numbers::pi / 180.0)).inverse(Eigen::Isometry);
  try {
    check_fields(p);
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    for (const char* k : kKeys)
      if (msg.find(std::string("contact.") + k + " ") == 0 && sec[k]) throw InputError(path, line_of(sec[k]), msg);
    throw InputError(path, line_of(sec), msg);
  }
  return p;
}

}  // namespace foresight::sim
