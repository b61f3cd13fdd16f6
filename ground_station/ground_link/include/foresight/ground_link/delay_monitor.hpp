#pragma once
// The delay monitor: continuous Ping at a rate, four-timestamp round trip and
// clock offset per Pong (protocol::delay_from_pong), statistics over a window
// of the latest round trips (median, p95, p99, max, and the share over 0.5 s
// and over 4 s, as Kim 1996 reports them). Usable alone (the predictive
// display, the demo) or inside GroundLink.
//
// Threads: its own thread pings and takes pongs; every public method is
// thread-safe. Not real-time. Construction may throw (DDS set-up).

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "foresight/protocol/codec.hpp"
#include <functional>

#include "foresight/protocol/dds.hpp"

namespace foresight::ground_link {

struct DelayStats {
  std::size_t count = 0;          ///< round trips in the window
  std::uint64_t sent = 0;         ///< pings sent since start
  std::uint64_t received = 0;     ///< pongs matched since start
  double median_s = 0.0, p95_s = 0.0, p99_s = 0.0, min_s = 0.0, max_s = 0.0, mean_s = 0.0;
  double share_over_0_5s = 0.0;   ///< of the window's round trips, in [0, 1]
  double share_over_4s = 0.0;
  /// Remote clock minus ground clock (s): the offset of the window's round
  /// trip with the smallest rtt (least queueing, so the least asymmetry).
  double clock_offset_s = 0.0;
  double last_rtt_s = 0.0;
};

/// Statistics of `samples` (any order). Percentiles by nearest rank. Empty ->
/// count 0 and zeros.
DelayStats compute_delay_stats(std::span<const protocol::DelaySample> samples);

class DelayMonitor {
 public:
  struct Config {
    double rate_hz = 5.0;        ///< pings per second
    std::size_t window = 600;    ///< latest round trips kept for the statistics
    /// A pong later than this after its ping is counted lost (still used if it comes).
    double pong_timeout_s = 30.0;
    /// Take pongs and stamp t4 in a Cyclone listener (its receive thread) so
    /// the round trip excludes this process's thread wake-up; false: on the
    /// monitor's own thread.
    bool pong_in_listener = true;
  };

  /// Creates its own Ping writer and Pong reader in `participant` (which must
  /// outlive the monitor) and starts pinging.
  DelayMonitor(const protocol::Participant& participant, Config config);
  explicit DelayMonitor(const protocol::Participant& participant) : DelayMonitor(participant, Config{}) {}
  ~DelayMonitor();
  DelayMonitor(const DelayMonitor&) = delete;
  DelayMonitor& operator=(const DelayMonitor&) = delete;

  DelayStats stats() const;
  /// The latest round trip, if any arrived.
  std::optional<protocol::DelaySample> last() const;
  /// Remote minus ground clock in ns (see DelayStats::clock_offset_s); 0 before the first pong.
  std::int64_t clock_offset_ns() const noexcept;
  /// The window's round trips, oldest first.
  std::vector<protocol::DelaySample> window() const;
  /// Waits until at least `count` round trips arrived since start (bounded by `timeout`).
  bool wait_samples(std::size_t count, std::chrono::nanoseconds timeout) const;
  /// Empties the window (keeps the clock offset).
  void clear();
  /// From now on a pong counts only when `accept` says its writer's
  /// participant is the remote's (another participant can read our pings and
  /// answer them with any stamps: a forged clock offset of an hour); the
  /// others are ignored and counted. Unset: every pong counts.
  void set_writer_check(std::function<bool(const protocol::ParticipantGuid&)> accept);
  /// Pongs ignored by the writer check since start.
  std::uint64_t ignored_pongs() const noexcept;
  void stop() noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace foresight::ground_link
