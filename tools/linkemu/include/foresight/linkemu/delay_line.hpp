#pragma once
// The timed queue of one direction: packets waiting for their delivery time.
// A fixed number of fixed-size slots allocated once (set-up); a binary
// min-heap of slot indices ordered by (delivery time, arrival sequence), so
// equal times keep arrival order. push/pop/front are real-time safe:
// noexcept, no allocation.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace foresight::linkemu {

class DelayLine {
 public:
  /// Set-up: `capacity` slots of `slot_bytes` each (pages touched lazily).
  DelayLine(std::size_t capacity, std::size_t slot_bytes);

  /// A free slot's buffer to read a packet into, or an empty span when full.
  /// The slot stays free until commit() is called for it.
  std::span<std::uint8_t> acquire() noexcept;
  /// Queues the packet read into the last acquire()d slot: `bytes` long,
  /// due at `deliver_ns`.
  void commit(std::size_t bytes, std::int64_t deliver_ns) noexcept;

  bool empty() const noexcept { return size_ == 0; }
  std::size_t size() const noexcept { return size_; }
  std::size_t capacity() const noexcept { return capacity_; }
  /// Delivery time of the earliest packet (undefined when empty).
  std::int64_t next_due_ns() const noexcept;
  /// The earliest packet's bytes (valid until pop()).
  std::span<const std::uint8_t> front() const noexcept;
  void pop() noexcept;

 private:
  struct Slot {
    std::int64_t deliver_ns = 0;
    std::uint64_t seq = 0;
    std::size_t bytes = 0;
  };
  bool before(std::uint32_t a, std::uint32_t b) const noexcept;
  void sift_up(std::size_t i) noexcept;
  void sift_down(std::size_t i) noexcept;

  std::size_t capacity_;
  std::size_t slot_bytes_;
  std::unique_ptr<std::uint8_t[]> storage_;
  std::vector<Slot> slots_;
  std::vector<std::uint32_t> heap_;  // slot indices, min-heap
  std::vector<std::uint32_t> free_;  // free slot indices (stack)
  std::size_t size_ = 0;
  std::size_t free_count_ = 0;
  std::uint64_t next_seq_ = 0;
};

}  // namespace foresight::linkemu
