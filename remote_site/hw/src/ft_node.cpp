#include "ft_node.hpp"

namespace foresight::hw {

FtNode::FtNode(const FtConfig& c)
    : CanNode(static_cast<std::size_t>(c.bus_index), c.node_id, -1),
      cfg(c),
      decoder(c.force_counts_per_n, c.torque_counts_per_nm) {}

CanNode::Rx FtNode::on_frame(Kind kind, const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept {
  switch (kind) {
    case Kind::FtForce:
    case Kind::FtTorque: return on_sample_frame(kind, f, events);
    case Kind::FtEmcy: return on_emcy(f, events);
    case Kind::FtHeartbeat: return on_heartbeat(f, ctx, events);
    default: return Rx::Taken;  // not routed to the sensor
  }
}

CanNode::Rx FtNode::on_sample_frame(Kind kind, const can_frame& f, EventQueue& events) noexcept {
  const FtDecoder::Result res = kind == Kind::FtForce ? decoder.on_force_frame(f) : decoder.on_torque_frame(f);
  if (res == FtDecoder::Result::Malformed) return Rx::Malformed;
  if (res == FtDecoder::Result::Mismatch)
    events.push(event(HwFault::FtFrameMismatch, f.can_id & CAN_SFF_MASK, f.data[7]));
  if (res == FtDecoder::Result::Sample) {
    reading = decoder.latest();
    const std::uint8_t sat = reading.saturated_mask;
    if (sat & ~saturated_reported_) events.push(event(HwFault::FtSaturated, sat, 0));
    saturated_reported_ = sat;
    if (reading.sensor_fault && !fault_reported_) events.push(event(HwFault::FtSensorFault, 0, 0));
    fault_reported_ = reading.sensor_fault;
  }
  return Rx::Taken;
}

HwEvent FtNode::supervise(Clock::time_point now, std::chrono::nanoseconds hb_timeout, bool sync_sent,
                          bool configured, int miss_limit, EventQueue& events, FtReading& out) noexcept {
  if (sync_sent) count_missed(reading.fresh, miss_limit, HwFault::FtMissing, events);
  check_heartbeat(now, hb_timeout, configured, events);
  out = reading;
  out.tare_in_progress = decoder.tare_in_progress();
  if (!heartbeat_lost && !miss_reported && !reading.sensor_fault && !reading.saturated_mask) return {};
  const HwFault why = heartbeat_lost        ? HwFault::HeartbeatLost
                      : miss_reported       ? HwFault::FtMissing
                      : reading.sensor_fault ? HwFault::FtSensorFault
                                             : HwFault::FtSaturated;
  return event(why, reading.saturated_mask, 0);
}

}  // namespace foresight::hw
