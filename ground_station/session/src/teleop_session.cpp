#include "foresight/session/teleop_session.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <ostream>

#include "foresight/camera/camera.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/teleop/evdev.hpp"
#include "foresight/teleop/teleop.hpp"

namespace foresight::session {

namespace {

/// Reads the hand controller at `rate_hz` until the duration ends, `stop`, or
/// a button is pressed; the samples as a recorded input (t from 0). Not
/// real-time code: it paces itself with absolute deadlines.
std::vector<teleop::HandSample> read_device(const TeleopRequest& o, std::ostream* progress,
                                            const std::atomic<bool>* stop, TeleopOutcome& out) {
  teleop::EvdevDevice dev(o.device, teleop::parse_axis_map(o.axes));
  out.device_name = dev.name();
  if (progress != nullptr)
    *progress << "teleop: " << o.device << " (" << dev.name() << "), " << o.rate_hz
              << " Hz; press a button or Ctrl-C to stop" << (o.duration_s > 0 ? " (or wait the duration)" : "")
              << "\n" << std::flush;
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / o.rate_hz));
  const auto t0 = Clock::now();
  const std::uint64_t presses0 = dev.state().presses();
  // Bounded: --duration, else at most one hour of samples.
  const long max_ticks = std::lround((o.duration_s > 0 ? o.duration_s : 3600.0) * o.rate_hz);
  std::vector<teleop::HandSample> samples;
  samples.reserve(static_cast<std::size_t>(std::min(max_ticks + 1, 360001L)));
  out.ended_by = "duration";
  for (long tick = 0; tick <= max_ticks; ++tick) {
    const auto deadline = t0 + tick * period;
    while (Clock::now() < deadline) {  // take events until the tick's deadline
      const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
      const int r = dev.poll(std::max(left, 0.0));
      if (r < 0) throw ComputationError(o.device + ": the input device went away");
    }
    samples.push_back({tick / o.rate_hz, dev.state().axes()});
    if (stop != nullptr && stop->load()) {
      out.ended_by = "interrupt";
      break;
    }
    if (dev.state().presses() != presses0) {
      out.ended_by = "button";
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

/// The camera frame's pose: calibrated (--cameras) or the work site's layout.
Pose camera_pose(const TeleopRequest& o, std::string* source) {
  if (o.camera.empty()) throw std::invalid_argument("--frame camera needs --camera NAME");
  if (!o.cameras.empty()) {
    const auto cams = camera::load_cameras(o.cameras);
    const auto it = cams.find(o.camera);
    if (it == cams.end()) throw InputError(o.cameras, "no camera '" + o.camera + "'");
    *source = o.cameras;
    return it->second.camera.base_T_camera;
  }
  const Scene scene = Scene::from_file(o.scene);
  const auto it = scene.cameras.find(o.camera);
  if (it == scene.cameras.end()) throw InputError(o.scene, "no camera '" + o.camera + "'");
  const auto& c = it->second;
  *source = o.scene + " (the work site's layout, not a calibration)";
  return camera::Camera::look_at(o.camera, camera::Viewport{c.width_px, c.height_px}, c.f_px, c.position_m, c.look_at_m, c.up)
      .base_T_camera;
}

}  // namespace

TeleopOutcome teleoperate(const TeleopRequest& o, std::ostream* progress, const std::atomic<bool>* stop) {
  if (o.device.empty() == o.input.empty()) throw std::invalid_argument("give one of --device or --input");
  if (o.joints.empty() == o.joints_deg.empty())
    throw std::invalid_argument("give one of --joints or --joints-deg (the start)");
  if (!o.record_input.empty() && o.device.empty()) throw std::invalid_argument("--record-input needs --device");
  const RobotModel model = RobotModel::from_file(o.robot);
  TeleopOutcome out;
  out.q_start = !o.joints.empty() ? parse_joints(o.joints, "--joints", model)
                                  : parse_joints(o.joints_deg, "--joints-deg", model, true);
  teleop::TeleopOptions t;
  t.frame = teleop::parse_reference_frame(o.frame);
  t.position_gain_m_s = o.position_gain_m_s;
  t.orientation_gain_rad_s = o.orientation_gain_deg_s * M_PI / 180.0;
  t.deadband = o.deadband;
  if (t.frame == teleop::ReferenceFrame::Camera) {
    t.base_T_camera = camera_pose(o, &out.camera_source);
  } else if (!o.camera.empty() || !o.cameras.empty()) {
    throw std::invalid_argument("--camera and --cameras go with --frame camera");
  }

  std::vector<teleop::HandSample> input;
  if (!o.input.empty()) {
    out.source = o.input;
    input = teleop::read_hand_input_csv(o.input);
    if (input.size() < 2) throw InputError(o.input, "needs at least 2 samples");
  } else {
    out.source = o.device;
    input = read_device(o, progress, stop, out);
    if (!o.record_input.empty()) write_input_csv(o.record_input, input);
    if (input.size() < 2) throw ComputationError(o.device + ": stopped before two samples were read");
  }
  out.input_samples = input.size();

  const Trajectory traj = teleop::play(model, out.q_start, input, t, o.rate_hz);
  out.samples = traj.samples();
  out.duration_s = traj.duration_s();
  KinematicsWorkspace ws(model);
  const Pose a = forward_kinematics(model, ws, out.q_start);
  out.q_end = traj.positions_rad.row(traj.samples() - 1).transpose();
  const Pose b = forward_kinematics(model, ws, out.q_end);
  out.tip_start_m = a.translation();
  out.tip_end_m = b.translation();
  out.displacement_base_m = b.translation() - a.translation();
  const Eigen::AngleAxisd turn(b.linear() * a.linear().transpose());
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // the reference frame at the start
  if (t.frame == teleop::ReferenceFrame::Tool) R = a.linear();
  if (t.frame == teleop::ReferenceFrame::Camera) R = t.base_T_camera.linear();
  out.displacement_frame_m = R.transpose() * out.displacement_base_m;
  out.turn_rad = turn.angle();
  out.rotation_base_rad = turn.angle() * turn.axis();

  const auto violations = validate(traj, TrajectoryLimits::from_model(model), &out.violations);
  out.sha256 = to_hex(trajectory_hash(traj));
  out.valid = violations.empty();
  if (!out.valid) out.first_violation = violations[0].message;
  if (!o.record.empty() && out.valid) {
    write_trajectory_csv(o.record, traj);
    out.record = o.record;
  }
  return out;
}

nlohmann::json teleop_json(const TeleopRequest& o, const TeleopOutcome& r) {
  nlohmann::json j = {{"frame", o.frame},
                      {"source", r.source},
                      {"ended_by", r.ended_by},
                      {"input_samples", r.input_samples},
                      {"samples", r.samples},
                      {"duration_s", r.duration_s},
                      {"start_q_rad", vec_json(r.q_start)},
                      {"final_q_rad", vec_json(r.q_end)},
                      {"tip_start_m", vec_json(r.tip_start_m)},
                      {"tip_end_m", vec_json(r.tip_end_m)},
                      {"displacement_base_m", vec_json(r.displacement_base_m)},
                      {"displacement_frame_m", vec_json(r.displacement_frame_m)},
                      {"rotation_base_rad", vec_json(r.rotation_base_rad)},
                      {"valid", r.valid},
                      {"violations", r.violations},
                      {"sha256", r.sha256},
                      {"record", r.valid ? nlohmann::json(o.record) : nlohmann::json(nullptr)}};
  if (!r.device_name.empty()) j["device_name"] = r.device_name;
  if (!r.camera_source.empty()) j["camera_source"] = r.camera_source;
  if (!r.valid) j["first_violation"] = r.first_violation;
  return j;
}

}  // namespace foresight::session
