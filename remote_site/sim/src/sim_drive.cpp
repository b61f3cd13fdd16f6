#include "foresight/sim/sim_drive.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "foresight/hw/can_bus.hpp"

namespace foresight::sim {

using namespace hw::canopen;

SimDrive::SimDrive(const SimDriveParams& p)
    : SimNode(p.node_id, 0x00020000u | kProfileDrive, "Foresight SimDrive CSP (" + p.name + ")"), p_(p) {
  x_ = p.initial_counts;
  demand_ = demand_prev_ = x_;
  std::lock_guard lock(mu_);
  reset_application();
}

PowerState SimDrive::power_state() const {
  std::lock_guard lock(mu_);
  return state_;
}
double SimDrive::position_counts() const {
  std::lock_guard lock(mu_);
  return x_;
}
double SimDrive::velocity_counts_s() const {
  std::lock_guard lock(mu_);
  return v_;
}
std::int32_t SimDrive::target_counts() const {
  std::lock_guard lock(mu_);
  return static_cast<std::int32_t>(get(od::kTargetPosition, 0));
}
std::uint16_t SimDrive::controlword() const {
  std::lock_guard lock(mu_);
  return static_cast<std::uint16_t>(get(od::kControlword, 0));
}
std::uint64_t SimDrive::sync_count() const {
  std::lock_guard lock(mu_);
  return syncs_;
}
std::uint32_t SimDrive::following_error_window() const {
  std::lock_guard lock(mu_);
  return get(od::kFollowingErrorWindow, 0);
}
DrivePowerRecord SimDrive::power_record() const {
  std::lock_guard lock(mu_);
  DrivePowerRecord r;
  r.state = state_;
  r.powered = power_enabled(state_);
  r.states_seen = states_seen_ | (1u << static_cast<unsigned>(state_));
  r.syncs = syncs_;
  r.power_off_sync = power_off_sync_;
  r.power_off_at = power_off_at_;
  return r;
}
void SimDrive::clear_power_record() {
  std::lock_guard lock(mu_);
  states_seen_ = 1u << static_cast<unsigned>(state_);
}
void SimDrive::inject_fault(std::uint16_t emcy_code) {
  std::lock_guard lock(mu_);
  injected_fault_ = true;
  injected_code_ = emcy_code;
}
void SimDrive::set_safe_torque_off(bool active) {
  std::lock_guard lock(mu_);
  sto_ = active;
}
void SimDrive::set_load_torque_nm(double t) {
  std::lock_guard lock(mu_);
  load_torque_nm_ = t;
}
void SimDrive::set_position_counts(double counts) {
  std::lock_guard lock(mu_);
  x_ = counts;
  v_ = 0.0;
}

void SimDrive::set_home_switch_counts(double counts) {
  std::lock_guard lock(mu_);
  home_switch_ = counts;
}

bool SimDrive::homing_attained() const {
  std::lock_guard lock(mu_);
  return homing_attained_;
}

void SimDrive::reset_application() {
  // Defaults differ from what the master needs (as on many real drives): the
  // master must map the PDOs and select the mode, or the frames are wrong.
  define(od::kCommCyclePeriod, 0, 4, true, 0);
  define(od::kConsumerHeartbeat, 0, 1, false, 1);
  define(od::kConsumerHeartbeat, 1, 4, true, 0);
  master_hb_armed_ = false;
  define(od::kRpdo1Comm, 1, 4, true, kRpdo1Base + node_id_);
  define(od::kRpdo1Comm, 2, 1, true, 255);
  define(od::kRpdo1Map, 0, 1, true, 1);
  define(od::kTpdo1Comm, 1, 4, true, kTpdo1Base + node_id_);
  define(od::kTpdo1Comm, 2, 1, true, 255);
  define(od::kTpdo1Map, 0, 1, true, 1);
  for (std::uint8_t s = 1; s <= 8; ++s) {
    define(od::kRpdo1Map, s, 4, true, s == 1 ? od::map_entry(od::kControlword, 0, 16) : 0);
    define(od::kTpdo1Map, s, 4, true, s == 1 ? od::map_entry(od::kStatusword, 0, 16) : 0);
  }
  define(od::kControlword, 0, 2, true, 0);
  define(od::kStatusword, 0, 2, false, 0);
  define(od::kModesOfOperation, 0, 1, true, 0);
  define(od::kModesDisplay, 0, 1, false, 0);
  define(od::kPositionActual, 0, 4, false, static_cast<std::uint32_t>(static_cast<std::int32_t>(std::lround(x_))));
  define(od::kFollowingErrorWindow, 0, 4, true, 0xFFFFFFFFu);  // disabled until set
  define(od::kRatedTorque, 0, 4, false, p_.rated_torque_mnm);
  define(od::kTorqueActual, 0, 2, false, 0);
  define(od::kTargetPosition, 0, 4, true, 0);
  define(od::kSoftwareLimits, 0, 1, false, 2);
  define(od::kSoftwareLimits, 1, 4, true, static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::min()));
  define(od::kSoftwareLimits, 2, 4, true, static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max()));
  define(od::kInterpolationPeriod, 1, 1, true, 1);
  define(od::kInterpolationPeriod, 2, 1, true, static_cast<std::uint8_t>(static_cast<std::int8_t>(-3)));
  define(od::kSyncCounterOverflow, 0, 1, true, 0);
  define(od::kIdentity, 0, 1, false, 4);
  define(od::kIdentity, 1, 4, false, p_.vendor_id);
  define(od::kIdentity, 2, 4, false, p_.product_code);
  define(od::kIdentity, 3, 4, false, p_.revision);
  define(od::kIdentity, 4, 4, false, 0x5100u + node_id_);
  define(od::kSupportedModes, 0, 4, false, (1u << 7) | (1u << 5));  // csp, homing
  define(od::kAbortConnection, 0, 2, true, 1);
  define(od::kQuickStopOption, 0, 2, true, 2);
  define(od::kFaultReaction, 0, 2, true, 0);
  define(0x6084, 0, 4, true, 2000000);                  // profile (slow-down) deceleration, counts/s^2
  define(od::kQuickStopDeceleration, 0, 4, true, 100000000);
  define(od::kFollowingErrorTimeout, 0, 2, true, 0);
  define(od::kMaxProfileVelocity, 0, 4, true, 0xFFFFFFFFu);
  define(od::kVelocityActual, 0, 4, false, 0);
  define(0x6098, 0, 1, true, 0);         // homing method (0: none)
  define(0x6099, 0, 1, false, 2);
  define(0x6099, 1, 4, true, 131072);    // speed during search for switch, counts/s
  define(0x6099, 2, 4, true, 13107);     // speed during search for zero
  define(0x609A, 0, 4, true, 1000000);   // homing acceleration, counts/s^2
  define(0x607C, 0, 4, true, 0);         // home offset
  homing_active_ = homing_attained_ = homing_slow_ = false;
  for (std::uint16_t i = 1; i < 4; ++i) {  // predefined connection set: PDOs 2-4 valid at boot
    define(static_cast<std::uint16_t>(od::kRpdo1Comm + i), 1, 4, true, kRpdo1Base + 0x100u * i + node_id_);
    define(static_cast<std::uint16_t>(od::kRpdo1Comm + i), 2, 1, true, 255);
    define(static_cast<std::uint16_t>(od::kTpdo1Comm + i), 1, 4, true, kTpdo1Base + 0x100u * i + node_id_);
    define(static_cast<std::uint16_t>(od::kTpdo1Comm + i), 2, 1, true, 1);  // on every SYNC: statusword
    define(static_cast<std::uint16_t>(od::kTpdo1Map + i), 0, 1, true, 1);
    for (std::uint8_t s = 1; s <= 8; ++s)
      define(static_cast<std::uint16_t>(od::kTpdo1Map + i), s, 4, true, s == 1 ? od::map_entry(od::kStatusword, 0, 16) : 0);
  }
  state_ = PowerState::NotReadyToSwitchOn;
  last_sync_ = Clock::time_point{};
  v_ = a_ = 0.0;
  demand_ = demand_prev_ = x_;
  prev_cw_ = 0;
  have_rpdo_ = false;
  following_error_ = internal_limit_ = false;
  fe_time_s_ = 0.0;
  update_statusword();
}

