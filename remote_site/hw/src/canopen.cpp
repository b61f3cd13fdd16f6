#include "foresight/hw/canopen.hpp"

namespace foresight::hw::canopen {

const char* to_string(NmtState s) noexcept {
  switch (s) {
    case NmtState::BootUp: return "boot-up";
    case NmtState::Stopped: return "stopped";
    case NmtState::Operational: return "operational";
    case NmtState::PreOperational: return "pre-operational";
  }
  return "unknown NMT state";
}

const char* sdo_abort_text(std::uint32_t code) noexcept {
  switch (static_cast<SdoAbort>(code)) {
    case SdoAbort::ToggleBit: return "toggle bit not alternated";
    case SdoAbort::Timeout: return "SDO protocol timed out";
    case SdoAbort::BadCommand: return "client/server command specifier not valid or unknown";
    case SdoAbort::OutOfMemory: return "out of memory";
    case SdoAbort::UnsupportedAccess: return "unsupported access to an object";
    case SdoAbort::WriteOnly: return "attempt to read a write only object";
    case SdoAbort::ReadOnly: return "attempt to write a read only object";
    case SdoAbort::NoObject: return "object does not exist in the object dictionary";
    case SdoAbort::CannotMap: return "object cannot be mapped to the PDO";
    case SdoAbort::PdoTooLong: return "number and length of mapped objects would exceed PDO length";
    case SdoAbort::Incompatible: return "general parameter incompatibility";
    case SdoAbort::HardwareError: return "access failed due to a hardware error";
    case SdoAbort::LengthMismatch: return "data type does not match, length of service parameter does not match";
    case SdoAbort::LengthTooHigh: return "data type does not match, length of service parameter too high";
    case SdoAbort::LengthTooLow: return "data type does not match, length of service parameter too low";
    case SdoAbort::NoSubIndex: return "sub-index does not exist";
    case SdoAbort::ValueRange: return "value range of parameter exceeded";
    case SdoAbort::ValueTooHigh: return "value of parameter written too high";
    case SdoAbort::ValueTooLow: return "value of parameter written too low";
    case SdoAbort::General: return "general error";
    case SdoAbort::CannotStore: return "data cannot be transferred or stored to the application";
    case SdoAbort::DeviceState: return "data cannot be transferred because of the present device state";
  }
  return "unknown abort code";
}

EmcyFault classify_emcy(std::uint16_t c) noexcept {
  if (c == 0x0000) return EmcyFault::None;
  switch (c) {  // codes known by name (CiA 301 / CiA 402)
    case 0x2310: return EmcyFault::OverCurrent;
    case 0x2320: return EmcyFault::ShortCircuit;
    case 0x3210: return EmcyFault::OverVoltage;
    case 0x3220: return EmcyFault::UnderVoltage;
    case 0x7121: return EmcyFault::MotorBlocked;
    case 0x8110: return EmcyFault::CanOverrun;
    case 0x8120: return EmcyFault::CanErrorPassive;
    case 0x8130: return EmcyFault::HeartbeatError;
    case 0x8140: return EmcyFault::RecoveredFromBusOff;
    case 0x8210: return EmcyFault::PdoLength;
    case 0x8700: return EmcyFault::SyncLost;
    case 0x8611: return EmcyFault::FollowingError;
    case 0x8612: return EmcyFault::PositionLimit;
    default: break;
  }
  const std::uint16_t group = c & 0xFF00;
  switch (c >> 12) {  // error code groups (CiA 301 table 21)
    case 0x0: return EmcyFault::Unknown;  // 0x00xx other than 0x0000 is not a group
    case 0x1: return group == 0x1000 ? EmcyFault::Generic : EmcyFault::Unknown;
    case 0x2: return group == 0x2300 ? EmcyFault::OverCurrent : EmcyFault::Current;
    case 0x3:
      if (group == 0x3100) return EmcyFault::MainsVoltage;
      if (group == 0x3300) return EmcyFault::OutputVoltage;
      return EmcyFault::Voltage;
    case 0x4: return EmcyFault::OverTemperature;
    case 0x5: return EmcyFault::DeviceHardware;
    case 0x6: return group == 0x6300 ? EmcyFault::ParameterError : EmcyFault::Software;
    case 0x7: return group == 0x7300 ? EmcyFault::EncoderFault : EmcyFault::AdditionalModules;
    case 0x8:
      if (group == 0x8100) return EmcyFault::Communication;
      if (group == 0x8200) return EmcyFault::ProtocolError;
      return EmcyFault::Monitoring;
    case 0x9: return EmcyFault::External;
    case 0xF:
      if (group == 0xF000) return EmcyFault::AdditionalFunctions;
      if (group == 0xFF00) return EmcyFault::DeviceSpecific;
      return EmcyFault::Unknown;
    default: return EmcyFault::Unknown;  // 0xA000..0xEFFF: no group
  }
}

std::uint8_t emcy_error_register_bits(std::uint16_t c) noexcept {
  if (c == 0x0000) return 0x00;
  std::uint8_t r = 0x01;  // generic error: set with every error
  switch (c >> 12) {
    case 0x2: r |= 0x02; break;
    case 0x3: r |= 0x04; break;
    case 0x4: r |= 0x08; break;
    case 0x8:
      if ((c & 0xFF00) == 0x8100 || (c & 0xFF00) == 0x8200) r |= 0x10;
      else if ((c & 0xFF00) == 0x8600) r |= 0x20;  // CiA 402: position control monitoring
      break;
    case 0xF:
      if ((c & 0xFF00) == 0xFF00) r |= 0x80;
      break;
    default: break;
  }
  return r;
}

const char* to_string(EmcyFault f) noexcept {
  switch (f) {
    case EmcyFault::None: return "error reset / no error";
    case EmcyFault::Generic: return "generic error";
    case EmcyFault::Current: return "current";
    case EmcyFault::OverCurrent: return "over-current";
    case EmcyFault::ShortCircuit: return "short circuit / earth leakage";
    case EmcyFault::Voltage: return "voltage";
    case EmcyFault::MainsVoltage: return "mains voltage";
    case EmcyFault::OverVoltage: return "DC link over-voltage";
    case EmcyFault::UnderVoltage: return "DC link under-voltage";
    case EmcyFault::OutputVoltage: return "output voltage";
    case EmcyFault::OverTemperature: return "over-temperature";
    case EmcyFault::DeviceHardware: return "device hardware";
    case EmcyFault::Software: return "device software";
    case EmcyFault::ParameterError: return "parameter error";
    case EmcyFault::AdditionalModules: return "additional modules";
    case EmcyFault::EncoderFault: return "position sensor (encoder) fault";
    case EmcyFault::MotorBlocked: return "motor blocked";
    case EmcyFault::Monitoring: return "monitoring";
    case EmcyFault::Communication: return "communication";
    case EmcyFault::CanOverrun: return "CAN overrun (objects lost)";
    case EmcyFault::CanErrorPassive: return "CAN in error passive mode";
    case EmcyFault::HeartbeatError: return "life guard or heartbeat error";
    case EmcyFault::RecoveredFromBusOff: return "recovered from bus off";
    case EmcyFault::ProtocolError: return "protocol error";
    case EmcyFault::PdoLength: return "PDO not processed due to length error";
    case EmcyFault::SyncLost: return "SYNC lost";
    case EmcyFault::FollowingError: return "following error";
    case EmcyFault::PositionLimit: return "position (reference) limit";
    case EmcyFault::External: return "external error";
    case EmcyFault::AdditionalFunctions: return "additional functions";
    case EmcyFault::DeviceSpecific: return "device specific";
    case EmcyFault::Unknown: return "unknown error code";
  }
  return "unknown error code";
}

const char* to_string(PowerState s) noexcept {
  switch (s) {
    case PowerState::NotReadyToSwitchOn: return "Not ready to switch on";
    case PowerState::SwitchOnDisabled: return "Switch on disabled";
    case PowerState::ReadyToSwitchOn: return "Ready to switch on";
    case PowerState::SwitchedOn: return "Switched on";
    case PowerState::OperationEnabled: return "Operation enabled";
    case PowerState::QuickStopActive: return "Quick stop active";
    case PowerState::FaultReactionActive: return "Fault reaction active";
    case PowerState::Fault: return "Fault";
  }
  return "?";
}

bool power_enabled(PowerState s) noexcept {
  return s == PowerState::SwitchedOn || s == PowerState::OperationEnabled || s == PowerState::QuickStopActive ||
         s == PowerState::FaultReactionActive;
}

PowerState decode_statusword(std::uint16_t sw) noexcept {
  if ((sw & 0x4F) == 0x00) return PowerState::NotReadyToSwitchOn;
  if ((sw & 0x4F) == 0x40) return PowerState::SwitchOnDisabled;
  if ((sw & 0x6F) == 0x21) return PowerState::ReadyToSwitchOn;
  if ((sw & 0x6F) == 0x23) return PowerState::SwitchedOn;
  if ((sw & 0x6F) == 0x27) return PowerState::OperationEnabled;
  if ((sw & 0x6F) == 0x07) return PowerState::QuickStopActive;
  if ((sw & 0x4F) == 0x0F) return PowerState::FaultReactionActive;
  if ((sw & 0x4F) == 0x08) return PowerState::Fault;
  return PowerState::NotReadyToSwitchOn;  // reserved patterns: treat as not ready
}

std::uint16_t statusword_bits(PowerState s) noexcept {
  switch (s) {
    case PowerState::NotReadyToSwitchOn: return 0x00;
    case PowerState::SwitchOnDisabled: return 0x40;
    case PowerState::ReadyToSwitchOn: return 0x21;
    case PowerState::SwitchedOn: return 0x23;
    case PowerState::OperationEnabled: return 0x27;
    case PowerState::QuickStopActive: return 0x07;
    case PowerState::FaultReactionActive: return 0x0F;
    case PowerState::Fault: return 0x08;
  }
  return 0;
}

DriveCommand decode_controlword(std::uint16_t cw, std::uint16_t previous_cw) noexcept {
  if ((cw & 0x80) && !(previous_cw & 0x80)) return DriveCommand::FaultReset;
  if (cw & 0x80) return DriveCommand::None;  // reset held high: no new command
  if ((cw & 0x02) == 0) return DriveCommand::DisableVoltage;
  if ((cw & 0x06) == 0x02) return DriveCommand::QuickStop;
  if ((cw & 0x07) == 0x06) return DriveCommand::Shutdown;
  if ((cw & 0x0F) == 0x07) return DriveCommand::SwitchOn;  // also "disable operation"
  if ((cw & 0x0F) == 0x0F) return DriveCommand::EnableOperation;
  return DriveCommand::None;
}

}  // namespace foresight::hw::canopen
