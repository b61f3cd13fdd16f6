#pragma once
// The forwarding loop: reads IP packets from the two TUN devices, passes each
// through its direction's DirectionModel and DelayLine, and writes it to the
// other TUN device when it is due. One thread, ppoll() with a nanosecond
// timeout to the next due packet.
//
// Set-up (may allocate, may throw): the constructor. run() is the loop: after
// set-up it does not allocate, lock or log; it only reads, writes and polls.

#include <array>
#include <cstdint>

#include "foresight/linkemu/delay_line.hpp"
#include "foresight/linkemu/link_model.hpp"

namespace foresight::linkemu {

struct DirectionStats {
  std::uint64_t packets_in = 0;
  std::uint64_t bytes_in = 0;
  std::uint64_t packets_out = 0;
  std::uint64_t bytes_out = 0;
  std::uint64_t dropped_loss = 0;      ///< random loss
  std::uint64_t dropped_queue = 0;     ///< bandwidth shaper's queue limit
  std::uint64_t dropped_overflow = 0;  ///< the delay line was full
  std::uint64_t dropped_write = 0;     ///< the far TUN refused the packet
  std::uint64_t dropped_outage = 0;    ///< entered while the link was down (set_down)
  std::uint64_t reordered = 0;
  std::uint64_t max_queued = 0;
  std::uint64_t dropped() const noexcept { return dropped_loss + dropped_queue + dropped_overflow + dropped_write + dropped_outage;
  }
};

enum Direction : int { kGroundToRemote = 0, kRemoteToGround = 1 };

struct ForwarderOptions {
  LinkParams ground_to_remote;
  LinkParams remote_to_ground;
  std::size_t queue_packets = 8192;  ///< delay line capacity per direction
  std::size_t mtu = 1500;
  std::uint64_t seed = 1;
};

class Forwarder {
 public:
  /// Takes the two TUN fds (not owned; must be non-blocking).
  Forwarder(int ground_fd, int remote_fd, const ForwarderOptions& options);

  /// Runs until `stop_fd` becomes readable (e.g. a signalfd) or CLOCK_MONOTONIC
  /// reaches `deadline_ns` (0 = none). Packets still queued stay queued: a
  /// later run() delivers them; the caller that stops for good drops them.
  /// Returns 0, or the errno of a failed ppoll().
  int run(int stop_fd, std::int64_t deadline_ns) noexcept;

  const DirectionStats& stats(Direction d) const noexcept { return lanes_[d].stats; }
  /// Packets still in the timed queue (in flight when run() returned).
  std::size_t queued(Direction d) const noexcept { return lanes_[d].line.size(); }

  /// A link outage (a dropped radio link, a ground station hand-over): while
  /// down, every packet entering either direction is dropped (dropped_outage);
  /// packets already in flight still arrive, as on a real path. Call between
  /// run()s: run() returns when stop_fd is readable, the caller reads the
  /// signal, sets this, and calls run() again (the delay lines keep their
  /// packets and times).
  void set_down(bool down) noexcept { down_ = down; }
  bool down() const noexcept { return down_; }

 private:
  struct Lane {
    Lane(int in, int out, const LinkParams& params, std::uint64_t seed, std::size_t capacity, std::size_t mtu);
    int in_fd;
    int out_fd;
    DirectionModel model;
    DelayLine line;
    DirectionStats stats;
  };
  void read_burst(Lane& lane) noexcept;
  void deliver_due(Lane& lane, std::int64_t now_ns) noexcept;

  std::array<Lane, 2> lanes_;
  std::array<std::uint8_t, 65536> scratch_{};
  bool down_ = false;  // for packets dropped before queueing
};

/// CLOCK_MONOTONIC in nanoseconds.
std::int64_t monotonic_ns() noexcept;

}  // namespace foresight::linkemu
