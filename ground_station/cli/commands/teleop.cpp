// foresight teleop: hand-controller teleoperation of the ground's simulated arm
// (Kim 1996's world / tool / camera-view referenced Cartesian modes), from a
// Linux joystick through evdev (--device /dev/input/eventN) or a recorded
// input file (--input REC.csv), through the remote's own damped-least-squares
// inverse Jacobian (foresight_teleop). --record writes the motion as a
// trajectory CSV that `foresight validate`, `preview` and `send` take; nothing
// is sent from here (preview it first, then send it). Not real-time code: the
// device loop paces itself at --rate with absolute deadlines.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <thread>

#include "command.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/teleop/evdev.hpp"
#include "foresight/teleop/teleop.hpp"

namespace foresight::cli {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_teleop_interrupt(int) { g_stop.store(true); }

struct Options {
  std::string device, input, frame = "world", camera, cameras;
  std::string joints, joints_deg;
  double position_gain_m_s = 0.05, orientation_gain_deg_s = 10.0, deadband = 0.05, rate_hz = 100.0;
  double duration_s = 0.0;
  std::string axes = "X,Y,Z,RX,RY,RZ";
  std::string record, record_input;
  std::string robot, scene;
  bool json = false;
};

std::vector<double> vec(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }
std::vector<double> vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

/// Reads the hand controller at `rate_hz` until the duration ends, Ctrl-C, or
/// a button is pressed; the samples as a recorded input (t from 0).
std::vector<teleop::HandSample> read_device(const Options& o, std::string* device_name, std::string* ended_by) {
  teleop::EvdevDevice dev(o.device, teleop::parse_axis_map(o.axes));
  *device_name = dev.name();
  if (!o.json)
    std::cout << "teleop: " << o.device << " (" << dev.name() << "), " << o.rate_hz
              << " Hz; press a button or Ctrl-C to stop" << (o.duration_s > 0 ? " (or wait the duration)" : "")
              << "\n" << std::flush;
  std::signal(SIGINT, on_teleop_interrupt);
  std::signal(SIGTERM, on_teleop_interrupt);
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / o.rate_hz));
  const auto t0 = Clock::now();
  const std::uint64_t presses0 = dev.state().presses();
  // Bounded: --duration, else at most one hour of samples.
  const long max_ticks = std::lround((o.duration_s > 0 ? o.duration_s : 3600.0) * o.rate_hz);
  std::vector<teleop::HandSample> samples;
  samples.reserve(static_cast<std::size_t>(std::min(max_ticks + 1, 360001L)));
  *ended_by = "duration";
  for (long tick = 0; tick <= max_ticks; ++tick) {
    const auto deadline = t0 + tick * period;
    while (Clock::now() < deadline) {  // take events until the tick's deadline
      const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
      const int r = dev.poll(std::max(left, 0.0));
      if (r < 0) throw ComputationError(o.device + ": the input device went away");
    }
    samples.push_back({tick / o.rate_hz, dev.state().axes()});
    if (g_stop.load()) {
      *ended_by = "interrupt";
      break;
    }
    if (dev.state().presses() != presses0) {
      *ended_by = "button";
      break;
    }
  }
  return samples;
}

void write_input_csv(const std::string& path, const std::vector<teleop::HandSample>& samples) {
  std::ofstream out(path);
  if (!out) throw InputError(path, "cannot write the recorded input");
  out << "t,x,y,z,rx,ry,rz\n";
  char buf[256];
  for (const auto& s : samples) {
    std::snprintf(buf, sizeof buf, "%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", s.t_s, s.axes[0], s.axes[1], s.axes[2],
                  s.axes[3], s.axes[4], s.axes[5]);
    out << buf;
  }
}

