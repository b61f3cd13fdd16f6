#pragma once
// Running a task script, as pure logic (no robot, no terminal): the script with
// its current command marked, and the operator's step / auto / cancel / abort
// (the paper's auto sequence), plus retry or skip after a stop and going on
// from a stopped command once the cause is fixed. The CLI (`foresight run`)
// drives it with a keyboard or flags and a runner that talks to the remote;
// tests drive it with scripted keys and a fake runner. Not real-time code.
//
// States of the whole run:
//   Ready    -> start() -> Running -> finish(Completed) -> Ready (next) | Finished (past the last)
//                                  -> finish(Failed | Canceled) -> Stopped (at that command)
//   Stopped  -> retry() -> Ready (same command) | skip() -> Ready (next)
//   any but Finished -> abort() -> Aborted (nothing more runs)

#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "foresight/script/script.hpp"

namespace foresight::script {

/// Sent: a command sent ahead in a chain (`run --chain`); the run goes on, and
/// settle() records how it ended once the remote says so.
enum class CommandState { Pending, Running, Completed, Failed, Canceled, Skipped, Sent };
const char* to_string(CommandState state) noexcept;

enum class RunState { Ready, Running, Stopped, Aborted, Finished };
const char* to_string(RunState state) noexcept;

struct Outcome {
  CommandState state = CommandState::Completed;  ///< Completed, Failed, Canceled, or Sent (chained)
  std::string message;                           ///< why it failed; what it did
  double seconds = 0.0;
};

class Executor {
 public:
  /// Commands before index `first` are marked Skipped (going on from a
  /// stopped command in a new session: `foresight run SCRIPT --from LINE`).
  explicit Executor(Script script, std::size_t first = 0);

  const Script& script() const noexcept { return script_; }
  RunState state() const noexcept { return state_; }
  /// Index of the current command; script().commands.size() once finished.
  std::size_t current() const noexcept { return current_; }
  const Command* current_command() const noexcept;
  CommandState command_state(std::size_t i) const { return outcomes_.at(i).state; }
  const Outcome& outcome(std::size_t i) const { return outcomes_.at(i); }
  bool auto_mode() const noexcept { return auto_; }
  void set_auto(bool on) noexcept { auto_ = on; }
  /// Why the run stopped or was aborted ("" otherwise).
  const std::string& stop_reason() const noexcept { return stop_reason_; }

  /// Ready -> Running; returns the command to run. std::logic_error otherwise.
  const Command& start();
  /// Running -> Ready/Finished (Completed, Sent) or Stopped (Failed, Canceled).
  /// After abort() the outcome is recorded and the run stays Aborted.
  void finish(const Outcome& outcome);
  /// How a Sent command (by its line) ended. Completed: only its mark changes.
  /// Failed or Canceled: the run stops at it (the earliest such command of the
  /// chain), so retry goes on from the first command that did not complete.
  /// std::logic_error when no Sent command is on that line, or the outcome is
  /// not Completed, Failed or Canceled.
  void settle(int line, const Outcome& outcome);
  /// True while any command is Sent (its end not known yet).
  bool has_sent() const noexcept;
  /// Stopped -> Ready at the same command.
  void retry();
  /// Ready or Stopped: mark the current command Skipped and go to the next.
  void skip();
  /// Ends the run: nothing more starts. A Running command stays Running until
  /// finish() records how it ended (the runner stops the robot).
  void abort(const std::string& reason);
  /// After the script file was fixed: the new script replaces the old one and
  /// the run goes on at the command on the current command's line (or the
  /// first after it). Outcomes of earlier lines are kept. Not while Running.
  void replace_script(Script fixed);

  /// Index of the first command at or after `line` (size() when none).
  static std::size_t index_at_line(const Script& script, int line);

  /// The script, one command a line: a mark per state and `>` at the current
  /// command, e.g. "> [ ]   5  TRAJECTORY to=hole_entrance:linear   # to the hole".
  std::string listing() const;

