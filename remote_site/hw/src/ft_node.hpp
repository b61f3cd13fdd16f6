#pragma once
// The wrist force/torque sensor node as the master sees it: its frames A and
// B go to the decoder (ft_sensor.hpp: scaling, tare, saturation), its EMCY
// and heartbeat to CanNode, and the cycle's supervision reports a missing
// sample, saturation and the sensor's fault bit. Internal to foresight_hw.

#include <linux/can.h>

#include <chrono>
#include <cstdint>

#include "can_node.hpp"
#include "foresight/hw/drive_system.hpp"
#include "foresight/hw/ft_sensor.hpp"
#include "foresight/hw/remote_config.hpp"

namespace foresight::hw {

class FtNode : public CanNode {
 public:
  /// Set-up: the sensor of `cfg` (validated config: bus_index set).
  explicit FtNode(const FtConfig& cfg);

  // ---- real-time ----------------------------------------------------------------
  /// A frame the router gave the sensor (FtForce, FtTorque, FtEmcy, FtHeartbeat).
  Rx on_frame(Kind kind, const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept;
  /// After the cycle's frames: sample (when the bus sent a SYNC) and heartbeat
  /// timeouts as events; the reading into `out`. Returns the persisting fault
  /// (fault None: none).
  HwEvent supervise(Clock::time_point now, std::chrono::nanoseconds hb_timeout, bool sync_sent, bool configured,
                    int miss_limit, EventQueue& events, FtReading& out) noexcept;

  FtConfig cfg;
  FtDecoder decoder;
  FtReading reading;  ///< the last sample; fresh when it arrived this cycle

 private:
  Rx on_sample_frame(Kind kind, const can_frame& f, EventQueue& events) noexcept;
  std::uint8_t saturated_reported_ = 0;
  bool fault_reported_ = false;
};

}  // namespace foresight::hw
