// The link commands' shared helpers (link_session.hpp). Registers no command.
#include "foresight/session/link_session.hpp"

#include "foresight/session/config_path.hpp"
#include "foresight/common/format.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/network.hpp"
#include "foresight/protocol/security.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

namespace foresight::session {

namespace {

using Clock = std::chrono::steady_clock;

std::chrono::nanoseconds seconds(double s) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(s));
}

}  // namespace

int resolve_domain(int option) {
  if (option >= 0) return option;
  return protocol::domain_from_environment().value_or(0);
}

namespace {
std::unique_ptr<ground_link::GroundLink> connect(const ground_link::Config& config, double timeout_s) {
  const int domain = config.domain;
  auto link = std::make_unique<ground_link::GroundLink>(config);
  if (!link->wait_for_remote(seconds(timeout_s)))
    throw LinkFailure("no remote answered on DDS domain " + std::to_string(domain) + " within " +
                      fixed(timeout_s, 1) + " s (is foresight-remote running? --domain / FORESIGHT_DDS_DOMAIN" +
                      (config.security_dir.empty() ? std::string(")")
                                                   : "; does it run with the same DDS Security CA, and is '" +
                                                         config.security_identity + "' granted?)"));
  return link;
}
}  // namespace

std::unique_ptr<ground_link::GroundLink> connect_remote(int domain, double timeout_s) {
  ground_link::Config config;
  config.domain = domain;
  return connect(config, timeout_s);
}

GroundLinkFile load_ground_link_file(const std::string& path) {
  GroundLinkFile f;
  f.path = path;
  f.network.source = path + ": link.network (the default)";
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return f;
  const YAML::Node root = yaml::parse(read_text_file(path, "cannot open the ground configuration"), path);
  const yaml::MapReader top(root, path, "");
  top.check_keys({"link", "contact_check"});  // contact_check: contact_check/config.hpp
  if (!top["link"]) return f;
  const yaml::MapReader link = top.map("link");
  link.check_keys({"security", "identity", "network"});
  const protocol::LinkSecuritySettings sec = protocol::read_link_security(link, f.identity);
  f.security_dir = sec.dir;
  f.identity = sec.identity;
  if (link["network"]) f.network = protocol::read_network(link.map("network"));
  return f;
}

std::unique_ptr<ground_link::GroundLink> connect_remote(const LinkOptions& o) {
  const GroundLinkFile file = load_ground_link_file(default_config("ground.yaml"));
  ground_link::Config config;
  config.domain = resolve_domain(o.domain);
  // Options, then the environment, then ground.yaml.
  auto env = [](const char* name) -> std::string {
    const char* v = std::getenv(name);
    return v != nullptr ? v : "";
  };
  std::string from = "--security";
  config.security_dir = o.security_dir;
  if (config.security_dir.empty()) {
    config.security_dir = env("FORESIGHT_DDS_SECURITY");
    from = "FORESIGHT_DDS_SECURITY";
  }
  if (config.security_dir.empty()) {
    config.security_dir = file.security_dir;
    from = file.path + ": link.security";
  }
  config.security_identity = !o.identity.empty()                        ? o.identity
                             : !env("FORESIGHT_DDS_IDENTITY").empty() ? env("FORESIGHT_DDS_IDENTITY")
                                                                       : file.identity;
  if (!config.security_dir.empty()) {
    try {
      protocol::verify_security_files(config.security_dir, config.security_identity);
    } catch (const protocol::ProtocolError& e) {
      throw InputError(from, e.what());
    }
    // An observer may not create command or chunk writers: it watches.
    std::ifstream role(config.security_dir + "/identities/" + config.security_identity + "/role");
    std::string r;
    config.read_only = role >> r && r == "observer";
  }
  protocol::use_network(file.network);  // before the first participant (a CYCLONEDDS_URI wins)
  return connect(config, o.connect_timeout_s);
}

std::chrono::nanoseconds final_ack_timeout(const ground_link::GroundLink& link, double expected_s,
                                           double override_s) {
  return override_s > 0 ? seconds(override_s) : link.timeout_for(expected_s);
}

ground_link::CommandResult send_and_wait(ground_link::GroundLink& link, protocol::CommandKind kind,
                                         const protocol::Payload& payload, std::chrono::nanoseconds timeout,
                                         const std::function<bool()>& interrupted) {
  const auto t0 = Clock::now();
  return wait_or_abort(link, link.send(kind, payload), t0, timeout, interrupted);
}