int teleop_command(Options& o) {
  if (o.device.empty() == o.input.empty()) throw std::invalid_argument("give one of --device or --input");
  if (o.joints.empty() == o.joints_deg.empty()) throw std::invalid_argument("give one of --joints or --joints-deg (the start)");
  if (!o.record_input.empty() && o.device.empty()) throw std::invalid_argument("--record-input needs --device");
  const RobotModel model = RobotModel::from_file(o.robot);
  const Eigen::VectorXd q0 = !o.joints.empty() ? parse_joints(o.joints, "--joints", model)
                                               : parse_joints(o.joints_deg, "--joints-deg", model, true);
  teleop::TeleopOptions t;
  t.frame = teleop::parse_reference_frame(o.frame);
  t.position_gain_m_s = o.position_gain_m_s;
  t.orientation_gain_rad_s = o.orientation_gain_deg_s * M_PI / 180.0;
  t.deadband = o.deadband;
  std::string camera_source;
  if (t.frame == teleop::ReferenceFrame::Camera) {
    if (o.camera.empty()) throw std::invalid_argument("--frame camera needs --camera NAME");
    if (!o.cameras.empty()) {
      const auto cams = camera::load_cameras(o.cameras);
      const auto it = cams.find(o.camera);
      if (it == cams.end()) throw InputError(o.cameras, "no camera '" + o.camera + "'");
      t.base_T_camera = it->second.camera.base_T_camera;
      camera_source = o.cameras;
    } else {  // the work site's camera as laid out (no calibration given)
      const Scene scene = Scene::from_file(o.scene);
      const auto it = scene.cameras.find(o.camera);
      if (it == scene.cameras.end()) throw InputError(o.scene, "no camera '" + o.camera + "'");
      const auto& c = it->second;
      t.base_T_camera = camera::Camera::look_at(o.camera, camera::Viewport{c.width_px, c.height_px}, c.f_px, c.position_m, c.look_at_m,
                                        c.up).base_T_camera;
      camera_source = o.scene + " (the work site's layout, not a calibration)";
    }
  } else if (!o.camera.empty() || !o.cameras.empty()) {
    throw std::invalid_argument("--camera and --cameras go with --frame camera");
  }

  std::string device_name, ended_by = "end of input";
  std::vector<teleop::HandSample> input;
  if (!o.input.empty()) {
    input = teleop::read_hand_input_csv(o.input);
    if (input.size() < 2) throw InputError(o.input, "needs at least 2 samples");
  } else {
    input = read_device(o, &device_name, &ended_by);
    if (!o.record_input.empty()) write_input_csv(o.record_input, input);
    if (input.size() < 2) throw ComputationError(o.device + ": stopped before two samples were read");
  }

  const Trajectory traj = teleop::play(model, q0, input, t, o.rate_hz);
  KinematicsWorkspace ws(model);
  const Pose a = forward_kinematics(model, ws, q0);
  const Eigen::VectorXd q1 = traj.positions_rad.row(traj.samples() - 1).transpose();
  const Pose b = forward_kinematics(model, ws, q1);
  const Eigen::Vector3d d_base = b.translation() - a.translation();
  const Eigen::AngleAxisd turn(b.linear() * a.linear().transpose());
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // the reference frame at the start
  if (t.frame == teleop::ReferenceFrame::Tool) R = a.linear();
  if (t.frame == teleop::ReferenceFrame::Camera) R = t.base_T_camera.linear();
  const Eigen::Vector3d d_ref = R.transpose() * d_base;
  const Eigen::Vector3d turn_base = turn.angle() * turn.axis();

  std::size_t total = 0;
  const auto violations = validate(traj, TrajectoryLimits::from_model(model), &total);
  const std::string hash = to_hex(trajectory_hash(traj));
  const bool ok = violations.empty();
  if (!o.record.empty() && ok) write_trajectory_csv(o.record, traj);

  if (o.json) {
    nlohmann::json j = {{"frame", o.frame},
                        {"source", o.input.empty() ? o.device : o.input},
                        {"ended_by", ended_by},
                        {"input_samples", input.size()},
                        {"samples", traj.samples()},
                        {"duration_s", traj.duration_s()},
                        {"start_q_rad", vec(q0)},
                        {"final_q_rad", vec(q1)},
                        {"tip_start_m", vec3(a.translation())},
                        {"tip_end_m", vec3(b.translation())},
                        {"displacement_base_m", vec3(d_base)},
                        {"displacement_frame_m", vec3(d_ref)},
                        {"rotation_base_rad", vec3(turn_base)},
                        {"valid", ok},
                        {"violations", total},
                        {"sha256", hash},
                        {"record", ok ? nlohmann::json(o.record) : nlohmann::json(nullptr)}};
    if (!device_name.empty()) j["device_name"] = device_name;
    if (!camera_source.empty()) j["camera_source"] = camera_source;
    if (!ok) j["first_violation"] = violations[0].message;
    std::cout << j.dump(2) << "\n";
  } else {
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "teleop (%s frame%s%s): %zu input samples -> %d trajectory samples, %.2f s (ended: %s)\n"
                  "  tool tip moved %.1f mm: base (%.1f, %.1f, %.1f) mm, %s frame (%.1f, %.1f, %.1f) mm; turned %.2f deg\n",
                  o.frame.c_str(), camera_source.empty() ? "" : ", camera from ", camera_source.c_str(), input.size(),
                  traj.samples(), traj.duration_s(), ended_by.c_str(), d_base.norm() * 1e3, d_base.x() * 1e3,
                  d_base.y() * 1e3, d_base.z() * 1e3, o.frame.c_str(), d_ref.x() * 1e3, d_ref.y() * 1e3,
                  d_ref.z() * 1e3, turn.angle() * 180.0 / M_PI);
    std::cout << buf;
    if (ok)
      std::cout << "  valid under the remote's rules; sha256 " << hash << "\n"
                << (o.record.empty() ? std::string("  (--record OUT.csv to keep it)\n")
                                     : "  recorded -> " + o.record + " (foresight preview / send it)\n");
  }
  if (!ok) {
    std::cerr << "foresight teleop: the motion breaks " << total << " rule(s), not recorded: " << violations[0].message
              << "\n";
    return kExitFailure;
  }
  return kExitOk;
}

