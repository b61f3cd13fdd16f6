#include "cia402_drive.hpp"

#include <cmath>

namespace foresight::hw {

using namespace canopen;

Cia402Drive::Cia402Drive(const DriveConfig& c, std::size_t joint_index)
    : CanNode(static_cast<std::size_t>(c.bus_index), c.node_id, static_cast<std::int8_t>(joint_index)),
      cfg(c),
      name(c.joint),
      fe_counts(static_cast<std::int64_t>(std::lround(std::abs(c.following_error_limit_rad * c.counts_per_rad())))) {}

CanNode::Rx Cia402Drive::on_frame(Kind kind, const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept {
  switch (kind) {
    case Kind::DriveTpdo: return on_tpdo(f, ctx, events);
    case Kind::DriveVelocity: return on_velocity(f, ctx);
    case Kind::DriveEmcy: return on_emcy(f, events);
    case Kind::DriveHeartbeat: return on_heartbeat(f, ctx, events);
    default: return Rx::Taken;  // not routed to a drive
  }
}

CanNode::Rx Cia402Drive::on_tpdo(const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept {
  if (f.can_dlc != 8) return Rx::Malformed;
  // Read before the echo of the last SYNC we sent: it answers an earlier
  // SYNC (late, or that SYNC was lost). Not taken as fresh.
  if (ctx.stale) return Rx::Stale;
  const PowerState before = st.state;
  st.statusword = get_u16(f.data);
  st.position_counts = static_cast<std::int32_t>(get_u32(f.data + 2));
  const auto torque_pm = static_cast<std::int16_t>(get_u16(f.data + 6));
  st.position_rad = cfg.to_rad(st.position_counts);
  st.torque_nm = torque_pm * 1e-3 * info.rated_torque_nm * cfg.gear_ratio * cfg.direction;
  st.state = decode_statusword(st.statusword);
  st.fresh = true;
  st.state_known = true;
  have_actual = true;
  if ((st.state == PowerState::Fault || st.state == PowerState::FaultReactionActive) &&
      before != PowerState::Fault && before != PowerState::FaultReactionActive)
    events.push(event(HwFault::DriveFault, st.statusword, last_emcy));
  if (st.state == PowerState::QuickStopActive && before == PowerState::OperationEnabled &&
      !ctx.quick_stop->load(std::memory_order_relaxed))
    events.push(event(HwFault::QuickStopActive, st.statusword, 0));
  return Rx::Taken;
}

CanNode::Rx Cia402Drive::on_velocity(const can_frame& f, const RxContext& ctx) noexcept {
  // TPDO2: velocity actual, on every velocity_tpdo_every-th SYNC
  if (f.can_dlc != 4) return Rx::Malformed;
  if (ctx.stale) return Rx::Stale;  // answers an earlier SYNC: not taken
  st.velocity_counts_s = static_cast<std::int32_t>(get_u32(f.data));
  st.velocity_rad_s = st.velocity_counts_s / cfg.counts_per_rad();
  st.velocity_cycle = ctx.cycle;
  return Rx::Taken;
}

void Cia402Drive::take_target(double target_rad, bool enabled, EventQueue& events) noexcept {
  std::int32_t counts = 0;
  if (!cfg.to_counts(target_rad, counts)) {
    events.push(event(HwFault::InvalidTarget, 0, 0));
  } else if (const std::int64_t step = static_cast<std::int64_t>(counts) - target_counts;
             enabled && (step > fe_counts || -step > fe_counts)) {
    // Refused here, before the drive: it would fault on its following error.
    events.push(event(HwFault::InvalidTarget, static_cast<std::uint32_t>(step < 0 ? -step : step), 1));
  } else {
    target_counts = counts;
  }
}

void Cia402Drive::apply_stops(bool quick_stop, bool power_off) noexcept {
  if (quick_stop) controlword = controlword::kQuickStop;
  if (power_off) controlword = controlword::kDisableVoltage;  // category 0 wins over everything
}

can_frame Cia402Drive::rpdo(std::uint16_t cw) const noexcept {
  can_frame f{};
  f.can_id = kRpdo1Base + node;
  f.can_dlc = 6;
  put_u16(f.data, cw);
  put_u32(f.data + 2, static_cast<std::uint32_t>(target_counts));
  return f;
}

HwEvent Cia402Drive::supervise(Clock::time_point now, std::chrono::nanoseconds hb_timeout, bool sync_sent,
                               bool configured, int miss_limit, EventQueue& events) noexcept {
  if (sync_sent) count_missed(st.fresh, miss_limit, HwFault::TpdoMissing, events);
  check_heartbeat(now, hb_timeout, configured, events);
  if (heartbeat_lost || miss_reported) st.state_known = false;  // a TPDO makes it known again
  if (!heartbeat_lost && !miss_reported && st.state != PowerState::Fault &&
      st.state != PowerState::FaultReactionActive)
    return {};
  const HwFault why = heartbeat_lost ? HwFault::HeartbeatLost
                      : miss_reported ? HwFault::TpdoMissing
                                      : HwFault::DriveFault;
  return event(why, st.statusword, 0);
}

void Cia402Drive::feedback(JointState& out) const noexcept {
  out = st;
  out.nmt = nmt;
  out.heartbeat_lost = heartbeat_lost;
  out.last_emcy = last_emcy;
}

void Cia402Drive::restart(Clock::time_point now) noexcept {
  start_monitoring(now);
  missed = 0;
  miss_reported = false;
  controlword = controlword::kDisableVoltage;
  have_actual = false;
  st.state_known = false;
}

void Cia402Drive::begin_power_change() noexcept {
  have_actual = false;  // decide on states answering this change's SYNCs only
  run_seen = false;
  state_cycles = 0;
  reset_sent = false;
  left_fault = false;
}

void Cia402Drive::step_to_enabled() noexcept {
  if (!have_actual) return;  // keep the last controlword until the drive reports
  if (st.state != PowerState::OperationEnabled) target_counts = st.position_counts;  // hold
  switch (st.state) {
    case PowerState::Fault:
      // One fault reset per change: a rising edge of bit 7 (from a
      // controlword without it), then bit 7 held while the TPDOs still say
      // Fault, so no second edge. A drive that faults again stays in Fault.
      if (!reset_sent) {
        if (controlword & controlword::kFaultReset) {
          controlword = controlword::kDisableVoltage;
        } else {
          controlword = controlword::kFaultReset;
          reset_sent = true;
        }
      }
      break;
    case PowerState::FaultReactionActive:
    case PowerState::NotReadyToSwitchOn:
    case PowerState::QuickStopActive: controlword = controlword::kDisableVoltage; break;
    case PowerState::SwitchOnDisabled: controlword = controlword::kShutdown; break;
    case PowerState::ReadyToSwitchOn: controlword = controlword::kSwitchOn; break;
    case PowerState::SwitchedOn:
    case PowerState::OperationEnabled: controlword = controlword::kEnableOperation; break;
  }
}

void Cia402Drive::step_to_disabled() noexcept {
  controlword = controlword::kDisableVoltage;
  if (have_actual) target_counts = st.position_counts;
}

void Cia402Drive::note_power_state(EventQueue& events) noexcept {
  if (!have_actual) {
    ++state_cycles;
    return;
  }
  if (run_seen && st.state == run_state) {
    ++state_cycles;
    return;
  }
  events.push(event(HwFault::PowerStateChanged, static_cast<std::uint32_t>(st.state),
                    run_seen ? static_cast<std::uint32_t>(run_state) : kUnknownState));
  run_seen = true;
  run_state = st.state;
  state_cycles = 0;
  if (reset_sent && st.state != PowerState::Fault && st.state != PowerState::FaultReactionActive) left_fault = true;
}

}  // namespace foresight::hw