std::uint32_t SimDrive::check_mapping(std::uint16_t map_index, std::uint8_t count) const {
  if (count > 8) return static_cast<std::uint32_t>(SdoAbort::PdoTooLong);
  int bits = 0;
  for (std::uint8_t s = 1; s <= count; ++s) {
    const std::uint32_t m = get(map_index, s);
    const auto idx = static_cast<std::uint16_t>(m >> 16);
    const auto sub = static_cast<std::uint8_t>((m >> 8) & 0xFF);
    const int len = static_cast<int>(m & 0xFF);
    auto it = od_.find(key(idx, sub));
    if (it == od_.end() || it->second.size == 0 || it->second.size * 8 != len)
      return static_cast<std::uint32_t>(SdoAbort::CannotMap);
    bits += len;
  }
  return bits > 64 ? static_cast<std::uint32_t>(SdoAbort::PdoTooLong) : 0;
}

std::uint32_t SimDrive::check_sdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
  if (index == od::kRpdo1Map || (index >= od::kTpdo1Map && index <= od::kTpdo1Map + 3)) {
    const std::uint16_t comm =
        index == od::kRpdo1Map ? od::kRpdo1Comm : static_cast<std::uint16_t>(od::kTpdo1Comm + (index - od::kTpdo1Map));
    if (!(get(comm, 1) & od::kCobIdInvalid)) return static_cast<std::uint32_t>(SdoAbort::DeviceState);
    if (sub == 0) return check_mapping(index, static_cast<std::uint8_t>(value));
    if (get(index, 0) != 0) return static_cast<std::uint32_t>(SdoAbort::DeviceState);
    return 0;
  }
  const bool pdo_comm = (index >= od::kRpdo1Comm && index <= od::kRpdo1Comm + 3) ||
                        (index >= od::kTpdo1Comm && index <= od::kTpdo1Comm + 3);
  if (pdo_comm && sub == 1) {
    if ((value & 0x7FF) == 0 || (value & 0x3FFFF800u)) return static_cast<std::uint32_t>(SdoAbort::ValueRange);
    return 0;
  }
  if (index == od::kSyncCounterOverflow)
    return value == 0 || (value >= 2 && value <= 240) ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  if (index == od::kQuickStopOption) {
    const auto v = static_cast<std::int16_t>(value);
    return (v >= 0 && v <= 2) || v == 5 || v == 6 ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  }
  if (index == od::kFaultReaction) {
    const auto v = static_cast<std::int16_t>(value);
    return v >= 0 && v <= 2 ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  }
  if (index == od::kAbortConnection) {
    const auto v = static_cast<std::int16_t>(value);
    return v >= 0 && v <= 3 ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  }
  if (index == od::kInterpolationPeriod && sub == 2) {
    const auto e = static_cast<std::int8_t>(value);
    return e >= -6 && e <= 0 ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  }
  if ((index == od::kRpdo1Comm || (index >= od::kTpdo1Comm && index <= od::kTpdo1Comm + 3)) && sub == 2)
    return (value >= 1 && value <= 240) || value >= 254 ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  if (index == od::kModesOfOperation)
    return static_cast<std::int8_t>(value) == kModeCyclicSyncPosition || static_cast<std::int8_t>(value) == 6
               ? 0
               : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  if (index == 0x6098) {  // homing methods this drive has: home switch (17-30), current position (35, 37)
    const auto m = static_cast<std::int8_t>(value);
    return (m >= 17 && m <= 30) || m == 35 || m == 37 ? 0 : static_cast<std::uint32_t>(SdoAbort::ValueRange);
  }
  if ((index == 0x6099 || index == 0x609A) && value == 0) return static_cast<std::uint32_t>(SdoAbort::ValueTooLow);
  if (index == od::kCommCyclePeriod && (value < 100 || value > 100000))
    return static_cast<std::uint32_t>(SdoAbort::ValueRange);
  if (index == od::kFollowingErrorWindow && value == 0) return static_cast<std::uint32_t>(SdoAbort::ValueTooLow);
  return 0;
}

