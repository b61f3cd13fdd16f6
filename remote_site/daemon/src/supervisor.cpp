#include "foresight/daemon/supervisor.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>

#include "foresight/common/format.hpp"
#include "foresight/control/command.hpp"

namespace foresight::daemon {

using control::MotionCommand;
using control::MotionCommandKind;
using control::MotionEvent;
using control::MotionEventKind;
using protocol::AckState;
using protocol::CommandKind;
using protocol::ControllerMode;
using protocol::Reason;

namespace {

SupervisorParts checked(SupervisorParts parts) {
  if (parts.loop == nullptr || parts.journal == nullptr || parts.model == nullptr)
    throw std::invalid_argument("Supervisor: the loop, the journal and the model are required");
  return parts;
}

}  // namespace

Supervisor::Supervisor(SupervisorParts parts)
    : p_(checked(std::move(parts))),
      model_(*p_.model),
      ledger_(*p_.journal, p_.outbox.ack),
      holder_({!p_.config.security_dir.empty(), p_.identities, p_.config.control_lease_s, p_.outbox.commander}),
      factory_(model_, p_.config, p_.tool, uploads_),
      bridge_(*p_.loop, ledger_, static_cast<std::size_t>(model_.dof())),
      jobs_(ledger_, {p_.config.max_queued_commands, p_.config.max_chain_length}, [this] { return current_q(); }),
      reports_(p_.config.reports, p_.outbox, p_.drive_nodes, {*p_.loop, bridge_, jobs_, site_, p_.tool}),
      next_input_check_(Clock::now()) {}

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
  reports_.publish(false);
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
  ledger_.event("command_inbox_full",
                std::to_string(inbox_dropped_) + " commands dropped" +
                    (span_s > 0 ? printf_text(" in %.1f s", span_s) : "") +
                    ": the supervisor's inbox held its limit of " + std::to_string(inbox_.max_commands()) +
                    " commands (ABORTs always pass)",
                d.dump());
  spdlog::warn("{} commands dropped: the supervisor's inbox is full", inbox_dropped_);
  inbox_dropped_ = 0;
  inbox_drop_since_ = now;
}

// ---- commands --------------------------------------------------------------------

void Supervisor::handle(const remote_link::CommandEvent& event) {
  const protocol::Command& c = event.command;
  holder_.set_writer(event.writer);
  early_stop_id_.reset();
  // A re-sent command: answer with its last state, never run it twice.
  if (event.duplicate && ledger_.resend(c.session_id, c.command_id)) return;
  // An ABORT that stops the arm reaches the loop first: its RECEIVED row is
  // synced to the disk before the ack leaves (milliseconds; seconds on a disk
  // that stalls), and the stop must not wait for that.
  send_early_stop(event);  // nothing when run_once() sent it ahead of the batch
  if (auto it = early_stops_.find(&event); it != early_stops_.end()) {
    early_stop_id_ = it->second;
    early_stops_.erase(it);
  }
  ledger_.received(c, event.writer.hex(), holder_.stations() ? holder_.writer_text(event.writer) : std::string());
  if (!event.accepted()) {
    ledger_.reject(c, event.code, event.reason);
    return;
  }
  if (shutting_down_) {
    ledger_.reject(c, Reason::Busy, "the controller is shutting down");
    return;
  }
  if (site_.link_lost && (holder_.session() == 0 || holder_.from_holder(c))) link_regained_by(c);
  if (holder_.from_holder(c)) holder_.touch(Clock::now());
  site_.last_sequence = std::max(site_.last_sequence, c.sequence_number);
  dispatch(c);
}

void Supervisor::link_regained_by(const protocol::Command& c) {
  // A command of the holder's that arrived proves the link works again, even
  // before the ground's first heartbeat (best effort, it may be lost or still
  // in flight when a new ground process sends its first command). Another
  // participant's proves nothing about the holder's link.
  site_.link_lost = false;
  p_.loop->set_link_lost(false);
  ledger_.event("link_regained", "a command arrived from session " + std::to_string(c.session_id) + " (" +
                                     holder_.writer_text(holder_.writer()) + ")");
  reports_.publish(true);
}

