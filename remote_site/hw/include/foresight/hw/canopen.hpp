#pragma once
// CANopen (CiA 301) and the CiA 402 drive profile: COB-IDs, NMT, SDO command
// bytes and abort codes, EMCY error codes, the power state machine's
// statusword/controlword, and the object dictionary indices the master uses.
// Everything here is constexpr or noexcept and allocation-free (real-time safe).
//
// Both the master (hw/) and the simulated far end (sim/) speak these
// definitions; the tests also check the wire bytes against literal frames, so
// a shared mistake here would not go unnoticed.

#include <cstdint>

namespace foresight::hw::canopen {

// ---- COB-IDs (predefined connection set, 11-bit) ----------------------------
inline constexpr std::uint32_t kNmt = 0x000;
inline constexpr std::uint32_t kSync = 0x080;
inline constexpr std::uint32_t kEmcyBase = 0x080;       // + node id
inline constexpr std::uint32_t kTpdo1Base = 0x180;      // + node id (drive -> master)
inline constexpr std::uint32_t kRpdo1Base = 0x200;      // + node id (master -> drive)
inline constexpr std::uint32_t kTpdo2Base = 0x280;
inline constexpr std::uint32_t kSdoTxBase = 0x580;      // server -> client (responses)
inline constexpr std::uint32_t kSdoRxBase = 0x600;      // client -> server (requests)
inline constexpr std::uint32_t kHeartbeatBase = 0x700;  // NMT error control
inline constexpr std::uint8_t kMaxNodeId = 127;

/// Function code (base) and node id of an 11-bit COB-ID.
constexpr std::uint32_t function_of(std::uint32_t cob_id) noexcept { return cob_id & 0x780; }
constexpr std::uint8_t node_of(std::uint32_t cob_id) noexcept { return static_cast<std::uint8_t>(cob_id & 0x7F); }

// ---- NMT --------------------------------------------------------------------
enum class NmtCommand : std::uint8_t {
  Start = 0x01,
  Stop = 0x02,
  EnterPreOperational = 0x80,
  ResetNode = 0x81,
  ResetCommunication = 0x82,
};
/// State byte of a heartbeat message.
enum class NmtState : std::uint8_t {
  BootUp = 0x00,
  Stopped = 0x04,
  Operational = 0x05,
  PreOperational = 0x7F,
};
const char* to_string(NmtState s) noexcept;

// ---- SDO (expedited and segmented upload) -------------------------------------
namespace sdo {
inline constexpr std::uint8_t kCcsDownloadInitiate = 1;  // client command specifiers (bits 7..5)
inline constexpr std::uint8_t kCcsUploadInitiate = 2;
inline constexpr std::uint8_t kCcsUploadSegment = 3;
inline constexpr std::uint8_t kScsUploadSegment = 0;  // server command specifiers
inline constexpr std::uint8_t kScsDownloadInitiate = 3;
inline constexpr std::uint8_t kScsUploadInitiate = 2;
inline constexpr std::uint8_t kCsAbort = 4;
/// Expedited download request command byte for 1..4 data bytes (0x2F/0x2B/0x27/0x23).
constexpr std::uint8_t expedited_download(int size) noexcept {
  return static_cast<std::uint8_t>(0x20 | ((4 - size) << 2) | 0x03);
}
}  // namespace sdo

/// CiA 301 SDO abort codes used here.
enum class SdoAbort : std::uint32_t {
  ToggleBit = 0x05030000,
  Timeout = 0x05040000,
  BadCommand = 0x05040001,
  OutOfMemory = 0x05040005,
  UnsupportedAccess = 0x06010000,
  WriteOnly = 0x06010001,
  ReadOnly = 0x06010002,
  NoObject = 0x06020000,
  CannotMap = 0x06040041,
  PdoTooLong = 0x06040042,
  Incompatible = 0x06040043,
  HardwareError = 0x06060000,
  LengthMismatch = 0x06070010,
  LengthTooHigh = 0x06070012,
  LengthTooLow = 0x06070013,
  NoSubIndex = 0x06090011,
  ValueRange = 0x06090030,
  ValueTooHigh = 0x06090031,
  ValueTooLow = 0x06090032,
  General = 0x08000000,
  CannotStore = 0x08000020,
  DeviceState = 0x08000022,
};
/// Text of an abort code ("toggle bit not alternated"); "unknown abort code" otherwise.
const char* sdo_abort_text(std::uint32_t code) noexcept;

// ---- EMCY -----------------------------------------------------------------------
/// Named faults that EMCY error codes decode into: the CiA 402 / CiA 301 codes
/// the master knows by name, else the CiA 301 error code group (table 21:
/// the high byte, or the high nibble) the code belongs to. A classification
/// never replaces the code: events and JointState keep the raw 16-bit code.
enum class EmcyFault : std::uint8_t {
  None,  ///< 0x0000: error reset / no error
  Generic,         ///< 0x10xx generic error
  Current,         ///< 0x2xxx current (other)
  OverCurrent,     ///< 0x2310 continuous over-current (and 0x23xx output side)
  ShortCircuit,    ///< 0x2320 short circuit / earth leakage
  Voltage,         ///< 0x3xxx voltage (other)
  MainsVoltage,    ///< 0x31xx mains voltage
  OverVoltage,     ///< 0x3210 DC link over-voltage
  UnderVoltage,    ///< 0x3220 DC link under-voltage
  OutputVoltage,   ///< 0x33xx output voltage
  OverTemperature, ///< 0x4xxx temperature
  DeviceHardware,  ///< 0x5xxx device hardware
  Software,        ///< 0x61xx/0x62xx/0x6xxx device software
  ParameterError,  ///< 0x63xx data set / parameter error
  AdditionalModules,  ///< 0x7xxx additional modules (other)
  EncoderFault,    ///< 0x73xx sensor (position encoder)
  MotorBlocked,    ///< 0x7121
  Monitoring,      ///< 0x8xxx monitoring (other)
  Communication,   ///< 0x81xx communication (other)
  CanOverrun,
  CanErrorPassive,
  HeartbeatError,  ///< the node lost its heartbeat/life guarding consumer
  RecoveredFromBusOff,
  ProtocolError,   ///< 0x82xx protocol error (other)
  PdoLength,       ///< PDO not processed due to length error
  SyncLost,
  FollowingError,  ///< 0x8611
  PositionLimit,   ///< 0x8612 reference limit
  External,        ///< 0x9xxx external error
  AdditionalFunctions,  ///< 0xF0xx
  DeviceSpecific,  ///< 0xFFxx
  Unknown,         ///< outside every CiA 301 group
};
EmcyFault classify_emcy(std::uint16_t error_code) noexcept;
const char* to_string(EmcyFault f) noexcept;
/// The error register (0x1001) bits a device sets with `error_code` (CiA 301
/// 7.5.2.2): bit 0 generic (always), 1 current, 2 voltage, 3 temperature,
/// 4 communication (0x81xx, 0x82xx), 5 device profile specific (the CiA 402
/// drive codes 0x86xx: following error, reference limit), 7 manufacturer.
std::uint8_t emcy_error_register_bits(std::uint16_t error_code) noexcept;

// ---- CiA 402 ----------------------------------------------------------------------
enum class PowerState : std::uint8_t {
  NotReadyToSwitchOn,
  SwitchOnDisabled,
  ReadyToSwitchOn,
  SwitchedOn,
  OperationEnabled,
  QuickStopActive,
  FaultReactionActive,
  Fault,
};
const char* to_string(PowerState s) noexcept;
/// True in the states where the drive's power stage is energised (CiA 402's
/// "power enabled" group: Switched on, Operation enabled, Quick stop active,
/// and Fault reaction active while it ramps). False in Not ready to switch
/// on, Switch on disabled, Ready to switch on and Fault: the motor gets no
/// torque. A category 0 stop ends in a state where this is false.
bool power_enabled(PowerState s) noexcept;
/// Decode the power state from statusword bits 0-3, 5, 6.
PowerState decode_statusword(std::uint16_t statusword) noexcept;
/// Statusword bits 0-3,5,6 for a state (what a drive reports; sim side).
std::uint16_t statusword_bits(PowerState s) noexcept;

namespace statusword {
inline constexpr std::uint16_t kVoltageEnabled = 1u << 4;
inline constexpr std::uint16_t kWarning = 1u << 7;
inline constexpr std::uint16_t kRemote = 1u << 9;
inline constexpr std::uint16_t kTargetReached = 1u << 10;
inline constexpr std::uint16_t kInternalLimit = 1u << 11;
inline constexpr std::uint16_t kCspFollowsCommand = 1u << 12;  // csp: drive follows the target
inline constexpr std::uint16_t kCspFollowingError = 1u << 13;
}  // namespace statusword

namespace controlword {
inline constexpr std::uint16_t kShutdown = 0x0006;
inline constexpr std::uint16_t kSwitchOn = 0x0007;
inline constexpr std::uint16_t kDisableVoltage = 0x0000;
inline constexpr std::uint16_t kQuickStop = 0x0002;
inline constexpr std::uint16_t kDisableOperation = 0x0007;
inline constexpr std::uint16_t kEnableOperation = 0x000F;
inline constexpr std::uint16_t kFaultReset = 0x0080;  // acts on the rising edge
}  // namespace controlword

/// A controlword command decoded (drive side), CiA 402 table 40.
enum class DriveCommand : std::uint8_t {
  None, Shutdown, SwitchOn, EnableOperation, DisableVoltage, QuickStop, DisableOperation, FaultReset,
};
DriveCommand decode_controlword(std::uint16_t cw, std::uint16_t previous_cw) noexcept;

/// Modes of operation (0x6060).
inline constexpr std::int8_t kModeCyclicSyncPosition = 8;
/// Device type (0x1000): low 16 bits are the device profile.
inline constexpr std::uint16_t kProfileDrive = 402;
inline constexpr std::uint16_t kProfileMeasuring = 404;  // used by the F/T sensor

// ---- object dictionary ------------------------------------------------------------
namespace od {
inline constexpr std::uint16_t kDeviceType = 0x1000;
inline constexpr std::uint16_t kErrorRegister = 0x1001;
inline constexpr std::uint16_t kCobIdSync = 0x1005;
inline constexpr std::uint16_t kCommCyclePeriod = 0x1006;  // us
inline constexpr std::uint16_t kDeviceName = 0x1008;       // visible string (segmented upload)
inline constexpr std::uint16_t kConsumerHeartbeat = 0x1016;  // sub 1: node id << 16 | ms
inline constexpr std::uint16_t kProducerHeartbeat = 0x1017;  // ms
inline constexpr std::uint16_t kSyncCounterOverflow = 0x1019;  // u8: SYNC counter 1..this; 0 = no counter
inline constexpr std::uint16_t kIdentity = 0x1018;           // sub 1 vendor, 2 product, 3 revision, 4 serial
inline constexpr std::uint16_t kAbortConnection = 0x6007;    // i16: 0 none, 1 fault, 2 disable voltage, 3 quick stop
inline constexpr std::uint16_t kRpdo1Comm = 0x1400;
inline constexpr std::uint16_t kRpdo1Map = 0x1600;
inline constexpr std::uint16_t kTpdo1Comm = 0x1800;
inline constexpr std::uint16_t kTpdo1Map = 0x1A00;
inline constexpr std::uint16_t kControlword = 0x6040;
inline constexpr std::uint16_t kStatusword = 0x6041;
inline constexpr std::uint16_t kQuickStopOption = 0x605A;  // i16: 0 coast, 1/2 ramp then disable, 5/6 ramp and hold
inline constexpr std::uint16_t kFaultReaction = 0x605E;     // i16: 0 coast, 1 slow-down ramp, 2 quick-stop ramp
inline constexpr std::uint16_t kModesOfOperation = 0x6060;
inline constexpr std::uint16_t kModesDisplay = 0x6061;
inline constexpr std::uint16_t kPositionActual = 0x6064;
inline constexpr std::uint16_t kFollowingErrorWindow = 0x6065;  // counts
inline constexpr std::uint16_t kFollowingErrorTimeout = 0x6066; // ms
inline constexpr std::uint16_t kVelocityActual = 0x606C;        // counts/s
inline constexpr std::uint16_t kRatedTorque = 0x6076;           // mN*m (motor)
inline constexpr std::uint16_t kTorqueActual = 0x6077;          // per mille of rated torque
inline constexpr std::uint16_t kTargetPosition = 0x607A;
inline constexpr std::uint16_t kSoftwareLimits = 0x607D;       // sub 1 min, sub 2 max (counts)
inline constexpr std::uint16_t kMaxProfileVelocity = 0x607F;   // counts/s
inline constexpr std::uint16_t kQuickStopDeceleration = 0x6085;  // counts/s^2
inline constexpr std::uint16_t kSupportedModes = 0x6502;       // bit 7: cyclic synchronous position
inline constexpr std::uint16_t kInterpolationPeriod = 0x60C2;  // sub 1 value, sub 2 exponent
/// A PDO mapping entry: index, sub-index, length in bits.
constexpr std::uint32_t map_entry(std::uint16_t index, std::uint8_t sub, std::uint8_t bits) noexcept {
  return (static_cast<std::uint32_t>(index) << 16) | (static_cast<std::uint32_t>(sub) << 8) | bits;
}
inline constexpr std::uint32_t kCobIdInvalid = 0x80000000u;  // PDO COB-ID bit 31: PDO disabled
}  // namespace od

}  // namespace foresight::hw::canopen
