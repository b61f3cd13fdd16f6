#pragma once
// Node configuration: what DriveSystem::configure() does to each node over SDO
// between NMT reset/boot-up and NMT start (docs/hardware.md, in order):
//   drive: device type 0x1000 (CiA 402) and identity 0x1018 (vendor, product,
//          revision from the drive's file, `expect` lines), device name, the
//          drive's file (stop and fault reactions 0x605A/0x605E/0x6007 ...,
//          each written and read back), heartbeats (0x1017, 0x1016), the PDOs
//          (RPDO1 controlword + target, TPDO1 statusword + position + torque,
//          TPDO2 velocity actual every n-th SYNC; every other PDO disabled), supported modes 0x6502 (CSP), mode
//          0x6060 read back in 0x6061, periods 0x1006 / 0x60C2 (exponent from
//          config), following-error window/timeout 0x6065/0x6066, software
//          limits 0x607D and max profile velocity 0x607F from the URDF, rated
//          torque 0x6076.
//   F/T:   device type (CiA 404), heartbeat.
// Set-up code only: blocks on SDO, allocates, throws HwError/SdoError naming
// the node and the object.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "foresight/hw/sdo_client.hpp"
#include "foresight/hw/sdo_list.hpp"

namespace foresight::hw {

/// Everything a drive is configured with, in drive units (counts, us, ms).
struct DriveSetup {
  std::uint8_t node = 0;
  std::uint32_t period_us = 2000;          ///< 0x1006
  std::uint8_t sync_counter_overflow = 0;  ///< 0x1019 (0: SYNC without counter)
  int interpolation_exponent = -4;         ///< 0x60C2:02 (0x60C2:01 = period in 10^exp s)
  std::uint16_t producer_heartbeat_ms = 50;
  std::uint8_t master_node_id = 127;
  std::uint16_t consumer_heartbeat_ms = 150;
  std::uint32_t following_error_counts = 0;    ///< 0x6065
  std::uint16_t following_error_timeout_ms = 0; ///< 0x6066 (0: not written)
  std::optional<std::pair<std::int32_t, std::int32_t>> limits_counts;  ///< 0x607D:01/02
  std::optional<std::uint32_t> max_velocity_counts_s;                   ///< 0x607F
  std::uint8_t velocity_tpdo_every = 0;  ///< TPDO2 = velocity actual 0x606C every n-th SYNC (0: TPDO2 off)
  std::vector<SdoEntry> file_entries;  ///< the drive's file (writes and expects)
};

/// What configuration learned about a drive.
struct DriveInfo {
  std::string device_name;        ///< 0x1008
  double rated_torque_nm = 0.0;   ///< 0x6076, motor side
  std::uint32_t vendor_id = 0, product_code = 0, revision = 0;  ///< 0x1018:01..03
  std::size_t verified = 0;       ///< objects written and read back equal
  std::size_t pdos_disabled = 0;  ///< unused RPDOs/TPDOs switched off
};

/// 0x60C2:01 for a period in us at 10^exponent s, or nullopt when the period is
/// not a whole number of those units or does not fit the u8.
std::optional<std::uint8_t> interpolation_period_value(std::uint32_t period_us, int exponent) noexcept;

class NodeConfigurator {
 public:
  using NodeLabel = std::function<std::string(std::uint8_t node)>;
  /// `sdo` must outlive the configurator.
  NodeConfigurator(SdoClient& sdo, NodeLabel label);

  /// The drive sequence above. Throws HwError/SdoError.
  DriveInfo configure_drive(const DriveSetup& setup);
  /// F/T sensor: device type 404, producer heartbeat.
  void configure_ft(std::uint8_t node, std::uint16_t producer_heartbeat_ms);
  /// Write, then read back and compare; throws HwError "... read back X, wrote Y".
  void write_verified(std::uint8_t node, const SdoEntry& e);
  /// Read and compare (`expect`); throws HwError naming both values.
  void expect(std::uint8_t node, const SdoEntry& e);

 private:
  void write_checked(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t value, std::uint8_t size,
                     bool is_signed, DriveInfo& info);
  std::size_t disable_pdo(std::uint8_t node, std::uint16_t comm_index);

  SdoClient& sdo_;
  NodeLabel label_;
};

}  // namespace foresight::hw
