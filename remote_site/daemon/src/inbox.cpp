#include "foresight/daemon/inbox.hpp"

namespace foresight::daemon {

bool Inbox::push(Item item) {
  {
    std::lock_guard lock(mu_);
    if (const auto* c = std::get_if<remote_link::CommandEvent>(&item)) {
      if (commands_ >= max_commands_ && c->command.kind != protocol::CommandKind::Abort) {
        ++dropped_;
        return false;
      }
      ++commands_;
    }
    items_.push_back(std::move(item));
  }
  cv_.notify_one();
  return true;
}

std::deque<Inbox::Item> Inbox::take_all() {
  std::deque<Item> out;
  std::lock_guard lock(mu_);
  out.swap(items_);
  commands_ = 0;
  return out;
}

void Inbox::wait(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mu_);
  cv_.wait_for(lock, timeout, [this] { return !items_.empty(); });
}

std::uint64_t Inbox::take_dropped() {
  std::lock_guard lock(mu_);
  const std::uint64_t n = dropped_;
  dropped_ = 0;
  return n;
}

}  // namespace foresight::daemon
