#pragma once
// The daemon's supervisor: everything between the link and the real-time
// loop, on one non-real-time thread.
//
//   link thread --submit()/upload()/link_event()--> inbox (mutex, non-RT)
//   supervisor thread (run_once, every ~2 ms):
//     commands: journal (durable) -> ack RECEIVED -> checks (control holder,
//       controller state, payload against the robot) -> REJECTED, or
//       QUEUED -> started when the arm is free -> EXECUTING -> COMPLETED |
//       FAILED | CANCELED with the actual final joints. Every state is
//       journaled durably before it is acknowledged.
//     motions: TRAJECTORY (a committed upload, hash equal, prepared for the
//       loop), GOTO_JOINT / GOTO_CART (planned here with the planner the
//       ground previews with, foresight::plan_motion: min-jerk joint move /
//       straight line of the tool tip), the RT algorithms (guarded_move,
//       insert, pull_out) -> the loop's command ring; the tool steps (latch,
//       unlatch, loosen, tighten) -> the tool thread while the arm holds
//       still; CAMERA -> the video switch; RECOVER -> enable / recover.
//     the loop's rings: events -> acks; stops -> fault rows (with evidence)
//       and a status report; telemetry -> reports at the configured rates and
//       journal rows.
//     inputs: the E-stop file, the link-loss events (the controller applies
//       the configured policy).
//   Control: one ground session holds control (TAKE_CONTROL / RELEASE_CONTROL);
//   every motion, tool, camera and recover command of another session is
//   REJECTED NotInControl; any session may ABORT and REQUEST. A holder that
//   has sent nothing for control_lease_s with nothing of its own running may
//   be superseded.
//
// Its parts, each in its own file: the ledger (journal rows, then acks), the
// control holder, the upload store, the job factory, the job queue with its
// chains, the loop bridge (telemetry and stops) and the reports. The
// supervisor itself routes commands between them and starts the jobs.
//
// Threads: submit, upload, link_event are thread-safe (the link thread);
// everything else runs on the supervisor thread. Not real-time.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "foresight/common/robot_model.hpp"
#include "foresight/control/control_loop.hpp"
#include "foresight/daemon/camera_worker.hpp"
#include "foresight/daemon/control_holder.hpp"
#include "foresight/daemon/daemon_config.hpp"
#include "foresight/daemon/inbox.hpp"
#include "foresight/daemon/job.hpp"
#include "foresight/daemon/job_queue.hpp"
#include "foresight/daemon/ledger.hpp"
#include "foresight/daemon/loop_bridge.hpp"
#include "foresight/daemon/reports.hpp"
#include "foresight/daemon/tool_worker.hpp"
#include "foresight/daemon/upload_store.hpp"
#include "foresight/journal/journal.hpp"
#include "foresight/remote_link/remote_link.hpp"

namespace foresight::daemon {

struct SupervisorParts {
  const RobotModel* model = nullptr;
  DaemonConfig config;
  control::ControlLoop* loop = nullptr;
  /// The loop's drives (may be null: no node is then configured again). A
  /// RECOVER first configures again, on this thread while the loop cycles
  /// on, every node that rebooted or left NMT operational
  /// (DriveSystem::configure_nodes: blocking SDO, never on the loop's thread).
  hw::DriveSystem* drives = nullptr;
  journal::Journal* journal = nullptr;
  ToolWorker* tool = nullptr;                  ///< may be null: tool steps are then refused
  CameraWorker* camera = nullptr;              ///< may be null: CAMERA is then refused
  std::vector<std::string> camera_names;       ///< video switch index = position
  std::vector<int> drive_nodes;                ///< CANopen node id per joint (status: drives)
  Outbox outbox;
  /// --sim only: the simulated plant's ground truth as JSON (the ORU's state
  /// and pose, its alignment against its slot), journaled as a `sim_truth`
  /// event after every motion and tool step, for the demo's report. Empty on
  /// a real cabinet, where no such truth exists.
  std::function<std::string()> sim_truth;
  /// With DDS Security (config.security_dir set) the link names writers by
  /// identity (protocol::identity_of) and control belongs to a station's
  /// identity, across its processes and sessions. The identities known by
  /// name (protocol::known_identities), for messages and the journal.
  std::vector<std::pair<protocol::ParticipantGuid, std::string>> identities;
};

class Supervisor {
 public:
  explicit Supervisor(SupervisorParts parts);
  ~Supervisor();
  Supervisor(const Supervisor&) = delete;
  Supervisor& operator=(const Supervisor&) = delete;

  // ---- link thread -------------------------------------------------------------
  void submit(const remote_link::CommandEvent& event);
  void upload(const remote_link::UploadEvent& event);
  void link_event(const remote_link::LinkEvent& event);