void SimDrive::on_sdo_written(std::uint16_t index, std::uint8_t) {
  if (index == od::kModesOfOperation) {
    set(od::kModesDisplay, 0, get(od::kModesOfOperation, 0));
    homing_active_ = homing_start_prev_ = false;  // attained stays until the next homing starts
  }
}

void SimDrive::step_homing(double dt) {
  const std::uint16_t cw = static_cast<std::uint16_t>(get(od::kControlword, 0));
  const bool start = (cw & 0x10) != 0;
  const bool edge = start && !homing_start_prev_;  // homing starts on the rising edge of bit 4
  homing_start_prev_ = start;
  if (state_ != PowerState::OperationEnabled || !start) {
    homing_active_ = false;  // bit 4 low or not enabled: halt (attained stays as it is)
    v_ = a_ = 0.0;
    demand_ = demand_prev_ = x_;
    return;
  }
  if (edge) {
    homing_active_ = true;
    homing_attained_ = homing_slow_ = false;
  }
  if (!homing_active_) return;
  const auto method = static_cast<std::int8_t>(get(0x6098, 0));
  const auto offset = static_cast<double>(static_cast<std::int32_t>(get(0x607C, 0)));
  bool at_home = method == 35 || method == 37;
  if (!at_home) {
    // To the switch at the switch-search speed, the last 1/100 rev at the zero-search speed.
    const double to_go = home_switch_ - x_;
    homing_slow_ = std::abs(to_go) < p_.counts_per_rev / 100.0;
    const double speed = static_cast<double>(get(0x6099, homing_slow_ ? 2 : 1));
    const double step = speed * dt;
    if (std::abs(to_go) <= step) {
      x_ = home_switch_;
      at_home = true;
    } else {
      x_ += to_go > 0 ? step : -step;
      v_ = to_go > 0 ? speed : -speed;
    }
  }
  if (at_home) {
    home_switch_ += offset - x_;  // the switch stays where it is; counts are redefined
    x_ = offset;
    v_ = a_ = 0.0;
    demand_ = demand_prev_ = x_;
    homing_active_ = false;
    homing_attained_ = true;
  }
}

