#pragma once
// The wrist force/torque sensor on the CAN bus: its frames, and the master's
// decoder (scaling, bias/tare, saturation). The sensor is a CANopen node
// (device profile 404 in 0x1000, heartbeat 0x1017, NMT) that, while
// operational, answers every SYNC with two frames of the same sample:
//
//   frame A  COB-ID 0x180 + node, DLC 8:  Fx Fy Fz  (int16 LE counts)  status  sequence
//   frame B  COB-ID 0x280 + node, DLC 8:  Tx Ty Tz  (int16 LE counts)  status  sequence
//
//   force_N   = counts / force_counts_per_n     (config ft_sensor.force_counts_per_n)
//   torque_Nm = counts / torque_counts_per_nm   (config ft_sensor.torque_counts_per_nm)
//   status    bit 0..5: channel Fx, Fy, Fz, Tx, Ty, Tz saturated (the reading is
//             clipped at +-32767 counts); bit 6: sensor fault (gauge/excitation)
//   sequence  8-bit sample counter, equal in A and B; A and B of different
//             sequences are never combined (FtFrameMismatch).
//
// The wrench is in the sensor frame `ft` (URDF link of the same name).
// Bias/tare is done by the master: the mean of the next N samples becomes the
// bias subtracted from every later reading (request_tare), or set explicitly.
//
// Real-time safety: every FtDecoder member except the constructor is noexcept
// and allocation-free.

#include <linux/can.h>

#include <array>
#include <cstdint>

namespace foresight::hw {

namespace ft_frame {
inline constexpr std::uint32_t kForceBase = 0x180;   // + node id
inline constexpr std::uint32_t kTorqueBase = 0x280;  // + node id
inline constexpr std::uint8_t kStatusSensorFault = 1u << 6;
inline constexpr std::int16_t kFullScale = 32767;

struct RawSample {
  std::array<std::int16_t, 6> counts{};  ///< Fx Fy Fz Tx Ty Tz
  std::uint8_t status = 0;
  std::uint8_t sequence = 0;
};
/// Encode a raw sample into frames A and B (sensor side).
void encode(const RawSample& s, std::uint8_t node_id, can_frame& a, can_frame& b) noexcept;
/// Quantize a wrench (N, N*m) with the scales, saturating at +-32767 and
/// setting the status bits of clipped channels.
RawSample quantize(const std::array<double, 6>& wrench, double force_counts_per_n,
                   double torque_counts_per_nm, std::uint8_t sequence) noexcept;
}  // namespace ft_frame

/// One F/T reading, SI units, sensor frame.
struct FtReading {
  std::array<double, 6> wrench_ft{};  ///< Fx Fy Fz [N], Tx Ty Tz [N*m], bias removed
  std::array<double, 6> raw_ft{};     ///< as measured, before bias removal
  std::uint8_t saturated_mask = 0;    ///< bit i: channel i clipped (value unknown beyond full scale)
  bool sensor_fault = false;
  bool fresh = false;                 ///< a complete new sample arrived this cycle
  bool tare_in_progress = false;
  std::uint8_t sequence = 0;
};

/// Decodes frames A/B into readings. Set-up: constructor. Everything else is
/// real-time safe.
class FtDecoder {
 public:
  enum class Result : std::uint8_t { Incomplete, Sample, Malformed, Mismatch };

  FtDecoder(double force_counts_per_n, double torque_counts_per_nm) noexcept
      : force_scale_(force_counts_per_n), torque_scale_(torque_counts_per_nm) {}

  /// Feed frame A or B. Sample when B completes a matching A; the new
  /// reading is then in latest().
  Result on_force_frame(const can_frame& f) noexcept;
  Result on_torque_frame(const can_frame& f) noexcept;

  const FtReading& latest() const noexcept { return latest_; }
  /// Average the next `samples` samples (>= 1) into the bias.
  void request_tare(int samples) noexcept;
  void set_bias(const std::array<double, 6>& bias) noexcept { bias_ = bias; }
  const std::array<double, 6>& bias() const noexcept { return bias_; }
  bool tare_in_progress() const noexcept { return tare_remaining_ > 0; }

 private:
  double force_scale_;
  double torque_scale_;
  bool have_a_ = false;
  ft_frame::RawSample a_{};
  FtReading latest_{};
  std::array<double, 6> bias_{};
  std::array<double, 6> tare_sum_{};
  int tare_remaining_ = 0;
  int tare_total_ = 0;
};

}  // namespace foresight::hw
