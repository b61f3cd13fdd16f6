// The task script executor and its driver loop (executor.hpp).
#include "foresight/script/executor.hpp"

#include <cstdio>
#include <stdexcept>

namespace foresight::script {

const char* to_string(CommandState state) noexcept {
  switch (state) {
    case CommandState::Pending: return "pending";
    case CommandState::Running: return "running";
    case CommandState::Completed: return "completed";
    case CommandState::Failed: return "failed";
    case CommandState::Canceled: return "canceled";
    case CommandState::Skipped: return "skipped";
    case CommandState::Sent: return "sent";
  }
  return "?";
}

const char* to_string(RunState state) noexcept {
  switch (state) {
    case RunState::Ready: return "ready";
    case RunState::Running: return "running";
    case RunState::Stopped: return "stopped";
    case RunState::Aborted: return "aborted";
    case RunState::Finished: return "finished";
  }
  return "?";
}

Executor::Executor(Script script, std::size_t first) : script_(std::move(script)) {
  outcomes_.assign(script_.commands.size(), Outcome{CommandState::Pending, "", 0.0});
  if (first > script_.commands.size()) first = script_.commands.size();
  for (std::size_t i = 0; i < first; ++i) outcomes_[i].state = CommandState::Skipped;
  current_ = first;
  if (current_ == script_.commands.size()) state_ = RunState::Finished;
}

const Command* Executor::current_command() const noexcept {
  return current_ < script_.commands.size() ? &script_.commands[current_] : nullptr;
}

const Command& Executor::start() {
  if (state_ != RunState::Ready)
    throw std::logic_error(std::string("script: cannot start a command while ") + to_string(state_));
  state_ = RunState::Running;
  outcomes_[current_] = Outcome{CommandState::Running, "", 0.0};
  return script_.commands[current_];
}

void Executor::finish(const Outcome& outcome) {
  if (outcomes_.empty() || current_ >= outcomes_.size() || outcomes_[current_].state != CommandState::Running)
    throw std::logic_error("script: finish() without a running command");
  if (outcome.state != CommandState::Completed && outcome.state != CommandState::Failed &&
      outcome.state != CommandState::Canceled && outcome.state != CommandState::Sent)
    throw std::logic_error("script: a command ends completed, failed, canceled or sent");
  outcomes_[current_] = outcome;
  if (state_ == RunState::Aborted) return;
  if (outcome.state == CommandState::Completed || outcome.state == CommandState::Sent) {
    ++current_;
    state_ = current_ == script_.commands.size() ? RunState::Finished : RunState::Ready;
    return;
  }
  const Command& c = script_.commands[current_];
  stop_reason_ = "line " + std::to_string(c.line) + " " + to_string(c.op) + " " + to_string(outcome.state) +
                 (outcome.message.empty() ? "" : ": " + outcome.message);
  state_ = RunState::Stopped;
}

void Executor::settle(int line, const Outcome& outcome) {
  if (outcome.state != CommandState::Completed && outcome.state != CommandState::Failed &&
      outcome.state != CommandState::Canceled)
    throw std::logic_error("script: a sent command settles completed, failed or canceled");
  if (state_ == RunState::Running) throw std::logic_error("script: settle() while a command runs");
  std::size_t i = 0;
  while (i < script_.commands.size() &&
         !(script_.commands[i].line == line && outcomes_[i].state == CommandState::Sent))
    ++i;
  if (i == script_.commands.size())
    throw std::logic_error("script: no command sent ahead on line " + std::to_string(line));
  outcomes_[i] = outcome;
  if (outcome.state == CommandState::Completed || state_ == RunState::Aborted) return;
  if (state_ == RunState::Stopped && current_ < i) return;  // an earlier command already stopped the run
  current_ = i;
  const Command& c = script_.commands[i];
  stop_reason_ = "line " + std::to_string(c.line) + " " + to_string(c.op) + " " + to_string(outcome.state) +
                 (outcome.message.empty() ? "" : ": " + outcome.message);
  state_ = RunState::Stopped;
}

bool Executor::has_sent() const noexcept {
  for (const auto& o : outcomes_)
    if (o.state == CommandState::Sent) return true;
  return false;
}

void Executor::retry() {
  if (state_ != RunState::Stopped) throw std::logic_error(std::string("script: retry while ") + to_string(state_));
  outcomes_[current_] = Outcome{CommandState::Pending, "", 0.0};
  stop_reason_.clear();
  state_ = RunState::Ready;
}

void Executor::skip() {
  if (state_ != RunState::Stopped && state_ != RunState::Ready)
    throw std::logic_error(std::string("script: skip while ") + to_string(state_));
  outcomes_[current_].state = CommandState::Skipped;
  stop_reason_.clear();
  ++current_;
  state_ = current_ == script_.commands.size() ? RunState::Finished : RunState::Ready;
}

void Executor::abort(const std::string& reason) {
  if (state_ == RunState::Finished || state_ == RunState::Aborted) return;
  stop_reason_ = reason;
  state_ = RunState::Aborted;
}

std::size_t Executor::index_at_line(const Script& script, int line) {
  for (std::size_t i = 0; i < script.commands.size(); ++i)
    if (script.commands[i].line >= line) return i;
  return script.commands.size();
}

void Executor::replace_script(Script fixed) {
  if (state_ == RunState::Running) throw std::logic_error("script: cannot replace the script while a command runs");
  const int line = current_ < script_.commands.size() ? script_.commands[current_].line
                                                      : (script_.commands.empty() ? 1 : script_.commands.back().line + 1);
  std::vector<Outcome> outcomes(fixed.commands.size(), Outcome{CommandState::Pending, "", 0.0});
  const std::size_t at = index_at_line(fixed, line);
  // Earlier commands keep their outcome by line; a new earlier line counts as skipped.
  for (std::size_t i = 0; i < at; ++i) {
    outcomes[i].state = CommandState::Skipped;
    for (std::size_t j = 0; j < current_ && j < outcomes_.size(); ++j)
      if (script_.commands[j].line == fixed.commands[i].line) outcomes[i] = outcomes_[j];
  }
  script_ = std::move(fixed);
  outcomes_ = std::move(outcomes);
  current_ = at;
  stop_reason_.clear();
  if (state_ != RunState::Aborted) state_ = current_ == script_.commands.size() ? RunState::Finished : RunState::Ready;
}

std::string Executor::listing() const {
  std::string out;
  for (std::size_t i = 0; i < script_.commands.size(); ++i) {
    const Command& c = script_.commands[i];
    const char* mark = "[ ]";
    switch (outcomes_[i].state) {
      case CommandState::Pending: mark = "[ ]"; break;
      case CommandState::Running: mark = "[~]"; break;
      case CommandState::Completed: mark = "[x]"; break;
      case CommandState::Failed: mark = "[!]"; break;
      case CommandState::Canceled: mark = "[c]"; break;
      case CommandState::Skipped: mark = "[-]"; break;
      case CommandState::Sent: mark = "[>]"; break;
    }
    char head[32];
    std::snprintf(head, sizeof head, "%s %s %4d  ", i == current_ && state_ != RunState::Finished ? ">" : " ", mark,
                  c.line);
    out += head + c.text;
    if (!c.note.empty()) out += "   # " + c.note;
    out += "\n";
  }
  return out;
}

Key key_from_char(char c) noexcept {
  switch (c) {
    case 's': case 'S': case ' ': case '\n': return Key::Step;
    case 'g': case 'G': return Key::Auto;
    case 'c': case 'C': return Key::Cancel;
    case 'a': case 'A': return Key::Abort;
    case 'r': case 'R': return Key::Retry;
    case 'k': case 'K': return Key::Skip;
    case 'q': case 'Q': return Key::Quit;
    default: return Key::None;
  }
}

std::optional<Key> key_from_name(const std::string& name) noexcept {
  if (name == "step") return Key::Step;
  if (name == "auto") return Key::Auto;
  if (name == "cancel") return Key::Cancel;
  if (name == "abort") return Key::Abort;
  if (name == "retry") return Key::Retry;
  if (name == "skip") return Key::Skip;
  if (name == "quit") return Key::Quit;
  return std::nullopt;
}

DriveEnd drive(Executor& ex, CommandRunner& runner, Controls& controls,
               const std::function<void(const Executor&)>& on_change, std::size_t max_keys) {
  const auto changed = [&] {
    if (on_change) on_change(ex);
  };
  // The operator's keys while something runs: Cancel or Abort interrupts it
  // (`where` names the line for the abort's reason), Step and Auto switch mode.
  const auto poller = [&](bool& interrupted, const std::string& where) {
    return [&interrupted, &ex, &controls, where]() -> bool {
      if (interrupted) return true;
      switch (controls.poll(0.0)) {
        case Key::Cancel: interrupted = true; break;
        case Key::Abort:
          interrupted = true;
          ex.abort("aborted by the operator " + where);
          break;
        case Key::Step: ex.set_auto(false); break;
        case Key::Auto: ex.set_auto(true); break;
        default: break;
      }
      return interrupted;
    };
  };
  // Waits for what was sent ahead (chained runs); `interrupt`: abort it all.
  const auto settle = [&](bool interrupt) {
    if (!ex.has_sent()) return;
    bool interrupted = interrupt;
    runner.settle(poller(interrupted, "while the chain ran"), [&](int line, const Outcome& o) {
      Outcome settled = o;
      if (settled.state != CommandState::Completed && settled.state != CommandState::Canceled)
        settled.state = CommandState::Failed;
      ex.settle(line, settled);
      changed();
    });
    if (ex.has_sent()) throw std::logic_error("script: the runner left commands sent ahead unsettled");
  };
  const auto run_current = [&] {
    const Command& c = ex.start();
    changed();
    bool interrupted = false;
    Outcome o = runner.run(c, poller(interrupted, "at line " + std::to_string(c.line)));
    if (o.state == CommandState::Running || o.state == CommandState::Pending || o.state == CommandState::Skipped)
      o.state = CommandState::Failed;
    ex.finish(o);
    changed();
    if (interrupted) settle(true);  // the rest of the chain is stopped too
  };
  // A command that needs the arm where it is now waits for the chain first.
  const auto ready_to_run = [&] {
    const Command* next = ex.current_command();
    if (next != nullptr && !runner.chains(*next)) settle(false);
    return ex.state() == RunState::Ready;
  };
  changed();
  std::size_t keys = 0;
  while (keys < max_keys) {
    switch (ex.state()) {
      case RunState::Finished:
        if (ex.has_sent()) {
          settle(false);
          break;
        }
        return DriveEnd::Finished;
      case RunState::Aborted:
        settle(true);
        return DriveEnd::Aborted;
      case RunState::Running: throw std::logic_error("script: drive() found a command still running");
      case RunState::Ready: {
        if (ex.auto_mode()) {  // keys are read while the command runs
          if (ready_to_run()) run_current();
          break;
        }
        const Key k = controls.poll(0.2);
        ++keys;
        if (k == Key::Abort) {
          ex.abort("aborted by the operator");
          changed();
        } else if (k == Key::Quit) {
          settle(false);
          if (ex.state() == RunState::Ready) return DriveEnd::Quit;
        } else if (k == Key::Skip) {
          ex.skip();
          changed();
        } else if (k == Key::Step || k == Key::Auto) {
          if (k == Key::Auto) ex.set_auto(true);
          if (ready_to_run()) run_current();
        }
        break;
      }
      case RunState::Stopped: {
        if (ex.has_sent()) {  // what was sent ahead runs on: its ends first (an earlier failure stops the run there)
          settle(false);
          break;
        }
        const Key k = controls.poll(0.2);
        ++keys;
        if (k == Key::Retry) {
          ex.retry();
          changed();
        } else if (k == Key::Skip) {
          ex.skip();
          changed();
        } else if (k == Key::Abort) {
          ex.abort("aborted by the operator after: " + ex.stop_reason());
          changed();
        } else if (k == Key::Quit) {
          return DriveEnd::Stopped;
        }
        break;
      }
    }
  }
  settle(false);
  return ex.state() == RunState::Stopped ? DriveEnd::Stopped : DriveEnd::Quit;
}

}  // namespace foresight::script
