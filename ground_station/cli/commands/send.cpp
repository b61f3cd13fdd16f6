// foresight send TRAJ.csv [--run] [--compliant]: validate the trajectory with
// the remote's rules, upload it, wait for COMMITTED with the remote's content
// hash equal to the local one (both printed); with --run the RUN (by id and
// hash) goes out right behind the chunks, the remote starts it once the
// upload committed, and the final ack is awaited (COMPLETED with the final
// joints, or why).
#include <cstdio>
#include <iostream>
#include <optional>

#include "command.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct Options {
  LinkOptions link;
  std::string trajectory;
  bool run = false;
  bool compliant = false;
  double upload_timeout_s = 0.0;
  double start_tolerance_rad = 0.0;
  std::string robot = default_config("robot.urdf");
};

int run(const Options& o) {
  const RobotModel model = RobotModel::from_file(o.robot);
  const Trajectory traj = read_trajectory_csv(o.trajectory);
  const auto violations = validate(traj, TrajectoryLimits::from_model(model));
  if (!violations.empty()) {
    for (const auto& v : violations) std::cerr << "foresight send: " << v.message << "\n";
    std::cerr << "foresight send: " << violations.size()
              << " violation(s); not sent (the remote would reject this trajectory)\n";
    return kExitFailure;
  }
  const std::string local = to_hex(trajectory_hash(traj));
  auto link = connect_remote(o.link);
  const double upload_timeout =
      o.upload_timeout_s > 0 ? o.upload_timeout_s
                             : std::chrono::duration<double>(link->timeout_for(1.0 + traj.samples() * 1e-4)).count();
  // With --run, the RUN goes out right behind the chunks (upload and run in
  // one go): the remote starts it once the whole upload committed with this
  // hash, not a round trip later.
  std::optional<ControlGuard> control_guard;
  UploadAndRun sent;
  ground_link::UploadResult up;
  if (o.run) {
    control_guard.emplace(*link);
    protocol::RunTrajectory run;
    run.compliant = o.compliant;
    run.start_tolerance_rad = o.start_tolerance_rad;
    sent = upload_and_run(*link, traj, run);
    up = sent.upload;
    link->wait_upload(up, std::chrono::duration_cast<std::chrono::nanoseconds>(
                              std::chrono::duration<double>(upload_timeout)));
    require_committed(up, upload_timeout);
  } else {
    up = upload_committed(*link, traj, upload_timeout);
  }
  nlohmann::json j = {{"file", o.trajectory},
                      {"samples", traj.samples()},
                      {"duration_s", traj.duration_s()},
                      {"trajectory_id", up.trajectory_id},
                      {"local_sha256", local},
                      {"remote_sha256", to_hex(up.remote_hash)},
                      {"chunks", up.chunk_count},
                      {"upload_s", up.elapsed_s},
                      {"committed", true}};
  if (!o.link.json)
    std::printf("committed trajectory %llu: %d samples, %.2f s, %u chunks in %.3f s\n  local  sha256 %s\n  remote "
                "sha256 %s\n",
                static_cast<unsigned long long>(up.trajectory_id), traj.samples(), traj.duration_s(), up.chunk_count,
                up.elapsed_s, local.c_str(), to_hex(up.remote_hash).c_str());
  int status = kExitOk;
  if (o.run) {
    const auto kind = protocol::CommandKind::Trajectory;
    const auto r = wait_or_abort(*link, sent.command_id, sent.sent,
                                 final_ack_timeout(*link, traj.duration_s() + sent.upload_wait_s, o.link.timeout_s));
    j["run"] = result_json(kind, r);
    j["compliant"] = o.compliant;
    j["upload_wait_s"] = sent.upload_wait_s;
    status = exit_status(r);
    if (!o.link.json) {
      std::cout << result_line(kind, r) << "\n";
      if (!r.final_q_rad.empty()) {
        std::printf("final joints (deg):");
        for (double q : r.final_q_rad) std::printf(" %.3f", q * 180.0 / M_PI);
        std::printf("\n");
      }
    }
  }
  if (o.link.json) std::cout << j.dump(2) << "\n";
  return status;
}

const bool registered = register_command(
    {"send", "validate, upload and commit a trajectory on the remote (hashes compared); --run executes it",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("trajectory", o->trajectory, "trajectory CSV (t,q1,...,qN; s, rad)")->required();
       sub.add_flag("--run", o->run, "run it once committed and wait for the final ack");
       sub.add_flag("--compliant", o->compliant, "run under the wrist F/T compliance");
       sub.add_option("--upload-timeout", o->upload_timeout_s, "seconds to wait for COMMITTED (default: derived)")
           ->check(check::WaitSeconds);
       sub.add_option("--start-tolerance", o->start_tolerance_rad,
                      "max |q_actual - q(0)| to start, rad, at most 0.02 (0: the remote's default)")
           ->check(check::Range(0.0, kMaxStartToleranceRad));
       sub.add_option("--robot", o->robot, "robot URDF")->capture_default_str();
       add_link_options(sub, o->link);
       return [o] {
         if (o->compliant && !o->run) throw std::invalid_argument("--compliant needs --run");
         return run(*o);
       };
     }});

}  // namespace
}  // namespace foresight::cli