const bool registered = register_command(
    {"teleop",
     "hand-controller teleoperation of the simulated arm (world/tool/camera frames); record the motion as a trajectory",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       o->robot = default_config("robot.urdf");
       o->scene = default_config("scene.yaml");
       sub.add_option("--device", o->device, "a Linux joystick: /dev/input/eventN (evdev)");
       sub.add_option("--input", o->input, "a recorded input file: t,x,y,z,rx,ry,rz (s, deflections in [-1, 1])");
       sub.add_option("--frame", o->frame, "reference frame of the deflections: world | tool | camera")
           ->check(check::IsMember({"world", "tool", "camera"}))
           ->capture_default_str();
       sub.add_option("--camera", o->camera, "camera-view frame: the camera (x right, y down, z forward)");
       sub.add_option("--cameras", o->cameras, "calibrated cameras.yaml (default: the work site's layout)");
       sub.add_option("--joints", o->joints, "start joint angles (rad)");
       sub.add_option("--joints-deg", o->joints_deg, "start joint angles (deg)");
       sub.add_option("--position-gain", o->position_gain_m_s, "tool speed at full deflection, m/s")
           ->check(check::PositiveNumber)
           ->capture_default_str();
       sub.add_option("--orientation-gain", o->orientation_gain_deg_s, "tool turn rate at full deflection, deg/s")
           ->check(check::PositiveNumber)
           ->capture_default_str();
       sub.add_option("--deadband", o->deadband, "deflections below this are zero")
           ->check(check::Range(0.0, 0.99))
           ->capture_default_str();
       sub.add_option("--rate", o->rate_hz, "steps per second (and device samples)")
           ->check(check::Range(1.0, 1000.0))
           ->capture_default_str();
       sub.add_option("--axes", o->axes, "device: ABS axes feeding x,y,z,rx,ry,rz ('-' flips, 'none' unused)")
           ->capture_default_str();
       sub.add_option("--duration", o->duration_s, "device: stop after this many seconds (else a button or Ctrl-C)")
           ->check(check::PositiveNumber);
       sub.add_option("--record", o->record, "write the motion as a trajectory CSV (t,q1..qN)");
       sub.add_option("--record-input", o->record_input, "device: also write the deflections as a recorded input file");
       sub.add_option("--robot", o->robot, "robot URDF")->capture_default_str();
       sub.add_option("--scene", o->scene, "work site (the cameras' layout)")->capture_default_str();
       sub.add_flag("--json", o->json, "print one JSON object");
       return [o] { return teleop_command(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
