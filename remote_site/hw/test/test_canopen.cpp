#include <gtest/gtest.h>

#include "foresight/hw/canopen.hpp"
#include "foresight/hw/cob_id_router.hpp"
#include "foresight/hw/ft_sensor.hpp"
#include "foresight/hw/remote_config.hpp"

using namespace foresight::hw;
using namespace foresight::hw::canopen;

TEST(CanOpen, StatuswordDecodesEveryPowerState) {
  // Literal statuswords as CiA 402 drives report them (with unrelated bits set).
  EXPECT_EQ(decode_statusword(0x0000), PowerState::NotReadyToSwitchOn);
  EXPECT_EQ(decode_statusword(0x0250), PowerState::SwitchOnDisabled);
  EXPECT_EQ(decode_statusword(0x0231), PowerState::ReadyToSwitchOn);
  EXPECT_EQ(decode_statusword(0x0233), PowerState::SwitchedOn);
  EXPECT_EQ(decode_statusword(0x1637), PowerState::OperationEnabled);
  EXPECT_EQ(decode_statusword(0x0217), PowerState::QuickStopActive);
  EXPECT_EQ(decode_statusword(0x021F), PowerState::FaultReactionActive);
  EXPECT_EQ(decode_statusword(0x2218), PowerState::Fault);
  for (int s = 0; s <= static_cast<int>(PowerState::Fault); ++s)
    EXPECT_EQ(decode_statusword(statusword_bits(static_cast<PowerState>(s))), static_cast<PowerState>(s));
}

TEST(CanOpen, ControlwordCommands) {
  EXPECT_EQ(decode_controlword(0x0006, 0), DriveCommand::Shutdown);
  EXPECT_EQ(decode_controlword(0x0007, 0), DriveCommand::SwitchOn);
  EXPECT_EQ(decode_controlword(0x000F, 0), DriveCommand::EnableOperation);
  EXPECT_EQ(decode_controlword(0x0000, 0), DriveCommand::DisableVoltage);
  EXPECT_EQ(decode_controlword(0x0002, 0), DriveCommand::QuickStop);
  EXPECT_EQ(decode_controlword(0x0080, 0x0000), DriveCommand::FaultReset);
  EXPECT_EQ(decode_controlword(0x0080, 0x0080), DriveCommand::None);  // edge only
}

TEST(CanOpen, SdoCommandBytesAndAbortTexts) {
  EXPECT_EQ(sdo::expedited_download(1), 0x2F);
  EXPECT_EQ(sdo::expedited_download(2), 0x2B);
  EXPECT_EQ(sdo::expedited_download(4), 0x23);
  EXPECT_STREQ(sdo_abort_text(0x05030000), "toggle bit not alternated");
  EXPECT_STREQ(sdo_abort_text(0x06020000), "object does not exist in the object dictionary");
  EXPECT_STREQ(sdo_abort_text(0x12345678), "unknown abort code");
  EXPECT_EQ(od::map_entry(0x607A, 0, 32), 0x607A0020u);
}

TEST(CanOpen, EmcyCodesMapToNamedFaults) {
  EXPECT_EQ(classify_emcy(0x0000), EmcyFault::None);
  EXPECT_EQ(classify_emcy(0x8611), EmcyFault::FollowingError);
  EXPECT_EQ(classify_emcy(0x8612), EmcyFault::PositionLimit);
  EXPECT_EQ(classify_emcy(0x2310), EmcyFault::OverCurrent);
  EXPECT_EQ(classify_emcy(0x3210), EmcyFault::OverVoltage);
  EXPECT_EQ(classify_emcy(0x3220), EmcyFault::UnderVoltage);
  EXPECT_EQ(classify_emcy(0x4310), EmcyFault::OverTemperature);
  EXPECT_EQ(classify_emcy(0x7305), EmcyFault::EncoderFault);
  EXPECT_EQ(classify_emcy(0x8130), EmcyFault::HeartbeatError);
  EXPECT_EQ(classify_emcy(0x8210), EmcyFault::PdoLength);
  EXPECT_EQ(classify_emcy(0xFF01), EmcyFault::DeviceSpecific);
  EXPECT_STREQ(to_string(classify_emcy(0x8611)), "following error");
}