void SimDrive::ramp(double dt, double decel) {
  const double dv = decel * dt;
  if (std::abs(ramp_v_) <= dv) ramp_v_ = 0.0;
  else ramp_v_ -= ramp_v_ > 0 ? dv : -dv;
  x_ += ramp_v_ * dt;
  v_ = ramp_v_;
  a_ = 0.0;
  demand_ = demand_prev_ = x_;
}

void SimDrive::quick_stop() {
  const auto option = static_cast<std::int16_t>(get(od::kQuickStopOption, 0));
  if (option == 0) {  // disable drive function: the motor coasts, power off
    state_ = PowerState::SwitchOnDisabled;
    v_ = a_ = 0.0;
    demand_ = demand_prev_ = x_;
    return;
  }
  state_ = PowerState::QuickStopActive;
  ramp_v_ = v_;
}

void SimDrive::on_tick(Clock::time_point now, FrameSink& out) {
  const double dt = last_tick_ == Clock::time_point{} ? 0.0 : std::chrono::duration<double>(now - last_tick_).count();
  last_tick_ = now;
  // The stop ramps run on the drive's own clock, SYNC or not (a master that
  // quick-stops and goes away sends no more SYNCs).
  if (state_ == PowerState::FaultReactionActive) {
    const auto reaction = static_cast<std::int16_t>(get(od::kFaultReaction, 0));
    ramp(std::min(dt, 0.01), static_cast<double>(get(reaction == 1 ? 0x6084 : od::kQuickStopDeceleration, 0)));
    if (ramp_v_ == 0.0) state_ = PowerState::Fault;
    update_statusword();
  } else if (state_ == PowerState::QuickStopActive) {
    const auto option = static_cast<std::int16_t>(get(od::kQuickStopOption, 0));
    ramp(std::min(dt, 0.01), static_cast<double>(get(option == 1 || option == 5 ? 0x6084 : od::kQuickStopDeceleration, 0)));
    if (ramp_v_ == 0.0 && (option == 1 || option == 2)) state_ = PowerState::SwitchOnDisabled;  // then power off
    update_statusword();
  }
  const std::uint32_t consumer = get(od::kConsumerHeartbeat, 1);
  const auto ms = std::chrono::milliseconds(consumer & 0xFFFF);
  if (master_hb_armed_ && ms.count() > 0 && now - master_hb_ > ms) {
    master_hb_armed_ = false;  // re-armed by the next heartbeat
    // Abort connection option code (0x6007): what a lost master means here.
    const auto option = static_cast<std::int16_t>(get(od::kAbortConnection, 0));
    const bool active = state_ == PowerState::OperationEnabled || state_ == PowerState::SwitchedOn ||
                        state_ == PowerState::ReadyToSwitchOn || state_ == PowerState::QuickStopActive;
    if (option == 1 && state_ != PowerState::Fault && state_ != PowerState::FaultReactionActive) {
      fault(0x8130, out);
      update_statusword();
      return;
    }
    if (option == 2 && active) {
      state_ = PowerState::SwitchOnDisabled;
      v_ = a_ = 0.0;
      demand_ = demand_prev_ = x_;
    } else if (option == 3 && state_ == PowerState::OperationEnabled) {
      quick_stop();
    }
    emit_emcy(0x8130, emcy_error_register_bits(0x8130), out);
    update_statusword();
  }
}

