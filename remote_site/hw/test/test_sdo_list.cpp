// The per-drive SDO list (sdo_list.hpp) and the configuration keys that point
// at it: parsed values against literal bytes, bad lines against their exact
// messages.
#include <gtest/gtest.h>

#include "foresight/common/error.hpp"
#include "foresight/hw/node_config.hpp"
#include "foresight/hw/remote_config.hpp"
#include "foresight/hw/sdo_list.hpp"

using namespace foresight;
using namespace foresight::hw;

namespace {
std::string error_of(const std::string& text) {
  try {
    parse_sdo_list(text, "d.sdo");
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}
}  // namespace

TEST(SdoList, ParsesWritesAndExpectsWithTheirTypes) {
  const auto l = parse_sdo_list(
      "# comment\n\n0x605A:00 i16 2   # quick stop\nexpect 0x1018:01 u32 0x00F0E5E7\n0x2000:02 i8 -3\n0x2001:1A u8 255\n",
      "d.sdo");
  ASSERT_EQ(l.size(), 4u);
  EXPECT_EQ(l[0].index, 0x605A);
  EXPECT_EQ(l[0].sub, 0);
  EXPECT_EQ(l[0].value, 2u);
  EXPECT_EQ(l[0].size, 2);
  EXPECT_TRUE(l[0].is_signed);
  EXPECT_FALSE(l[0].expect_only);
  EXPECT_EQ(l[0].origin, "d.sdo:3");
  EXPECT_TRUE(l[1].expect_only);
  EXPECT_EQ(l[1].value, 0x00F0E5E7u);
  EXPECT_EQ(l[1].size, 4);
  EXPECT_EQ(l[2].value, 0xFDu);  // -3 as one byte
  EXPECT_EQ(sdo_value_text(l[2], l[2].value), "-3");
  EXPECT_EQ(l[3].sub, 0x1A);
  EXPECT_EQ(sdo_value_text(l[1], 0x402), "0x00000402");
}

TEST(SdoList, BadLinesAreNamedWithFileAndLine) {
  EXPECT_EQ(error_of("0x605A:00 i16\n"), "d.sdo:1: expected 'index:sub type value' (e.g. 0x605A:00 i16 6), got '0x605A:00 i16'");
  EXPECT_EQ(error_of("\n605A:00 i16 6\n"), "d.sdo:2: object '605A:00' is not index:sub in hex (0x1000:00 .. 0xFFFF:FF)");
  EXPECT_EQ(error_of("0x605A:100 i16 6\n"), "d.sdo:1: object '0x605A:100' is not index:sub in hex (0x1000:00 .. 0xFFFF:FF)");
  EXPECT_EQ(error_of("0x605A:00 int 6\n"), "d.sdo:1: type 'int' is not one of u8 u16 u32 i8 i16 i32");
  EXPECT_EQ(error_of("0x605A:00 i16 40000\n"), "d.sdo:1: value 40000 is outside i16 (-32768..32767)");
  EXPECT_EQ(error_of("0x1017:00 u16 -1\n"), "d.sdo:1: value -1 is outside u16 (0..65535)");
  EXPECT_EQ(error_of("0x1017:00 u16 fifty\n"), "d.sdo:1: value 'fifty' is not an integer");
  EXPECT_EQ(error_of("0x1017:00 u16 50 ms\n"), "d.sdo:1: unexpected 'ms' after the value");
  EXPECT_EQ(error_of("expect\n"), "d.sdo:1: 'expect' needs index:sub type value");
}

// A file of 200,000 valid entries took minutes of SDO traffic at every
// start-up (past the unit's start timeout): bounded at the entry after the last allowed.
TEST(SdoList, AFileBeyondTheEntryBoundIsRefusedAtTheLineThatPassesIt) {
  std::string text;
  for (std::size_t i = 0; i < kMaxSdoEntries; ++i) text += "0x2000:01 u8 1\n";
  EXPECT_EQ(parse_sdo_list(text, "d.sdo").size(), kMaxSdoEntries);
  text = "# many\n" + text + "0x2000:02 u8 1\n";
  EXPECT_EQ(error_of(text), "d.sdo:1026: more than 1024 entries (a drive's configurable objects are dozens; each "
                            "costs two SDO transfers at every start-up)");
}

// The objects that govern stopping, against the master's stop handling
// (category 0 is Disable Voltage; quick stop only when the master leaves,
// and it must end without power): refused at load, naming the line.
TEST(SdoList, StopObjectsMustMatchTheMastersStopHandling) {
  EXPECT_EQ(error_of("0x605A:00 i16 6\n"),
            "d.sdo:1: quick stop option code 0x605A:00 = 6 contradicts the master's stop handling: allowed 1 or 2 "
            "(ramp, then Switch on disabled: power off)");
  EXPECT_EQ(error_of("\nexpect 0x605A:00 i16 5\n"),
            "d.sdo:2: quick stop option code 0x605A:00 = 5 contradicts the master's stop handling: allowed 1 or 2 "
            "(ramp, then Switch on disabled: power off)");
  EXPECT_EQ(error_of("0x605A:00 i16 0\n"),
            "d.sdo:1: quick stop option code 0x605A:00 = 0 contradicts the master's stop handling: allowed 1 or 2 "
            "(ramp, then Switch on disabled: power off)");
  EXPECT_EQ(error_of("0x6007:00 i16 0\n"),
            "d.sdo:1: abort connection option code 0x6007:00 = 0 is outside 1..3 (fault, disable voltage, quick "
            "stop): with 0 a drive whose master died keeps following its last target");
  EXPECT_EQ(error_of("0x605E:00 i16 -1\n"),
            "d.sdo:1: fault reaction option code 0x605E:00 = -1 is outside 0..2 (coast, or ramp; then Fault)");
  EXPECT_EQ(error_of("0x6085:00 u32 0\n"),
            "d.sdo:1: quick stop deceleration 0x6085:00 = 0 must be above 0 counts/s^2 (a zero ramp never stops)");
  EXPECT_EQ(error_of("0x6084:00 u32 0\n"),
            "d.sdo:1: profile deceleration 0x6084:00 = 0 must be above 0 counts/s^2 (a zero ramp never stops)");
  EXPECT_EQ(parse_sdo_list("0x605A:00 i16 1\n0x6007:00 i16 3\n0x605E:00 i16 0\n", "d.sdo").size(), 3u);
}

// What the master writes itself at every boot cannot be in the file (it would
// be overwritten, or fight the cycle); reading it back with `expect` is fine.
TEST(SdoList, ObjectsTheMasterWritesAreRefused) {
  EXPECT_EQ(error_of("0x6040:00 u16 15\n"),
            "d.sdo:1: object 0x6040:00 (controlword) is written by the master itself at every boot; remove it from "
            "the file");
  EXPECT_EQ(error_of("0x607A:00 i32 1000\n"),
            "d.sdo:1: object 0x607A:00 (target position) is written by the master itself at every boot; remove it "
            "from the file");
  EXPECT_EQ(error_of("0x1A01:01 u32 0x60640020\n"),
            "d.sdo:1: object 0x1A01:01 (PDO communication or mapping) is written by the master itself at every "
            "boot; remove it from the file");
  EXPECT_EQ(error_of("0x1016:01 u32 0x007F00C8\n"),
            "d.sdo:1: object 0x1016:01 (consumer heartbeat time) is written by the master itself at every boot; "
            "remove it from the file");
  EXPECT_EQ(parse_sdo_list("expect 0x6060:00 i8 8\n", "d.sdo").size(), 1u);
}

TEST(SdoList, TheProjectConfigLoadsEachDrivesFile) {
  const RemoteConfig c = load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_EQ(c.interpolation_exponent, -3);
  for (const DriveConfig& d : c.drives) {
    EXPECT_NE(d.sdo_file.find("drives/simdrive.sdo"), std::string::npos) << d.joint;
    EXPECT_DOUBLE_EQ(d.following_error_timeout_s, 0.020);
    int expects = 0;
    bool quick_stop = false;
    for (const SdoEntry& e : d.sdo_entries) {
      expects += e.expect_only;
      if (e.index == 0x605A) quick_stop = e.value == 2;
    }
    EXPECT_EQ(expects, 3) << d.joint;  // 0x1018:01..03
    EXPECT_TRUE(quick_stop) << d.joint;
  }
}

TEST(SdoList, MissingFileIsNamed) {
  const std::string yaml =
      "cycle_rate_hz: 500\nheartbeat: {producer_ms: 50, consumer_ms: 150}\nbuses:\n  - {name: a, interface: mock, bitrate: 1000000}\n"
      "drives:\n  - {joint: j1, bus: a, node_id: 1, counts_per_rev: 131072, gear_ratio: 100, following_error_limit_rad: 0.02, "
      "sdo_file: nowhere.sdo}\n";
  try {
    parse_remote_config(yaml, "/tmp/x/remote.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/tmp/x/nowhere.sdo"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("cannot open the drive's SDO configuration file"), std::string::npos) << e.what();
  }
}

TEST(NodeConfig, InterpolationPeriodInTheUnitsTheDriveExpects) {
  EXPECT_EQ(interpolation_period_value(2000, -3), 2);   // 2 ms in ms
  EXPECT_EQ(interpolation_period_value(2000, -4), 20);  // in 100 us
  EXPECT_EQ(interpolation_period_value(2000, -6), std::nullopt);  // 2000 > 255
  EXPECT_EQ(interpolation_period_value(2500, -3), std::nullopt);  // not whole ms
  EXPECT_EQ(interpolation_period_value(2500, -4), 25);
  EXPECT_EQ(interpolation_period_value(2000, 1), std::nullopt);
}
