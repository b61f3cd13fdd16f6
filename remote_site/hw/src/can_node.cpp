#include "can_node.hpp"

namespace foresight::hw {

using namespace canopen;

CanNode::Rx CanNode::on_emcy(const can_frame& f, EventQueue& events) noexcept {
  if (f.can_dlc != 8) return Rx::Malformed;
  const std::uint16_t code = get_u16(f.data);
  // CiA 301: the error register (byte 2) has bit 0 set while any error is
  // present; an EMCY with a code and an empty register is a warning.
  const HwFault kind = code == 0 ? HwFault::EmergencyCleared
                       : f.data[2] == 0 ? HwFault::EmergencyWarning
                                        : HwFault::Emergency;
  if (kind != HwFault::EmergencyWarning) last_emcy = code;
  events.push(event(kind, code, f.data[2]));
  return Rx::Taken;
}

CanNode::Rx CanNode::on_heartbeat(const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept {
  if (f.can_dlc != 1) return Rx::Malformed;
  const auto state = static_cast<NmtState>(f.data[0] & 0x7F);
  last_hb = ctx.now;
  if (state == NmtState::BootUp) {
    booted = true;
    if (ctx.configured) {
      events.push(event(HwFault::NodeRebooted, 0, 0));
      unconfigured = true;
    }
    nmt = NmtState::PreOperational;
    return Rx::Taken;
  }
  if (ctx.configured && state != NmtState::Operational && nmt == NmtState::Operational) {
    events.push(event(HwFault::NodeNotOperational, static_cast<std::uint32_t>(state), 0));
    unconfigured = true;
  }
  nmt = state;
  return Rx::Taken;
}

void CanNode::count_missed(bool fresh, int limit, HwFault missing, EventQueue& events) noexcept {
  if (fresh) {
    missed = 0;
    miss_reported = false;
  } else if (++missed >= limit && !miss_reported) {
    miss_reported = true;
    events.push(event(missing, static_cast<std::uint32_t>(missed), 0));
  }
}

void CanNode::check_heartbeat(Clock::time_point now, std::chrono::nanoseconds timeout, bool configured,
                              EventQueue& events) noexcept {
  if (!configured || heartbeat_lost || now - last_hb <= timeout) return;
  heartbeat_lost = true;
  const auto silent_ms = std::chrono::duration_cast<std::chrono::milliseconds>(now - last_hb).count();
  events.push(event(HwFault::HeartbeatLost, static_cast<std::uint32_t>(silent_ms), 0));
}

}  // namespace foresight::hw