void SimDrive::on_frame(const can_frame& f, FrameSink& out) {
  const std::uint32_t id = f.can_id & CAN_SFF_MASK;
  const std::uint32_t consumer = get(od::kConsumerHeartbeat, 1);
  if ((consumer & 0xFFFF) != 0 && id == kHeartbeatBase + ((consumer >> 16) & 0x7F) && f.can_dlc == 1) {
    master_hb_armed_ = true;
    master_hb_ = now_;
    return;
  }
  const std::uint32_t rpdo_cob = get(od::kRpdo1Comm, 1);
  if (nmt_ != NmtState::Operational || (rpdo_cob & od::kCobIdInvalid) || id != (rpdo_cob & 0x7FF)) return;
  int bits = 0;
  for (std::uint8_t s = 1; s <= get(od::kRpdo1Map, 0); ++s) bits += static_cast<int>(get(od::kRpdo1Map, s) & 0xFF);
  if (f.can_dlc * 8 < bits) {  // CiA 301: PDO length error
    emit_emcy(0x8210, 0x11, out);
    return;
  }
  std::copy(f.data, f.data + 8, rpdo_.begin());
  rpdo_len_ = f.can_dlc;
  have_rpdo_ = true;
}

void SimDrive::fault(std::uint16_t emcy_code, FrameSink& out) {
  if (state_ == PowerState::Fault || state_ == PowerState::FaultReactionActive) return;
  // Fault reaction option code (0x605E): 0 coast (power off at once), 1/2 ramp
  // down in Fault reaction active first.
  const auto reaction = static_cast<std::int16_t>(get(od::kFaultReaction, 0));
  const bool was_moving = state_ == PowerState::OperationEnabled || state_ == PowerState::QuickStopActive;
  if (reaction != 0 && was_moving && v_ != 0.0) {
    state_ = PowerState::FaultReactionActive;
    ramp_v_ = v_;
  } else {
    state_ = PowerState::Fault;
    v_ = a_ = 0.0;
  }
  demand_ = demand_prev_ = x_;
  emit_emcy(emcy_code, emcy_error_register_bits(emcy_code), out);
}

