#include "foresight/linkemu/delay_line.hpp"

#include <stdexcept>
#include <utility>

namespace foresight::linkemu {

DelayLine::DelayLine(std::size_t capacity, std::size_t slot_bytes)
    : capacity_(capacity),
      slot_bytes_(slot_bytes),
      storage_(std::make_unique_for_overwrite<std::uint8_t[]>(capacity * slot_bytes)),
      slots_(capacity),
      heap_(capacity),
      free_(capacity),
      free_count_(capacity) {
  if (capacity == 0 || capacity > UINT32_MAX) throw std::invalid_argument("delay line capacity must be in 1..2^32-1");
  if (slot_bytes == 0) throw std::invalid_argument("delay line slot size must be > 0");
  // Hand out low indices first (their pages are touched first).
  for (std::size_t i = 0; i < capacity; ++i) free_[i] = static_cast<std::uint32_t>(capacity - 1 - i);
}

std::span<std::uint8_t> DelayLine::acquire() noexcept {
  if (free_count_ == 0) return {};
  const std::uint32_t slot = free_[free_count_ - 1];
  return {storage_.get() + static_cast<std::size_t>(slot) * slot_bytes_, slot_bytes_};
}

void DelayLine::commit(std::size_t bytes, std::int64_t deliver_ns) noexcept {
  if (free_count_ == 0) return;
  const std::uint32_t slot = free_[--free_count_];
  slots_[slot] = Slot{deliver_ns, next_seq_++, bytes < slot_bytes_ ? bytes : slot_bytes_};
  heap_[size_] = slot;
  sift_up(size_);
  ++size_;
}

std::int64_t DelayLine::next_due_ns() const noexcept { return slots_[heap_[0]].deliver_ns; }

std::span<const std::uint8_t> DelayLine::front() const noexcept {
  const std::uint32_t slot = heap_[0];
  return {storage_.get() + static_cast<std::size_t>(slot) * slot_bytes_, slots_[slot].bytes};
}

void DelayLine::pop() noexcept {
  if (size_ == 0) return;
  free_[free_count_++] = heap_[0];
  --size_;
  if (size_ > 0) {
    heap_[0] = heap_[size_];
    sift_down(0);
  }
}

bool DelayLine::before(std::uint32_t a, std::uint32_t b) const noexcept {
  const Slot& x = slots_[a];
  const Slot& y = slots_[b];
  return x.deliver_ns != y.deliver_ns ? x.deliver_ns < y.deliver_ns : x.seq < y.seq;
}

void DelayLine::sift_up(std::size_t i) noexcept {
  while (i > 0) {
    const std::size_t parent = (i - 1) / 2;
    if (!before(heap_[i], heap_[parent])) break;
    std::swap(heap_[i], heap_[parent]);
    i = parent;
  }
}

void DelayLine::sift_down(std::size_t i) noexcept {
  for (;;) {
    const std::size_t l = 2 * i + 1;
    const std::size_t r = l + 1;
    std::size_t best = i;
    if (l < size_ && before(heap_[l], heap_[best])) best = l;
    if (r < size_ && before(heap_[r], heap_[best])) best = r;
    if (best == i) return;
    std::swap(heap_[i], heap_[best]);
    i = best;
  }
}

}  // namespace foresight::linkemu
