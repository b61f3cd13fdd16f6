#pragma once
// The supervisor's inbox: what the link thread hands the supervisor thread
// (commands, upload events, link events), bounded of its own. The link
// already rate-limits each participant (50/s, burst 100), but 256
// participants could still stack up 25,600 commands at once; past
// `max_commands` queued commands a new one is dropped (counted, never acked:
// as the link's own rate limit does) unless it is an ABORT. Upload and link
// events always pass: their own sources bound them (upload slots, one event
// per state change). Thread-safe; not for the control cycle.

#include <condition_variable>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <variant>

#include "foresight/remote_link/remote_link.hpp"

namespace foresight::daemon {

class Inbox {
 public:
  using Item = std::variant<remote_link::CommandEvent, remote_link::UploadEvent, remote_link::LinkEvent>;

  explicit Inbox(std::size_t max_commands = 1024) : max_commands_(max_commands) {}

  /// Link thread: false when the command was dropped (the inbox holds
  /// max_commands commands and it is not an ABORT).
  bool push(Item item);
  /// Supervisor thread: everything queued, oldest first; the queue is empty after.
  std::deque<Item> take_all();
  /// Waits until something is queued or `timeout` passes.
  void wait(std::chrono::milliseconds timeout);
  /// Commands dropped since the last call (then 0 again).
  std::uint64_t take_dropped();
  std::size_t max_commands() const noexcept { return max_commands_; }

 private:
  const std::size_t max_commands_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Item> items_;
  std::size_t commands_ = 0;
  std::uint64_t dropped_ = 0;
};

}  // namespace foresight::daemon
