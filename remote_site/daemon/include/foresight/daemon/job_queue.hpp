#pragma once
// The jobs the remote holds: the one running and the queue behind it, with
// the chains between them.
//
// A command may follow another (after_command_id): it waits in the queue
// behind it, and when that one does not complete, every held command after
// it is canceled ("chain broken at command N: ..."). Every cancel and
// failure goes through the ledger (journaled, then acknowledged) with the
// arm's joints as the final ones.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "foresight/daemon/job.hpp"
#include "foresight/daemon/ledger.hpp"

namespace foresight::daemon {

class JobQueue {
 public:
  struct Limits {
    std::size_t max_held = 0;   ///< controller.max_queued_commands
    std::size_t max_chain = 0;  ///< controller.max_chain_length
  };
  /// `current_q`: the arm's joints now, the final joints of what is canceled.
  JobQueue(Ledger& ledger, Limits limits, std::function<std::vector<double>()> current_q)
      : ledger_(ledger), limits_(limits), current_q_(std::move(current_q)) {}

  /// Nothing runs and nothing waits.
  bool idle() const noexcept { return !running_ && queue_.empty(); }
  Job* running() noexcept { return running_.get(); }
  const Job* running() const noexcept { return running_.get(); }
  void set_running(std::unique_ptr<Job> job) noexcept { running_ = std::move(job); }
  std::unique_ptr<Job> take_running() noexcept { return std::move(running_); }
  const std::deque<std::unique_ptr<Job>>& queued() const noexcept { return queue_; }

  void push(std::unique_ptr<Job> job) { queue_.push_back(std::move(job)); }
  /// The next job that may start (nothing running; the head does not wait
  /// for its upload); null when none.
  std::unique_ptr<Job> pop_startable();
  /// Every queued job for which `pred` holds, taken out, in order (`pred`
  /// may complete a job it keeps, e.g. with its upload).
  std::vector<std::unique_ptr<Job>> take_if(const std::function<bool(Job&)>& pred);

  /// The kinds a command may follow or be followed by.
  static bool chainable(protocol::CommandKind kind) noexcept;
  /// The queue's bound and the chain's checks at receipt; "" when fine.
  std::string check(const protocol::Command& command, protocol::Reason* code) const;
  /// The running or queued command (session, id); null when not held.
  const protocol::Command* held(std::uint64_t session, std::uint64_t command_id) const;
  bool is_queued(std::uint64_t command_id) const;

  /// Cancel the queued command `command_id` and its chain; false when it is not queued.
  bool cancel(std::uint64_t command_id, const std::string& why);
  /// Cancel every queued command.
  void cancel_all(const std::string& why);
  /// Cancel every held command that follows `broken`, directly or through another.
  void cancel_chain(const protocol::Command& broken, const std::string& why);
  /// A job that will never start: FAILED, and its chain canceled.
  void fail(const Job& job, protocol::Reason code, const std::string& why);

 private:
  Ledger& ledger_;
  Limits limits_;
  std::function<std::vector<double>()> current_q_;
  std::deque<std::unique_ptr<Job>> queue_;
  std::unique_ptr<Job> running_;
};

}  // namespace foresight::daemon