ground_link::CommandResult wait_or_abort(ground_link::GroundLink& link, std::uint64_t id,
                                         std::chrono::steady_clock::time_point sent, std::chrono::nanoseconds timeout,
                                         const std::function<bool()>& interrupted) {
  const auto deadline = sent + timeout;
  bool aborted = false;
  ground_link::CommandResult r;
  r.command_id = id;
  while (Clock::now() < deadline) {
    const auto slice = std::min<std::chrono::nanoseconds>(std::chrono::milliseconds(100), deadline - Clock::now());
    r = link.wait_final(id, slice);
    if (r.finished) break;
    if (!aborted && interrupted && interrupted()) {
      aborted = true;
      protocol::Abort a;
      a.target_command_id = id;
      a.category = protocol::StopCategory::Cat2;
      a.reason = "canceled by the operator";
      link.send(protocol::CommandKind::Abort, a);
    }
  }
  r.elapsed_s = std::chrono::duration<double>(Clock::now() - sent).count();
  return r;
}

ControlGuard::ControlGuard(ground_link::GroundLink& link) : link_(link) {
  const auto r = send_and_wait(link_, protocol::CommandKind::TakeControl, protocol::NoPayload{}, link_.timeout_for(0.0));
  if (!r.succeeded()) throw LinkFailure("cannot take control: " + result_line(protocol::CommandKind::TakeControl, r));
}

ControlGuard::~ControlGuard() {
  if (link_.secured()) return;  // the station keeps control across its commands (its lease)
  try {
    send_and_wait(link_, protocol::CommandKind::ReleaseControl, protocol::NoPayload{}, link_.timeout_for(0.0));
  } catch (const std::exception&) {
  }
}

nlohmann::json result_json(protocol::CommandKind kind, const ground_link::CommandResult& r) {
  nlohmann::json acks = nlohmann::json::array();
  for (const auto& a : r.acks)
    acks.push_back({{"state", protocol::to_string(a.state)}, {"code", protocol::to_string(a.code)}, {"reason", a.reason}});
  return {{"command", protocol::to_string(kind)},
          {"command_id", r.command_id},
          {"state", r.finished ? protocol::to_string(r.state) : "timeout"},
          {"code", protocol::to_string(r.code)},
          {"reason", r.reason},
          {"finished", r.finished},
          {"elapsed_s", r.elapsed_s},
          {"final_q_rad", r.final_q_rad},
          {"acks", acks}};
}

std::string result_line(protocol::CommandKind kind, const ground_link::CommandResult& r) {
  std::string s = std::string(protocol::to_string(kind)) + " " + std::to_string(r.command_id) + ": ";
  if (!r.finished) {
    const std::string last = r.acks.empty() ? "no ack" : protocol::to_string(r.acks.back().state);
    return s + "timed out after " + fixed(r.elapsed_s, 1) + " s waiting for the final ack (last: " + last + ")";
  }
  s += protocol::to_string(r.state);
  if (r.state == protocol::AckState::Completed) return s + " in " + fixed(r.elapsed_s, 2) + " s";
  s += std::string(" (") + protocol::to_string(r.code) + ")";
  if (!r.reason.empty()) s += ": " + r.reason;
  return s;
}

int exit_status(const ground_link::CommandResult& r) { return r.succeeded() ? 0 : 1; }

std::optional<Eigen::VectorXd> joints_of(const protocol::JointReport& report, const RobotModel& model) {
  if (static_cast<int>(report.q_rad.size()) != model.dof()) return std::nullopt;
  return Eigen::Map<const Eigen::VectorXd>(report.q_rad.data(), model.dof());
}

Eigen::VectorXd require_joints(const protocol::JointReport& report, const RobotModel& model) {
  auto q = joints_of(report, model);
  if (!q)
    throw LinkFailure("the remote reports " + std::to_string(report.q_rad.size()) + " joint angles, the robot model has " +
                      std::to_string(model.dof()) + " joints");
  return std::move(*q);
}

