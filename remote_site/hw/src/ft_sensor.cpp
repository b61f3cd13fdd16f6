#include "foresight/hw/ft_sensor.hpp"

#include <cmath>

#include "foresight/hw/can_bus.hpp"

namespace foresight::hw {

namespace ft_frame {

void encode(const RawSample& s, std::uint8_t node_id, can_frame& a, can_frame& b) noexcept {
  a = can_frame{};
  b = can_frame{};
  a.can_id = kForceBase + node_id;
  b.can_id = kTorqueBase + node_id;
  a.can_dlc = b.can_dlc = 8;
  for (int i = 0; i < 3; ++i) {
    put_u16(a.data + 2 * i, static_cast<std::uint16_t>(s.counts[static_cast<std::size_t>(i)]));
    put_u16(b.data + 2 * i, static_cast<std::uint16_t>(s.counts[static_cast<std::size_t>(i + 3)]));
  }
  a.data[6] = b.data[6] = s.status;
  a.data[7] = b.data[7] = s.sequence;
}

RawSample quantize(const std::array<double, 6>& w, double force_counts_per_n, double torque_counts_per_nm,
                   std::uint8_t sequence) noexcept {
  RawSample s;
  s.sequence = sequence;
  for (std::size_t i = 0; i < 6; ++i) {
    const double c = std::round(w[i] * (i < 3 ? force_counts_per_n : torque_counts_per_nm));
    if (!(c < kFullScale)) {  // also catches NaN
      s.counts[i] = kFullScale;
      s.status |= static_cast<std::uint8_t>(1u << i);
    } else if (c <= -kFullScale) {
      s.counts[i] = -kFullScale;
      s.status |= static_cast<std::uint8_t>(1u << i);
    } else {
      s.counts[i] = static_cast<std::int16_t>(c);
    }
  }
  return s;
}

}  // namespace ft_frame

FtDecoder::Result FtDecoder::on_force_frame(const can_frame& f) noexcept {
  if (f.can_dlc != 8) return Result::Malformed;
  for (std::size_t i = 0; i < 3; ++i) a_.counts[i] = static_cast<std::int16_t>(get_u16(f.data + 2 * i));
  a_.status = f.data[6];
  a_.sequence = f.data[7];
  have_a_ = true;
  return Result::Incomplete;
}

FtDecoder::Result FtDecoder::on_torque_frame(const can_frame& f) noexcept {
  if (f.can_dlc != 8) return Result::Malformed;
  if (!have_a_ || f.data[7] != a_.sequence) {
    have_a_ = false;
    return Result::Mismatch;
  }
  have_a_ = false;
  std::array<std::int16_t, 6> counts = a_.counts;
  for (std::size_t i = 0; i < 3; ++i) counts[i + 3] = static_cast<std::int16_t>(get_u16(f.data + 2 * i));
  const std::uint8_t status = static_cast<std::uint8_t>(a_.status | f.data[6]);
  FtReading r;
  r.sequence = a_.sequence;
  r.sensor_fault = (status & ft_frame::kStatusSensorFault) != 0;
  r.saturated_mask = status & 0x3F;
  for (std::size_t i = 0; i < 6; ++i) {
    if (counts[i] >= ft_frame::kFullScale || counts[i] <= -ft_frame::kFullScale)
      r.saturated_mask |= static_cast<std::uint8_t>(1u << i);
    r.raw_ft[i] = counts[i] / (i < 3 ? force_scale_ : torque_scale_);
  }
  if (tare_remaining_ > 0) {
    for (std::size_t i = 0; i < 6; ++i) tare_sum_[i] += r.raw_ft[i];
    if (--tare_remaining_ == 0)
      for (std::size_t i = 0; i < 6; ++i) bias_[i] = tare_sum_[i] / tare_total_;
  }
  for (std::size_t i = 0; i < 6; ++i) r.wrench_ft[i] = r.raw_ft[i] - bias_[i];
  r.tare_in_progress = tare_remaining_ > 0;
  r.fresh = true;
  latest_ = r;
  return Result::Sample;
}

void FtDecoder::request_tare(int samples) noexcept {
  if (samples < 1) samples = 1;
  tare_sum_ = {};
  tare_total_ = samples;
  tare_remaining_ = samples;
}

}  // namespace foresight::hw