void SimDrive::apply_command(std::uint16_t cw, FrameSink& out) {
  const DriveCommand c = decode_controlword(cw, prev_cw_);
  prev_cw_ = cw;
  switch (state_) {
    case PowerState::NotReadyToSwitchOn: state_ = PowerState::SwitchOnDisabled; break;  // self test done
    case PowerState::SwitchOnDisabled:
      if (c == DriveCommand::Shutdown) state_ = PowerState::ReadyToSwitchOn;
      break;
    case PowerState::ReadyToSwitchOn:
      if (c == DriveCommand::SwitchOn) state_ = PowerState::SwitchedOn;
      else if (c == DriveCommand::DisableVoltage || c == DriveCommand::QuickStop) state_ = PowerState::SwitchOnDisabled;
      break;
    case PowerState::SwitchedOn:
      if (c == DriveCommand::EnableOperation) {
        if (const auto mode = static_cast<std::int8_t>(get(od::kModesOfOperation, 0));
            mode != kModeCyclicSyncPosition && mode != 6) {
          fault(0x6320, out);  // parameter error: no mode selected
          break;
        }
        state_ = PowerState::OperationEnabled;
        demand_ = demand_prev_ = x_;
      } else if (c == DriveCommand::Shutdown) state_ = PowerState::ReadyToSwitchOn;
      else if (c == DriveCommand::DisableVoltage || c == DriveCommand::QuickStop) state_ = PowerState::SwitchOnDisabled;
      break;
    case PowerState::OperationEnabled:
      if (c == DriveCommand::SwitchOn) state_ = PowerState::SwitchedOn;
      else if (c == DriveCommand::Shutdown) state_ = PowerState::ReadyToSwitchOn;
      else if (c == DriveCommand::DisableVoltage) state_ = PowerState::SwitchOnDisabled;
      else if (c == DriveCommand::QuickStop) quick_stop();
      break;
    case PowerState::QuickStopActive:
      if (c == DriveCommand::DisableVoltage) state_ = PowerState::SwitchOnDisabled;
      else if (c == DriveCommand::EnableOperation && ramp_v_ == 0.0) {
        state_ = PowerState::OperationEnabled;
        demand_ = demand_prev_ = x_;
      }
      break;
    case PowerState::FaultReactionActive: break;  // the ramp ends it (on_tick)
    case PowerState::Fault:
      if (c == DriveCommand::FaultReset) {
        state_ = PowerState::SwitchOnDisabled;
        following_error_ = internal_limit_ = false;
        emit_emcy(0x0000, 0x00, out);
      }
      break;
  }
  if (state_ != PowerState::OperationEnabled && state_ != PowerState::QuickStopActive &&
      state_ != PowerState::FaultReactionActive) {
    demand_ = demand_prev_ = x_;
  }
}

void SimDrive::step_physics(double dt) {
  const double wn = 2.0 * std::numbers::pi * p_.natural_frequency_hz;
  const double demand_v = (demand_ - demand_prev_) / dt;
  const bool moving = state_ == PowerState::OperationEnabled || state_ == PowerState::QuickStopActive;
  if (!moving) {
    v_ = a_ = 0.0;
    return;
  }
  const int substeps = 20;
  const double h = dt / substeps;
  double a_sum = 0.0;
  for (int i = 0; i < substeps; ++i) {
    // the demand is interpolated linearly over the cycle (CSP interpolation)
    const double r = demand_prev_ + (demand_ - demand_prev_) * (i + 1) / substeps;
    const double a = wn * wn * (r - x_) + 2.0 * p_.damping * wn * (demand_v - v_);
    v_ = std::clamp(v_ + a * h, -p_.max_motor_speed_counts_s, p_.max_motor_speed_counts_s);
    x_ += v_ * h;
    a_sum += a;
  }
  a_ = a_sum / substeps;
}