  // ---- supervisor thread ---------------------------------------------------------
  /// One pass: inbox, loop rings, tool results, reports, inputs.
  void run_once();
  /// run_once until `quit`, waking on the inbox or every 2 ms.
  void run(const std::atomic<bool>& quit);
  /// Refuse new commands, cancel what is queued and the tool step, stop the
  /// loop (category 1 and drives off), ack what ran, journal it.
  void shutdown(const std::string& why);

  /// Latest telemetry from the loop (stamp is CLOCK_MONOTONIC).
  const control::TelemetrySample& latest() const noexcept { return bridge_.latest(); }
  protocol::ControllerMode mode() const noexcept { return bridge_.latest().mode; }
  std::uint64_t commander() const noexcept { return holder_.session(); }

 private:
  using Clock = std::chrono::steady_clock;

  void handle(const remote_link::CommandEvent& event);
  void handle(const remote_link::UploadEvent& event);
  void handle(const remote_link::LinkEvent& event);
  void dispatch(const protocol::Command& command);
  void take_control(const protocol::Command& command);
  void release_control(const protocol::Command& command);
  /// The link works again: a command of the holder's (or, with nobody in
  /// control, of anyone's) arrived while it was lost.
  void link_regained_by(const protocol::Command& command);

  /// "" when the controller can take a new motion, else why not (the code in *code).
  std::string check_can_move(protocol::Reason* code) const;
  /// The arm is free: a GOTO is planned and a trajectory's start checked now,
  /// so that an unreachable goal is REJECTED before anything is queued.
  bool check_start_now(Job& job, protocol::Reason* code, std::string* reason);

  void enqueue(std::unique_ptr<Job> job, const std::string& note = {});
  void start_next();
  /// Start `job` on the loop or the tool; "" when started, else why not (the code in *code).
  std::string start(Job& job, protocol::Reason* code);
  /// RECOVER: the nodes that rebooted configured again first ("" when done
  /// or none, else why not).
  std::string configure_nodes_again();
  void finish_running(protocol::AckState state, protocol::Reason code, const std::string& reason,
                      std::vector<double> final_q);

  // RUN before its upload committed: the jobs waiting for `trajectory_id`
  // get it (or fail: hash, rejected upload); a wait past its deadline fails.
  void resolve_upload_waits(std::uint64_t trajectory_id);
  void check_upload_waits();

  void do_abort(const protocol::Command& command);
  /// An accepted ABORT that stops the arm: its Stop goes to the loop now
  /// (remembered in early_stops_ for the ABORT's own handling).
  void send_early_stop(const remote_link::CommandEvent& event);
  /// Whether do_abort would stop the arm: a valid category, and no target, or
  /// the running motion as target.
  bool abort_stops_arm(const protocol::Command& command) const;
  void do_request(const protocol::Command& command);
  void do_camera(const protocol::Command& command);

  void poll_loop();
  void poll_events();
  void poll_tool();
  /// The ORU latched on (loosen) or off (tighten, unlatch) the tool: SetPayload to the loop, journaled.
  void tell_payload(bool oru_latched);
  void poll_camera();
  void check_inputs();
  /// The inbox's dropped commands, journaled once a second at most.
  void journal_inbox_drops();
  std::uint64_t internal_id() noexcept { return (1ull << 63) | ++internal_counter_; }
  std::vector<double> current_q() const { return bridge_.current_q(); }
  std::uint64_t running_command_id() const noexcept {
    return jobs_.running() ? jobs_.running()->command.command_id : 0;
  }

  SupervisorParts p_;
  const RobotModel& model_;

  daemon::Inbox inbox_;
  Clock::time_point inbox_drop_since_{};
  std::uint64_t inbox_dropped_ = 0;  ///< since inbox_drop_since_, journaled once a second

  Ledger ledger_;
  ControlHolder holder_;
  UploadStore uploads_;
  JobFactory factory_;
  LoopBridge bridge_;
  JobQueue jobs_;
  SiteInputs site_;
  Reports reports_;

  std::map<std::uint64_t, protocol::Command> aborts_;  ///< ABORT commands by the loop id of the Stop sent for them
  std::optional<protocol::Command> camera_command_;   ///< the CAMERA command the camera thread runs
  /// The Stops run_once() sent ahead of their batch, by event.
  std::map<const remote_link::CommandEvent*, std::uint64_t> early_stops_;
  /// The loop id of a Stop sent for an ABORT before its RECEIVED row went to
  /// the disk (handle): do_abort takes it over instead of sending another.
  std::optional<std::uint64_t> early_stop_id_;

  bool shutting_down_ = false;
  std::uint64_t internal_counter_ = 0;
  Clock::time_point next_input_check_{};
};

}  // namespace foresight::daemon
