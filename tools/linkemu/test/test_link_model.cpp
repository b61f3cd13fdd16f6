// The link emulator's timing model and delay line, against hand-computed
// answers (no namespaces needed).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "foresight/linkemu/dds_config.hpp"
#include "foresight/linkemu/delay_line.hpp"
#include "foresight/linkemu/link_model.hpp"
#include "foresight/linkemu/netns.hpp"
// Counts heap allocations, to show the per-packet path does not allocate (the
// shared counter: it also counts under ASan, where a local operator new/delete
// replacement mismatched the sanitizer's nothrow new, which std::stable_sort uses).
#include "foresight/test/allocation_counter.hpp"

namespace le = foresight::linkemu;

namespace {

constexpr std::int64_t kMs = 1'000'000;

TEST(LinkModel, DelayOnlyDeliversAtArrivalPlusDelay) {
  le::LinkParams p;
  p.delay_ns = 200 * kMs;
  le::DirectionModel m(p, 1);
  for (std::int64_t t : {0LL, 5LL, 1'000'000LL, 7'000'000'000LL}) {
    const auto d = m.admit(t, 100);
    ASSERT_EQ(d.verdict, le::Verdict::kDeliver);
    EXPECT_EQ(d.deliver_ns, t + 200 * kMs);
    EXPECT_FALSE(d.reordered);
  }
}

TEST(LinkModel, LossRateWithinStatisticalBounds) {
  le::LinkParams p;
  p.loss = 0.1;
  le::DirectionModel m(p, 42);
  const int n = 100000;
  int lost = 0;
  for (int i = 0; i < n; ++i) lost += m.admit(i * 1000, 100).verdict == le::Verdict::kDropLoss ? 1 : 0;
  const double sd = std::sqrt(n * 0.1 * 0.9);  // ~95
  EXPECT_NEAR(lost, 0.1 * n, 5 * sd);
}

TEST(LinkModel, JitterSpreadsDelayButKeepsOrder) {
  le::LinkParams p;
  p.delay_ns = 100 * kMs;
  p.jitter_ns = 20 * kMs;
  le::DirectionModel m(p, 7);
  std::int64_t last = 0;
  std::int64_t min_offset = INT64_MAX;
  std::int64_t max_offset = INT64_MIN;
  // Sparse packets (100 ms apart): the order clamp never bites, so each
  // offset is the raw uniform jitter.
  for (int i = 0; i < 2000; ++i) {
    const std::int64_t t = i * 100 * kMs;
    const auto d = m.admit(t, 100);
    ASSERT_GE(d.deliver_ns, last);
    last = d.deliver_ns;
    min_offset = std::min(min_offset, d.deliver_ns - t - p.delay_ns);
    max_offset = std::max(max_offset, d.deliver_ns - t - p.delay_ns);
  }
  EXPECT_GE(min_offset, -20 * kMs);
  EXPECT_LE(max_offset, 20 * kMs);
  EXPECT_LT(min_offset, -19 * kMs);
  EXPECT_GT(max_offset, 19 * kMs);
  // Dense packets (0.1 ms apart, jitter 20 ms): still never reordered.
  le::DirectionModel dense(p, 8);
  last = 0;
  for (int i = 0; i < 5000; ++i) {
    const auto d = dense.admit(i * 100'000, 100);
    ASSERT_GE(d.deliver_ns, last) << "packet " << i;
    last = d.deliver_ns;
  }
}

TEST(LinkModel, TokenBucketBurstRateAndQueueLimit) {
  le::LinkParams p;
  p.delay_ns = 10 * kMs;
  p.rate_bit_s = 8e6;  // 1 byte per microsecond: a 1000 B packet takes 1 ms
  p.burst_bytes = 3000;
  p.queue_bytes = 10000;
  le::DirectionModel m(p, 1);
  // 20 packets of 1000 B at once: 3 leave at once (the burst), the next 10
  // leave 1 ms apart (10000 B backlog), the rest are tail-dropped.
  for (int k = 1; k <= 20; ++k) {
    const auto d = m.admit(0, 1000);
    if (k <= 13) {
      ASSERT_EQ(d.verdict, le::Verdict::kDeliver) << "packet " << k;
      const std::int64_t depart = k <= 3 ? 0 : (k - 3) * kMs;
      EXPECT_EQ(d.deliver_ns, depart + p.delay_ns) << "packet " << k;
    } else {
      EXPECT_EQ(d.verdict, le::Verdict::kDropQueue) << "packet " << k;
    }
  }
  // Offered at twice the rate for 1 s: what leaves is the rate.
  le::DirectionModel steady(p, 1);
  std::int64_t delivered_bytes = 0;
  std::int64_t last_deliver = 0;
  for (int i = 0; i < 2000; ++i) {
    const auto d = steady.admit(i * 500'000, 1000);  // 2000 B/ms offered, 1000 B/ms allowed
    if (d.verdict != le::Verdict::kDeliver) continue;
    delivered_bytes += 1000;
    last_deliver = d.deliver_ns;
  }
  const double seconds = static_cast<double>(last_deliver - p.delay_ns) * 1e-9;
  EXPECT_NEAR(delivered_bytes * 8.0 / seconds, 8e6, 8e6 * 0.02);
}

TEST(LinkModel, ReorderHoldsPacketsBackSoOthersPass) {
  le::LinkParams p;
  p.delay_ns = 50 * kMs;
  p.reorder = 0.25;
  p.reorder_gap_ns = 5 * kMs;
  le::DirectionModel m(p, 3);
  std::vector<std::pair<std::int64_t, int>> deliveries;  // (time, index)
  int reordered = 0;
  std::int64_t last_in_order = 0;
  for (int i = 0; i < 1000; ++i) {
    const auto d = m.admit(i * kMs, 100);
    if (d.reordered) {
      ++reordered;
      EXPECT_EQ(d.deliver_ns, i * kMs + p.delay_ns + p.reorder_gap_ns);
    } else {
      EXPECT_GE(d.deliver_ns, last_in_order);
      last_in_order = d.deliver_ns;
    }
    deliveries.emplace_back(d.deliver_ns, i);
  }
  EXPECT_NEAR(reordered, 250, 5 * std::sqrt(1000 * 0.25 * 0.75));
  std::stable_sort(deliveries.begin(), deliveries.end());
  int inversions = 0;
  for (std::size_t k = 1; k < deliveries.size(); ++k) inversions += deliveries[k].second < deliveries[k - 1].second;
  EXPECT_GT(inversions, 100);
}

TEST(LinkModel, BadParametersAreRejectedByName) {
  le::LinkParams p;
  p.loss = 1.5;
  try {
    le::validate(p);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "loss must be a probability in [0, 1]");
  }
  p = {};
  p.delay_ns = -1;
  EXPECT_THROW(le::DirectionModel(p, 1), std::invalid_argument);
  p = {};
  p.reorder = -0.1;
  try {
    le::validate(p);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "reorder must be a probability in [0, 1]");
  }
}

TEST(DelayLine, PopsInDeliveryOrderTiesInArrivalOrder) {
  le::DelayLine line(8, 16);
  const std::int64_t times[] = {50, 10, 30, 10, 20};
  for (int i = 0; i < 5; ++i) {
    auto slot = line.acquire();
    ASSERT_EQ(slot.size(), 16u);
    slot[0] = static_cast<std::uint8_t>(i);
    line.commit(1, times[i]);
  }
  std::vector<int> order;
  while (!line.empty()) {
    order.push_back(line.front()[0]);
    line.pop();
  }
  EXPECT_EQ(order, (std::vector<int>{1, 3, 4, 2, 0}));
}

TEST(DelayLine, FullLineRefusesAndFreesOnPop) {
  le::DelayLine line(2, 8);
  line.acquire();
  line.commit(8, 1);
  line.acquire();
  line.commit(8, 2);
  EXPECT_TRUE(line.acquire().empty());
  line.pop();
  EXPECT_EQ(line.acquire().size(), 8u);
  EXPECT_EQ(line.size(), 1u);
}

TEST(DelayLine, PerPacketPathDoesNotAllocate) {
  le::LinkParams p;
  p.delay_ns = 10 * kMs;
  p.jitter_ns = 2 * kMs;
  p.loss = 0.01;
  p.reorder = 0.01;
  p.rate_bit_s = 1e7;
  le::DirectionModel model(p, 5);
  le::DelayLine line(1024, 1500);
  foresight::test::AllocationCounter allocations;
  std::int64_t now = 0;
  for (int i = 0; i < 100000; ++i) {
    now += 200'000;
    while (!line.empty() && line.next_due_ns() <= now) line.pop();
    auto slot = line.acquire();
    if (slot.empty()) continue;
    const auto d = model.admit(now, 1000);
    if (d.verdict == le::Verdict::kDeliver) line.commit(1000, d.deliver_ns);
  }
  EXPECT_EQ(allocations.count(), 0);
}

TEST(Netns, OwnerPidFromName) {
  EXPECT_EQ(le::netns_name("fslemu", 4242, "ground"), "fslemu-4242-ground");
  EXPECT_EQ(le::netns_owner("fslemu-4242-ground", "fslemu"), 4242);
  EXPECT_EQ(le::netns_owner("fslemu-4242-remote", "fslemu"), 4242);
  EXPECT_FALSE(le::netns_owner("fslemu-x42-ground", "fslemu"));
  EXPECT_FALSE(le::netns_owner("other-4242-ground", "fslemu"));
  EXPECT_FALSE(le::netns_owner("fslemu-4242", "fslemu"));
  EXPECT_FALSE(le::netns_owner("fslemu_t-4242-ground", "fslemu"));
}

TEST(DdsConfig, UnicastPeerOnTheTunInterface) {
  const std::string xml = le::cyclone_config_xml("fsl0", "10.200.0.2");
  EXPECT_NE(xml.find("<NetworkInterface name=\"fsl0\"/>"), std::string::npos);
  EXPECT_NE(xml.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos);
  EXPECT_NE(xml.find("<Peer address=\"10.200.0.2\"/>"), std::string::npos);
  EXPECT_NE(xml.find("<SPDPInterval>2s</SPDPInterval>"), std::string::npos);
}

}  // namespace
