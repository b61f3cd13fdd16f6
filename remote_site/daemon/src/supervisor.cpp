#include "foresight/daemon/supervisor.hpp"
#include "foresight/common/json_text.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>

#include "foresight/common/plan.hpp"
#include "foresight/hw/canopen.hpp"

// Telemetry's drive_state is the PowerState value (protocol DriveState numbering, remote_link/convert.cpp).
static_assert(static_cast<int>(foresight::hw::canopen::PowerState::OperationEnabled) == 4 &&
              static_cast<int>(foresight::hw::canopen::PowerState::QuickStopActive) == 5 &&
              static_cast<int>(foresight::hw::canopen::PowerState::Fault) == 7);
#include "foresight/daemon/algorithm_params.hpp"

namespace foresight::daemon {

using protocol::AckState;
using protocol::CommandKind;
using protocol::ControllerMode;
using control::MotionCommand;
using control::MotionCommandKind;
using control::MotionEvent;
using control::MotionEventKind;
using protocol::Reason;

namespace {

constexpr std::size_t kAckMemory = 1024;      // commands whose last ack is kept (duplicates)
constexpr std::size_t kUploadsKept = 8;

std::string upper(const char* s) {
  std::string out(s);
  for (auto& c : out) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}

std::int64_t mono_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

std::int64_t wall_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

/// HASH_MISMATCH's reason: a RUN's hash against its committed upload's.
std::string hash_mismatch(std::uint64_t trajectory_id, const TrajectoryHash& command_hash,
                          const TrajectoryHash& committed_hash) {
  return "trajectory " + std::to_string(trajectory_id) + ": the command's hash " + to_hex(command_hash) +
         " differs from the committed upload's " + to_hex(committed_hash);
}

/// A session id as 16 hex digits.
std::string hex16(std::uint64_t v) {
  char buf[20];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

std::string fmt(const char* f, double a, double b = 0.0) {
  char buf[160];
  std::snprintf(buf, sizeof buf, f, a, b);
  return buf;
}

/// The payload as JSON, for the RECEIVED row.
nlohmann::json payload_json(const protocol::Command& c) {
  nlohmann::json j = nlohmann::json::object();
  std::visit(
      [&](const auto& p) {
        using P = std::decay_t<decltype(p)>;
        if constexpr (std::is_same_v<P, protocol::RunTrajectory>) {
          j["trajectory_id"] = p.trajectory_id;
          j["hash"] = to_hex(p.content_hash);
          j["compliant"] = p.compliant;
          j["start_tolerance_rad"] = p.start_tolerance_rad;
          j["upload_wait_s"] = p.upload_wait_s;
        } else if constexpr (std::is_same_v<P, protocol::InvokeAlgorithm>) {
          j["name"] = p.name;
          nlohmann::json params = nlohmann::json::object();
          for (const auto& nv : p.params) params[nv.name] = nv.value;
          j["params"] = params;
          j["timeout_s"] = p.timeout_s;
        } else if constexpr (std::is_same_v<P, protocol::Request>) {
          j["what"] = static_cast<int>(p.what);
        } else if constexpr (std::is_same_v<P, protocol::CameraCommand>) {
          j["camera"] = p.camera;
          j["action"] = static_cast<int>(p.action);
          j["pan_rad"] = p.pan_rad;
          j["tilt_rad"] = p.tilt_rad;
          j["focal_px"] = p.focal_px;
        } else if constexpr (std::is_same_v<P, protocol::GotoJoint>) {
          j["q_rad"] = p.q_rad;
          j["speed_fraction"] = p.speed_fraction;
        } else if constexpr (std::is_same_v<P, protocol::GotoCart>) {
          j["frame"] = p.frame;
          const Eigen::Vector3d t = p.base_T_frame.translation();
          j["position_m"] = {t.x(), t.y(), t.z()};
          const Eigen::Quaterniond q(p.base_T_frame.linear());
          j["orientation_xyzw"] = {q.x(), q.y(), q.z(), q.w()};
          j["speed_fraction"] = p.speed_fraction;
        } else if constexpr (std::is_same_v<P, protocol::Abort>) {
          j["target_command_id"] = p.target_command_id;
          j["category"] = static_cast<int>(p.category);
          j["reason"] = p.reason;
        }
      },
      c.payload);
  return j;
}

}  // namespace

Supervisor::Supervisor(SupervisorParts parts) : p_(std::move(parts)), model_(*p_.model) {
  if (p_.loop == nullptr || p_.journal == nullptr || p_.model == nullptr)
    throw std::invalid_argument("Supervisor: the loop, the journal and the model are required");
  latest_.joints = static_cast<std::size_t>(model_.dof());
  const auto now = Clock::now();
  next_joints_ = next_wrench_ = next_tool_ = next_status_ = next_input_check_ = now;
}

Supervisor::~Supervisor() = default;

// ---- link thread --------------------------------------------------------------------

void Supervisor::submit(const remote_link::CommandEvent& event) { inbox_.push(event); }

void Supervisor::upload(const remote_link::UploadEvent& event) { inbox_.push(event); }

void Supervisor::link_event(const remote_link::LinkEvent& event) { inbox_.push(event); }

// ---- supervisor thread ------------------------------------------------------------

void Supervisor::run(const std::atomic<bool>& quit) {
  while (!quit.load(std::memory_order_acquire)) {
    run_once();
    inbox_.wait(std::chrono::milliseconds(2));
  }
}

void Supervisor::run_once() {
  poll_loop();
  const std::deque<Inbox::Item> batch = inbox_.take_all();
  journal_inbox_drops();
  // An ABORT that stops the arm is sent to the loop before anything else of
  // the batch is handled (journal rows, acks, other commands behind it): the
  // stop never waits for what arrived just before it. The commands ahead of
  // it are handled after, in order, against a stopping controller.
  for (const auto& item : batch)
    if (const auto* ce = std::get_if<remote_link::CommandEvent>(&item)) send_early_stop(*ce);
  for (const auto& item : batch) std::visit([this](const auto& e) { handle(e); }, item);
  early_stops_.clear();
  poll_tool();
  poll_camera();
  poll_loop();
  check_upload_waits();
  check_inputs();
  publish_reports(false);
}

void Supervisor::journal_inbox_drops() {
  inbox_dropped_ += inbox_.take_dropped();
  const auto now = Clock::now();
  if (inbox_dropped_ == 0 || now - inbox_drop_since_ < std::chrono::seconds(1)) return;
  const double span_s = inbox_drop_since_ == Clock::time_point{}
                            ? 0.0
                            : std::chrono::duration<double>(now - inbox_drop_since_).count();
  nlohmann::json d;
  d["dropped"] = inbox_dropped_;
  d["limit"] = inbox_.max_commands();
  journal_event("command_inbox_full",
                std::to_string(inbox_dropped_) + " commands dropped" + (span_s > 0 ? fmt(" in %.1f s", span_s) : "") +
                    ": the supervisor's inbox held its limit of " + std::to_string(inbox_.max_commands()) +
                    " commands (ABORTs always pass)",
                d.dump());
  spdlog::warn("{} commands dropped: the supervisor's inbox is full", inbox_dropped_);
  inbox_dropped_ = 0;
  inbox_drop_since_ = now;
}

void Supervisor::journal_event(const std::string& kind, const std::string& text, const std::string& detail) {
  try {
    journal::EventRow row;
    row.stamp_ns = wall_now_ns();
    row.kind = kind;
    row.text = text;
    row.detail = detail;
    p_.journal->record_event(row);
  } catch (const std::exception& e) {
    spdlog::error("journal: {}", e.what());
  }
}

void Supervisor::ack(const protocol::Command& command, AckState state, Reason code, const std::string& reason,
                     std::vector<double> final_q) {
  protocol::Ack a;
  a.session_id = command.session_id;
  a.command_id = command.command_id;
  a.sequence_number = command.sequence_number;
  a.kind = command.kind;
  a.state = state;
  a.code = code;
  a.reason = reason;
  a.stamp_ns = wall_now_ns();
  a.final_q_rad = std::move(final_q);

  journal::CommandRow row;
  row.stamp_ns = a.stamp_ns;
  row.session_id = a.session_id;
  row.command_id = a.command_id;
  row.sequence_number = a.sequence_number;
  row.kind = upper(control::to_string(a.kind));
  row.state = upper(control::to_string(state));
  row.code = upper(control::to_string(code));
  row.reason = reason;
  nlohmann::json detail = state == AckState::Received ? payload_json(command) : nlohmann::json::object();
  if (state == AckState::Received) {
    detail["writer"] = current_writer_.hex();  // the participant (with DDS Security: the identity) that sent it
    if (stations()) detail["station"] = writer_text(current_writer_);
    if (command.after_command_id != 0) detail["after_command_id"] = command.after_command_id;
  }
  if (!a.final_q_rad.empty()) detail["final_q_rad"] = a.final_q_rad;
  row.detail = json_text(detail);
  try {
    p_.journal->record_command(row);  // durable before the ack leaves
  } catch (const std::exception& e) {
    spdlog::error("journal: {} (command {} {})", e.what(), a.command_id, row.state);
  }
  if (p_.outbox.ack) p_.outbox.ack(a);
  const CommandKey key{a.session_id, a.command_id};
  if (!last_ack_.count(key)) {
    last_ack_order_.push_back(key);
    if (last_ack_order_.size() > kAckMemory) {
      last_ack_.erase(last_ack_order_.front());
      last_ack_order_.pop_front();
    }
  }
  last_ack_[key] = std::move(a);
}

void Supervisor::reject(const protocol::Command& command, Reason code, const std::string& reason) {
  spdlog::warn("command {} ({}) rejected: {}: {}", command.command_id, control::to_string(command.kind),
               control::to_string(code), reason);
  ack(command, AckState::Rejected, code, reason);
}

void Supervisor::handle(const remote_link::CommandEvent& event) {
  const protocol::Command& c = event.command;
  current_writer_ = event.writer;
  early_stop_id_.reset();
  if (event.duplicate) {
    // A re-sent command: answer with its last state, never run it twice.
    if (auto it = last_ack_.find({c.session_id, c.command_id}); it != last_ack_.end()) {
      if (p_.outbox.ack) p_.outbox.ack(it->second);
      return;
    }
  }
  // An ABORT that stops the arm reaches the loop first: its RECEIVED row is
  // synced to the disk before the ack leaves (milliseconds; seconds on a disk
  // that stalls), and the stop must not wait for that.
  send_early_stop(event);  // nothing when run_once() sent it ahead of the batch
  if (auto it = early_stops_.find(&event); it != early_stops_.end()) {
    early_stop_id_ = it->second;
    early_stops_.erase(it);
  }
  ack(c, AckState::Received);
  if (!event.accepted()) {
    reject(c, event.code, event.reason);
    return;
  }
  if (shutting_down_) {
    reject(c, Reason::Busy, "the controller is shutting down");
    return;
  }
  if (link_lost_ && (commander_ == 0 || from_commander(c))) {
    // A command of the commander's that arrived proves the link works again,
    // even before the ground's first heartbeat (best effort, it may be lost
    // or still in flight when a new ground process sends its first command).
    // Another participant's proves nothing about the commander's link.
    link_lost_ = false;
    p_.loop->set_link_lost(false);
    journal_event("link_regained", "a command arrived from session " + std::to_string(c.session_id) +
                                       " (" + writer_text(current_writer_) + ")");
    publish_reports(true);
  }
  if (from_commander(c)) commander_active_ = Clock::now();
  last_sequence_ = std::max(last_sequence_, c.sequence_number);
  dispatch(c);
}

void Supervisor::set_commander(std::uint64_t session, const protocol::ParticipantGuid& writer) {
  commander_ = session;
  commander_writer_ = session != 0 ? writer : protocol::ParticipantGuid{};
  if (p_.outbox.commander) p_.outbox.commander(commander_writer_);
}

std::string Supervisor::writer_text(const protocol::ParticipantGuid& writer) const {
  if (!stations()) return "participant " + writer.hex();
  for (const auto& [id, name] : p_.identities)
    if (id == writer) return "station '" + name + "' (" + writer.hex() + ")";
  return "station " + writer.hex();
}

std::string Supervisor::check_commander(const protocol::Command& c, Reason* code) const {
  if (from_commander(c)) return {};
  *code = Reason::NotInControl;
  if (commander_ != 0 && c.session_id == commander_) {
    // The commander's session id from another participant: read off a
    // published ack, it must not move the arm (journaled with its writer).
    return "session " + hex16(commander_) + " is in control from " + writer_text(commander_writer_) +
           "; this command came from " + writer_text(current_writer_);
  }
  if (commander_ == 0)
    return std::string("no ground station holds control: send TAKE_CONTROL first");
  if (stations()) return writer_text(commander_writer_) + " holds control";
  return "ground session " + hex16(commander_) + " holds control";
}

std::string Supervisor::check_can_move(Reason* code) const {
  if (link_lost_) {
    *code = Reason::NotInControl;
    return "the link to the ground is lost: no new motion";
  }
  switch (latest_.mode) {
    case ControllerMode::Idle:
    case ControllerMode::Trajectory:
    case ControllerMode::Goto:
    case ControllerMode::Algorithm:
      return {};
    case ControllerMode::Disabled:
      *code = Reason::Faulted;
      return "the drives are not enabled: send RECOVER first";
    case ControllerMode::Stopping:
    case ControllerMode::Stopped:
    case ControllerMode::Fault: {
      *code = Reason::Faulted;
      std::string why = std::string("the controller is ") + control::to_string(latest_.mode);
      if (have_stop_)
        why += std::string(" (") + control::to_string(last_stop_.category) + ": " + last_stop_.text.data() + ")";
      return why + ": send RECOVER first";
    }
  }
  return {};
}

void Supervisor::dispatch(const protocol::Command& c) {
  Reason code = Reason::None;
  if (c.after_command_id != 0 && !chainable(c.kind)) {
    reject(c, Reason::BadArgument,
           std::string(control::to_string(c.kind)) + " cannot follow another command (after_command_id " +
               std::to_string(c.after_command_id) + "): only trajectories, GOTOs, algorithms and reports chain");
    return;
  }
  switch (c.kind) {
    case CommandKind::TakeControl: {
      const bool lease_over = commander_ != 0 && !running_ && queue_.empty() &&
                              Clock::now() - commander_active_ >
                                  std::chrono::duration<double>(p_.config.control_lease_s);
      if (commander_ != 0 && !from_commander(c) && !lease_over) {
        std::string why = check_commander(c, &code);
        reject(c, Reason::NotInControl, why + " (it may RELEASE_CONTROL, or its lease ends after " +
                                            fmt("%.0f s", p_.config.control_lease_s) + " of silence)");
        return;
      }
      const bool kept = from_commander(c);  // with DDS Security: this station already held it
      if (lease_over && !kept)
        journal_event("control", "control lease of a silent session ended; taken over by " + writer_text(current_writer_));
      set_commander(c.session_id, current_writer_);
      commander_active_ = Clock::now();
      ack(c, AckState::Completed, Reason::None,
          kept && stations() ? "control kept: " + writer_text(current_writer_) + " already held it" : "control taken",
          current_q());
      publish_reports(true);
      return;
    }
    case CommandKind::ReleaseControl: {
      if (!from_commander(c)) {
        const std::string why = check_commander(c, &code);
        reject(c, code, why);
        return;
      }
      set_commander(0, {});
      ack(c, AckState::Completed, Reason::None, "control released", current_q());
      return;
    }
    case CommandKind::Abort:
      do_abort(c);
      return;
    case CommandKind::Request:
      if (c.after_command_id == 0) {  // a chained one reports once its predecessor completed (queued below)
        do_request(c);
        return;
      }
      break;
    default:
      break;
  }
  if (std::string why = check_commander(c, &code); !why.empty()) {
    reject(c, code, why);
    return;
  }
  if (c.kind == CommandKind::Camera) {
    do_camera(c);
    return;
  }
  if (c.kind != CommandKind::Recover && c.kind != CommandKind::Request) {
    if (std::string why = check_can_move(&code); !why.empty()) {
      reject(c, code, why);
      return;
    }
  }
  if (std::string why = check_queue(c, &code); !why.empty()) {
    reject(c, code, why);
    return;
  }
  std::string reason;
  auto job = make_job(c, &code, &reason);
  if (!job) {
    reject(c, code, reason);
    return;
  }
  // Plan and check the start now when the arm is free, so that an
  // unreachable goal or a trajectory that does not start at the arm is
  // REJECTED before anything is queued.
  if (!running_ && queue_.empty()) {
    if (job->kind == JobKind::Goto && !plan_goto(*job, &code, &reason)) {
      reject(c, code, reason);
      return;
    }
    if (job->prepared && have_telemetry_) {
      const double tol = job->start_tolerance_rad > 0.0 ? job->start_tolerance_rad : p_.config.start_tolerance_rad;
      int joint = -1;
      const double err = job->prepared->start_error(latest_.q_cmd, &joint);
      if (err > tol) {
        reject(c, Reason::StartMismatch,
               "the trajectory starts " + fmt("%.4f rad from the arm at joint ", err) + std::to_string(joint + 1) +
                   fmt(" (tolerance %.4f rad): plan an approach segment (a GOTO_JOINT to its first sample)", tol));
        return;
      }
    }
  }
  std::string note;
  if (job->awaiting_upload != 0)
    note = "waiting for upload " + std::to_string(job->awaiting_upload) +
           fmt(" to commit (at most %.1f s)", std::get<protocol::RunTrajectory>(c.payload).upload_wait_s);
  enqueue(std::move(job), note);
}

std::unique_ptr<Supervisor::Job> Supervisor::make_job(const protocol::Command& c, Reason* code, std::string* reason) {
  auto job = std::make_unique<Job>();
  job->command = c;
  bool made = false;
  switch (c.kind) {
    case CommandKind::Trajectory:
      made = make_trajectory_job(std::get<protocol::RunTrajectory>(c.payload), *job, code, reason);
      break;
    case CommandKind::GotoJoint:
    case CommandKind::GotoCart:
      made = check_goto(c, code, reason);
      job->kind = JobKind::Goto;
      break;
    case CommandKind::InvokeAlgorithm:
      made = make_invoke_job(std::get<protocol::InvokeAlgorithm>(c.payload), *job, code, reason);
      break;
    case CommandKind::Recover:
      job->kind = JobKind::Recover;
      made = true;
      break;
    case CommandKind::Request:  // chained: the report once the chain got here
      job->kind = JobKind::Report;
      made = true;
      break;
    default:
      *code = Reason::Internal;
      *reason = std::string("no handler for ") + control::to_string(c.kind);
      break;
  }
  return made ? std::move(job) : nullptr;
}

bool Supervisor::make_trajectory_job(const protocol::RunTrajectory& p, Job& job, Reason* code, std::string* reason) {
  if (!(p.start_tolerance_rad >= 0.0) || !std::isfinite(p.start_tolerance_rad) ||
      p.start_tolerance_rad > kMaxStartToleranceRad) {
    *code = Reason::BadArgument;
    *reason = fmt("start_tolerance_rad %g out of range [0, ", p.start_tolerance_rad) +
              fmt("%g] rad: a larger start offset would jump the arm; plan an approach segment (a GOTO_JOINT to "
                  "the first sample)", kMaxStartToleranceRad);
    return false;
  }
  if (!(p.upload_wait_s >= 0.0) || !(p.upload_wait_s <= p_.config.max_upload_wait_s)) {
    *code = Reason::BadArgument;
    *reason = fmt("upload_wait_s %g out of range [0, %g] s (controller.max_upload_wait_s)", p.upload_wait_s,
                  p_.config.max_upload_wait_s);
    return false;
  }
  job.kind = JobKind::Trajectory;
  job.compliant = p.compliant;
  job.start_tolerance_rad = p.start_tolerance_rad;
  const auto it = uploads_.find(p.trajectory_id);
  if (it == uploads_.end()) {
    const auto refused = upload_refused_.find(p.trajectory_id);
    if (refused != upload_refused_.end()) {
      *code = Reason::IncompleteUpload;
      *reason = "upload " + std::to_string(p.trajectory_id) + " was refused: " + refused->second;
      return false;
    }
    if (p.upload_wait_s == 0.0) {
      *code = Reason::UnknownTrajectory;
      *reason = "no committed upload with id " + std::to_string(p.trajectory_id) +
                " (a RUN with upload_wait_s > 0 may overtake its upload)";
      return false;
    }
    // RUN overtook its upload (issue 29): held until the whole upload
    // committed with this hash, or failed at the deadline.
    job.awaiting_upload = p.trajectory_id;
    job.upload_deadline =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(p.upload_wait_s));
    return true;
  }
  if (upload_hash_[p.trajectory_id] != p.content_hash) {
    *code = Reason::HashMismatch;
    *reason = hash_mismatch(p.trajectory_id, p.content_hash, upload_hash_[p.trajectory_id]);
    return false;
  }
  job.trajectory = it->second;
  try {
    job.prepared = std::make_unique<control::PreparedTrajectory>(*it->second, p.trajectory_id);
  } catch (const std::exception& e) {
    *code = Reason::ValidationFailed;
    *reason = e.what();
    return false;
  }
  return true;
}

bool Supervisor::check_goto(const protocol::Command& c, Reason* code, std::string* reason) const {
  const double speed_fraction = c.kind == CommandKind::GotoJoint ? std::get<protocol::GotoJoint>(c.payload).speed_fraction
                                                                 : std::get<protocol::GotoCart>(c.payload).speed_fraction;
  if (c.kind == CommandKind::GotoJoint) {
    const auto& p = std::get<protocol::GotoJoint>(c.payload);
    const std::size_t dof = static_cast<std::size_t>(model_.dof());
    if (p.q_rad.size() != dof) {
      *code = Reason::JointCount;
      *reason = std::to_string(p.q_rad.size()) + " joint values for a " + std::to_string(dof) + "-joint arm";
      return false;
    }
    for (std::size_t j = 0; j < dof; ++j) {
      const auto& lim = model_.limits()[j];
      if (!std::isfinite(p.q_rad[j]) || p.q_rad[j] < lim.lower_rad || p.q_rad[j] > lim.upper_rad) {
        *code = Reason::BadArgument;
        *reason = "joint " + std::to_string(j + 1) + fmt(": %.4f rad outside its limits", p.q_rad[j]) +
                  fmt(" [%.4f, %.4f]", lim.lower_rad, lim.upper_rad);
        return false;
      }
    }
  } else {
    const auto& p = std::get<protocol::GotoCart>(c.payload);
    const std::string tip = model_.links()[static_cast<std::size_t>(model_.tip_index())].name;
    if (p.frame != tip) {
      *code = Reason::BadArgument;
      *reason = "unknown frame '" + p.frame + "' (GOTO_CART moves the tool tip '" + tip + "')";
      return false;
    }
  }
  if (!(speed_fraction > 0.0 && speed_fraction <= 1.0)) {
    *code = Reason::BadArgument;
    *reason = fmt("speed_fraction %g out of range (0, 1]", speed_fraction);
    return false;
  }
  if (c.kind == CommandKind::GotoCart && !std::get<protocol::GotoCart>(c.payload).base_T_frame.matrix().allFinite()) {
    *code = Reason::BadArgument;
    *reason = "the target pose is not finite";
    return false;
  }
  return true;
}

bool Supervisor::make_invoke_job(const protocol::InvokeAlgorithm& p, Job& job, Reason* code, std::string* reason) {
  if (const auto step = tool_step_from_name(p.name)) {
    if (p_.tool == nullptr) {
      *code = Reason::ToolFault;
      *reason = p.name + ": no tool configured";
      return false;
    }
    const std::string why = parse_tool_step(p, *step, p_.tool->config(), job.tool_step);
    if (!why.empty()) {
      *code = Reason::BadArgument;
      *reason = why;
      return false;
    }
    job.tool_step.command_id = job.command.command_id;
    job.kind = JobKind::ToolStep;
    return true;
  }
  if (p.name == "tare") {
    // Zero the F/T sensor with the arm still (after picking up the ORU:
    // its weight is then no contact force). Parameter: samples (1..10000).
    for (const auto& nv : p.params) {
      if (nv.name != "samples") {
        *code = Reason::BadArgument;
        *reason = "tare: unknown parameter '" + nv.name + "' (expected one of: samples)";
        return false;
      }
      if (!(nv.value >= 1.0 && nv.value <= 10000.0) || nv.value != std::floor(nv.value)) {
        *code = Reason::BadArgument;
        *reason = fmt("tare: samples %g must be an integer in 1..10000", nv.value);
        return false;
      }
      job.tare_samples = static_cast<int>(nv.value);
    }
    job.kind = JobKind::Tare;
    return true;
  }
  const std::string why = parse_algorithm(p, job.algorithm);
  if (!why.empty()) {
    *code = job.algorithm.kind == control::AlgorithmKind::None ? Reason::UnknownAlgorithm : Reason::BadArgument;
    *reason = job.algorithm.kind == control::AlgorithmKind::None
                  ? why + " (expected one of: guarded_move, insert, pull_out, latch, unlatch, loosen, tighten, tare)"
                  : why;
    return false;
  }
  job.kind = JobKind::Algorithm;
  return true;
}

bool Supervisor::plan_goto(Job& job, Reason* code, std::string* reason) {
  const std::size_t dof = static_cast<std::size_t>(model_.dof());
  Eigen::VectorXd q0(static_cast<Eigen::Index>(dof));
  for (std::size_t j = 0; j < dof; ++j) q0[static_cast<Eigen::Index>(j)] = latest_.q_cmd[j];
  Goal goal;
  PlanOptions options;
  if (const auto* gj = std::get_if<protocol::GotoJoint>(&job.command.payload)) {
    goal.name = "goto_joint";
    goal.kind = SegmentKind::Joint;
    goal.is_pose = false;
    goal.q = Eigen::Map<const Eigen::VectorXd>(gj->q_rad.data(), static_cast<Eigen::Index>(dof));
    options.limit_fraction = gj->speed_fraction;
  } else {
    const auto& gc = std::get<protocol::GotoCart>(job.command.payload);
    goal.name = "goto_cart";
    goal.kind = SegmentKind::Linear;
    goal.is_pose = true;
    goal.base_T_tip = gc.base_T_frame;
    options.limit_fraction = gc.speed_fraction;
    options.tool_speed_m_s = 0.1 * gc.speed_fraction;
  }
  try {
    const Plan plan = plan_motion(model_, q0, {goal}, options);
    job.trajectory = std::make_shared<const Trajectory>(plan.trajectory);
    job.prepared = std::make_unique<control::PreparedTrajectory>(plan.trajectory, 0);
  } catch (const std::exception& e) {
    *code = Reason::Unreachable;
    *reason = e.what();
    return false;
  }
  return true;
}

void Supervisor::enqueue(std::unique_ptr<Job> job, const std::string& note) {
  ack(job->command, AckState::Queued, Reason::None, note);
  queue_.push_back(std::move(job));
  start_next();
}

void Supervisor::start_next() {
  while (!running_ && !queue_.empty()) {
    if (queue_.front()->awaiting_upload != 0) return;  // the head waits for its upload; the rest behind it
    std::unique_ptr<Job> job = std::move(queue_.front());
    queue_.pop_front();
    Reason code = Reason::None;
    std::string reason;
    // A job that cannot start fails, and so does the rest of its chain.
    auto fail = [&](Reason why_code, const std::string& why) {
      ack(job->command, AckState::Failed, why_code, why, current_q());
      cancel_chain(job->command, std::string("failed: ") + why);
    };
    if (job->kind == JobKind::Report) {  // no motion: reported and COMPLETED at once
      do_request(job->command);
      continue;
    }
    if (job->kind != JobKind::Recover) {
      if (std::string why = check_can_move(&code); !why.empty()) {
        fail(code, why);
        continue;
      }
    }
    if (job->kind == JobKind::Goto && !job->prepared && !plan_goto(*job, &code, &reason)) {
      fail(code, reason);
      continue;
    }
    MotionCommand mc;
    mc.command_id = job->loop_id = internal_id();
    switch (job->kind) {
      case JobKind::Trajectory:
      case JobKind::Goto:
        mc.kind = MotionCommandKind::RunTrajectory;
        mc.trajectory = job->prepared.get();
        mc.compliant = job->compliant;
        mc.start_tolerance_rad = job->start_tolerance_rad;
        break;
      case JobKind::Algorithm:
        mc.kind = MotionCommandKind::RunAlgorithm;
        mc.algorithm = job->algorithm;
        break;
      case JobKind::Recover:
        mc.kind = latest_.mode == ControllerMode::Disabled ? MotionCommandKind::Enable : MotionCommandKind::Recover;
        break;
      case JobKind::Tare:
        mc.kind = MotionCommandKind::Tare;
        mc.tare_samples = job->tare_samples;
        break;
      case JobKind::Report: break;  // handled above
      case JobKind::ToolStep: {
        // The arm holds its position stiffly while the tool latches or turns:
        // when the screw comes free the ORU's weight moves onto the tool, and
        // a compliant hold would let it sag into its slot's walls. (Tare
        // afterwards so that compliant motions see the ORU as payload.)
        MotionCommand hold;
        hold.command_id = internal_id();
        hold.kind = MotionCommandKind::Hold;
        hold.compliant = false;
        (void)p_.loop->send(hold);
        if (!p_.tool->start_step(job->tool_step)) {
          fail(Reason::Busy, "the tool is busy");
          continue;
        }
        job->executing = true;
        ack(job->command, AckState::Executing);
        running_ = std::move(job);
        return;
      }
    }
    if (!p_.loop->send(mc)) {
      fail(Reason::Busy, "the control loop's command ring is full");
      continue;
    }
    running_ = std::move(job);
  }
}

void Supervisor::finish_running(AckState state, Reason code, const std::string& reason, std::vector<double> final_q) {
  if (!running_) return;
  // The plant's truth is journaled before the final ack leaves, so a ground
  // that reads the journal after the ack finds it.
  if (p_.sim_truth)
    journal_event("sim_truth", "after command " + std::to_string(running_->command.command_id) + " (" +
                                   control::to_string(running_->command.kind) + ", " + control::to_string(state) + ")",
                  p_.sim_truth());
  ack(running_->command, state, code, reason, std::move(final_q));
  const protocol::Command done = running_->command;
  running_.reset();
  if (state != AckState::Completed) cancel_chain(done, std::string(control::to_string(state)) + ": " + reason);
  start_next();
}

bool Supervisor::chainable(CommandKind kind) noexcept {
  return kind == CommandKind::Trajectory || kind == CommandKind::InvokeAlgorithm || kind == CommandKind::GotoJoint ||
         kind == CommandKind::GotoCart || kind == CommandKind::Request;
}

const protocol::Command* Supervisor::held_command(std::uint64_t session, std::uint64_t command_id) const {
  if (running_ && running_->command.session_id == session && running_->command.command_id == command_id)
    return &running_->command;
  for (const auto& job : queue_)
    if (job->command.session_id == session && job->command.command_id == command_id) return &job->command;
  return nullptr;
}

std::string Supervisor::check_queue(const protocol::Command& c, Reason* code) const {
  const std::size_t held = queue_.size() + (running_ ? 1 : 0);
  if (held >= p_.config.max_queued_commands) {
    *code = Reason::Busy;
    return "the remote already holds " + std::to_string(held) + " commands (controller.max_queued_commands " +
           std::to_string(p_.config.max_queued_commands) + ")";
  }
  if (c.after_command_id == 0) return {};
  const std::string after = "command " + std::to_string(c.after_command_id);
  *code = Reason::BadArgument;
  if (c.after_command_id == c.command_id) return "command " + std::to_string(c.command_id) + " cannot follow itself";
  if (const protocol::Command* pred = held_command(c.session_id, c.after_command_id)) {
    // The chain's length: this command and every predecessor still held.
    std::size_t length = 2;
    for (const protocol::Command* p = pred; p->after_command_id != 0; ++length) {
      p = held_command(p->session_id, p->after_command_id);
      if (p == nullptr) break;
    }
    if (length > p_.config.max_chain_length)
      return "a chain of " + std::to_string(length) + " commands exceeds controller.max_chain_length " +
             std::to_string(p_.config.max_chain_length);
    return {};
  }
  const auto it = last_ack_.find({c.session_id, c.after_command_id});
  if (it == last_ack_.end())
    return after + " is not a command of this session (unknown here, or too old to be remembered)";
  const protocol::Ack& a = it->second;
  if (a.state == AckState::Completed) return {};  // done: this one starts from where it left the arm
  if (protocol::is_terminal(a.state)) {
    *code = Reason::Aborted;
    return "chain broken at " + after + ": " + control::to_string(a.state) + (a.reason.empty() ? "" : ": " + a.reason);
  }
  return after + " is not a motion the remote runs (" + std::string(control::to_string(a.kind)) +
         " cannot be followed)";
}

void Supervisor::cancel_chain(const protocol::Command& broken, const std::string& why) {
  // Every held command that follows `broken`, directly or through another,
  // is canceled with the place and cause of the break; nothing of it runs.
  const std::string reason = "chain broken at command " + std::to_string(broken.command_id) + ": " + why;
  std::vector<std::uint64_t> broken_ids{broken.command_id};
  for (std::size_t k = 0; k < broken_ids.size(); ++k) {
    for (auto it = queue_.begin(); it != queue_.end();) {
      const protocol::Command& q = (*it)->command;
      if (q.session_id == broken.session_id && q.after_command_id == broken_ids[k]) {
        broken_ids.push_back(q.command_id);
        ack(q, AckState::Canceled, Reason::Aborted, reason, current_q());
        it = queue_.erase(it);
      } else {
        ++it;
      }
    }
  }
}

void Supervisor::fail_queued(std::unique_ptr<Job> job, Reason code, const std::string& why) {
  ack(job->command, AckState::Failed, code, why, current_q());
  cancel_chain(job->command, std::string("failed: ") + why);
}

void Supervisor::resolve_upload_waits(std::uint64_t trajectory_id) {
  std::vector<std::pair<std::unique_ptr<Job>, std::pair<Reason, std::string>>> failed;
  const auto committed = uploads_.find(trajectory_id);
  const auto refused = upload_refused_.find(trajectory_id);
  for (auto it = queue_.begin(); it != queue_.end();) {
    Job& job = **it;
    if (job.awaiting_upload != trajectory_id) {
      ++it;
      continue;
    }
    const auto& run = std::get<protocol::RunTrajectory>(job.command.payload);
    Reason code = Reason::None;
    std::string why;
    if (committed != uploads_.end()) {
      if (upload_hash_[trajectory_id] != run.content_hash) {
        code = Reason::HashMismatch;
        why = hash_mismatch(trajectory_id, run.content_hash, upload_hash_[trajectory_id]);
      } else {
        try {
          job.prepared = std::make_unique<control::PreparedTrajectory>(*committed->second, trajectory_id);
          job.trajectory = committed->second;
          job.awaiting_upload = 0;
        } catch (const std::exception& e) {
          code = Reason::ValidationFailed;
          why = e.what();
        }
      }
    } else if (refused != upload_refused_.end()) {
      code = Reason::IncompleteUpload;
      why = "upload " + std::to_string(trajectory_id) + " was refused: " + refused->second;
    }
    if (code == Reason::None) {
      ++it;
      continue;
    }
    failed.emplace_back(std::move(*it), std::make_pair(code, why));
    it = queue_.erase(it);
  }
  for (auto& [job, why] : failed) fail_queued(std::move(job), why.first, why.second);
  start_next();
}

void Supervisor::check_upload_waits() {
  const auto now = Clock::now();
  // Taken out first, failed after: failing one cancels its chain, which
  // erases from the queue.
  std::vector<std::unique_ptr<Job>> late;
  for (auto it = queue_.begin(); it != queue_.end();) {
    if ((*it)->awaiting_upload != 0 && now >= (*it)->upload_deadline) {
      late.push_back(std::move(*it));
      it = queue_.erase(it);
    } else {
      ++it;
    }
  }
  for (auto& job : late) {
    const auto& run = std::get<protocol::RunTrajectory>(job->command.payload);
    const std::string why = "upload " + std::to_string(run.trajectory_id) +
                            fmt(" did not commit within %.1f s of the RUN (upload_wait_s): nothing of it ran",
                                run.upload_wait_s);
    fail_queued(std::move(job), Reason::IncompleteUpload, why);
  }
  if (!late.empty()) start_next();
}

void Supervisor::cancel_queued(const std::string& why) {
  while (!queue_.empty()) {
    ack(queue_.front()->command, AckState::Canceled, Reason::Aborted, why, current_q());
    queue_.pop_front();
  }
}

void Supervisor::do_abort(const protocol::Command& c) {
  const auto& a = std::get<protocol::Abort>(c.payload);
  if (a.category != protocol::StopCategory::Cat1 && a.category != protocol::StopCategory::Cat2) {
    reject(c, Reason::BadArgument, "ABORT category must be 1 or 2");
    return;
  }
  const std::string why = "aborted by command " + std::to_string(c.command_id) + (a.reason.empty() ? "" : ": " + a.reason);
  if (a.target_command_id != 0) {
    for (auto it = queue_.begin(); it != queue_.end(); ++it) {
      if ((*it)->command.command_id == a.target_command_id) {
        const protocol::Command canceled = (*it)->command;
        ack(canceled, AckState::Canceled, Reason::Aborted, why, current_q());
        queue_.erase(it);
        cancel_chain(canceled, "canceled: " + why);
        ack(c, AckState::Completed, Reason::None, "canceled the queued command", current_q());
        return;
      }
    }
    if (!running_ || running_->command.command_id != a.target_command_id) {
      reject(c, Reason::BadArgument,
             "command " + std::to_string(a.target_command_id) + " is neither running nor queued");
      return;
    }
  } else {
    cancel_queued(why);
  }
  if (running_ && running_->kind == JobKind::ToolStep) {
    p_.tool->cancel(running_->command.command_id);
    if (a.target_command_id != 0) {
      ack(c, AckState::Completed, Reason::None, "tool step canceled", current_q());
      return;
    }
  }
  // Stop the arm with the requested category (already sent by handle() when
  // it could be); the loop cancels what runs.
  MotionCommand stop;
  stop.kind = MotionCommandKind::Stop;
  stop.category = a.category;
  if (early_stop_id_) {
    stop.command_id = *early_stop_id_;
    early_stop_id_.reset();
  } else {
    stop.command_id = internal_id();
    if (!p_.loop->send(stop)) {
      ack(c, AckState::Failed, Reason::Internal, "the control loop's command ring is full", current_q());
      return;
    }
  }
  aborts_[stop.command_id] = c;
  ack(c, AckState::Executing);
}

void Supervisor::send_early_stop(const remote_link::CommandEvent& event) {
  const protocol::Command& c = event.command;
  if (!event.accepted() || event.duplicate || shutting_down_ || c.kind != CommandKind::Abort) return;
  if (early_stops_.count(&event) != 0 || c.after_command_id != 0 || !abort_stops_arm(c)) return;
  MotionCommand stop;
  stop.command_id = internal_id();
  stop.kind = MotionCommandKind::Stop;
  stop.category = std::get<protocol::Abort>(c.payload).category;
  if (p_.loop->send(stop)) early_stops_[&event] = stop.command_id;
}

bool Supervisor::abort_stops_arm(const protocol::Command& c) const {
  const auto& a = std::get<protocol::Abort>(c.payload);
  if (a.category != protocol::StopCategory::Cat1 && a.category != protocol::StopCategory::Cat2) return false;
  if (a.target_command_id == 0) return true;
  for (const auto& job : queue_)
    if (job->command.command_id == a.target_command_id) return false;  // canceled in the queue: nothing stops
  return running_ && running_->command.command_id == a.target_command_id && running_->kind != JobKind::ToolStep;
}

void Supervisor::do_request(const protocol::Command& c) {
  const auto& r = std::get<protocol::Request>(c.payload);
  switch (r.what) {
    case protocol::RequestWhat::Status:
      if (p_.outbox.status) p_.outbox.status(status_report());
      break;
    case protocol::RequestWhat::JointState:
    case protocol::RequestWhat::Wrench:
      next_joints_ = next_wrench_ = Clock::time_point{};  // publish both now
      publish_reports(false);
      break;
    case protocol::RequestWhat::ToolState:
      next_tool_ = Clock::time_point{};
      publish_reports(false);
      break;
    case protocol::RequestWhat::Trajectories:
      if (p_.outbox.republish_uploads) p_.outbox.republish_uploads();
      break;
  }
  ack(c, AckState::Completed, Reason::None, "", current_q());
}

void Supervisor::do_camera(const protocol::Command& c) {
  const auto& cam = std::get<protocol::CameraCommand>(c.payload);
  if (p_.camera == nullptr) {
    reject(c, Reason::BadArgument, "no video switch configured");
    return;
  }
  const auto it = std::find(p_.camera_names.begin(), p_.camera_names.end(), cam.camera);
  if (it == p_.camera_names.end()) {
    std::string list;
    for (const auto& n : p_.camera_names) list += (list.empty() ? "" : ", ") + n;
    reject(c, Reason::BadArgument, "unknown camera '" + cam.camera + "' (expected one of: " + list + ")");
    return;
  }
  CameraJob job;
  job.command_id = c.command_id;
  job.action = cam.action;
  job.camera = static_cast<int>(it - p_.camera_names.begin());
  job.pan_rad = cam.pan_rad;
  job.tilt_rad = cam.tilt_rad;
  job.focal_px = cam.focal_px;
  if (camera_command_ || !p_.camera->start(job)) {
    reject(c, Reason::Busy,
           "the video switch is busy with command " +
               std::to_string(camera_command_ ? camera_command_->command_id : p_.camera->running_command()));
    return;
  }
  // Runs on the camera thread beside any motion; poll_camera acks the end.
  camera_command_ = c;
  ack(c, AckState::Queued);
  ack(c, AckState::Executing);
}

void Supervisor::poll_camera() {
  if (p_.camera == nullptr || !camera_command_) return;
  const auto r = p_.camera->poll_result();
  if (!r) return;
  const protocol::Command c = *camera_command_;
  camera_command_.reset();
  if (r->ok) {
    ack(c, AckState::Completed, Reason::None, "camera " + std::get<protocol::CameraCommand>(c.payload).camera,
        current_q());
  } else {
    ack(c, AckState::Failed, r->refused ? Reason::BadArgument : Reason::Internal, "video switch: " + r->error,
        current_q());
  }
}

void Supervisor::handle(const remote_link::UploadEvent& e) {
  journal::UploadRow row;
  row.stamp_ns = wall_now_ns();
  row.trajectory_id = e.trajectory_id;
  static constexpr const char* kStates[] = {"ASSEMBLING", "COMMITTED", "REJECTED", "DISCARDED"};
  row.state = kStates[static_cast<int>(e.state)];
  row.code = upper(control::to_string(e.code));
  row.reason = e.reason;
  row.hash_hex = to_hex(e.hash);
  if (e.trajectory) {
    row.samples = static_cast<std::uint32_t>(e.trajectory->samples());
    row.joints = static_cast<std::uint32_t>(e.trajectory->joints());
  }
  if (e.state != protocol::UploadState::Assembling) {
    try {
      p_.journal->record_upload(row);
    } catch (const std::exception& ex) {
      spdlog::error("journal: {}", ex.what());
    }
  }
  if (e.state == protocol::UploadState::Committed && e.trajectory) {
    if (!uploads_.count(e.trajectory_id)) upload_order_.push_back(e.trajectory_id);
    uploads_[e.trajectory_id] = e.trajectory;
    upload_hash_[e.trajectory_id] = e.hash;
    while (upload_order_.size() > kUploadsKept) {
      const std::uint64_t old = upload_order_.front();
      upload_order_.pop_front();
      if (running_ && running_->kind == JobKind::Trajectory &&
          std::get<protocol::RunTrajectory>(running_->command.payload).trajectory_id == old) {
        upload_order_.push_back(old);  // still running: keep it
        break;
      }
      uploads_.erase(old);
      upload_hash_.erase(old);
    }
    spdlog::info("upload {} committed: {} samples x {} joints, {:.2f} s, hash {}", e.trajectory_id,
                 e.trajectory->samples(), e.trajectory->joints(), e.trajectory->duration_s(), row.hash_hex);
    resolve_upload_waits(e.trajectory_id);
  } else if (e.state == protocol::UploadState::Rejected || e.state == protocol::UploadState::Discarded) {
    if (e.state == protocol::UploadState::Rejected) spdlog::warn("upload {} rejected: {}", e.trajectory_id, e.reason);
    uploads_.erase(e.trajectory_id);
    upload_hash_.erase(e.trajectory_id);
    if (!upload_refused_.count(e.trajectory_id)) upload_refused_order_.push_back(e.trajectory_id);
    upload_refused_[e.trajectory_id] = std::string(row.state == "REJECTED" ? "rejected" : "discarded") + " (" +
                                       control::to_string(e.code) + ")" + (e.reason.empty() ? "" : ": " + e.reason);
    while (upload_refused_order_.size() > kUploadsKept) {
      upload_refused_.erase(upload_refused_order_.front());
      upload_refused_order_.pop_front();
    }
    resolve_upload_waits(e.trajectory_id);
  }
}

void Supervisor::handle(const remote_link::LinkEvent& e) {
  if (e.kind == remote_link::LinkEvent::Kind::CommanderLeft) {
    // Its process ended: nobody can speak in that session any more, so the
    // lease would only keep the next ground station waiting.
    if (commander_ != 0 && commander_writer_ == e.participant) {
      journal_event("control", "control released: the commander's participant " + e.participant.hex() +
                                   " left the DDS domain");
      set_commander(0, {});
      publish_reports(true);
    }
    return;
  }
  if (e.kind == remote_link::LinkEvent::Kind::RateLimited) {
    // One row a second per flooding participant, naming it: the flood's own
    // commands never reach the journal (nor rotate the commanders' out).
    nlohmann::json d;
    d["participant"] = e.participant.hex();
    d["dropped"] = e.dropped;
    d["seconds"] = e.silence_s;
    journal_event("command_rate_limit",
                  std::to_string(e.dropped) + " commands of participant " + e.participant.hex() + " dropped in " +
                      fmt("%.1f s", e.silence_s) + ": over its rate limit",
                  d.dump());
    return;
  }
  link_lost_ = e.kind == remote_link::LinkEvent::Kind::Lost;
  p_.loop->set_link_lost(link_lost_);
  const std::string text = link_lost_ ? fmt("link lost: no ground heartbeat for %.2f s", e.silence_s) + " (policy " +
                                            to_string(p_.config.link_loss_policy) + ")"
                                      : fmt("link regained after %.2f s", e.silence_s);
  if (link_lost_) {
    spdlog::warn("{}", text);
  } else {
    spdlog::info("{}", text);
  }
  journal_event(link_lost_ ? "link_lost" : "link_regained", text);
  publish_reports(true);
}

// ---- the loop's rings ------------------------------------------------------------------

std::vector<double> Supervisor::current_q() const {
  const std::size_t n = std::min<std::size_t>(latest_.joints, control::kMaxJoints);
  return std::vector<double>(latest_.q.begin(), latest_.q.begin() + static_cast<std::ptrdiff_t>(n));
}

namespace {
/// The 1-based joints of a bit mask (bit j = joint j + 1).
std::vector<std::size_t> joint_numbers(std::uint32_t mask) {
  std::vector<std::size_t> out;
  for (std::size_t j = 0; j < control::kMaxJoints; ++j)
    if ((mask >> j) & 1u) out.push_back(j + 1);
  return out;
}
std::string joint_list(std::uint32_t mask) {
  std::string s;
  for (const std::size_t j : joint_numbers(mask)) s += (s.empty() ? "" : ", ") + std::to_string(j);
  return s;
}
}  // namespace

void Supervisor::track_rate_limiter(const control::TelemetrySample& t) {
  const std::size_t n = std::min<std::size_t>(t.joints, control::kMaxJoints);
  std::uint32_t joints = 0;
  double lag = 0.0;
  for (std::size_t j = 0; j < n; ++j) {
    if (t.rate_limited_joint_cycles[j] != rate_limited_joint_cycles_[j]) joints |= std::uint32_t{1} << j;
    lag = std::max(lag, std::abs(t.rate_limit_lag[j]));
  }
  rate_limited_joint_cycles_ = t.rate_limited_joint_cycles;
  RateLimitEpisode& e = rate_limit_;
  auto detail = [&](bool end) {
    nlohmann::json d;
    d["joints"] = joint_numbers(e.joints);
    d["command_id"] = e.command_id;
    d["max_lag_rad"] = e.max_lag_rad;
    if (end) d["cycles"] = t.rate_limited_cycles - e.first_cycles;
    return d.dump();
  };
  if (joints != 0) {
    const bool begins = !e.active;
    if (begins) {
      e = RateLimitEpisode{};
      e.active = true;
      e.first_cycles = rate_limit_report_.cycles;  // the count before this episode
      e.command_id = running_ ? running_->command.command_id : 0;
    }
    e.joints |= joints;
    e.max_lag_rad = std::max(e.max_lag_rad, lag);
    e.last_limited_ns = t.stamp_ns;
    if (begins) {
      journal_event("rate_limit",
                    "the rate limiter limits joint(s) " + joint_list(e.joints) +
                        (e.command_id != 0 ? " of command " + std::to_string(e.command_id) : std::string()),
                    detail(false));
      spdlog::warn("rate limiter: limiting joint(s) {}", joint_list(e.joints));
    }
  } else if (e.active && t.stamp_ns - e.last_limited_ns >= 200'000'000) {
    e.active = false;
    journal_event("rate_limit",
                  "the rate limiter let go of joint(s) " + joint_list(e.joints) + " after " +
                      std::to_string(t.rate_limited_cycles - e.first_cycles) + " limited cycles, lag up to " +
                      fmt("%.4f", e.max_lag_rad) + " rad",
                  detail(true));
  }
  rate_limit_report_.cycles = t.rate_limited_cycles;
  rate_limit_report_.limiting = e.active;
  if (e.joints != 0) {
    rate_limit_report_.last_joint_mask = e.joints;
    rate_limit_report_.last_command_id = e.command_id;
    rate_limit_report_.last_max_lag_rad = e.max_lag_rad;
  }
}

std::int64_t Supervisor::to_wall_ns(std::int64_t mono_ns) const noexcept {
  return wall_now_ns() - (mono_now_ns() - mono_ns);
}

void Supervisor::poll_loop() {
  control::TelemetrySample t;
  while (p_.loop->poll_telemetry(t)) {
    latest_ = t;
    have_telemetry_ = true;
    journal::TelemetryRow row;
    row.stamp_ns = to_wall_ns(t.stamp_ns);
    row.cycle = t.cycle;
    row.mode = static_cast<std::uint8_t>(t.mode);
    row.joint_count = static_cast<std::uint8_t>(std::min<std::size_t>(t.joints, journal::TelemetryRow::kMaxJoints));
    for (std::size_t j = 0; j < row.joint_count && j < control::kMaxJoints; ++j) {
      row.q_rad[j] = t.q[j];
      row.q_cmd_rad[j] = t.q_cmd[j];
    }
    for (std::size_t i = 0; i < 6; ++i) row.wrench[i] = t.wrench_tool[i];
    (void)p_.journal->push_telemetry(row);
    track_rate_limiter(t);
  }
  control::StopEvent s;
  while (p_.loop->poll_stop(s)) {
    last_stop_ = s;
    have_stop_ = true;
    fault_text_ = s.text.data();
    journal::FaultRow row;
    row.stamp_ns = to_wall_ns(s.stamp_ns);
    row.cycle = s.cycle;
    row.category = s.category == protocol::StopCategory::Cat0 ? 0 : s.category == protocol::StopCategory::Cat1 ? 1 : 2;
    row.cause = control::to_string(s.cause);
    row.text = s.text.data();
    nlohmann::json ev;
    // The running command as the ground knows it (the loop knows it by its loop id).
    const bool ours = running_ && s.command_id != 0 && running_->loop_id == s.command_id;
    ev["command_id"] = ours ? running_->command.command_id : 0;
    ev["session_id"] = ours ? running_->command.session_id : 0;
    ev["joint"] = s.joint;
    ev["value"] = s.value;
    ev["limit"] = s.limit;
    ev["hw_fault"] = s.hw_fault;
    ev["hw_node"] = s.hw_node;
    ev["hw_code"] = s.hw_code;
    nlohmann::json samples = nlohmann::json::array();
    for (std::size_t i = 0; i < s.evidence_count && i < s.evidence.size(); ++i) {
      const auto& e = s.evidence[i];
      std::vector<double> q(e.q.begin(), e.q.begin() + static_cast<std::ptrdiff_t>(s.joints));
      std::vector<double> qc(e.q_cmd.begin(), e.q_cmd.begin() + static_cast<std::ptrdiff_t>(s.joints));
      samples.push_back({{"cycle", e.cycle}, {"q", q}, {"q_cmd", qc}, {"wrench_tool", e.wrench_tool}});
    }
    ev["samples"] = samples;
    row.evidence = json_text(ev);
    try {
      p_.journal->record_fault(row);
    } catch (const std::exception& ex) {
      spdlog::error("journal: {}", ex.what());
    }
    spdlog::warn("stop {} ({}): {} at cycle {}", control::to_string(s.category), control::to_string(s.cause),
                 s.text.data(), s.cycle);
    cancel_queued(std::string("the controller stopped: ") + s.text.data());
    if (running_ && running_->kind == JobKind::ToolStep) p_.tool->cancel(running_->command.command_id);
    publish_reports(true);
  }
  MotionEvent e;
  while (p_.loop->poll_event(e)) {
    std::vector<double> fq(e.final_q.begin(), e.final_q.begin() + static_cast<std::ptrdiff_t>(
                                                                     std::min(e.joints, control::kMaxJoints)));
    if (auto it = aborts_.find(e.command_id); it != aborts_.end()) {
      if (control::is_final(e.kind)) {
        const bool ok = e.kind == MotionEventKind::Completed;
        ack(it->second, ok ? AckState::Completed : AckState::Failed, ok ? Reason::None : e.code, e.text.data(), fq);
        aborts_.erase(it);
      }
      continue;
    }
    if (!running_ || running_->loop_id != e.command_id) continue;  // internal (holds) or stale
    if (running_->kind == JobKind::ToolStep) continue;  // the hold under a tool step
    switch (e.kind) {
      case MotionEventKind::Started:
        if (!running_->executing) {
          running_->executing = true;
          ack(running_->command, AckState::Executing);
        }
        break;
      case MotionEventKind::Completed: {
        // The loop is holding now; its telemetry may lag the event.
        if (running_->kind == JobKind::Recover) latest_.mode = ControllerMode::Idle;
        std::string text = e.text.data();
        if (running_->kind == JobKind::Algorithm && text.empty())
          text = fmt("distance %.4f m, peak force %.1f N", e.distance_m, e.peak_force_n);
        finish_running(AckState::Completed, Reason::None, text, fq);
        break;
      }
      case MotionEventKind::Failed:
        finish_running(AckState::Failed, e.code == Reason::None ? Reason::Internal : e.code, e.text.data(), fq);
        break;
      case MotionEventKind::Canceled:
        finish_running(AckState::Canceled, e.code == Reason::None ? Reason::Aborted : e.code, e.text.data(), fq);
        break;
      case MotionEventKind::Rejected:
        // Refused by the loop after it was queued (e.g. the arm moved since):
        // nothing moved.
        finish_running(AckState::Failed, e.code == Reason::None ? Reason::Internal : e.code, e.text.data(), fq);
        break;
    }
  }
  if (latest_.mode != reported_mode_) publish_reports(true);
}

void Supervisor::poll_tool() {
  if (p_.tool == nullptr) return;
  if (auto r = p_.tool->poll_result()) {
    if (running_ && running_->kind == JobKind::ToolStep && running_->command.command_id == r->command_id) {
      if (r->ok) {
        finish_running(AckState::Completed, Reason::None, r->text, current_q());
      } else {
        finish_running(r->code == Reason::Aborted ? AckState::Canceled : AckState::Failed, r->code, r->text,
                       current_q());
      }
    }
  }
}

protocol::StatusReport Supervisor::status_report() const {
  protocol::StatusReport s;
  s.stamp_ns = wall_now_ns();
  s.mode = latest_.mode;
  s.active_command_id = running_ ? running_->command.command_id : 0;
  if (running_ && running_->kind == JobKind::Trajectory)
    s.active_trajectory_id = std::get<protocol::RunTrajectory>(running_->command.payload).trajectory_id;
  s.last_sequence = last_sequence_;
  s.stop_category = latest_.stop_category;
  if (have_stop_ && latest_.stop_category != protocol::StopCategory::None) s.stop_reason = last_stop_.text.data();
  std::uint32_t bits = 0;
  std::string text;
  if (estop_) {
    bits |= 1u;
    text += "E-stop pressed; ";
  }
  if (link_lost_) {
    bits |= 2u;
    text += "link lost; ";
  }
  if (latest_.mode == ControllerMode::Fault || latest_.mode == ControllerMode::Stopped) {
    bits |= 4u;
    text += fault_text_ + "; ";
  }
  if (!text.empty()) text.resize(text.size() - 2);
  s.fault_bits = bits;
  s.fault_text = text;
  // The drives as they reported themselves (their statusword), not the
  // controller's belief: what a category 0 stop must show unpowered.
  const std::size_t joints = std::min<std::size_t>(have_telemetry_ ? latest_.joints : 0, control::kMaxJoints);
  for (std::size_t j = 0; j < joints; ++j) {
    protocol::DriveReport d;
    d.joint = static_cast<int>(j + 1);
    d.node_id = j < p_.drive_nodes.size() ? p_.drive_nodes[j] : 0;
    d.state = latest_.drive_state[j] < protocol::kDriveStateUnknown ? latest_.drive_state[j] : protocol::kDriveStateUnknown;
    d.powered = d.state != protocol::kDriveStateUnknown &&
                hw::canopen::power_enabled(static_cast<hw::canopen::PowerState>(d.state));
    s.drives.push_back(d);
  }
  s.rate_limit = rate_limit_report_;
  if (running_)
    s.queue.push_back({running_->command.command_id, running_->command.kind, running_->command.after_command_id,
                       AckState::Executing});
  for (const auto& job : queue_)  // at most controller.max_queued_commands (<= the IDL's MAX_QUEUE)
    s.queue.push_back({job->command.command_id, job->command.kind, job->command.after_command_id, AckState::Queued});
  if (p_.loop != nullptr) {
    const control::LoopStats st = p_.loop->stats();
    using LS = control::LoopStats;
    s.loop.realtime = st.realtime;
    s.loop.memory_locked = st.memory_locked;
    s.loop.realtime_required = p_.loop->options().require_realtime;
    s.loop.cycles = st.cycles;
    s.loop.overruns = st.overruns;
    s.loop.missed_streak_max = static_cast<std::uint32_t>(std::min<std::uint64_t>(st.missed_streak_max, UINT32_MAX));
    s.loop.max_missed_cycles = static_cast<std::uint32_t>(p_.loop->options().max_missed_cycles);
    s.loop.wakeup_latency_p99_us = LS::percentile_us(st.latency_hist, 0.99);
    s.loop.wakeup_latency_max_us = st.wakeup_latency_us_max;
    s.loop.compute_p99_us = LS::percentile_us(st.compute_hist, 0.99);
    s.loop.compute_max_us = st.compute_us_max;
  }
  return s;
}

void Supervisor::publish_reports(bool force_status) {
  const auto now = Clock::now();
  auto period = [](double hz) { return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz)); };
  const std::size_t n = std::min<std::size_t>(latest_.joints, control::kMaxJoints);
  if (have_telemetry_ && now >= next_joints_ && p_.outbox.joints) {
    next_joints_ = now + period(p_.config.reports.joint_state_hz);
    protocol::JointReport r;
    r.stamp_ns = to_wall_ns(latest_.stamp_ns);
    r.cycle = latest_.cycle;
    r.q_rad.assign(latest_.q.begin(), latest_.q.begin() + static_cast<std::ptrdiff_t>(n));
    r.dq_rad_s.assign(latest_.dq.begin(), latest_.dq.begin() + static_cast<std::ptrdiff_t>(n));
    r.torque_nm.assign(latest_.torque.begin(), latest_.torque.begin() + static_cast<std::ptrdiff_t>(n));
    p_.outbox.joints(r);
  }
  if (have_telemetry_ && now >= next_wrench_ && p_.outbox.wrench) {
    next_wrench_ = now + period(p_.config.reports.wrench_hz);
    protocol::WrenchReport w;
    w.stamp_ns = to_wall_ns(latest_.stamp_ns);
    for (int i = 0; i < 3; ++i) {
      w.force_tool_n[i] = latest_.wrench_tool[i];
      w.torque_tool_nm[i] = latest_.wrench_tool[i + 3];
    }
    w.saturated = latest_.ft_saturated;
    p_.outbox.wrench(w);
  }
  if (p_.tool != nullptr && now >= next_tool_ && p_.outbox.tool) {
    next_tool_ = now + period(p_.config.reports.tool_hz);
    const auto t = p_.tool->latest();
    protocol::ToolReport r;
    r.stamp_ns = t.stamp_ns;
    r.latched = t.status.latched();
    r.running = t.status.running();
    r.direction = !t.status.running() ? 0 : t.status.speed_rad_s >= 0.0 ? 1 : 2;
    r.turns = t.status.turns;
    r.torque_nm = t.status.torque_nm;
    r.fault_bits = t.link_ok ? t.status.fault_bits : 0x8000u;  // 0x8000: the tool does not answer
    p_.outbox.tool(r);
  }
  if ((force_status || now >= next_status_) && p_.outbox.status) {
    next_status_ = now + period(p_.config.reports.status_hz);
    reported_mode_ = latest_.mode;
    p_.outbox.status(status_report());
  }
}

