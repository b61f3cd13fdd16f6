#include "foresight/daemon/job_queue.hpp"

#include "foresight/control/command.hpp"

namespace foresight::daemon {

using protocol::AckState;
using protocol::CommandKind;
using protocol::Reason;

std::unique_ptr<Job> JobQueue::pop_startable() {
  if (running_ || queue_.empty() || queue_.front()->awaiting_upload != 0)
    return nullptr;  // the head waits for its upload; the rest behind it
  std::unique_ptr<Job> job = std::move(queue_.front());
  queue_.pop_front();
  return job;
}

std::vector<std::unique_ptr<Job>> JobQueue::take_if(const std::function<bool(Job&)>& pred) {
  std::vector<std::unique_ptr<Job>> taken;
  for (auto it = queue_.begin(); it != queue_.end();) {
    if (pred(**it)) {
      taken.push_back(std::move(*it));
      it = queue_.erase(it);
    } else {
      ++it;
    }
  }
  return taken;
}

bool JobQueue::chainable(CommandKind kind) noexcept {
  return kind == CommandKind::Trajectory || kind == CommandKind::InvokeAlgorithm || kind == CommandKind::GotoJoint ||
         kind == CommandKind::GotoCart || kind == CommandKind::Request;
}

const protocol::Command* JobQueue::held(std::uint64_t session, std::uint64_t command_id) const {
  if (running_ && running_->command.session_id == session && running_->command.command_id == command_id)
    return &running_->command;
  for (const auto& job : queue_)
    if (job->command.session_id == session && job->command.command_id == command_id) return &job->command;
  return nullptr;
}

bool JobQueue::is_queued(std::uint64_t command_id) const {
  for (const auto& job : queue_)
    if (job->command.command_id == command_id) return true;
  return false;
}

std::string JobQueue::check(const protocol::Command& c, Reason* code) const {
  const std::size_t held_now = queue_.size() + (running_ ? 1 : 0);
  if (held_now >= limits_.max_held) {
    *code = Reason::Busy;
    return "the remote already holds " + std::to_string(held_now) + " commands (controller.max_queued_commands " +
           std::to_string(limits_.max_held) + ")";
  }
  if (c.after_command_id == 0) return {};
  const std::string after = "command " + std::to_string(c.after_command_id);
  *code = Reason::BadArgument;
  if (c.after_command_id == c.command_id) return "command " + std::to_string(c.command_id) + " cannot follow itself";
  if (const protocol::Command* pred = held(c.session_id, c.after_command_id)) {
    // The chain's length: this command and every predecessor still held.
    std::size_t length = 2;
    for (const protocol::Command* p = pred; p->after_command_id != 0; ++length) {
      p = held(p->session_id, p->after_command_id);
      if (p == nullptr) break;
    }
    if (length > limits_.max_chain)
      return "a chain of " + std::to_string(length) + " commands exceeds controller.max_chain_length " +
             std::to_string(limits_.max_chain);
    return {};
  }
  const protocol::Ack* a = ledger_.last(c.session_id, c.after_command_id);
  if (a == nullptr) return after + " is not a command of this session (unknown here, or too old to be remembered)";
  if (a->state == AckState::Completed) return {};  // done: this one starts from where it left the arm
  if (protocol::is_terminal(a->state)) {
    *code = Reason::Aborted;
    return "chain broken at " + after + ": " + control::to_string(a->state) + (a->reason.empty() ? "" : ": " + a->reason);
  }
  return after + " is not a motion the remote runs (" + std::string(control::to_string(a->kind)) +
         " cannot be followed)";
}

bool JobQueue::cancel(std::uint64_t command_id, const std::string& why) {
  for (auto it = queue_.begin(); it != queue_.end(); ++it) {
    if ((*it)->command.command_id != command_id) continue;
    const protocol::Command canceled = (*it)->command;
    ledger_.ack(canceled, AckState::Canceled, Reason::Aborted, why, current_q_());
    queue_.erase(it);
    cancel_chain(canceled, "canceled: " + why);
    return true;
  }
  return false;
}

void JobQueue::cancel_all(const std::string& why) {
  while (!queue_.empty()) {
    ledger_.ack(queue_.front()->command, AckState::Canceled, Reason::Aborted, why, current_q_());
    queue_.pop_front();
  }
}

void JobQueue::cancel_chain(const protocol::Command& broken, const std::string& why) {
  // Every held command that follows `broken`, directly or through another,
  // is canceled with the place and cause of the break; nothing of it runs.
  const std::string reason = "chain broken at command " + std::to_string(broken.command_id) + ": " + why;
  std::vector<std::uint64_t> broken_ids{broken.command_id};
  for (std::size_t k = 0; k < broken_ids.size(); ++k) {
    for (auto it = queue_.begin(); it != queue_.end();) {
      const protocol::Command& q = (*it)->command;
      if (q.session_id == broken.session_id && q.after_command_id == broken_ids[k]) {
        broken_ids.push_back(q.command_id);
        ledger_.ack(q, AckState::Canceled, Reason::Aborted, reason, current_q_());
        it = queue_.erase(it);
      } else {
        ++it;
      }
    }
  }
}

void JobQueue::fail(const Job& job, Reason code, const std::string& why) {
  ledger_.ack(job.command, AckState::Failed, code, why, current_q_());
  cancel_chain(job.command, std::string("failed: ") + why);
}

}  // namespace foresight::daemon
