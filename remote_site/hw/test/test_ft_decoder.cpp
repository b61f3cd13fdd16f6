#include <gtest/gtest.h>

#include "foresight/hw/ft_sensor.hpp"

using namespace foresight::hw;

namespace {
void feed(FtDecoder& d, const std::array<double, 6>& w, std::uint8_t seq, double fs = 100.0, double ts = 1000.0) {
  can_frame a{}, b{};
  ft_frame::encode(ft_frame::quantize(w, fs, ts, seq), 32, a, b);
  ASSERT_EQ(d.on_force_frame(a), FtDecoder::Result::Incomplete);
  ASSERT_EQ(d.on_torque_frame(b), FtDecoder::Result::Sample);
}
}  // namespace

TEST(FtDecoder, ScalesCountsToNewtonsAndNewtonMetres) {
  FtDecoder d(100.0, 1000.0);
  feed(d, {12.34, -5.0, 100.0, 0.5, -1.25, 3.001}, 7);
  const FtReading& r = d.latest();
  EXPECT_TRUE(r.fresh);
  EXPECT_EQ(r.sequence, 7);
  const double expect[6] = {12.34, -5.0, 100.0, 0.5, -1.25, 3.001};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(r.wrench_ft[static_cast<std::size_t>(i)], expect[i], 0.5 / (i < 3 ? 100.0 : 1000.0)) << i;
  EXPECT_EQ(r.saturated_mask, 0);
}

TEST(FtDecoder, SaturationIsReportedPerChannel) {
  FtDecoder d(100.0, 1000.0);
  feed(d, {400.0, 0.0, -500.0, 0.0, 40.0, 0.0}, 1);  // +-327 N, +-32.7 N*m full scale
  EXPECT_EQ(d.latest().saturated_mask, 0b010101);
  EXPECT_NEAR(d.latest().wrench_ft[0], 327.67, 1e-9);
}

TEST(FtDecoder, TareAveragesTheNextSamples) {
  FtDecoder d(100.0, 1000.0);
  d.request_tare(4);
  EXPECT_TRUE(d.tare_in_progress());
  const std::array<double, 6> offsets[4] = {{1.0, 2, 3, 0.1, 0.2, 0.3}, {1.2, 2, 3, 0.1, 0.2, 0.3},
                                            {0.8, 2, 3, 0.1, 0.2, 0.3}, {1.0, 2, 3, 0.1, 0.2, 0.3}};
  for (std::uint8_t i = 0; i < 4; ++i) feed(d, offsets[i], i);
  EXPECT_FALSE(d.tare_in_progress());
  EXPECT_NEAR(d.bias()[0], 1.0, 1e-9);
  EXPECT_NEAR(d.bias()[5], 0.3, 1e-9);
  feed(d, {11.0, 2.0, 3.0, 0.1, 0.2, 0.8}, 4);
  EXPECT_NEAR(d.latest().wrench_ft[0], 10.0, 1e-9);
  EXPECT_NEAR(d.latest().wrench_ft[1], 0.0, 1e-9);
  EXPECT_NEAR(d.latest().wrench_ft[5], 0.5, 1e-9);
  EXPECT_NEAR(d.latest().raw_ft[0], 11.0, 1e-9);
}

TEST(FtDecoder, MismatchedAndMalformedFramesAreNamed) {
  FtDecoder d(100.0, 1000.0);
  can_frame a{}, b{};
  ft_frame::encode(ft_frame::quantize({1, 2, 3, 4, 5, 6}, 100, 1000, 5), 32, a, b);
  b.data[7] = 6;  // torque frame of another sample
  EXPECT_EQ(d.on_force_frame(a), FtDecoder::Result::Incomplete);
  EXPECT_EQ(d.on_torque_frame(b), FtDecoder::Result::Mismatch);
  EXPECT_EQ(d.on_torque_frame(b), FtDecoder::Result::Mismatch);  // no force frame pending
  a.can_dlc = 6;
  EXPECT_EQ(d.on_force_frame(a), FtDecoder::Result::Malformed);
  EXPECT_FALSE(d.latest().fresh);
}