void Supervisor::check_inputs() {
  if (p_.config.estop_file.empty()) return;
  const auto now = Clock::now();
  if (now < next_input_check_) return;
  next_input_check_ = now + std::chrono::milliseconds(10);
  std::error_code ec;
  const bool pressed = std::filesystem::exists(p_.config.estop_file, ec);
  if (pressed != estop_) {
    estop_ = pressed;
    p_.loop->set_estop(pressed);
    const std::string text = pressed ? "E-stop pressed (" + p_.config.estop_file + " exists)" : "E-stop released";
    if (pressed) {
      spdlog::error("{}", text);
    } else {
      spdlog::info("{}", text);
    }
    journal_event(pressed ? "estop_pressed" : "estop_released", text);
    publish_reports(true);
  }
}

void Supervisor::shutdown(const std::string& why) {
  if (shutting_down_) return;
  shutting_down_ = true;
  journal_event("shutdown", why);
  cancel_queued("the controller is shutting down: " + why);
  if (p_.tool != nullptr && running_ && running_->kind == JobKind::ToolStep) p_.tool->cancel();
  p_.loop->stop();  // category 1: controlled stop, then the drives off
  poll_loop();
  poll_tool();
  poll_camera();
  if (camera_command_) {
    ack(*camera_command_, AckState::Canceled, Reason::Aborted,
        "the controller shut down while the video switch was answering: its outcome is unknown: " + why, current_q());
    camera_command_.reset();
  }
  if (running_)
    finish_running(AckState::Canceled, Reason::Aborted, "the controller shut down: " + why, current_q());
  for (auto& [id, c] : aborts_) ack(c, AckState::Completed, Reason::None, "shut down", current_q());
  aborts_.clear();
  publish_reports(true);
}

}  // namespace foresight::daemon