void SimDrive::update_statusword() {
  states_seen_ |= 1u << static_cast<unsigned>(state_);
  const bool powered = power_enabled(state_);
  if (powered_ && !powered) {
    power_off_sync_ = syncs_;
    power_off_at_ = now_;
  }
  powered_ = powered;
  std::uint16_t sw = statusword_bits(state_);
  if (state_ == PowerState::OperationEnabled || state_ == PowerState::SwitchedOn ||
      state_ == PowerState::ReadyToSwitchOn || state_ == PowerState::QuickStopActive)
    sw |= statusword::kVoltageEnabled;
  sw |= statusword::kRemote;
  if (static_cast<std::int8_t>(get(od::kModesOfOperation, 0)) == 6) {  // homing: bit 12 attained, bit 10 reached
    if (homing_attained_) sw |= statusword::kCspFollowsCommand | statusword::kTargetReached;
  } else {
    if (state_ == PowerState::OperationEnabled) sw |= statusword::kCspFollowsCommand;
    if (std::abs(demand_ - x_) < 10.0) sw |= statusword::kTargetReached;
  }
  if (internal_limit_) sw |= statusword::kInternalLimit;
  if (sto_ && p_.sto_status_bit >= 0) sw |= static_cast<std::uint16_t>(1u << p_.sto_status_bit);
  if (following_error_) sw |= statusword::kCspFollowingError;
  set(od::kStatusword, 0, sw);
  set(od::kModesDisplay, 0, get(od::kModesOfOperation, 0));
  const double xr = std::clamp(std::round(x_), -2147483648.0, 2147483647.0);
  set(od::kPositionActual, 0, static_cast<std::uint32_t>(static_cast<std::int32_t>(xr)));
  const double vr = std::clamp(std::round(v_), -2147483648.0, 2147483647.0);
  set(od::kVelocityActual, 0, static_cast<std::uint32_t>(static_cast<std::int32_t>(vr)));
  const double motor_acc = a_ * 2.0 * std::numbers::pi / p_.counts_per_rev;
  const double torque = p_.rotor_inertia_kgm2 * motor_acc + load_torque_nm_;
  const double pm = std::clamp(std::round(torque / (p_.rated_torque_mnm * 1e-3) * 1000.0), -32768.0, 32767.0);
  set(od::kTorqueActual, 0, static_cast<std::uint16_t>(static_cast<std::int16_t>(pm)));
}

