#include "foresight/sim/plant.hpp"

#include <Eigen/Geometry>
#include <kdl/chain.hpp>
#include <cmath>
#include <stdexcept>

#include "foresight/common/error.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/sim/lst_server.hpp"
#include "foresight/common/param_checks.hpp"

namespace foresight::sim {

const char* to_string(OruState s) noexcept {
  switch (s) {
    case OruState::Fastened: return "fastened";
    case OruState::Carried: return "carried";
    case OruState::Seated: return "seated";
    case OruState::Dropped: return "dropped";
  }
  return "unknown";
}

// ---- parameters ------------------------------------------------------------------

void validate(const PlantParams& p) {
  auto positive = [](double v, const char* name) { require_positive(v, "plant", name); };
  auto non_negative = [](double v, const char* name) { require_non_negative(v, "plant", name); };
  auto slot_positive = [](double v, const char* name) { require_positive(v, "slot", name); };
  slot_positive(p.slot.guide_diameter_m, "guide_diameter_m");
  slot_positive(p.slot.radial_clearance_m, "radial_clearance_m");
  slot_positive(p.slot.depth_m, "depth_m");
  slot_positive(p.slot.seat_tolerance_m, "seat_tolerance_m");
  slot_positive(p.slot.face_stiffness_n_per_m, "face_stiffness_n_per_m");
  slot_positive(p.slot.bottom_stiffness_n_per_m, "bottom_stiffness_n_per_m");
  slot_positive(p.slot.wall_stiffness_n_per_m2, "wall_stiffness_n_per_m2");
  require_non_negative(p.slot.friction_coefficient, "slot", "friction_coefficient");
  if (!(p.slot.seat_tolerance_m < p.slot.depth_m))
    throw std::invalid_argument("slot.seat_tolerance_m must be smaller than slot.depth_m");
  non_negative(p.tool_mass_kg, "tool_mass_kg");
  non_negative(p.oru_mass_kg, "oru_mass_kg");
  positive(p.grasp_depth_m, "grasp_depth_m");
  positive(p.latch_stiffness_n_per_m, "latch_stiffness_n_per_m");
  positive(p.screw_engaged_turns, "screw_engaged_turns");
  if (!p.tool_com_sensor_m.allFinite()) throw std::invalid_argument("plant.tool_com_m has non-finite numbers");
  if (!p.oru_com_m.allFinite()) throw std::invalid_argument("plant.oru_com_m has non-finite numbers");
  for (double b : p.sensor_bias)
    if (!std::isfinite(b)) throw std::invalid_argument("plant.sensor_bias has non-finite numbers");
}

PlantParams load_plant_params(const std::string& path) {
  using yaml::line_of;
  PlantParams p;
  p.contact = load_contact_params(path);
  p.screw_engaged_turns = load_lst_mechanism_params(path).screw.engaged_turns;
  const YAML::Node root = yaml::load_file(path, "cannot open the scene file");
  if (const YAML::Node slot = root["slot"]) {
    if (!slot.IsMap()) throw InputError(path, line_of(slot), "slot: expected a map");
    static constexpr const char* kKeys[] = {"guide_diameter_m",       "radial_clearance_m",       "depth_m",
                                            "seat_tolerance_m",       "face_stiffness_n_per_m",   "bottom_stiffness_n_per_m",
                                            "wall_stiffness_n_per_m2", "friction_coefficient"};
    if (const auto key = yaml::unknown_key(slot, kKeys))
      throw InputError(path, line_of(*key), "slot." + key->as<std::string>() + ": unknown key");
    SlotParams& s = p.slot;
    auto number = [&](const char* key, double& v) { v = yaml::number_or(slot, key, v, path, "slot."); };
    number("guide_diameter_m", s.guide_diameter_m);
    number("radial_clearance_m", s.radial_clearance_m);
    number("depth_m", s.depth_m);
    number("seat_tolerance_m", s.seat_tolerance_m);
    number("face_stiffness_n_per_m", s.face_stiffness_n_per_m);
    number("bottom_stiffness_n_per_m", s.bottom_stiffness_n_per_m);
    number("wall_stiffness_n_per_m2", s.wall_stiffness_n_per_m2);
    number("friction_coefficient", s.friction_coefficient);
  }
  YAML::Node plant_node = root["plant"];
  if (plant_node) {
    if (!plant_node.IsMap()) throw InputError(path, line_of(plant_node), "plant: expected a map");
    static constexpr const char* kKeys[] = {"tool_mass_kg", "tool_com_m",    "tool_from_urdf",
                                            "sensor_bias",  "oru_mass_kg",   "oru_com_m",
                                            "grasp_depth_m", "latch_stiffness_n_per_m"};
    if (const auto key = yaml::unknown_key(plant_node, kKeys))
      throw InputError(path, line_of(*key), "plant." + key->as<std::string>() + ": unknown key");
    auto number = [&](const char* key, double& v) { v = yaml::number_or(plant_node, key, v, path, "plant."); };
    number("tool_mass_kg", p.tool_mass_kg);
    number("oru_mass_kg", p.oru_mass_kg);
    number("grasp_depth_m", p.grasp_depth_m);
    number("latch_stiffness_n_per_m", p.latch_stiffness_n_per_m);
    if (plant_node["tool_com_m"])
      p.tool_com_sensor_m = yaml::read_vector<3>(plant_node["tool_com_m"], path, "plant.tool_com_m");
    if (plant_node["oru_com_m"]) p.oru_com_m = yaml::read_vector<3>(plant_node["oru_com_m"], path, "plant.oru_com_m");
    if (plant_node["sensor_bias"]) {
      const Eigen::Matrix<double, 6, 1> b = yaml::read_vector<6>(plant_node["sensor_bias"], path, "plant.sensor_bias");
      for (int i = 0; i < 6; ++i) p.sensor_bias[static_cast<std::size_t>(i)] = b[i];
    }
    if (const YAML::Node n = plant_node["tool_from_urdf"]) {
      try {
        p.tool_from_urdf = n.as<bool>();
      } catch (const YAML::Exception&) {
        throw InputError(path, line_of(n), "plant.tool_from_urdf: not a boolean");
      }
    }
  }
  try {
    validate(p);
  } catch (const std::invalid_argument& e) {
    // "<section>.<key> ...": the key's line when the file has it, else the section's.
    const std::string msg = e.what();
    const bool in_slot = msg.rfind("slot.", 0) == 0;
    const YAML::Node sec = in_slot ? root["slot"] : plant_node;
    const std::size_t dot = msg.find('.');
    const std::string key = msg.substr(dot + 1, msg.find(' ') - dot - 1);
    int line = sec ? line_of(sec) : 0;
    if (sec && sec.IsMap() && sec[key]) line = line_of(sec[key]);
    throw InputError(path, line, msg);
  }
  return p;
}

// ---- plant -------------------------------------------------------------------------

namespace {

ObjectModel slot_object(const SlotParams& s) {
  ObjectModel slot;
  slot.name = "slot";
  slot.size_m = Eigen::Vector3d(4.0, 4.0, s.depth_m + 0.5);  // the panel around the bore
  slot.oru_T_box = Pose(Eigen::Translation3d(0.0, 0.0, 0.5 * slot.size_m.z()));
  slot.hole_entrance_m = Eigen::Vector3d::Zero();
  slot.hole_axis = Eigen::Vector3d::UnitZ();
  slot.hole_diameter_m = s.guide_diameter_m + 2.0 * s.radial_clearance_m;
  slot.hole_depth_m = s.depth_m;
  return slot;
}

ContactParams slot_contact_params(const PlantParams& p, const ObjectModel& oru) {
  ContactParams c;
  c.socket_diameter_m = p.slot.guide_diameter_m;
  c.tool_length_m = oru.size_m.z();  // the whole ORU body can touch the bore wall
  c.face_stiffness_n_per_m = p.slot.face_stiffness_n_per_m;
  c.bottom_stiffness_n_per_m = p.slot.bottom_stiffness_n_per_m;
  c.wall_stiffness_n_per_m2 = p.slot.wall_stiffness_n_per_m2;
  c.damping_n_s_per_m = 0.0;
  c.friction_coefficient = p.slot.friction_coefficient;
  c.friction_velocity_m_s = p.contact.friction_velocity_m_s;
  // The ORU's back is 0.38 m across: rings out to within ~1 mm of its edge
  // so a back landing on the bore's rim (> 1 mm off) touches the panel face.
  c.face_rings = 48;
  c.face_ring_points = 64;
  c.shaft_stations = 50;
  c.tip_T_sensor = Pose::Identity();  // the wrench comes back about the ORU's back; moved to the sensor here
  return c;
}

const PlantParams& checked(const PlantParams& p) {
  validate(p);
  return p;
}

Pose back_of(const ObjectModel& oru) {
  const double back_z = oru.oru_T_box.translation().z() + 0.5 * oru.size_m.z();
  return Pose(Eigen::Translation3d(oru.hole_entrance_m.x(), oru.hole_entrance_m.y(), back_z));
}

}  // namespace

Plant::Plant(const RobotModel& robot, const ObjectModel& oru, const Pose& base_T_oru_home, const PlantParams& params)
    : robot_(robot),
      params_(checked(params)),
      tool_contact_(oru, params_.contact),
      slot_contact_(slot_object(params_.slot), slot_contact_params(params_, oru)),
      base_T_oru_home_(base_T_oru_home),
      oru_T_back_(back_of(oru)),
      ws_(robot_),
      q_(Eigen::VectorXd::Zero(robot_.dof())),
      qd_(Eigen::VectorXd::Zero(robot_.dof())),
      J_(6, robot_.dof()),
      base_T_oru_(base_T_oru_home) {
  base_T_slot_ = base_T_oru_home_ * oru_T_back_ * Pose(Eigen::Translation3d(0.0, 0.0, -params_.slot.depth_m));
  J_.setZero();
  q_buf_.assign(static_cast<std::size_t>(robot_.dof()), 0.0);
  qd_buf_.assign(static_cast<std::size_t>(robot_.dof()), 0.0);

  // The tool below the sensor: every link after `ft_sensor` on the chain.
  sensor_link_ = robot_.link_index("ft_sensor");
  tool_mass_kg_ = params_.tool_mass_kg;
  tool_com_sensor_m_ = params_.tool_com_sensor_m;
  sensor_T_tip_ = params_.contact.tip_T_sensor.inverse(Eigen::Isometry);
  if (sensor_link_ > 0) {
    const Eigen::VectorXd q0 = robot_.mid_configuration();
    const Pose base_T_s = forward_kinematics(robot_, ws_, q0, sensor_link_);
    sensor_T_tip_ = base_T_s.inverse(Eigen::Isometry) * forward_kinematics(robot_, ws_, q0);
    if (params_.tool_from_urdf) {
      double m = 0.0;
      Eigen::Vector3d moment = Eigen::Vector3d::Zero();
      for (int k = sensor_link_ + 1; k <= robot_.tip_index(); ++k) {
        const KDL::RigidBodyInertia& I = robot_.chain().getSegment(static_cast<unsigned>(k - 1)).getInertia();
        if (!(I.getMass() > 0.0)) continue;
        const Pose s_T_k = base_T_s.inverse(Eigen::Isometry) * forward_kinematics(robot_, ws_, q0, k);
        const KDL::Vector c = I.getCOG();
        moment += I.getMass() * (s_T_k * Eigen::Vector3d(c.x(), c.y(), c.z()));
        m += I.getMass();
      }
      if (m > 0.0) {
        tool_mass_kg_ = m;
        tool_com_sensor_m_ = moment / m;
      }
    }
  }
  std::lock_guard lock(truth_mu_);
  truth_.base_T_oru = base_T_oru_;
  truth_.base_T_oru_home = base_T_oru_home_;
}

Plant::~Plant() { detach(); }

std::unique_ptr<Plant> Plant::from_files(const std::string& urdf_path, const std::string& oru_yaml_path,
                                         const std::string& scene_yaml_path) {
  const RobotModel robot = RobotModel::from_file(urdf_path);
  const ObjectModel oru = ObjectModel::from_file(oru_yaml_path);
  const Scene scene = Scene::from_file(scene_yaml_path);
  return std::make_unique<Plant>(robot, oru, scene.base_T_object, load_plant_params(scene_yaml_path));
}

void Plant::attach(CanSimulator& sim, LstServer* tool) {
  if (!sim.ft_sensor()) throw std::logic_error("Plant::attach: the simulator has no F/T sensor");
  if (sim.drive_count() != static_cast<std::size_t>(robot_.dof()))
    throw std::logic_error("Plant::attach: the simulator has " + std::to_string(sim.drive_count()) +
                           " drives, the robot " + std::to_string(robot_.dof()) + " joints");
  detach();  // an earlier attachment's callback no longer runs once this returns
  sim.joint_positions_rad(q_buf_);  // throws std::logic_error for drives without scaling
  sim_ = &sim;
  tool_ = tool;
  auto last_engaged = std::make_shared<int>(-1);
  sim.ft_sensor()->set_wrench_source([this, last_engaged]() {
    sim_->joint_positions_rad(q_buf_);
    sim_->joint_velocities_rad_s(qd_buf_);
    const LstToolState ts = tool_ ? tool_->state() : LstToolState{};
    const PlantStep r = step(q_buf_, qd_buf_, ts);
    if (tool_ && static_cast<int>(r.socket_engaged) != *last_engaged) {
      tool_->set_socket_engaged(r.socket_engaged);
      *last_engaged = r.socket_engaged ? 1 : 0;
    }
    return r.wrench_ft;
  });
}

void Plant::detach() {
  if (sim_ && sim_->ft_sensor()) sim_->ft_sensor()->set_wrench_source({});
  sim_ = nullptr;
  tool_ = nullptr;
}

void Plant::reset() { reset_requested_ = true; }

void Plant::add_wrench_at(const Eigen::Vector3d& f_base, const Eigen::Vector3d& p_base, const Pose& base_T_sensor,
                          Wrench& out) const noexcept {
  const Eigen::Matrix3d R = base_T_sensor.linear();
  const Eigen::Vector3d f_s = R.transpose() * f_base;
  const Eigen::Vector3d p_s = R.transpose() * (p_base - base_T_sensor.translation());
  out.force_n += f_s;
  out.torque_nm += p_s.cross(f_s);
}

PlantStep Plant::step(std::span<const double> q, std::span<const double> qd, const LstToolState& tool) noexcept {
  PlantStep out;
  const auto n = static_cast<std::size_t>(robot_.dof());
  for (std::size_t i = 0; i < n; ++i) {
    q_[static_cast<Eigen::Index>(i)] = i < q.size() ? q[i] : 0.0;
    qd_[static_cast<Eigen::Index>(i)] = i < qd.size() ? qd[i] : 0.0;
  }
  if (reset_requested_.exchange(false)) {
    state_ = OruState::Fastened;
    base_T_oru_ = base_T_oru_home_;
    follows_tool_ = false;
    gripped_ = false;
    prev_latched_ = tool.latched;
  }

  const Pose base_T_tip = forward_kinematics(robot_, ws_, q_);
  jacobian(robot_, ws_, q_, J_);
  const Eigen::Matrix<double, 6, 1> tw = J_ * qd_;
  Twist twist;
  twist.v_m_s = tw.head<3>();
  twist.w_rad_s = tw.tail<3>();
  const Pose base_T_sensor = base_T_tip * params_.contact.tip_T_sensor;

  if (follows_tool_) base_T_oru_ = base_T_tip * tip_T_oru_;
  out.tool_contact = tool_contact_.compute(base_T_tip, base_T_oru_, twist);
  const double depth = out.tool_contact.insertion_depth_m;
  const bool at_grasp = out.tool_contact.tip_in_hole() && depth >= params_.grasp_depth_m;

  // Latch: gripping needs the tip in the hole when the jaws close.
  if (tool.latched && !prev_latched_) {
    gripped_ = at_grasp && state_ != OruState::Dropped;
    grip_depth_m_ = depth;
  }
  if (!tool.latched) gripped_ = false;
  prev_latched_ = tool.latched;

  const Pose slot_T_back_now = base_T_slot_.inverse(Eigen::Isometry) * base_T_oru_ * oru_T_back_;
  const double slot_depth = slot_T_back_now.translation().z();
  const double seated_depth = params_.slot.depth_m - params_.slot.seat_tolerance_m;
  const bool screw_free = tool.engaged_turns <= 0.0;
  const bool screw_seated = tool.engaged_turns >= params_.screw_engaged_turns;

  auto start_following = [&] {
    follows_tool_ = true;
    tip_T_oru_ = base_T_tip.inverse(Eigen::Isometry) * base_T_oru_;
  };
  switch (state_) {
    case OruState::Fastened:
      if (gripped_ && screw_free && !oru_stuck_.load(std::memory_order_relaxed)) {
        state_ = OruState::Seated;  // loose in its slot, held by the tool: it comes out with it
        start_following();
      }
      break;
    case OruState::Carried:
      if (!gripped_) {
        state_ = OruState::Dropped;
        follows_tool_ = false;
      } else if (slot_depth >= seated_depth) {
        state_ = OruState::Seated;
      }
      break;
    case OruState::Seated:
      if (screw_seated) {
        state_ = OruState::Fastened;
        follows_tool_ = false;
      } else if (!screw_free || !gripped_) {
        follows_tool_ = false;  // held by the screw, or resting in the slot
      } else if (!follows_tool_) {
        start_following();  // gripped again with the screw free
      } else if (slot_depth < seated_depth - 0.005) {
        state_ = OruState::Carried;  // pulled back out before the screw engaged
      }
      break;
    case OruState::Dropped:
      break;
  }
  out.state = state_;
  out.socket_engaged = at_grasp && state_ != OruState::Carried && state_ != OruState::Dropped;
  socket_engaged_ = out.socket_engaged;

  // Tool/ORU contact and the latch hold (internal while the ORU follows the tool).
  if (!follows_tool_) {
    out.contact_ft = out.tool_contact.sensor;
    if (gripped_ && depth < grip_depth_m_) {
      const Eigen::Vector3d f = base_T_oru_.linear().col(2) * (params_.latch_stiffness_n_per_m * (grip_depth_m_ - depth));
      add_wrench_at(f, base_T_tip.translation(), base_T_sensor, out.contact_ft);
    }
  }
  const Eigen::Vector3d g = robot_.gravity();
  add_wrench_at(tool_mass_kg_ * g, base_T_sensor * tool_com_sensor_m_, base_T_sensor, out.weight_ft);
  if (follows_tool_) {
    add_wrench_at(params_.oru_mass_kg * g, base_T_oru_ * params_.oru_com_m, base_T_sensor, out.weight_ft);
    // The ORU's back in its slot: a contact like the tool's, about the back.
    const Pose base_T_back = base_T_oru_ * oru_T_back_;
    Twist back_twist;
    back_twist.w_rad_s = twist.w_rad_s;
    back_twist.v_m_s = twist.v_m_s + twist.w_rad_s.cross(base_T_back.translation() - base_T_tip.translation());
    out.slot_contact = slot_contact_.compute(base_T_back, base_T_slot_, back_twist);
    const Pose sensor_T_back = base_T_sensor.inverse(Eigen::Isometry) * base_T_back;
    const Eigen::Matrix3d R = sensor_T_back.linear();
    out.slot_ft.force_n = R * out.slot_contact.sensor.force_n;
    out.slot_ft.torque_nm = R * out.slot_contact.sensor.torque_nm + sensor_T_back.translation().cross(out.slot_ft.force_n);
  }
  const Eigen::Vector3d f = out.contact_ft.force_n + out.slot_ft.force_n + out.weight_ft.force_n;
  const Eigen::Vector3d m = out.contact_ft.torque_nm + out.slot_ft.torque_nm + out.weight_ft.torque_nm;
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    out.wrench_ft[k] = f[i] + params_.sensor_bias[k];
    out.wrench_ft[k + 3] = m[i] + params_.sensor_bias[k + 3];
  }

  // Ground truth.
  const Pose home_T_now = base_T_oru_home_.inverse(Eigen::Isometry) * base_T_oru_;
  std::lock_guard lock(truth_mu_);
  truth_.state = state_;
  truth_.gripped = gripped_;
  truth_.socket_engaged = socket_engaged_;
  truth_.base_T_tip = base_T_tip;
  truth_.base_T_oru = base_T_oru_;
  truth_.tip_depth_m = depth;
  truth_.oru_slot_depth_m = (base_T_slot_.inverse(Eigen::Isometry) * base_T_oru_ * oru_T_back_).translation().z();
  truth_.alignment_error_m = home_T_now.translation().norm();
  truth_.alignment_error_rad = Eigen::AngleAxisd(home_T_now.linear()).angle();
  truth_.wrench_ft = out.wrench_ft;
  ++truth_.steps;
  return out;
}

PlantTruth Plant::truth() const {
  std::lock_guard lock(truth_mu_);
  return truth_;
}

OruState Plant::oru_state() const {
  std::lock_guard lock(truth_mu_);
  return truth_.state;
}

}  // namespace foresight::sim
