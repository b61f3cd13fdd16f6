// The lock-free SPSC ring: exact capacity, FIFO order across wrap-around, one
// producer and one consumer thread moving 200,000 values in order, and no
// heap allocation in try_push / try_pop (its own binary: it counts
// allocations, foresight/test/allocation_counter.hpp).

#include "foresight/common/spsc_ring.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>

#include "foresight/test/allocation_counter.hpp"

namespace foresight {
namespace {

long allocations_in(const std::function<void()>& work) {
  test::AllocationCounter counter;
  work();
  return counter.count();
}


struct Item {
  std::uint64_t seq;
  double payload[4];
};

TEST(SpscRing, HoldsExactlyCapacityInFifoOrderAcrossWrapAround) {
  SpscRing<Item> ring(5);
  EXPECT_EQ(ring.capacity(), 5u);
  Item out{};
  EXPECT_FALSE(ring.try_pop(out));
  std::uint64_t next_in = 0, next_out = 0;
  for (int round = 0; round < 7; ++round) {  // 7 x (fill 5, drain 3): wraps the 5 slots several times
    while (ring.try_push(Item{next_in, {}})) ++next_in;
    EXPECT_EQ(ring.size(), 5u);
    for (int k = 0; k < 3; ++k) {
      ASSERT_TRUE(ring.try_pop(out));
      EXPECT_EQ(out.seq, next_out++);
    }
  }
  while (ring.try_pop(out)) EXPECT_EQ(out.seq, next_out++);
  EXPECT_EQ(next_out, next_in);
  EXPECT_EQ(ring.size(), 0u);
  EXPECT_TRUE(ring.empty());
}

TEST(SpscRing, ZeroCapacityRefused) { EXPECT_THROW(SpscRing<Item>(0), std::invalid_argument); }

TEST(SpscRing, PushAndPopDoNotAllocate) {
  SpscRing<Item> ring(16);
  Item out{};
  EXPECT_EQ(allocations_in([&] {
              for (std::uint64_t i = 0; i < 10'000; ++i) {
                (void)ring.try_push(Item{i, {}});
                if (i % 3 == 0) (void)ring.try_pop(out);
              }
            }),
            0);
}

TEST(SpscRing, TwoThreadsTransferEverythingInOrder) {
  constexpr std::uint64_t kCount = 200'000;
  SpscRing<Item> ring(64);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  std::atomic<bool> producer_timed_out{false};
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kCount; ++i) {
      while (!ring.try_push(Item{i, {double(i), 0, 0, 0}})) {
        if (std::chrono::steady_clock::now() > deadline) {
          producer_timed_out = true;
          return;
        }
        std::this_thread::yield();
      }
    }
  });
  std::uint64_t expected = 0;
  bool in_order = true;
  Item out{};
  while (expected < kCount && std::chrono::steady_clock::now() < deadline) {
    if (ring.try_pop(out)) {
      in_order = in_order && out.seq == expected && out.payload[0] == double(expected);
      ++expected;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  EXPECT_FALSE(producer_timed_out.load());
  EXPECT_EQ(expected, kCount);
  EXPECT_TRUE(in_order);
}

}  // namespace
}  // namespace foresight