std::optional<ground_link::Timed<protocol::JointReport>> wait_joints(const ground_link::GroundLink& link,
                                                                    double timeout_s) {
  const auto deadline = Clock::now() + seconds(timeout_s);
  while (true) {
    if (auto j = link.joint_state()) return j;
    if (Clock::now() >= deadline) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

ground_link::UploadResult upload_committed(ground_link::GroundLink& link, const Trajectory& trajectory,
                                           double timeout_s) {
  const auto r = link.upload(trajectory, seconds(timeout_s));
  require_committed(r, timeout_s);
  return r;
}

void require_committed(const ground_link::UploadResult& r, double timeout_s) {
  if (r.state == protocol::UploadState::Committed && r.local_hash != r.remote_hash)
    throw LinkFailure("upload " + std::to_string(r.trajectory_id) + ": the remote committed hash " +
                      to_hex(r.remote_hash) + " but the local hash is " + to_hex(r.local_hash));
  if (r.state == protocol::UploadState::Rejected || r.state == protocol::UploadState::Discarded)
    throw LinkFailure("upload " + std::to_string(r.trajectory_id) + " rejected (" + protocol::to_string(r.code) +
                      ")" + (r.reason.empty() ? "" : ": " + r.reason));
  if (r.state != protocol::UploadState::Committed)
    throw LinkFailure("upload " + std::to_string(r.trajectory_id) + ": not committed within " + fixed(timeout_s, 1) +
                      " s");
}

double upload_wait_for(const ground_link::GroundLink& link, const Trajectory& trajectory) {
  const double derived =
      std::chrono::duration<double>(link.timeout_for(1.0 + trajectory.samples() * 1e-4)).count();
  return std::min(derived, kMaxUploadWaitS);
}

UploadAndRun upload_and_run(ground_link::GroundLink& link, const Trajectory& trajectory, protocol::RunTrajectory run,
                            std::uint64_t after_command_id) {
  UploadAndRun u;
  u.upload_wait_s = upload_wait_for(link, trajectory);
  u.upload = link.start_upload(trajectory);
  run.trajectory_id = u.upload.trajectory_id;
  run.content_hash = u.upload.local_hash;
  run.upload_wait_s = u.upload_wait_s;
  u.sent = Clock::now();
  u.command_id = link.send(protocol::CommandKind::Trajectory, run, -1.0, after_command_id);
  return u;
}

double planned_goto_duration_s(const RobotModel& model, const std::vector<double>& q_now,
                               const protocol::Payload& payload) {
  if (static_cast<int>(q_now.size()) != model.dof())
    throw PlanError("the remote reported " + std::to_string(q_now.size()) + " joints; the model has " +
                    std::to_string(model.dof()));
  const Eigen::VectorXd q0 = Eigen::Map<const Eigen::VectorXd>(q_now.data(), model.dof());
  Goal goal;
  PlanOptions options;
  if (const auto* gj = std::get_if<protocol::GotoJoint>(&payload)) {
    goal.name = "goto_joint";
    goal.kind = SegmentKind::Joint;
    goal.is_pose = false;
    goal.q = Eigen::Map<const Eigen::VectorXd>(gj->q_rad.data(), static_cast<Eigen::Index>(gj->q_rad.size()));
    options.limit_fraction = gj->speed_fraction;
  } else if (const auto* gc = std::get_if<protocol::GotoCart>(&payload)) {
    goal.name = "goto_cart";
    goal.kind = SegmentKind::Linear;
    goal.base_T_tip = gc->base_T_frame;
    options.limit_fraction = gc->speed_fraction;
    options.tool_speed_m_s = 0.1 * gc->speed_fraction;
  } else {
    throw std::invalid_argument("planned_goto_duration_s: not a goto payload");
  }
  return plan_motion(model, q0, {goal}, options).trajectory.duration_s();
}

std::string queue_text(const protocol::StatusReport& status) {
  std::string running, queued;
  for (const auto& q : status.queue) {
    const std::string id = std::to_string(q.command_id);
    if (q.state == protocol::AckState::Queued) queued += (queued.empty() ? "" : " ") + id;
    else running += (running.empty() ? "" : " ") + id + " " + protocol::to_string(q.kind);
  }
  if (running.empty() && queued.empty()) return "";
  return "running " + (running.empty() ? std::string("-") : running) + " | queued " +
         (queued.empty() ? std::string("-") : queued);
}

nlohmann::json status_json(const ground_link::GroundLink& link) {
  const auto d = link.delay().stats();
  nlohmann::json j;
  j["rtt_s"] = {{"median", d.median_s}, {"p95", d.p95_s},         {"p99", d.p99_s},
                {"max", d.max_s},       {"min", d.min_s},         {"count", d.count},
                {"share_over_0_5s", d.share_over_0_5s}, {"share_over_4s", d.share_over_4s}};
  j["clock_offset_s"] = d.clock_offset_s;
  j["remote_alive"] = link.remote_alive();
  j["session_id"] = link.session_id();
  // DDS Security admits no plain participant: a plain station that hears the
  // remote means the remote runs its link open (--sim, or insecure: true).
  j["link_security"] = link.secured() ? nlohmann::json{{"dds_security", true}, {"identity", link.identity()}}
                                      : nlohmann::json{{"dds_security", false}, {"identity", ""}};
  nlohmann::json faults = nlohmann::json::array();
  if (const auto js = link.joint_state()) {
    j["joints_rad"] = js->value.q_rad;
    j["joint_velocities_rad_s"] = js->value.dq_rad_s;
    j["joints_age_s"] = js->age_s;
  } else {
    j["joints_rad"] = nlohmann::json::array();
    j["joint_velocities_rad_s"] = nlohmann::json::array();
    j["joints_age_s"] = nullptr;
  }
  const auto dropped = link.dropped();
  j["joint_states_dropped"] = {{"joint_count", dropped.joint_state_joint_count},
                               {"length", dropped.joint_state_length},
                               {"not_finite", dropped.joint_state_not_finite}};
  // Samples of the remote's topics from another participant than the remote's (ground_link.hpp).
  j["ignored_samples"] = dropped.foreign;
  j["remote_participant"] = link.remote_participant().hex();
  if (const auto st = link.status()) {
    const auto& s = st->value;
    j["state"] = protocol::to_string(s.mode);
    j["active_command_id"] = s.active_command_id;
    j["active_trajectory_id"] = s.active_trajectory_id;
    j["stop_category"] = protocol::to_string(s.stop_category);
    j["stop_reason"] = s.stop_reason;
    j["fault_bits"] = s.fault_bits;
    j["status_age_s"] = st->age_s;
    // Each drive as it reported itself (CiA 402 state from its statusword).
    nlohmann::json drives = nlohmann::json::array();
    for (const auto& d : s.drives)
      drives.push_back({{"joint", d.joint},
                        {"node_id", d.node_id},
                        {"state", protocol::drive_state_name(static_cast<protocol::msg::DriveState>(d.state))},
                        {"powered", d.powered}});
    j["drives"] = drives;
    const protocol::LoopTiming& l = s.loop;
    j["loop"] = {{"realtime", l.realtime},
                 {"memory_locked", l.memory_locked},
                 {"realtime_required", l.realtime_required},
                 {"cycles", l.cycles},
                 {"overruns", l.overruns},
                 {"missed_streak_max", l.missed_streak_max},
                 {"max_missed_cycles", l.max_missed_cycles},
                 {"wakeup_latency_us", {{"p99", l.wakeup_latency_p99_us}, {"max", l.wakeup_latency_max_us}}},
                 {"compute_us", {{"p99", l.compute_p99_us}, {"max", l.compute_max_us}}}};
    // The rate limiter: how often it changed a command, and its last episode.
    const protocol::RateLimitReport& rl = s.rate_limit;
    nlohmann::json rl_joints = nlohmann::json::array();
    for (int b = 0; b < 32; ++b)
      if ((rl.last_joint_mask >> b) & 1u) rl_joints.push_back(b + 1);
    j["rate_limit"] = {{"cycles", rl.cycles},
                       {"limiting", rl.limiting},
                       {"last_joints", rl_joints},
                       {"last_command_id", rl.last_command_id},
                       {"last_max_lag_rad", rl.last_max_lag_rad}};
    // What the remote holds: the running command, then the queued ones (chains).
    nlohmann::json queue = nlohmann::json::array();
    for (const auto& q : s.queue)
      queue.push_back({{"command_id", q.command_id},
                       {"kind", protocol::to_string(q.kind)},
                       {"after_command_id", q.after_command_id},
                       {"state", protocol::to_string(q.state)}});
    j["queue"] = queue;
    if (s.fault_bits != 0 || !s.fault_text.empty())
      faults.push_back(s.fault_text.empty() ? "fault bits " + std::to_string(s.fault_bits) : s.fault_text);
    if (s.stop_category != protocol::StopCategory::None)
      faults.push_back(std::string("stop ") + protocol::to_string(s.stop_category) +
                       (s.stop_reason.empty() ? "" : ": " + s.stop_reason));
  } else {
    j["state"] = "unknown";
    j["drives"] = nlohmann::json::array();
    j["queue"] = nlohmann::json::array();
  }
  if (const auto t = link.tool()) {
    const auto& v = t->value;
    j["tool"] = {{"latched", v.latched}, {"running", v.running}, {"direction", v.direction},
                 {"turns", v.turns},     {"torque_nm", v.torque_nm}, {"fault_bits", v.fault_bits},
                 {"age_s", t->age_s}};
    if (v.fault_bits != 0) faults.push_back("tool fault bits " + std::to_string(v.fault_bits));
  }
  if (const auto w = link.wrench()) {
    j["wrench"] = {{"force_tool_n", w->value.force_tool_n},
                   {"torque_tool_nm", w->value.torque_tool_nm},
                   {"saturated", w->value.saturated},
                   {"age_s", w->age_s}};
    if (w->value.saturated) faults.push_back("F/T sensor saturated");
  }
  j["faults"] = faults;
  return j;
}

}  // namespace foresight::session
