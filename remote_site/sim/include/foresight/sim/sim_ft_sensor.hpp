#pragma once
// The simulated wrist F/T sensor: a CANopen node (profile 404) that answers
// every SYNC, while operational, with frames A and B (see hw/ft_sensor.hpp)
// encoding the true wrench plus a sensor offset, quantized and clipped with
// the configured scales.
//
// The wrench input: set_true_wrench() (thread-safe; the latest value is used
// at the next SYNC), or set_wrench_source() (a callback run on the simulator
// thread at every SYNC, for a contact model that computes the wrench from the
// simulated arm state). Wrench in the sensor frame `ft`: Fx Fy Fz [N], Tx Ty Tz [N*m].

#include <array>
#include <functional>

#include "foresight/sim/sim_node.hpp"

namespace foresight::sim {

struct SimFtParams {
  std::uint8_t node_id = 32;
  double force_counts_per_n = 50.0;
  double torque_counts_per_nm = 1000.0;
};

class SimFtSensor final : public SimNode {
 public:
  using Wrench = std::array<double, 6>;
  explicit SimFtSensor(const SimFtParams& p);

  /// Thread-safe: the wrench the sensor measures from the next SYNC on.
  void set_true_wrench(const Wrench& wrench_ft);
  /// Callback evaluated at each SYNC on the simulator thread (replaces the
  /// value from set_true_wrench while set; pass {} to clear). It must not
  /// call back into this sensor.
  void set_wrench_source(std::function<Wrench()> source);
  /// Raw zero offset of the gauges (what tare removes).
  void set_offset(const Wrench& offset_ft);
  /// Report a sensor fault (status bit 6) in every sample while on.
  void inject_sensor_fault(bool on);
  std::uint64_t samples_sent() const;

 protected:
  void reset_application() override;
  void on_sync(Clock::time_point now, FrameSink& out) override;

 private:
  SimFtParams p_;
  Wrench wrench_{};
  Wrench offset_{};
  std::function<Wrench()> source_;
  bool sensor_fault_ = false;
  std::uint8_t sequence_ = 0;
  std::uint64_t samples_ = 0;
};

}  // namespace foresight::sim
