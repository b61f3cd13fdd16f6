#include "foresight/sim/sim_ft_sensor.hpp"

#include "foresight/hw/ft_sensor.hpp"

namespace foresight::sim {

SimFtSensor::SimFtSensor(const SimFtParams& p)
    : SimNode(p.node_id, hw::canopen::kProfileMeasuring, "Foresight SimFT six-axis wrist sensor"), p_(p) {}

void SimFtSensor::set_true_wrench(const Wrench& w) {
  std::lock_guard lock(mu_);
  wrench_ = w;
}
void SimFtSensor::set_wrench_source(std::function<Wrench()> source) {
  std::lock_guard lock(mu_);
  source_ = std::move(source);
}
void SimFtSensor::set_offset(const Wrench& o) {
  std::lock_guard lock(mu_);
  offset_ = o;
}
void SimFtSensor::inject_sensor_fault(bool on) {
  std::lock_guard lock(mu_);
  sensor_fault_ = on;
}
std::uint64_t SimFtSensor::samples_sent() const {
  std::lock_guard lock(mu_);
  return samples_;
}

void SimFtSensor::reset_application() { sequence_ = 0; }

void SimFtSensor::on_sync(Clock::time_point, FrameSink& out) {
  const Wrench truth = source_ ? source_() : wrench_;
  Wrench measured;
  for (std::size_t i = 0; i < 6; ++i) measured[i] = truth[i] + offset_[i];
  hw::ft_frame::RawSample s =
      hw::ft_frame::quantize(measured, p_.force_counts_per_n, p_.torque_counts_per_nm, sequence_++);
  if (sensor_fault_) s.status |= hw::ft_frame::kStatusSensorFault;
  can_frame a{}, b{};
  hw::ft_frame::encode(s, node_id_, a, b);
  out.send(a);
  out.send(b);
  ++samples_;
}

}  // namespace foresight::sim