std::string Supervisor::check_can_move(Reason* code) const {
  if (site_.link_lost) {
    *code = Reason::NotInControl;
    return "the link to the ground is lost: no new motion";
  }
  const ControllerMode mode = bridge_.latest().mode;
  switch (mode) {
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
      std::string why = std::string("the controller is ") + control::to_string(mode);
      if (const control::StopEvent* stop = bridge_.last_stop())
        why += std::string(" (") + control::to_string(stop->category) + ": " + stop->text.data() + ")";
      return why + ": send RECOVER first";
    }
  }
  return {};
}

void Supervisor::dispatch(const protocol::Command& c) {
  Reason code = Reason::None;
  if (c.after_command_id != 0 && !JobQueue::chainable(c.kind)) {
    ledger_.reject(c, Reason::BadArgument,
                   std::string(control::to_string(c.kind)) + " cannot follow another command (after_command_id " +
                       std::to_string(c.after_command_id) +
                       "): only trajectories, GOTOs, algorithms and reports chain");
    return;
  }
  switch (c.kind) {
    case CommandKind::TakeControl:
      take_control(c);
      return;
    case CommandKind::ReleaseControl:
      release_control(c);
      return;
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
  if (std::string why = holder_.check(c, &code); !why.empty()) {
    ledger_.reject(c, code, why);
    return;
  }
  if (c.kind == CommandKind::Camera) {
    do_camera(c);
    return;
  }
  if (c.kind != CommandKind::Recover && c.kind != CommandKind::Request) {
    if (std::string why = check_can_move(&code); !why.empty()) {
      ledger_.reject(c, code, why);
      return;
    }
  }
  if (std::string why = jobs_.check(c, &code); !why.empty()) {
    ledger_.reject(c, code, why);
    return;
  }
  std::string reason;
  auto job = factory_.make(c, &code, &reason);
  if (!job || (jobs_.idle() && !check_start_now(*job, &code, &reason))) {
    ledger_.reject(c, code, reason);
    return;
  }
  std::string note;
  if (job->awaiting_upload != 0)
    note = "waiting for upload " + std::to_string(job->awaiting_upload) +
           printf_text(" to commit (at most %.1f s)", std::get<protocol::RunTrajectory>(c.payload).upload_wait_s);
  enqueue(std::move(job), note);
}

void Supervisor::take_control(const protocol::Command& c) {
  const bool lease_over = jobs_.idle() && holder_.lease_over(Clock::now());
  if (holder_.session() != 0 && !holder_.from_holder(c) && !lease_over) {
    Reason code = Reason::None;
    const std::string why = holder_.check(c, &code);
    ledger_.reject(c, Reason::NotInControl,
                   why + " (it may RELEASE_CONTROL, or its lease ends after " +
                       printf_text("%.0f s", p_.config.control_lease_s) + " of silence)");
    return;
  }
  const bool kept = holder_.from_holder(c);  // with DDS Security: this station already held it
  if (lease_over && !kept)
    ledger_.event("control", "control lease of a silent session ended; taken over by " +
                                 holder_.writer_text(holder_.writer()));
  holder_.take(c.session_id);
  holder_.touch(Clock::now());
  ledger_.ack(c, AckState::Completed, Reason::None,
              kept && holder_.stations() ? "control kept: " + holder_.writer_text(holder_.writer()) + " already held it"
                                         : "control taken",
              current_q());
  reports_.publish(true);
}

void Supervisor::release_control(const protocol::Command& c) {
  Reason code = Reason::None;
  if (std::string why = holder_.check(c, &code); !why.empty()) {
    ledger_.reject(c, code, why);
    return;
  }
  holder_.release();
  ledger_.ack(c, AckState::Completed, Reason::None, "control released", current_q());
}

bool Supervisor::check_start_now(Job& job, Reason* code, std::string* reason) {
  if (job.kind == JobKind::Goto && !factory_.plan_goto(job, bridge_.latest().q_cmd, code, reason)) return false;
  if (job.prepared && bridge_.have_telemetry()) {
    const double tol = job.start_tolerance_rad > 0.0 ? job.start_tolerance_rad : p_.config.start_tolerance_rad;
    int joint = -1;
    const double err = job.prepared->start_error(bridge_.latest().q_cmd, &joint);
    if (err > tol) {
      *code = Reason::StartMismatch;
      *reason = "the trajectory starts " + printf_text("%.4f rad from the arm at joint ", err) +
                std::to_string(joint + 1) +
                printf_text(" (tolerance %.4f rad): plan an approach segment (a GOTO_JOINT to its first sample)", tol);
      return false;
    }
  }
  return true;
}

// ---- jobs --------------------------------------------------------------------

void Supervisor::enqueue(std::unique_ptr<Job> job, const std::string& note) {
  ledger_.ack(job->command, AckState::Queued, Reason::None, note);
  jobs_.push(std::move(job));
  start_next();
}

void Supervisor::start_next() {
  while (std::unique_ptr<Job> job = jobs_.pop_startable()) {
    if (job->kind == JobKind::Report) {  // no motion: reported and COMPLETED at once
      do_request(job->command);
      continue;
    }
    Reason code = Reason::None;
    if (const std::string why = start(*job, &code); !why.empty()) {
      jobs_.fail(*job, code, why);  // a job that cannot start fails, and so does the rest of its chain
      continue;
    }
    jobs_.set_running(std::move(job));  // pop_startable gives nothing more while it runs
  }
}

std::string Supervisor::start(Job& job, Reason* code) {
  if (job.kind != JobKind::Recover) {
    if (std::string why = check_can_move(code); !why.empty()) return why;
  }
  std::string reason;
  if (job.kind == JobKind::Goto && !job.prepared &&
      !factory_.plan_goto(job, bridge_.latest().q_cmd, code, &reason))
    return reason;
  if (job.kind == JobKind::ToolStep) {
    // The arm holds its position stiffly while the tool latches or turns:
    // when the screw comes free the ORU's weight moves onto the tool, and a
    // compliant hold would let it sag into its slot's walls. (The ORU's
    // weight is payload from the loosen on: tell_payload.)
    MotionCommand hold;
    hold.command_id = internal_id();
    hold.kind = MotionCommandKind::Hold;
    hold.compliant = false;
    (void)p_.loop->send(hold);
    if (!p_.tool->start_step(job.tool_step)) {
      *code = Reason::Busy;
      return "the tool is busy";
    }
    job.executing = true;
    ledger_.ack(job.command, AckState::Executing);
    return {};
  }
  MotionCommand mc;
  mc.command_id = job.loop_id = internal_id();
  switch (job.kind) {
    case JobKind::Trajectory:
    case JobKind::Goto:
      mc.kind = MotionCommandKind::RunTrajectory;
      mc.trajectory = job.prepared.get();
      mc.compliant = job.compliant;
      mc.start_tolerance_rad = job.start_tolerance_rad;
      break;
    case JobKind::Algorithm:
      mc.kind = MotionCommandKind::RunAlgorithm;
      mc.algorithm = job.algorithm;
      break;
    case JobKind::Recover:
      if (std::string why = configure_nodes_again(); !why.empty()) {
        *code = Reason::Faulted;
        return why;
      }
      mc.kind = bridge_.latest().mode == ControllerMode::Disabled ? MotionCommandKind::Enable
                                                                  : MotionCommandKind::Recover;
      break;
    case JobKind::Tare:
      mc.kind = MotionCommandKind::Tare;
      mc.tare_samples = job.tare_samples;
      break;
    case JobKind::Report:
    case JobKind::ToolStep:
      break;  // handled above
  }
  if (!p_.loop->send(mc)) {
    *code = Reason::Busy;
    return "the control loop's command ring is full";
  }
  return {};
}

std::string Supervisor::configure_nodes_again() {
  if (p_.drives == nullptr || p_.drives->unconfigured_nodes() == 0) return {};
  // Blocking SDO on this thread (a few hundred ms a node): the loop cycles
  // on meanwhile (heartbeat, SYNC, supervision); nothing is enabled yet.
  const std::size_t n = p_.drives->unconfigured_nodes();
  const auto t0 = Clock::now();
  try {
    const std::size_t done = p_.drives->configure_nodes();
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    const std::string text = std::to_string(done) + " node(s) configured again from " +
                             p_.drives->config().source + " (rebooted or left NMT operational) in " +
                             printf_text("%.0f ms", ms);
    ledger_.event("drive_configured", text);
    spdlog::info("RECOVER: {}", text);
    return {};
  } catch (const std::exception& e) {
    const std::string text = std::string("RECOVER: configuring again ") + std::to_string(n) + " node(s) failed: " + e.what();
    ledger_.event("drive_configured", text);
    spdlog::error("{}", text);
    return text;
  }
}

void Supervisor::finish_running(AckState state, Reason code, const std::string& reason, std::vector<double> final_q) {
  const Job* running = jobs_.running();
  if (running == nullptr) return;
  // The plant's truth is journaled before the final ack leaves, so a ground
  // that reads the journal after the ack finds it.
  if (p_.sim_truth)
    ledger_.event("sim_truth", "after command " + std::to_string(running->command.command_id) + " (" +
                                   control::to_string(running->command.kind) + ", " + control::to_string(state) + ")",
                  p_.sim_truth());
  ledger_.ack(running->command, state, code, reason, std::move(final_q));
  const protocol::Command done = running->command;
  jobs_.take_running().reset();
  if (state != AckState::Completed) jobs_.cancel_chain(done, std::string(control::to_string(state)) + ": " + reason);
  start_next();
}

void Supervisor::resolve_upload_waits(std::uint64_t trajectory_id) {
  const UploadStore::Committed* committed = uploads_.committed(trajectory_id);
  const std::string* refused = uploads_.refused(trajectory_id);
  std::vector<std::pair<Reason, std::string>> why;
  // Taken out first, failed after: failing one cancels its chain, which
  // erases from the queue.
  auto failed = jobs_.take_if([&](Job& job) {
    if (job.awaiting_upload != trajectory_id) return false;
    Reason code = Reason::None;
    std::string reason;
    if (committed != nullptr) {
      if (factory_.attach_upload(job, *committed, &code, &reason)) return false;
    } else if (refused != nullptr) {
      code = Reason::IncompleteUpload;
      reason = "upload " + std::to_string(trajectory_id) + " was refused: " + *refused;
    } else {
      return false;
    }
    why.emplace_back(code, reason);
    return true;
  });
  for (std::size_t k = 0; k < failed.size(); ++k) jobs_.fail(*failed[k], why[k].first, why[k].second);
  start_next();
}

void Supervisor::check_upload_waits() {
  const auto now = Clock::now();
  auto late = jobs_.take_if([&](Job& job) { return job.awaiting_upload != 0 && now >= job.upload_deadline; });
  for (const auto& job : late) {
    const auto& run = std::get<protocol::RunTrajectory>(job->command.payload);
    jobs_.fail(*job, Reason::IncompleteUpload,
               "upload " + std::to_string(run.trajectory_id) +
                   printf_text(" did not commit within %.1f s of the RUN (upload_wait_s): nothing of it ran",
                               run.upload_wait_s));
  }
  if (!late.empty()) start_next();
}

// ---- ABORT, REQUEST, CAMERA ------------------------------------------------------------

void Supervisor::do_abort(const protocol::Command& c) {
  const auto& a = std::get<protocol::Abort>(c.payload);
  if (a.category != protocol::StopCategory::Cat1 && a.category != protocol::StopCategory::Cat2) {
    ledger_.reject(c, Reason::BadArgument, "ABORT category must be 1 or 2");
    return;
  }
  const std::string why =
      "aborted by command " + std::to_string(c.command_id) + (a.reason.empty() ? "" : ": " + a.reason);
  Job* running = jobs_.running();
  if (a.target_command_id != 0) {
    if (jobs_.cancel(a.target_command_id, why)) {
      ledger_.ack(c, AckState::Completed, Reason::None, "canceled the queued command", current_q());
      return;
    }
    if (!running || running->command.command_id != a.target_command_id) {
      ledger_.reject(c, Reason::BadArgument,
                     "command " + std::to_string(a.target_command_id) + " is neither running nor queued");
      return;
    }
  } else {
    jobs_.cancel_all(why);
  }
  if (running && running->kind == JobKind::ToolStep) {
    p_.tool->cancel(running->command.command_id);
    if (a.target_command_id != 0) {
      ledger_.ack(c, AckState::Completed, Reason::None, "tool step canceled", current_q());
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
      ledger_.ack(c, AckState::Failed, Reason::Internal, "the control loop's command ring is full", current_q());
      return;
    }
  }
  aborts_[stop.command_id] = c;
  ledger_.ack(c, AckState::Executing);
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
  if (jobs_.is_queued(a.target_command_id)) return false;  // canceled in the queue: nothing stops
  const Job* running = jobs_.running();
  return running && running->command.command_id == a.target_command_id && running->kind != JobKind::ToolStep;
}

void Supervisor::do_request(const protocol::Command& c) {
  const auto& r = std::get<protocol::Request>(c.payload);
  switch (r.what) {
    case protocol::RequestWhat::Status:
      if (p_.outbox.status) p_.outbox.status(reports_.status());
      break;
    case protocol::RequestWhat::JointState:
    case protocol::RequestWhat::Wrench:
      reports_.joints_and_wrench_now();  // publish both now
      reports_.publish(false);
      break;
    case protocol::RequestWhat::ToolState:
      reports_.tool_now();
      reports_.publish(false);
      break;
    case protocol::RequestWhat::Trajectories:
      if (p_.outbox.republish_uploads) p_.outbox.republish_uploads();
      break;
  }
  ledger_.ack(c, AckState::Completed, Reason::None, "", current_q());
}

void Supervisor::do_camera(const protocol::Command& c) {
  const auto& cam = std::get<protocol::CameraCommand>(c.payload);
  if (p_.camera == nullptr) {
    ledger_.reject(c, Reason::BadArgument, "no video switch configured");
    return;
  }
  const auto it = std::find(p_.camera_names.begin(), p_.camera_names.end(), cam.camera);
  if (it == p_.camera_names.end()) {
    std::string list;
    for (const auto& n : p_.camera_names) list += (list.empty() ? "" : ", ") + n;
    ledger_.reject(c, Reason::BadArgument, "unknown camera '" + cam.camera + "' (expected one of: " + list + ")");
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
    ledger_.reject(c, Reason::Busy,
                   "the video switch is busy with command " +
                       std::to_string(camera_command_ ? camera_command_->command_id : p_.camera->running_command()));
    return;
  }
  // Runs on the camera thread beside any motion; poll_camera acks the end.
  camera_command_ = c;
  ledger_.ack(c, AckState::Queued);
  ledger_.ack(c, AckState::Executing);
}

void Supervisor::poll_camera() {
  if (p_.camera == nullptr || !camera_command_) return;
  const auto r = p_.camera->poll_result();
  if (!r) return;
  const protocol::Command c = *camera_command_;
  camera_command_.reset();
  if (r->ok) {
    ledger_.ack(c, AckState::Completed, Reason::None, "camera " + std::get<protocol::CameraCommand>(c.payload).camera,
                current_q());
  } else {
    ledger_.ack(c, AckState::Failed, r->refused ? Reason::BadArgument : Reason::Internal, "video switch: " + r->error,
                current_q());
  }
}

// ---- uploads and link events ------------------------------------------------------------

void Supervisor::handle(const remote_link::UploadEvent& e) {
  journal::UploadRow row;
  row.stamp_ns = journal::Journal::now_ns();
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
  if (e.state != protocol::UploadState::Assembling) ledger_.upload(row);
  if (e.state == protocol::UploadState::Committed && e.trajectory) {
    const Job* running = jobs_.running();
    const std::uint64_t running_trajectory =
        running && running->kind == JobKind::Trajectory
            ? std::get<protocol::RunTrajectory>(running->command.payload).trajectory_id
            : 0;
    uploads_.commit(e.trajectory_id, e.trajectory, e.hash, running_trajectory);
    spdlog::info("upload {} committed: {} samples x {} joints, {:.2f} s, hash {}", e.trajectory_id,
                 e.trajectory->samples(), e.trajectory->joints(), e.trajectory->duration_s(), row.hash_hex);
    resolve_upload_waits(e.trajectory_id);
  } else if (e.state == protocol::UploadState::Rejected || e.state == protocol::UploadState::Discarded) {
    if (e.state == protocol::UploadState::Rejected) spdlog::warn("upload {} rejected: {}", e.trajectory_id, e.reason);
    uploads_.refuse(e.trajectory_id, std::string(row.state == "REJECTED" ? "rejected" : "discarded") + " (" +
                                         control::to_string(e.code) + ")" + (e.reason.empty() ? "" : ": " + e.reason));
    resolve_upload_waits(e.trajectory_id);
  }
}

void Supervisor::handle(const remote_link::LinkEvent& e) {
  if (e.kind == remote_link::LinkEvent::Kind::CommanderLeft) {
    // Its process ended: nobody can speak in that session any more, so the
    // lease would only keep the next ground station waiting.
    if (holder_.session() != 0 && holder_.holder_writer() == e.participant) {
      ledger_.event("control", "control released: the commander's participant " + e.participant.hex() +
                                   " left the DDS domain");
      holder_.release();
      reports_.publish(true);
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
    ledger_.event("command_rate_limit",
                  std::to_string(e.dropped) + " commands of participant " + e.participant.hex() + " dropped in " +
                      printf_text("%.1f s", e.silence_s) + ": over its rate limit",
                  d.dump());
    return;
  }
  site_.link_lost = e.kind == remote_link::LinkEvent::Kind::Lost;
  p_.loop->set_link_lost(site_.link_lost);
  const std::string text = site_.link_lost ? printf_text("link lost: no ground heartbeat for %.2f s", e.silence_s) +
                                                 " (policy " + to_string(p_.config.link_loss_policy) + ")"
                                           : printf_text("link regained after %.2f s", e.silence_s);
  if (site_.link_lost) {
    spdlog::warn("{}", text);
  } else {
    spdlog::info("{}", text);
  }
  ledger_.event(site_.link_lost ? "link_lost" : "link_regained", text);
  reports_.publish(true);
}

// ---- the loop's rings, the tool, the inputs ------------------------------------------------

void Supervisor::poll_loop() {
  bridge_.drain_telemetry(running_command_id());
  bridge_.drain_drive_events();
  control::StopEvent s;
  while (bridge_.next_stop(jobs_.running(), s)) {
    jobs_.cancel_all(std::string("the controller stopped: ") + s.text.data());
    const Job* running = jobs_.running();
    if (running && running->kind == JobKind::ToolStep) p_.tool->cancel(running->command.command_id);
    reports_.publish(true);
  }
  poll_events();
  if (reports_.mode_changed()) reports_.publish(true);
}

void Supervisor::poll_events() {
  MotionEvent e;
  while (p_.loop->poll_event(e)) {
    std::vector<double> fq(e.final_q.begin(),
                           e.final_q.begin() + static_cast<std::ptrdiff_t>(std::min(e.joints, control::kMaxJoints)));
    if (auto it = aborts_.find(e.command_id); it != aborts_.end()) {
      if (control::is_final(e.kind)) {
        const bool ok = e.kind == MotionEventKind::Completed;
        ledger_.ack(it->second, ok ? AckState::Completed : AckState::Failed, ok ? Reason::None : e.code,
                    e.text.data(), fq);
        aborts_.erase(it);
      }
      continue;
    }
    Job* running = jobs_.running();
    if (!running || running->loop_id != e.command_id) continue;  // internal (holds) or stale
    if (running->kind == JobKind::ToolStep) continue;              // the hold under a tool step
    switch (e.kind) {
      case MotionEventKind::Started:
        if (!running->executing) {
          running->executing = true;
          ledger_.ack(running->command, AckState::Executing);
        }
        break;
      case MotionEventKind::Completed: {
        // The loop is holding now; its telemetry may lag the event.
        if (running->kind == JobKind::Recover) bridge_.set_mode(ControllerMode::Idle);
        std::string text = e.text.data();
        if (running->kind == JobKind::Algorithm && text.empty())
          text = printf_text("distance %.4f m, peak force %.1f N", e.distance_m, e.peak_force_n);
        if (running->kind == JobKind::Algorithm && running->algorithm.kind == control::AlgorithmKind::IdentifyPayload)
          ledger_.event("payload", "identify_payload (command " + std::to_string(running->command.command_id) +
                                       "): " + text + " is the payload from now on");
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
}

void Supervisor::poll_tool() {
  if (p_.tool == nullptr) return;
  if (auto r = p_.tool->poll_result()) {
    const Job* running = jobs_.running();
    if (running && running->kind == JobKind::ToolStep && running->command.command_id == r->command_id) {
      if (r->ok) {
        const ToolStepKind kind = running->tool_step.kind;
        if (kind == ToolStepKind::Loosen || kind == ToolStepKind::Tighten || kind == ToolStepKind::Unlatch)
          tell_payload(kind == ToolStepKind::Loosen);
        finish_running(AckState::Completed, Reason::None, r->text, current_q());
      } else {
        finish_running(r->code == Reason::Aborted ? AckState::Canceled : AckState::Failed, r->code, r->text,
                       current_q());
      }
    }
  }
}

void Supervisor::tell_payload(bool oru_latched) {
  // The latched ORU hangs on the tool once its bolt is loose (loosen); it
  // leaves the tool when the bolt holds it again (tighten) or the latch
  // opens (unlatch). The controller then removes the tool's weight, plus the
  // ORU's while latched, at every orientation (docs/control.md "Payload").
  MotionCommand mc;
  mc.command_id = internal_id();
  mc.kind = MotionCommandKind::SetPayload;
  mc.oru_latched = oru_latched;
  const bool sent = p_.loop->send(mc);
  ledger_.event("payload", std::string(oru_latched ? "the ORU hangs on the tool: payload tool + ORU"
                                                   : "the ORU left the tool: payload tool alone") +
                               (sent ? "" : " (NOT sent: the control loop's command ring is full)"));
}

void Supervisor::check_inputs() {
  if (p_.config.estop_file.empty()) return;
  const auto now = Clock::now();
  if (now < next_input_check_) return;
  next_input_check_ = now + std::chrono::milliseconds(10);
  std::error_code ec;
  const bool pressed = std::filesystem::exists(p_.config.estop_file, ec);
  if (pressed != site_.estop) {
    site_.estop = pressed;
    p_.loop->set_estop(pressed);
    const std::string text = pressed ? "E-stop pressed (" + p_.config.estop_file + " exists)" : "E-stop released";
    if (pressed) {
      spdlog::error("{}", text);
    } else {
      spdlog::info("{}", text);
    }
    ledger_.event(pressed ? "estop_pressed" : "estop_released", text);
    reports_.publish(true);
  }
}

void Supervisor::shutdown(const std::string& why) {
  if (shutting_down_) return;
  shutting_down_ = true;
  ledger_.event("shutdown", why);
  jobs_.cancel_all("the controller is shutting down: " + why);
  if (p_.tool != nullptr && jobs_.running() && jobs_.running()->kind == JobKind::ToolStep) p_.tool->cancel();
  p_.loop->stop();  // category 1: controlled stop, then the drives off
  poll_loop();
  poll_tool();
  poll_camera();
  if (camera_command_) {
    ledger_.ack(*camera_command_, AckState::Canceled, Reason::Aborted,
                "the controller shut down while the video switch was answering: its outcome is unknown: " + why,
                current_q());
    camera_command_.reset();
  }
  if (jobs_.running())
    finish_running(AckState::Canceled, Reason::Aborted, "the controller shut down: " + why, current_q());
  for (auto& [id, c] : aborts_) ledger_.ack(c, AckState::Completed, Reason::None, "shut down", current_q());
  aborts_.clear();
  reports_.publish(true);
}

}  // namespace foresight::daemon
