#pragma once
// The timing model of one direction of the emulated link: what happens to a
// packet that enters the link at time t (nanoseconds, CLOCK_MONOTONIC).
//
//   1. random loss with probability `loss`;
//   2. the bandwidth limit: a token bucket of `rate_bit_s` with depth
//      `burst_bytes`, feeding a FIFO whose backlog may not exceed
//      `queue_bytes` (tail drop beyond it, as tc's tbf "limit");
//   3. the one-way delay plus jitter, uniform in [-jitter, +jitter] (netem's
//      default distribution), never below zero;
//   4. order: a packet is never delivered before one that entered earlier
//      (jitter alone does not reorder), unless it is picked for reordering
//      (probability `reorder`): then it is held back by an extra
//      `reorder_gap_ns` and packets behind it may overtake it.
//
// Everything here is plain arithmetic on caller-owned state: no allocation,
// no system calls; admit() is real-time safe (noexcept). The random source is
// a seeded std::mt19937_64 so runs are reproducible from the seed.

#include <cstdint>
#include <random>
#include <string>

namespace foresight::linkemu {

/// One direction's parameters (SI-ish: nanoseconds, bits per second, bytes).
struct LinkParams {
  std::int64_t delay_ns = 0;
  std::int64_t jitter_ns = 0;
  double loss = 0.0;            ///< probability in [0, 1]
  double reorder = 0.0;         ///< probability in [0, 1]
  std::int64_t reorder_gap_ns = 10'000'000;
  double rate_bit_s = 0.0;      ///< 0 = unlimited
  std::int64_t burst_bytes = 3000;
  std::int64_t queue_bytes = 65536;  ///< shaper backlog limit (with a rate)
};

/// Throws std::invalid_argument naming the first bad field (set-up).
void validate(const LinkParams& params);

enum class Verdict : std::uint8_t { kDeliver, kDropLoss, kDropQueue };

struct Decision {
  Verdict verdict = Verdict::kDeliver;
  std::int64_t deliver_ns = 0;  ///< when to hand the packet to the far side
  bool reordered = false;       ///< picked for reordering (held back)
};

/// The state of one direction. Real-time: admit() only.
class DirectionModel {
 public:
  DirectionModel(const LinkParams& params, std::uint64_t seed);

  /// Decides the fate of a packet of `bytes` entering at `now_ns`. Calls
  /// must come with non-decreasing now_ns. noexcept, no allocation.
  Decision admit(std::int64_t now_ns, std::int64_t bytes) noexcept;

  const LinkParams& params() const noexcept { return params_; }

 private:
  LinkParams params_;
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> unit_{0.0, 1.0};
  double virtual_finish_ns_ = -1e300;       // token bucket: when the shaper's backlog drains
  std::int64_t last_in_order_ns_ = INT64_MIN;  // latest delivery time of an in-order packet
};

}  // namespace foresight::linkemu
