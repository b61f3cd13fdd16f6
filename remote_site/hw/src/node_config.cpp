#include "foresight/hw/node_config.hpp"

#include <cmath>

#include "foresight/hw/canopen.hpp"

namespace foresight::hw {

using namespace canopen;

std::optional<std::uint8_t> interpolation_period_value(std::uint32_t period_us, int exponent) noexcept {
  if (exponent > 0 || exponent < -6) return std::nullopt;
  std::uint64_t unit_us = 1;  // 10^exponent s in us
  for (int e = exponent + 6; e > 0; --e) unit_us *= 10;
  if (period_us % unit_us != 0) return std::nullopt;
  const std::uint64_t v = period_us / unit_us;
  if (v == 0 || v > 255) return std::nullopt;
  return static_cast<std::uint8_t>(v);
}

NodeConfigurator::NodeConfigurator(SdoClient& sdo, NodeLabel label) : sdo_(sdo), label_(std::move(label)) {}

void NodeConfigurator::write_verified(std::uint8_t node, const SdoEntry& e) {
  sdo_.write(node, e.index, e.sub, e.value, e.size);
  const std::uint32_t mask = e.size == 4 ? 0xFFFFFFFFu : ((1u << (8 * e.size)) - 1);
  const std::uint32_t back = sdo_.read(node, e.index, e.sub) & mask;
  if (back != (e.value & mask))
    throw HwError(label_(node) + ": " + od_name(e.index, e.sub) + " read back " + sdo_value_text(e, back) +
                  " after writing " + sdo_value_text(e, e.value) + (e.origin.empty() ? "" : " (" + e.origin + ")"));
}

void NodeConfigurator::expect(std::uint8_t node, const SdoEntry& e) {
  const std::uint32_t mask = e.size == 4 ? 0xFFFFFFFFu : ((1u << (8 * e.size)) - 1);
  const std::uint32_t v = sdo_.read(node, e.index, e.sub) & mask;
  if (v != (e.value & mask))
    throw HwError(label_(node) + ": " + od_name(e.index, e.sub) + " is " + sdo_value_text(e, v) + ", expected " +
                  sdo_value_text(e, e.value) + (e.origin.empty() ? "" : " (" + e.origin + ")") +
                  (e.index == 0x1018 ? ": not the drive this configuration is for" : ""));
}

void NodeConfigurator::write_checked(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t value,
                                     std::uint8_t size, bool is_signed, DriveInfo& info) {
  SdoEntry e;
  e.index = index;
  e.sub = sub;
  e.value = value;
  e.size = size;
  e.is_signed = is_signed;
  write_verified(node, e);
  ++info.verified;
}

std::size_t NodeConfigurator::disable_pdo(std::uint8_t node, std::uint16_t comm_index) {
  std::uint32_t cob = 0;
  try {
    cob = sdo_.read(node, comm_index, 1);
  } catch (const SdoError& e) {
    if (e.kind() == SdoError::Kind::Abort &&
        (e.abort_code() == static_cast<std::uint32_t>(SdoAbort::NoObject) ||
         e.abort_code() == static_cast<std::uint32_t>(SdoAbort::NoSubIndex)))
      return 0;  // the drive has fewer PDOs
    throw;
  }
  if (cob & od::kCobIdInvalid) return 0;
  sdo_.write(node, comm_index, 1, cob | od::kCobIdInvalid, 4);
  if (!(sdo_.read(node, comm_index, 1) & od::kCobIdInvalid))
    throw HwError(label_(node) + ": " + od_name(comm_index, 1) + " still valid after disabling the PDO");
  return 1;
}

DriveInfo NodeConfigurator::configure_drive(const DriveSetup& s) {
  const std::uint8_t n = s.node;
  DriveInfo info;
  const std::uint32_t type = sdo_.read(n, od::kDeviceType, 0);
  if ((type & 0xFFFF) != kProfileDrive)
    throw HwError(label_(n) + ": device type " + hex_text(type, 8) + " is not a CiA 402 drive (profile " +
                  std::to_string(type & 0xFFFF) + ", expected 402)");
  // Identity first: nothing is written to a drive this file is not for.
  for (const SdoEntry& e : s.file_entries)
    if (e.expect_only) expect(n, e);
  info.vendor_id = sdo_.read(n, od::kIdentity, 1);
  info.product_code = sdo_.read(n, od::kIdentity, 2);
  info.revision = sdo_.read(n, od::kIdentity, 3);
  info.device_name = sdo_.read_string(n, od::kDeviceName, 0);
  // The drive's own file: stop and fault reactions, ramps, vendor objects.
  for (const SdoEntry& e : s.file_entries)
    if (!e.expect_only) {
      write_verified(n, e);
      ++info.verified;
    }
  // The drive's own quick stop must end without power (sdo_list.cpp): a
  // drive whose default the file left alone is checked here.
  if (const auto qs = static_cast<std::int16_t>(sdo_.read(n, od::kQuickStopOption, 0)); qs != 1 && qs != 2)
    throw HwError(label_(n) + ": quick stop option code 0x605A:00 is " + std::to_string(qs) +
                  "; the master's stop handling needs 1 or 2 (ramp, then Switch on disabled): set it in the "
                  "drive's SDO file");
  write_checked(n, od::kProducerHeartbeat, 0, s.producer_heartbeat_ms, 2, false, info);
  // The drive watches the master's heartbeat: a silent master triggers the
  // abort-connection option (0x6007) instead of leaving it following a stale target.
  write_checked(n, od::kConsumerHeartbeat, 1,
                (static_cast<std::uint32_t>(s.master_node_id) << 16) | s.consumer_heartbeat_ms, 4, false, info);
  // Every PDO the profile enables by default but we do not use goes off, so
  // nothing unplanned loads the bus.
  for (std::uint16_t i = 1; i < 4; ++i) {
    info.pdos_disabled += disable_pdo(n, static_cast<std::uint16_t>(od::kRpdo1Comm + i));
    info.pdos_disabled += disable_pdo(n, static_cast<std::uint16_t>(od::kTpdo1Comm + i));
  }
  // RPDO1: controlword + target position, applied at the next SYNC.
  sdo_.write(n, od::kRpdo1Comm, 1, od::kCobIdInvalid | (kRpdo1Base + n), 4);
  sdo_.write(n, od::kRpdo1Comm, 2, 1, 1);
  sdo_.write(n, od::kRpdo1Map, 0, 0, 1);
  sdo_.write(n, od::kRpdo1Map, 1, od::map_entry(od::kControlword, 0, 16), 4);
  sdo_.write(n, od::kRpdo1Map, 2, od::map_entry(od::kTargetPosition, 0, 32), 4);
  sdo_.write(n, od::kRpdo1Map, 0, 2, 1);
  write_checked(n, od::kRpdo1Comm, 1, kRpdo1Base + n, 4, false, info);
  // TPDO1: statusword + position actual + torque actual, on every SYNC.
  sdo_.write(n, od::kTpdo1Comm, 1, od::kCobIdInvalid | (kTpdo1Base + n), 4);
  sdo_.write(n, od::kTpdo1Comm, 2, 1, 1);
  sdo_.write(n, od::kTpdo1Map, 0, 0, 1);
  sdo_.write(n, od::kTpdo1Map, 1, od::map_entry(od::kStatusword, 0, 16), 4);
  sdo_.write(n, od::kTpdo1Map, 2, od::map_entry(od::kPositionActual, 0, 32), 4);
  sdo_.write(n, od::kTpdo1Map, 3, od::map_entry(od::kTorqueActual, 0, 16), 4);
  sdo_.write(n, od::kTpdo1Map, 0, 3, 1);
  write_checked(n, od::kTpdo1Comm, 1, kTpdo1Base + n, 4, false, info);
  // TPDO2: velocity actual, on every n-th SYNC (TPDO1 is full; at every SYNC
  // the 4 drives of a bus would pass the bus-load limit: docs/hardware.md).
  if (s.velocity_tpdo_every) {
    constexpr std::uint16_t kTpdo2Comm = od::kTpdo1Comm + 1, kTpdo2Map = od::kTpdo1Map + 1;
    sdo_.write(n, kTpdo2Comm, 1, od::kCobIdInvalid | (kTpdo1Base + 0x100u + n), 4);
    write_checked(n, kTpdo2Comm, 2, s.velocity_tpdo_every, 1, false, info);
    sdo_.write(n, kTpdo2Map, 0, 0, 1);
    sdo_.write(n, kTpdo2Map, 1, od::map_entry(od::kVelocityActual, 0, 32), 4);
    sdo_.write(n, kTpdo2Map, 0, 1, 1);
    write_checked(n, kTpdo2Comm, 1, kTpdo1Base + 0x100u + n, 4, false, info);
  }
  // Cyclic synchronous position: supported (0x6502 bit 7), selected, confirmed.
  const std::uint32_t modes = sdo_.read(n, od::kSupportedModes, 0);
  if (!(modes & (1u << 7)))
    throw HwError(label_(n) + ": supported drive modes 0x6502 = " + hex_text(modes, 8) +
                  " has no cyclic synchronous position (bit 7)");
  sdo_.write(n, od::kModesOfOperation, 0, static_cast<std::uint8_t>(kModeCyclicSyncPosition), 1);
  const auto display = static_cast<std::int8_t>(sdo_.read(n, od::kModesDisplay, 0));
  if (display != kModeCyclicSyncPosition)
    throw HwError(label_(n) + ": modes of operation display 0x6061 is " + std::to_string(display) +
                  " after selecting 8 (cyclic synchronous position) in 0x6060");
  write_checked(n, od::kCommCyclePeriod, 0, s.period_us, 4, false, info);
  if (s.sync_counter_overflow) write_checked(n, od::kSyncCounterOverflow, 0, s.sync_counter_overflow, 1, false, info);
  const std::optional<std::uint8_t> ip = interpolation_period_value(s.period_us, s.interpolation_exponent);
  if (!ip)
    throw HwError(label_(n) + ": a " + std::to_string(s.period_us) + " us cycle is not a whole number (1..255) of 10^" +
                  std::to_string(s.interpolation_exponent) + " s for 0x60C2");
  write_checked(n, od::kInterpolationPeriod, 1, *ip, 1, false, info);
  write_checked(n, od::kInterpolationPeriod, 2, static_cast<std::uint8_t>(static_cast<std::int8_t>(s.interpolation_exponent)),
                1, true, info);
  // Following error window and timeout, software limits, max velocity.
  write_checked(n, od::kFollowingErrorWindow, 0, s.following_error_counts, 4, false, info);
  if (s.following_error_timeout_ms)
    write_checked(n, od::kFollowingErrorTimeout, 0, s.following_error_timeout_ms, 2, false, info);
  if (s.limits_counts) {
    write_checked(n, od::kSoftwareLimits, 1, static_cast<std::uint32_t>(s.limits_counts->first), 4, true, info);
    write_checked(n, od::kSoftwareLimits, 2, static_cast<std::uint32_t>(s.limits_counts->second), 4, true, info);
  }
  if (s.max_velocity_counts_s) write_checked(n, od::kMaxProfileVelocity, 0, *s.max_velocity_counts_s, 4, false, info);
  const std::uint32_t rated_mnm = sdo_.read(n, od::kRatedTorque, 0);
  if (rated_mnm == 0) throw HwError(label_(n) + ": rated torque 0x6076 is 0");
  info.rated_torque_nm = rated_mnm * 1e-3;
  return info;
}

void NodeConfigurator::configure_ft(std::uint8_t n, std::uint16_t producer_heartbeat_ms) {
  const std::uint32_t type = sdo_.read(n, od::kDeviceType, 0);
  if ((type & 0xFFFF) != kProfileMeasuring)
    throw HwError(label_(n) + ": device type " + hex_text(type, 8) + " is not the F/T sensor (profile " +
                  std::to_string(type & 0xFFFF) + ", expected 404)");
  sdo_.write(n, od::kProducerHeartbeat, 0, producer_heartbeat_ms, 2);
}

}  // namespace foresight::hw
