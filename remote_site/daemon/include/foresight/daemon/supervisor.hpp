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
// Threads: submit, upload, link_event are thread-safe (the link thread);
// everything else runs on the supervisor thread. Not real-time.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "foresight/common/robot_model.hpp"
#include "foresight/control/control_loop.hpp"
#include "foresight/control/trajectory_executor.hpp"
#include "foresight/hw/lst_tool.hpp"
#include "foresight/journal/journal.hpp"
#include "foresight/daemon/daemon_config.hpp"
#include "foresight/daemon/inbox.hpp"
#include "foresight/daemon/camera_worker.hpp"
#include "foresight/daemon/tool_worker.hpp"
#include "foresight/remote_link/remote_link.hpp"

namespace foresight::daemon {

/// Where acks and reports go (the DDS link in the daemon; a recorder in tests).
struct Outbox {
  std::function<void(const protocol::Ack&)> ack;
  std::function<void(const protocol::JointReport&)> joints;
  std::function<void(const protocol::WrenchReport&)> wrench;
  std::function<void(const protocol::ToolReport&)> tool;
  std::function<void(const protocol::StatusReport&)> status;
  std::function<void()> republish_uploads;
  /// The participant in control changed (unknown: nobody): the link keeps
  /// only its heartbeats and chunks (RemoteLink::set_commander).
  std::function<void(const protocol::ParticipantGuid&)> commander;
};

struct SupervisorParts {
  const RobotModel* model = nullptr;
  DaemonConfig config;
  control::ControlLoop* loop = nullptr;
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
  const control::TelemetrySample& latest() const noexcept { return latest_; }
  protocol::ControllerMode mode() const noexcept { return latest_.mode; }
  std::uint64_t commander() const noexcept { return commander_; }

 private:
  enum class JobKind { Trajectory, Goto, Algorithm, ToolStep, Recover, Tare, Report };
  using Clock = std::chrono::steady_clock;
  struct Job {
    protocol::Command command;
    JobKind kind = JobKind::Trajectory;
    std::shared_ptr<const Trajectory> trajectory;           ///< Trajectory, or the planned Goto
    std::unique_ptr<control::PreparedTrajectory> prepared;  ///< alive until the final event
    control::AlgorithmParams algorithm{};
    int tare_samples = 50;
    ToolStep tool_step;
    bool compliant = false;
    double start_tolerance_rad = 0.0;
    bool executing = false;
    /// A RUN that overtook its upload (RunTrajectory.upload_wait_s > 0): the
    /// upload's id (0: not waiting); it starts only once that upload
    /// committed with the RUN's hash, and FAILS at upload_deadline.
    std::uint64_t awaiting_upload = 0;
    Clock::time_point upload_deadline{};
    /// The id the control loop knows this job's MotionCommand by: internal_id(),
    /// unique whatever the sessions' own command ids (a loop event is matched
    /// by it, so another session's command with the same id cannot finish it).
    std::uint64_t loop_id = 0;
  };

  void handle(const remote_link::CommandEvent& event);
  void handle(const remote_link::UploadEvent& event);
  void handle(const remote_link::LinkEvent& event);
  void dispatch(const protocol::Command& command);

  /// Journal durably, then acknowledge; remembers the last ack of the command.
  void ack(const protocol::Command& command, protocol::AckState state, protocol::Reason code = protocol::Reason::None,
           const std::string& reason = {}, std::vector<double> final_q = {});
  void reject(const protocol::Command& command, protocol::Reason code, const std::string& reason);

  // Checks; "" when fine, else the reason (code in *code).
  std::string check_commander(const protocol::Command& command, protocol::Reason* code) const;
  std::string check_can_move(protocol::Reason* code) const;

  // The job factory: a command's checks and its job; nullptr (false), with
  // the code and the reason, when refused.
  std::unique_ptr<Job> make_job(const protocol::Command& command, protocol::Reason* code, std::string* reason);
  bool make_trajectory_job(const protocol::RunTrajectory& run, Job& job, protocol::Reason* code, std::string* reason);
  bool check_goto(const protocol::Command& command, protocol::Reason* code, std::string* reason) const;
  bool make_invoke_job(const protocol::InvokeAlgorithm& invoke, Job& job, protocol::Reason* code, std::string* reason);
  bool plan_goto(Job& job, protocol::Reason* code, std::string* reason);
  void enqueue(std::unique_ptr<Job> job, const std::string& note = {});
  void start_next();
  void finish_running(protocol::AckState state, protocol::Reason code, const std::string& reason,
                      std::vector<double> final_q);
  void cancel_queued(const std::string& why);

  // Chains (after_command_id): a command waits in the queue behind the one it
  // follows; when that one does not complete, cancel_chain cancels every held
  // command after it ("chain broken at command N: ...").
  static bool chainable(protocol::CommandKind kind) noexcept;
  /// The running or queued command (session, id); null when not held.
  const protocol::Command* held_command(std::uint64_t session, std::uint64_t command_id) const;
  /// The queue's bound and the chain's checks at receipt; "" when fine.
  std::string check_queue(const protocol::Command& command, protocol::Reason* code) const;
  void cancel_chain(const protocol::Command& broken, const std::string& why);
  /// A queued job that will never start: FAILED, and its chain canceled.
  void fail_queued(std::unique_ptr<Job> job, protocol::Reason code, const std::string& why);

