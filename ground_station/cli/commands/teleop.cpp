// foresight teleop: hand-controller teleoperation of the ground's simulated arm
// (Kim 1996's world / tool / camera-view referenced Cartesian modes), from a
// Linux joystick through evdev (--device /dev/input/eventN) or a recorded
// input file (--input REC.csv), through the remote's own damped-least-squares
// inverse Jacobian (session::teleoperate). --record writes the motion as a
// trajectory CSV that `foresight validate`, `preview` and `send` take; nothing
// is sent from here (preview it first, then send it).
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/session/teleop_session.hpp"

namespace foresight::cli {
namespace {

struct Options : session::TeleopRequest {
  bool json = false;
};

std::atomic<bool> g_stop{false};
extern "C" void on_teleop_interrupt(int) { g_stop.store(true); }

int teleop_command(const Options& o) {
  if (!o.device.empty()) {  // Ctrl-C ends the device's reading, and the motion is still checked and printed
    std::signal(SIGINT, on_teleop_interrupt);
    std::signal(SIGTERM, on_teleop_interrupt);
  }
  const session::TeleopOutcome r = session::teleoperate(o, o.json ? nullptr : &std::cout, &g_stop);
  if (o.json) {
    std::cout << session::teleop_json(o, r).dump(2) << "\n";
  } else {
    const Eigen::Vector3d& d = r.displacement_base_m;
    const Eigen::Vector3d& f = r.displacement_frame_m;
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "teleop (%s frame%s%s): %zu input samples -> %d trajectory samples, %.2f s (ended: %s)\n"
                  "  tool tip moved %.1f mm: base (%.1f, %.1f, %.1f) mm, %s frame (%.1f, %.1f, %.1f) mm; turned %.2f deg\n",
                  o.frame.c_str(), r.camera_source.empty() ? "" : ", camera from ", r.camera_source.c_str(),
                  r.input_samples, r.samples, r.duration_s, r.ended_by.c_str(), d.norm() * 1e3, d.x() * 1e3,
                  d.y() * 1e3, d.z() * 1e3, o.frame.c_str(), f.x() * 1e3, f.y() * 1e3, f.z() * 1e3,
                  r.turn_rad * 180.0 / M_PI);
    std::cout << buf;
    if (r.valid)
      std::cout << "  valid under the remote's rules; sha256 " << r.sha256 << "\n"
                << (o.record.empty() ? std::string("  (--record OUT.csv to keep it)\n")
                                     : "  recorded -> " + o.record + " (foresight preview / send it)\n");
  }
  if (!r.valid) {
    std::cerr << "foresight teleop: the motion breaks " << r.violations << " rule(s), not recorded: "
              << r.first_violation << "\n";
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