// Issue 12: an unmatched 0x3xxx code was "DC link over-voltage"; codes are
// classified by their CiA 301 group, and the raw code is never lost.
TEST(CanOpen, EmcyCodesOutsideTheNamedOnesFallIntoTheirCiA301Group) {
  EXPECT_EQ(classify_emcy(0x3100), EmcyFault::MainsVoltage);
  EXPECT_EQ(classify_emcy(0x3130), EmcyFault::MainsVoltage);
  EXPECT_EQ(classify_emcy(0x3310), EmcyFault::OutputVoltage);
  EXPECT_EQ(classify_emcy(0x3000), EmcyFault::Voltage);
  EXPECT_EQ(classify_emcy(0x3230), EmcyFault::Voltage);
  EXPECT_STREQ(to_string(classify_emcy(0x3310)), "output voltage");
  EXPECT_EQ(classify_emcy(0x2110), EmcyFault::Current);
  EXPECT_EQ(classify_emcy(0x2350), EmcyFault::OverCurrent);
  EXPECT_EQ(classify_emcy(0x8100), EmcyFault::Communication);
  EXPECT_EQ(classify_emcy(0x8250), EmcyFault::ProtocolError);  // RPDO timeout
  EXPECT_EQ(classify_emcy(0x8400), EmcyFault::Monitoring);
  EXPECT_EQ(classify_emcy(0x1000), EmcyFault::Generic);
  EXPECT_EQ(classify_emcy(0x1234), EmcyFault::Unknown);
  EXPECT_EQ(classify_emcy(0x0001), EmcyFault::Unknown);
  EXPECT_EQ(classify_emcy(0xA000), EmcyFault::Unknown);
  EXPECT_EQ(classify_emcy(0xF001), EmcyFault::AdditionalFunctions);
  EXPECT_EQ(classify_emcy(0xF101), EmcyFault::Unknown);
  EXPECT_EQ(classify_emcy(0x7000), EmcyFault::AdditionalModules);
}

TEST(CanOpen, ErrorRegisterBitsFollowTheCodeGroup) {
  EXPECT_EQ(emcy_error_register_bits(0x0000), 0x00);
  EXPECT_EQ(emcy_error_register_bits(0x2310), 0x03);  // generic + current
  EXPECT_EQ(emcy_error_register_bits(0x3210), 0x05);  // generic + voltage
  EXPECT_EQ(emcy_error_register_bits(0x4310), 0x09);  // generic + temperature
  EXPECT_EQ(emcy_error_register_bits(0x8130), 0x11);  // generic + communication
  EXPECT_EQ(emcy_error_register_bits(0x8210), 0x11);
  EXPECT_EQ(emcy_error_register_bits(0x8611), 0x21);  // generic + device profile: not communication
  EXPECT_EQ(emcy_error_register_bits(0x8612), 0x21);
  EXPECT_EQ(emcy_error_register_bits(0xFF01), 0x81);
  EXPECT_EQ(emcy_error_register_bits(0x6320), 0x01);
}

TEST(BusLoad, WorstCaseFrameBits) {
  EXPECT_EQ(worst_case_frame_bits(0), 55);   // SYNC
  EXPECT_EQ(worst_case_frame_bits(1), 65);   // heartbeat
  EXPECT_EQ(worst_case_frame_bits(6), 115);  // RPDO
  EXPECT_EQ(worst_case_frame_bits(8), 135);  // TPDO, F/T
}

TEST(FtFrames, WireBytesAreLittleEndianWithStatusAndSequence) {
  ft_frame::RawSample s;
  s.counts = {1, -2, 300, -32767, 32767, 0};
  s.status = 0x18;
  s.sequence = 0xAB;
  can_frame a{}, b{};
  ft_frame::encode(s, 32, a, b);
  EXPECT_EQ(a.can_id, 0x1A0u);
  EXPECT_EQ(b.can_id, 0x2A0u);
  const std::uint8_t ea[8] = {0x01, 0x00, 0xFE, 0xFF, 0x2C, 0x01, 0x18, 0xAB};
  const std::uint8_t eb[8] = {0x01, 0x80, 0xFF, 0x7F, 0x00, 0x00, 0x18, 0xAB};
  for (int i = 0; i < 8; ++i) {
    EXPECT_EQ(a.data[i], ea[i]) << i;
    EXPECT_EQ(b.data[i], eb[i]) << i;
  }
}

// The master's COB-ID router (cob_id_router.hpp): literal COB-IDs of the
// predefined connection set for drive 3 and the F/T sensor (node 9).
TEST(CobIdRouter, RoutesEachNodesCobIdsToItsHandler) {
  using Kind = CobIdRouter::Kind;
  CobIdRouter r;
  r.add_drive(3, 2, true);
  r.add_ft(9);
  r.add_master(127);
  auto is = [&](std::uint32_t id, Kind k, std::uint8_t slot) {
    EXPECT_EQ(r.route(id).kind, k) << std::hex << id;
    EXPECT_EQ(r.route(id).slot, slot) << std::hex << id;
  };
  is(0x183, Kind::DriveTpdo, 2);
  is(0x283, Kind::DriveVelocity, 2);
  is(0x083, Kind::DriveEmcy, 2);
  is(0x703, Kind::DriveHeartbeat, 2);
  is(0x583, Kind::DriveSdo, 2);
  is(0x203, Kind::Own, 2);  // our RPDO and SDO requests, looped back
  is(0x603, Kind::Own, 2);
  is(0x189, Kind::FtForce, 0);
  is(0x289, Kind::FtTorque, 0);
  is(0x089, Kind::FtEmcy, 0);
  is(0x709, Kind::FtHeartbeat, 0);
  is(0x589, Kind::FtSdo, 0);
  is(0x000, Kind::Own, 0);  // NMT
  is(0x77F, Kind::Own, 0);  // the master's heartbeat
  is(0x184, Kind::None, 0);
  is(0x7FF, Kind::None, 0);

  CobIdRouter no_velocity;
  no_velocity.add_drive(3, 0, false);
  EXPECT_EQ(no_velocity.route(0x283).kind, Kind::None);
}