  // RUN before its upload committed: the jobs waiting for `trajectory_id`
  // get it (or fail: hash, rejected upload); a wait past its deadline fails.
  void resolve_upload_waits(std::uint64_t trajectory_id);
  void check_upload_waits();

  void do_abort(const protocol::Command& command);
  /// Whether do_abort would stop the arm: a valid category, and no target, or
  /// the running motion as target.
  /// An accepted ABORT that stops the arm: its Stop goes to the loop now
  /// (remembered in early_stops_ for the ABORT's own handling).
  void send_early_stop(const remote_link::CommandEvent& event);
  std::map<const remote_link::CommandEvent*, std::uint64_t> early_stops_;
  bool abort_stops_arm(const protocol::Command& command) const;
  /// The loop id of a Stop sent for an ABORT before its RECEIVED row went to
  /// the disk (handle): do_abort takes it over instead of sending another.
  std::optional<std::uint64_t> early_stop_id_;
  void do_request(const protocol::Command& command);
  void do_camera(const protocol::Command& command);

  void poll_loop();
  void poll_tool();
  void poll_camera();
  void publish_reports(bool force_status);
  void check_inputs();
  std::uint64_t internal_id() noexcept { return (1ull << 63) | ++internal_counter_; }
  std::vector<double> current_q() const;
  std::int64_t to_wall_ns(std::int64_t mono_ns) const noexcept;
  protocol::StatusReport status_report() const;
  void journal_event(const std::string& kind, const std::string& text, const std::string& detail = {});
  /// The inbox's dropped commands, journaled once a second at most.
  void journal_inbox_drops();

  SupervisorParts p_;
  const RobotModel& model_;

  daemon::Inbox inbox_;
  std::chrono::steady_clock::time_point inbox_drop_since_{};
  std::uint64_t inbox_dropped_ = 0;  ///< since inbox_drop_since_, journaled once a second

  std::map<std::uint64_t, std::shared_ptr<const Trajectory>> uploads_;  ///< committed, by id
  std::map<std::uint64_t, TrajectoryHash> upload_hash_;
  std::deque<std::uint64_t> upload_order_;
  /// Why recent uploads were refused (bounded): a RUN waiting for one fails with it.
  std::map<std::uint64_t, std::string> upload_refused_;
  std::deque<std::uint64_t> upload_refused_order_;
  using CommandKey = std::pair<std::uint64_t, std::uint64_t>;  ///< (session, command id): ids restart per session
  std::map<CommandKey, protocol::Ack> last_ack_;  ///< the last ack of each command (bounded)
  std::deque<CommandKey> last_ack_order_;
  std::map<std::uint64_t, protocol::Command> aborts_;  ///< ABORT commands by the loop id of the Stop sent for them
  std::optional<protocol::Command> camera_command_;   ///< the CAMERA command the camera thread runs

  std::deque<std::unique_ptr<Job>> queue_;
  std::unique_ptr<Job> running_;

  std::uint64_t commander_ = 0;
  /// The participant whose TAKE_CONTROL made commander_ (unknown when
  /// discovery had lost its writer): the commanding session speaks only from it.
  protocol::ParticipantGuid commander_writer_;
  /// The writer of the command handle() is working on.
  protocol::ParticipantGuid current_writer_;
  /// The command at hand is the commander's: its session, from its
  /// participant; with DDS Security any session of the commanding station.
  bool from_commander(const protocol::Command& c) const noexcept {
    return commander_ != 0 && current_writer_ == commander_writer_ && (stations() || c.session_id == commander_);
  }
  bool stations() const noexcept { return !p_.config.security_dir.empty(); }
  /// "participant 0110a4c1.5e3f0001.00000000.000001c1", or with DDS Security
  /// "station 'ground' (eb49bb7a.00a60000.00000000.00000000)".
  std::string writer_text(const protocol::ParticipantGuid& writer) const;
  void set_commander(std::uint64_t session, const protocol::ParticipantGuid& writer);
  Clock::time_point commander_active_{};
  std::uint64_t last_sequence_ = 0;

  control::TelemetrySample latest_{};
  bool have_telemetry_ = false;
  control::StopEvent last_stop_{};
  bool have_stop_ = false;
  protocol::ControllerMode reported_mode_ = protocol::ControllerMode::Disabled;
  bool estop_ = false;
  bool link_lost_ = false;
  bool shutting_down_ = false;
  std::uint64_t internal_counter_ = 0;
  std::string fault_text_;

  /// The rate limiter's episodes, from the telemetry's counters: one journal
  /// row when it starts limiting, one when it has let go for 200 ms.
  void track_rate_limiter(const control::TelemetrySample& t);
  struct RateLimitEpisode {
    bool active = false;
    std::uint32_t joints = 0;        ///< bit j: joint j + 1 limited in this episode
    std::uint64_t first_cycles = 0;  ///< the loop's rate_limited_cycles when it began
    std::uint64_t command_id = 0;    ///< the ground's command running when it began (0: none)
    double max_lag_rad = 0.0;
    std::int64_t last_limited_ns = 0;
  } rate_limit_{};
  protocol::RateLimitReport rate_limit_report_{};
  std::array<std::uint32_t, control::kMaxJoints> rate_limited_joint_cycles_{};

  Clock::time_point next_joints_{}, next_wrench_{}, next_tool_{}, next_status_{}, next_input_check_{};
};

}  // namespace foresight::daemon