void SimDrive::on_sync(Clock::time_point now, FrameSink& out) {
  ++syncs_;
  // A drive in cyclic synchronous position mode at SYNC k (CiA 301 synchronous
  // PDOs, CiA 402 csp): the motion of the period that just ended ran toward
  // the target latched at SYNC k-1; the TPDOs sample the state now, at the
  // SYNC; then the RPDO received since SYNC k-1 is latched and becomes the
  // demand of the period that starts now (reached at SYNC k+1). So a target
  // sent after SYNC k shows in the TPDO of SYNC k+2, never earlier.
  //
  // 1. motion over the elapsed period. Physics advances by the wall time since
  // the previous SYNC, so late, lost or irregular SYNCs show (bounded: a drive
  // interpolates at most 5 periods).
  std::uint32_t period_us = get(od::kCommCyclePeriod, 0);
  if (period_us == 0) period_us = 1000;
  const double period_s = period_us * 1e-6;
  double dt = period_s;
  if (last_sync_ != Clock::time_point{})
    dt = std::clamp(std::chrono::duration<double>(now - last_sync_).count(), 0.1 * period_s, 5.0 * period_s);
  last_sync_ = now;
  const bool homing_mode = static_cast<std::int8_t>(get(od::kModesOfOperation, 0)) == 6;
  if (homing_mode) step_homing(dt);
  if (state_ != PowerState::QuickStopActive && state_ != PowerState::FaultReactionActive && !homing_mode) {
    // (the quick-stop and fault-reaction ramps run in on_tick)
    step_physics(dt);
  }
  // Following error: beyond the window (0x6065) for longer than the timeout (0x6066, ms).
  const std::uint32_t window = get(od::kFollowingErrorWindow, 0);
  if (state_ == PowerState::OperationEnabled && !homing_mode && window != 0xFFFFFFFFu && std::abs(demand_ - x_) > window) {
    fe_time_s_ += dt;
    if (fe_time_s_ * 1e3 >= static_cast<double>(get(od::kFollowingErrorTimeout, 0))) {
      following_error_ = true;
      fault(0x8611, out);
    }
  } else {
    fe_time_s_ = 0.0;
  }
  update_statusword();
  // 2. synchronous TPDOs (transmission type n: every n-th SYNC), each as
  // mapped, sampled at this SYNC. TPDOs 2-4 carry the statusword by default
  // while valid (the predefined set's default; a master that forgets them
  // sees extra COB-IDs).
  for (std::uint16_t i = 0; i < 4; ++i) {
    const auto comm = static_cast<std::uint16_t>(od::kTpdo1Comm + i);
    const auto map = static_cast<std::uint16_t>(od::kTpdo1Map + i);
    const std::uint32_t cob = get(comm, 1);
    const std::uint32_t type = get(comm, 2);
    if ((cob & od::kCobIdInvalid) || type < 1 || type > 240 || syncs_ % type != 0) continue;
    can_frame f{};
    f.can_id = cob & 0x7FF;
    int bit = 0;
    for (std::uint8_t s = 1; s <= get(map, 0); ++s) {
      const std::uint32_t m = get(map, s);
      const int len = static_cast<int>(m & 0xFF);
      const std::uint32_t v = get(static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>((m >> 8) & 0xFF));
      for (int b = 0; b < len / 8; ++b) f.data[bit / 8 + b] = static_cast<std::uint8_t>(v >> (8 * b));
      bit += len;
    }
    f.can_dlc = static_cast<std::uint8_t>(bit / 8);
    out.send(f);
  }
  // 3. the synchronous RPDO received since the last SYNC takes effect now
  if (have_rpdo_) {
    have_rpdo_ = false;
    int bit = 0;
    for (std::uint8_t s = 1; s <= get(od::kRpdo1Map, 0); ++s) {
      const std::uint32_t m = get(od::kRpdo1Map, s);
      const int len = static_cast<int>(m & 0xFF);
      std::uint32_t v = 0;
      for (int b = 0; b < len / 8; ++b) v |= static_cast<std::uint32_t>(rpdo_[static_cast<std::size_t>(bit / 8 + b)]) << (8 * b);
      set(static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>((m >> 8) & 0xFF), v);
      bit += len;
    }
  }
  if (injected_fault_) {
    injected_fault_ = false;
    fault(injected_code_, out);
  }
  // 4. power state machine, then the new target: the demand the next period
  // interpolates toward (with limit supervision). Safe torque off overrides
  // the master: no torque, and nothing switches the power stage on.
  apply_command(static_cast<std::uint16_t>(get(od::kControlword, 0)), out);
  if (sto_ && (state_ == PowerState::ReadyToSwitchOn || state_ == PowerState::SwitchedOn ||
               state_ == PowerState::OperationEnabled || state_ == PowerState::QuickStopActive)) {
    state_ = PowerState::SwitchOnDisabled;
    v_ = 0.0;
    ramp_v_ = 0.0;
  }
  if (!homing_mode && state_ == PowerState::OperationEnabled) {
    const auto target = static_cast<double>(static_cast<std::int32_t>(get(od::kTargetPosition, 0)));
    const auto lo = static_cast<double>(static_cast<std::int32_t>(get(od::kSoftwareLimits, 1)));
    const auto hi = static_cast<double>(static_cast<std::int32_t>(get(od::kSoftwareLimits, 2)));
    demand_prev_ = demand_;
    if (target < lo || target > hi) {
      internal_limit_ = true;
      fault(0x8612, out);
    } else {
      demand_ = target;
    }
  }
  update_statusword();  // what SDO reads see until the next SYNC
}

}  // namespace foresight::sim
