#include "foresight/linkemu/forwarder.hpp"

#include <poll.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>

namespace foresight::linkemu {

std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

Forwarder::Lane::Lane(int in, int out, const LinkParams& params, std::uint64_t seed, std::size_t capacity,
                      std::size_t mtu)
    : in_fd(in), out_fd(out), model(params, seed), line(capacity, mtu) {}

Forwarder::Forwarder(int ground_fd, int remote_fd, const ForwarderOptions& o)
    : lanes_{Lane(ground_fd, remote_fd, o.ground_to_remote, o.seed, o.queue_packets, o.mtu),
             Lane(remote_fd, ground_fd, o.remote_to_ground, o.seed ^ 0x9e3779b97f4a7c15ull, o.queue_packets,
                  o.mtu)} {}

void Forwarder::read_burst(Lane& lane) noexcept {
  // Bounded: at most 256 packets per wake-up, so the other direction and the
  // due deliveries are served in between.
  for (int i = 0; i < 256; ++i) {
    auto slot = lane.line.acquire();
    const bool have_slot = !slot.empty();
    const bool keep = have_slot && !down_;
    std::uint8_t* buffer = keep ? slot.data() : scratch_.data();
    const std::size_t size = keep ? slot.size() : scratch_.size();
    const ssize_t n = ::read(lane.in_fd, buffer, size);
    if (n <= 0) return;  // EAGAIN (drained), EINTR or an error: poll again
    const std::int64_t now = monotonic_ns();
    lane.stats.packets_in += 1;
    lane.stats.bytes_in += static_cast<std::uint64_t>(n);
    if (down_) {
      lane.stats.dropped_outage += 1;
      continue;
    }
    if (!have_slot) {
      lane.stats.dropped_overflow += 1;
      continue;
    }
    const Decision d = lane.model.admit(now, n);
    switch (d.verdict) {
      case Verdict::kDropLoss:
        lane.stats.dropped_loss += 1;
        continue;
      case Verdict::kDropQueue:
        lane.stats.dropped_queue += 1;
        continue;
      case Verdict::kDeliver:
        break;
    }
    if (d.reordered) lane.stats.reordered += 1;
    lane.line.commit(static_cast<std::size_t>(n), d.deliver_ns);
    lane.stats.max_queued = std::max<std::uint64_t>(lane.stats.max_queued, lane.line.size());
  }
}

void Forwarder::deliver_due(Lane& lane, std::int64_t now_ns) noexcept {
  while (!lane.line.empty() && lane.line.next_due_ns() <= now_ns) {
    const auto packet = lane.line.front();
    const ssize_t n = ::write(lane.out_fd, packet.data(), packet.size());
    if (n == static_cast<ssize_t>(packet.size())) {
      lane.stats.packets_out += 1;
      lane.stats.bytes_out += packet.size();
    } else {
      lane.stats.dropped_write += 1;
    }
    lane.line.pop();
  }
}

int Forwarder::run(int stop_fd, std::int64_t deadline_ns) noexcept {
  pollfd fds[3] = {{lanes_[0].in_fd, POLLIN, 0}, {lanes_[1].in_fd, POLLIN, 0}, {stop_fd, POLLIN, 0}};
  const nfds_t nfds = stop_fd >= 0 ? 3 : 2;
  constexpr std::int64_t kMaxWaitNs = 1'000'000'000;  // re-check the deadline at least every second
  for (;;) {
    std::int64_t now = monotonic_ns();
    if (deadline_ns > 0 && now >= deadline_ns) return 0;
    deliver_due(lanes_[0], now);
    deliver_due(lanes_[1], now);
    std::int64_t next = now + kMaxWaitNs;
    for (const Lane& lane : lanes_) {
      if (!lane.line.empty()) next = std::min(next, lane.line.next_due_ns());
    }
    if (deadline_ns > 0) next = std::min(next, deadline_ns);
    now = monotonic_ns();
    const std::int64_t wait = std::max<std::int64_t>(0, next - now);
    const timespec ts{static_cast<time_t>(wait / 1'000'000'000), static_cast<long>(wait % 1'000'000'000)};
    const int ready = ::ppoll(fds, nfds, &ts, nullptr);
    if (ready < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (nfds == 3 && (fds[2].revents & (POLLIN | POLLHUP | POLLERR)) != 0) return 0;
    if ((fds[0].revents & POLLIN) != 0) read_burst(lanes_[0]);
    if ((fds[1].revents & POLLIN) != 0) read_burst(lanes_[1]);
  }
}

}  // namespace foresight::linkemu