 private:
  Script script_;
  std::vector<Outcome> outcomes_;
  std::size_t current_ = 0;
  RunState state_ = RunState::Ready;
  bool auto_ = false;
  std::string stop_reason_;
};

// ---- the driver: one loop for the keyboard, flags and tests ----------------------

/// What the operator can press (or a flag stands for).
enum class Key { None, Step, Auto, Cancel, Abort, Retry, Skip, Quit };
/// 's' step, 'g' auto (go), 'c' cancel, 'a' abort, 'r' retry, 'k' skip, 'q' quit; None otherwise.
Key key_from_char(char c) noexcept;
/// "step", "auto", "cancel", "abort", "retry", "skip", "quit" (for --keys).
std::optional<Key> key_from_name(const std::string& name) noexcept;

class Controls {
 public:
  virtual ~Controls() = default;
  /// The next key, waiting at most `timeout_s` (0: do not wait). None when
  /// nothing was pressed in time.
  virtual Key poll(double timeout_s) = 0;
};

/// Keys from a list (the --keys flag, tests), in order. A poll that waits for
/// the operator (timeout > 0: Ready in step mode, Stopped) takes the next key,
/// or Quit once they run out, so a scripted run never waits for a keyboard
/// that is not there. A poll while a command runs (timeout 0) takes the next
/// key only when it is Cancel, Abort or None (None: "one poll passes", to
/// place a cancel later in a command), else answers None and keeps it.
class ScriptedControls : public Controls {
 public:
  explicit ScriptedControls(std::vector<Key> keys) : keys_(std::move(keys)) {}
  Key poll(double timeout_s) override {
    if (next_ >= keys_.size()) return timeout_s > 0 ? Key::Quit : Key::None;
    const Key k = keys_[next_];
    if (timeout_s > 0 || k == Key::Cancel || k == Key::Abort || k == Key::None) {
      ++next_;
      return k;
    }
    return Key::None;
  }
  /// Keys not consumed yet (a test asserts they were all used).
  std::size_t remaining() const noexcept { return keys_.size() - next_; }

 private:
  std::vector<Key> keys_;
  std::size_t next_ = 0;
};

class CommandRunner {
 public:
  virtual ~CommandRunner() = default;
  /// Runs one command to its end. `interrupted()` returns true once the
  /// operator cancelled or aborted: the runner then stops the robot (ABORT of
  /// the command), waits for that, and returns Canceled. Poll it at least
  /// every 0.1 s while waiting.
  virtual Outcome run(const Command& command, const std::function<bool()>& interrupted) = 0;
  /// Chained mode: waits until every command the runner sent ahead (returned
  /// as Sent) has ended, calling `on_settled(line, outcome)` for each, in the
  /// order sent. `interrupted()` true: the runner aborts what runs and what is
  /// queued, and reports each as it ended. A runner that never sends ahead has
  /// nothing to settle.
  virtual void settle(const std::function<bool()>& interrupted,
                      const std::function<void(int line, const Outcome&)>& on_settled) {
    (void)interrupted;
    (void)on_settled;
  }
  /// False for a command that may be sent while commands sent ahead still run
  /// (it does not depend on where the arm is now); drive() settles first otherwise.
  virtual bool chains(const Command& command) const {
    (void)command;
    return false;
  }
};

/// How drive() ended.
enum class DriveEnd { Finished, Aborted, Stopped, Quit };

/// Runs the executor until it finishes, is aborted, or the operator quits
/// (Quit while Ready or Stopped; Stopped also ends a run whose controls ran
/// out). In step mode each command needs a Step key; Auto runs on until a
/// command fails or is cancelled, or Step pressed while a command runs
/// switches back to step mode. Keys are read while a command runs (Cancel,
/// Abort, Step, Auto) and while waiting for the operator.
/// `on_change` is called after every state change (the CLI redraws the
/// listing). At most `max_keys` keys are read while idle (a bound on the loop).
/// Chained runs: before a command the runner does not chain, at the script's
/// end, and after an interruption, drive() settles what was sent ahead (a
/// chain broken on the remote stops the run at its first failed command).
DriveEnd drive(Executor& executor, CommandRunner& runner, Controls& controls,
               const std::function<void(const Executor&)>& on_change = {}, std::size_t max_keys = 1000000);

}  // namespace foresight::script
