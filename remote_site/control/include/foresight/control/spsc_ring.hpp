#pragma once
// A lock-free single-producer / single-consumer ring of trivially copyable T
// with a fixed capacity (a power of two). One thread pushes, one other thread
// pops; both calls are wait-free, noexcept and allocation-free (real-time
// safe on both sides). Storage is inline (no heap): put large rings in
// objects that live on the heap (ControlLoop does), not on a thread's stack.
//
//   SpscRing<MotionCommand, 64> commands;
//   producer: if (!commands.try_push(cmd)) { /* full: report Busy */ }
//   consumer: MotionCommand c; while (commands.try_pop(c)) handle(c);

#include <array>
#include <atomic>
#include <cstddef>
#include <new>
#include <type_traits>

namespace foresight::control {

template <class T, std::size_t Capacity>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "SpscRing holds trivially copyable types only");
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0, "capacity must be a power of two");

 public:
  static constexpr std::size_t capacity() noexcept { return Capacity; }

  /// Producer thread only. False when full (nothing written).
  bool try_push(const T& value) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ >= Capacity) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ >= Capacity) return false;
    }
    slots_[head & (Capacity - 1)] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  /// Consumer thread only. False when empty (out untouched).
  bool try_pop(T& out) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return false;
    }
    out = slots_[tail & (Capacity - 1)];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Approximate fill level (exact when both sides are quiet). Any thread.
  std::size_t size() const noexcept {
    const std::size_t tail = tail_.load(std::memory_order_acquire);
    const std::size_t head = head_.load(std::memory_order_acquire);
    return head - tail;
  }
  bool empty() const noexcept { return size() == 0; }

 private:
  static constexpr std::size_t kLine = 64;
  alignas(kLine) std::atomic<std::size_t> head_{0};  // written by the producer
  std::size_t tail_cache_ = 0;                        // producer's view of tail_
  alignas(kLine) std::atomic<std::size_t> tail_{0};  // written by the consumer
  std::size_t head_cache_ = 0;                        // consumer's view of head_
  alignas(kLine) std::array<T, Capacity> slots_{};
};

}  // namespace foresight::control
