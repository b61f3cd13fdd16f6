#pragma once
// A bounded lock-free single-producer / single-consumer ring: the one the
// remote's real-time loop talks to its daemon through (commands in; events,
// stops, telemetry out) and the journal's telemetry queue.
//
// Construction allocates (set-up). try_push() and try_pop() are noexcept,
// allocation-free, wait-free and never block: one producer thread may call
// try_push() while one consumer thread calls try_pop(). T must be trivially
// copyable (the slots are plain storage, copied in and out).
//
// The ring holds exactly `capacity` elements. Head and tail are monotonic
// 64-bit counters (they never wrap in practice), each on its own cache line;
// each side caches the other's counter to avoid touching its line on every call.
//
//   SpscRing<MotionCommand> commands(64);
//   producer: if (!commands.try_push(cmd)) { /* full: report Busy */ }
//   consumer: MotionCommand c; while (commands.try_pop(c)) handle(c);

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <stdexcept>
#include <type_traits>

namespace foresight {

template <typename T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "SpscRing carries trivially copyable values");

 public:
  /// Set-up: allocates `capacity` slots. Throws std::invalid_argument on 0.
  explicit SpscRing(std::size_t capacity) : capacity_(capacity) {
    if (capacity == 0) throw std::invalid_argument("SpscRing: capacity must be positive");
    slots_ = std::make_unique<T[]>(capacity);
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  /// Producer. False (nothing written) when the ring is full.
  bool try_push(const T& value) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ >= capacity_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ >= capacity_) return false;
    }
    slots_[head % capacity_] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  /// Consumer. False (out untouched) when the ring is empty.
  bool try_pop(T& out) noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return false;
    }
    out = slots_[tail % capacity_];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  std::size_t capacity() const noexcept { return capacity_; }
  /// Approximate when called while the other side runs.
  std::size_t size() const noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_acquire);
    return static_cast<std::size_t>(head_.load(std::memory_order_acquire) - tail);
  }
  bool empty() const noexcept { return size() == 0; }

 private:
  static constexpr std::size_t kLine = 64;
  const std::size_t capacity_;
  std::unique_ptr<T[]> slots_;
  alignas(kLine) std::atomic<std::uint64_t> head_{0};  ///< written by the producer
  std::uint64_t tail_cache_ = 0;                       ///< producer's copy of tail_
  alignas(kLine) std::atomic<std::uint64_t> tail_{0};  ///< written by the consumer
  std::uint64_t head_cache_ = 0;                       ///< consumer's copy of head_
};

}  // namespace foresight
