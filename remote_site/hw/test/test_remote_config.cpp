#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <regex>

#include "foresight/common/error.hpp"
#include "foresight/hw/remote_config.hpp"
#include "foresight/hw/video_switch.hpp"

using namespace foresight;
using namespace foresight::hw;

namespace {
// A valid base configuration; tests replace one piece to make it bad.
std::string base_yaml(const std::string& drives, const std::string& buses =
                          "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n",
                      const std::string& head = "cycle_rate_hz: 500\n", const std::string& ft =
                          "ft_sensor: {bus: b, node_id: 32, force_counts_per_n: 100, torque_counts_per_nm: 1000}\n") {
  return head + "heartbeat: {producer_ms: 50, consumer_ms: 150}\nbuses:\n" + buses + "drives:\n" + drives + ft;
}
std::string drive(const std::string& joint, const std::string& bus, int node, const std::string& extra = "") {
  return "  - {joint: " + joint + ", bus: " + bus + ", node_id: " + std::to_string(node) +
         (extra.empty() ? ", counts_per_rev: 131072, gear_ratio: 100, following_error_limit_rad: 0.02" : extra) + "}\n";
}
std::string error_of(const std::string& yaml) {
  try {
    parse_remote_config(yaml, "remote.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}
}  // namespace

TEST(RemoteConfig, LoadsTheProjectFile) {
  const RemoteConfig c = load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_EQ(c.cycle_rate_hz, 500.0);
  ASSERT_EQ(c.drives.size(), 7u);
  ASSERT_EQ(c.buses.size(), 2u);
  for (int i = 0; i < 7; ++i) EXPECT_EQ(c.drives[static_cast<std::size_t>(i)].joint, "joint" + std::to_string(i + 1));
  EXPECT_TRUE(c.ft.present);
  EXPECT_EQ(c.ft.bus_index, 1);
  EXPECT_DOUBLE_EQ(c.heartbeat_consumer_s, 0.175);  // 3.5 x the 50 ms producer (docs/hardware.md "Timing defaults")
  // Known loads (SYNC with its 1-byte counter: 65 bits): arm_a 4 drives:
  // (65 + 4*(115+135)) * 500 + (4+1 master)*65/0.05 = 539000 bit/s
  EXPECT_EQ(c.sync_counter_overflow, 240);
  EXPECT_EQ(c.sto_status_bit, 14);
  const auto loads = compute_bus_loads(c);
  ASSERT_EQ(loads.size(), 2u);
  EXPECT_EQ(loads[0].frames_per_cycle, 9);
  EXPECT_EQ(loads[0].bits_per_cycle, 1065);
  // + velocity TPDO2 (4 bytes, 95 bits) every 5th SYNC: 4*95*500/5 = 38000 bit/s -> 577000
  EXPECT_NEAR(loads[0].velocity_bits_per_s, 38000.0, 1e-6);
  EXPECT_NEAR(loads[0].load, 0.5770, 1e-6);
  // arm_b 3 drives + F/T: (65 + 3*250 + 2*135) * 500 + (4+1)*65/0.05 = 549000 bit/s, + 3*95*100 = 577500
  EXPECT_EQ(loads[1].frames_per_cycle, 9);
  EXPECT_EQ(loads[1].bits_per_cycle, 1085);
  EXPECT_NEAR(loads[1].load, 0.5775, 1e-6);
  // Velocity on every SYNC would not fit arm_a: 539000 + 4*95*500 = 729000 bit/s, 72.9% > 70%.
  RemoteConfig every = c;
  every.velocity_tpdo_every = 1;
  EXPECT_NEAR(compute_bus_loads(every)[0].load, 0.729, 1e-6);
  EXPECT_NEAR(compute_bus_loads(every)[1].load, 0.69150, 1e-6);
  // Without the counter, SYNC is 0 bytes (55 bits).
  RemoteConfig no_counter = c;
  no_counter.sync_counter_overflow = 0;
  EXPECT_EQ(compute_bus_loads(no_counter)[0].bits_per_cycle, 1055);
  EXPECT_EQ(c.master_node_id, 127);
}

TEST(RemoteConfig, CountsRadiansRoundTripWithDirectionAndOffset) {
  DriveConfig d;
  d.counts_per_rev = 131072;
  d.gear_ratio = 100;
  d.direction = -1;
  d.offset_rad = 0.25;
  std::int32_t c = 0;
  ASSERT_TRUE(d.to_counts(0.25 + std::numbers::pi / 2, c));
  EXPECT_EQ(c, -131072 * 100 / 4);
  EXPECT_NEAR(d.to_rad(c), 0.25 + std::numbers::pi / 2, 1e-9);
  EXPECT_FALSE(d.to_counts(std::nan(""), c));
  EXPECT_FALSE(d.to_counts(1e6, c));  // beyond int32
}

TEST(RemoteConfig, SevenDrivesOnOneBusAt500HzAreRefusedWithTheNumbers) {
  std::string drives;
  for (int i = 1; i <= 7; ++i) drives += drive("joint" + std::to_string(i), "b", i);
  const std::string msg = error_of(base_yaml(drives));
  // (55 + 7*250 + 270) * 500 + 7*95*500/5 (velocity) + (8+1)*65/0.05 = 1115700 bit/s
  EXPECT_NE(msg.find("remote.yaml:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("bus b: 7 drives + F/T, 17 frames/cycle"), std::string::npos) << msg;
  EXPECT_NE(msg.find("2075 bits/cycle"), std::string::npos) << msg;
  EXPECT_NE(msg.find("x 500 Hz + velocity TPDOs 66500 bit/s + heartbeats 11700 bit/s"), std::string::npos) << msg;
  EXPECT_NE(msg.find("111.6% of 1000 kbit/s"), std::string::npos) << msg;
  EXPECT_NE(msg.find("exceeds the 70% limit"), std::string::npos) << msg;
  // The same bus at 250 Hz fits (56.4%).
  const RemoteConfig ok = parse_remote_config(base_yaml(drives, "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n", "cycle_rate_hz: 250\n"), "x");
  EXPECT_NEAR(compute_bus_loads(ok)[1].load, 0.5637, 1e-6);
}

TEST(RemoteConfig, DuplicateNodeIdOnABusIsNamed) {
  const std::string msg = error_of(base_yaml(drive("joint1", "a", 1) + drive("joint2", "a", 2) + drive("joint3", "a", 2)));
  EXPECT_EQ(msg, "remote.yaml:9: drives[2] (joint3): node_id 2 on bus 'a' is already used by drives[1] (joint2)");
  // The same node id on another bus is fine.
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1) + drive("joint2", "b", 1))), "no error");
}

TEST(RemoteConfig, FtNodeIdCollidingWithADriveIsNamed) {
  const std::string msg = error_of(base_yaml(drive("joint1", "b", 32)));
  EXPECT_NE(msg.find("ft_sensor: node_id 32 on bus 'b' is already used by drives[0] (joint1)"), std::string::npos) << msg;
}

TEST(RemoteConfig, MissingScalingIsNamed) {
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", gear_ratio: 100, following_error_limit_rad: 0.02"))),
            "remote.yaml:7: drives[0] (joint1): missing 'counts_per_rev' (scaling: encoder counts per motor revolution)");
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 0, gear_ratio: 100, following_error_limit_rad: 0.02"))),
            "remote.yaml:7: drives[0] (joint1).counts_per_rev: 0 is outside [1, 2147483648] counts per motor revolution");
  const std::string ft = error_of(base_yaml(drive("joint1", "a", 1), "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n",
                                            "cycle_rate_hz: 500\n", "ft_sensor: {bus: b, node_id: 32, force_counts_per_n: 100}\n"));
  EXPECT_NE(ft.find("ft_sensor: missing 'torque_counts_per_nm' (scaling: int16 counts per N*m)"), std::string::npos) << ft;
}

// Issue 26's classes in remote.yaml: a value 0x1016 cannot hold (16-bit
// milliseconds: 65536 would become 0, the drives stop watching the master), a
// NaN that once passed its range, a duplicated key, a second document.
TEST(RemoteConfig, ValuesTheHardwareCannotHoldNaNAndDuplicatesAreRefused) {
  const std::string drives = drive("joint1", "a", 1);
  auto with_hb = [&](const std::string& hb) {
    std::string y = base_yaml(drives);
    y.replace(y.find("heartbeat: {producer_ms: 50, consumer_ms: 150}"), 46, hb);
    return y;
  };
  EXPECT_EQ(error_of(with_hb("heartbeat: {producer_ms: 50, consumer_ms: 65536}")),
            "remote.yaml:2: heartbeat.consumer_ms: 65536 is outside [1, 65535] ms (0x1016 holds 16 bits)");
  EXPECT_EQ(error_of(with_hb("heartbeat: {producer_ms: .nan, consumer_ms: 150}")),
            "remote.yaml:2: heartbeat.producer_ms: nan is outside [1, 65000] ms");
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 100, "
                                                     "following_error_limit_rad: 0.02, following_error_timeout_ms: .nan"))),
            "remote.yaml:7: drives[0] (joint1).following_error_timeout_ms: nan is outside [0, 65535] ms (0x6066, 16 bits)");
  EXPECT_EQ(error_of(base_yaml(drives, "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n",
                               "cycle_rate_hz: 500\nmax_bus_load: .inf\n")),
            "remote.yaml:2: max_bus_load: inf is outside [0.01, 1] (fraction of the bit rate)");
  EXPECT_EQ(error_of(base_yaml(drives, "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n",
                               "cycle_rate_hz: 500\ncycle_rate_hz: 1000000000\n")),
            "remote.yaml:2: duplicate key 'cycle_rate_hz' (first on line 1)");
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", node_id: 2, counts_per_rev: 131072, gear_ratio: 100, following_error_limit_rad: 0.02"))),
            "remote.yaml:7: duplicate key 'node_id' (first on line 7)");
  EXPECT_EQ(error_of(base_yaml(drives) + "---\ncycle_rate_hz: 1000\n"),
            "remote.yaml:9: a second YAML document (one document per file)");
  EXPECT_EQ(error_of(base_yaml(drives)), "no error");
  // The rest of the keys on the same range reader: counts, codes and ids are
  // integers in their range; every scaling has one.
  const std::string two_buses = "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n";
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: .nan\n")),
            "remote.yaml:1: cycle_rate_hz: nan is outside [40, 4000] Hz");
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: 500\ntpdo_miss_limit: 0\n")),
            "remote.yaml:2: tpdo_miss_limit: 0 is outside [1, 1000] cycles");
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: 500\ninterpolation_exponent: -4.5\n")),
            "remote.yaml:2: interpolation_exponent: not an integer: '-4.5'");
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: 500\nsync_counter_overflow: 1\n")),
            "remote.yaml:2: sync_counter_overflow: 1 is not a counter overflow (CiA 301 0x1019: 2..240, or 0 for no counter)");
  // Issue 25, item 9: the drives' STO status bit is one of CiA 402's manufacturer-specific bits.
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: 500\nsto_status_bit: 3\n")),
            "remote.yaml:2: sto_status_bit: 3 is a bit CiA 402 defines itself: the drive's STO status is one of the "
            "manufacturer-specific bits 8, 14 or 15 (or -1: not wired)");
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: 500\nsto_status_bit: 16\n")),
            "remote.yaml:2: sto_status_bit: 16 is outside [-1, 15] (a statusword bit)");
  EXPECT_EQ(error_of(base_yaml(drives, two_buses, "cycle_rate_hz: 500\nbus_off_restart_limit: 1e9\n")),
            "remote.yaml:2: bus_off_restart_limit: not an integer: '1e9'");
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 100, following_error_limit_rad: 2"))),
            "remote.yaml:7: drives[0] (joint1).following_error_limit_rad: 2 is outside [1e-05, 0.5] rad (0x6065)");
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 1e300, following_error_limit_rad: 0.02"))),
            "remote.yaml:7: drives[0] (joint1).gear_ratio: 1e+300 is outside [0.001, 100000] motor revolutions per joint revolution");
  EXPECT_EQ(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 100, offset_rad: .inf, following_error_limit_rad: 0.02"))),
            "remote.yaml:7: drives[0] (joint1).offset_rad: inf is outside [-6.283185307, 6.283185307] rad");
  EXPECT_EQ(error_of(base_yaml(drives, "  - {name: a, interface: mock, bitrate: 1e12}\n  - {name: b, interface: mock, bitrate: 1000000}\n")),
            "remote.yaml:4: buses[0].bitrate: not an integer: '1e12'");
  EXPECT_EQ(error_of(base_yaml(drives, "  - {name: a, interface: can0, bitrate: 1000000}\n  - {name: b, interface: can0, bitrate: 1000000}\n")),
            "remote.yaml:5: buses[1] (b): interface 'can0' is already bus 'a'");
}

// Heartbeat and boot-up times that make the bring-up outlast the systemd
// unit's start timeout: refused with what the start-up is made of.
TEST(RemoteConfig, AStartUpLongerThanTheUnitAllowsIsRefused) {
  const std::string drives = drive("joint1", "a", 1) + drive("joint2", "a", 2);
  std::string y = base_yaml(drives);
  y.replace(y.find("heartbeat: {producer_ms: 50, consumer_ms: 150}"), 46,
            "heartbeat: {producer_ms: 15000, consumer_ms: 60000}");
  EXPECT_EQ(error_of(y), "remote.yaml: start-up: the drives' bring-up could take up to 62.7 s (boot-up wait 2 s, 132 "
                         "SDO transfers 0.66 s, the first operational heartbeat 60 s), over the 45 s the daemon has "
                         "to start within the systemd unit's TimeoutStartSec (60 s): shorten heartbeat.consumer_ms, "
                         "enable_timeout_ms or the SDO files");
  // The shipped configuration starts well within it.
  const RemoteConfig shipped = load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_LT(estimate_startup(shipped).total_s(), 10.0) << estimate_startup(shipped).describe();
}

TEST(RemoteConfig, OtherBadInputsAreNamed) {
  EXPECT_NE(error_of(base_yaml(drive("joint1", "c", 1))).find("drives[0] (joint1): bus 'c' is not defined in buses"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 128))).find("remote.yaml:7: drives[0] (joint1).node_id: 128 is outside [1, 127] (CANopen node id)"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 127))).find("drives[0] (joint1): node_id 127 is the master's heartbeat id"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1) + drive("joint1", "a", 2))).find("joint 'joint1' has two drives"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 100, direction: 2, following_error_limit_rad: 0.02")))
                .find("drives[0] (joint1).direction: 2 is outside [-1, 1] (1 or -1)"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 100, direction: 0, following_error_limit_rad: 0.02")))
                .find("drives[0] (joint1): direction must be 1 or -1, not 0"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1, ", counts_per_rev: 131072, gear_ratio: 100, following_error_limit_rad: 0.02, gain: 3")))
                .find("remote.yaml:7: drives[0] (joint1).gain: unknown key (expected one of: joint, bus, node_id, "
                      "counts_per_rev, gear_ratio, direction, offset_rad, following_error_limit_rad, "
                      "following_error_timeout_ms, sdo_file, homing)"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1), "  - {name: a, interface: mock, bitrate: 900000}\n"))
                .find("buses[0] (a): bitrate 900000 is not a CiA 301 bit rate"), std::string::npos);
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1), "  - {name: a, interface: mock, bitrate: 1000000}\n  - {name: b, interface: mock, bitrate: 1000000}\n", "cycle_rate_hz: 300\n"))
                .find("is not a multiple of 0.1 ms"), std::string::npos);
  // Malformed YAML in the words every config reader uses (common/yaml_util).
  const std::string malformed = error_of("cycle_rate_hz: [500\n");
  EXPECT_EQ(malformed.rfind("remote.yaml:", 0), 0u) << malformed;
  EXPECT_NE(malformed.find(": malformed YAML: "), std::string::npos) << malformed;
  EXPECT_NE(error_of(base_yaml(drive("joint1", "a", 1), "  - {name: a, interface: mock, bitrate: fast}\n"))
                .find(": buses[0].bitrate: not an integer: 'fast'"), std::string::npos);
  EXPECT_EQ(error_of("cycle_rate_hz: fast\n"), "remote.yaml:1: cycle_rate_hz: not a number: 'fast'");
  EXPECT_EQ(error_of("cycle_rate_hz: 500\nheartbeat: {producer_ms: 10, consumer_ms: 50, master_node_id: [1]}\n"),
            "remote.yaml:2: heartbeat.master_node_id: not an integer (a list)");
  EXPECT_EQ(error_of("cycle_rate_hz: 500\nheartbeat: {producer_ms: 10, consumer_ms: 50}\nbeat: 3\n"),
            "remote.yaml:3: beat: unknown key (expected one of: cycle_rate_hz, heartbeat, sdo_timeout_ms, "
            "enable_timeout_ms, power_step_timeout_ms, tpdo_miss_limit, max_bus_load, interpolation_exponent, sync_counter_overflow, "
            "sto_status_bit, bus_off_restart_limit, velocity_tpdo_every, buses, drives, ft_sensor, tool, video_switch, controller)");
  EXPECT_EQ(error_of("cycle_rate_hz: 500\n"), "remote.yaml:1: top level: missing 'heartbeat' (producer_ms, consumer_ms)");
  EXPECT_EQ(error_of("- 1\n"), "remote.yaml:1: expected a map at the top level");
  // A section that is a scalar where a map belongs (yaml-cpp threw its own
  // BadSubscript before, without the file: fuzz_remote_yaml).
  EXPECT_EQ(error_of("cycle_rate_hz: 500\nheartbeat: 5\n"), "remote.yaml:2: heartbeat: expected a map");
  EXPECT_NE(error_of("cycle_rate_hz: 500\nheartbeat:\n").find(": heartbeat: expected a map"), std::string::npos);
  try {
    load_remote_config("/nonexistent/remote.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/remote.yaml: cannot open the remote configuration file");
  }
}

// ---- the optional video_switch: section ----

namespace {
std::string video_error(const std::string& yaml) {
  try {
    foresight::hw::parse_video_switch_section(yaml, "remote.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}
}  // namespace

// A heartbeat consumer time below 3 x the producer period is refused: one lost
// heartbeat and the jitter of the next would stop the arm (the drives fault
// on the silent master, EMCY 0x8130; the master stops on HeartbeatLost).
// Exactly 3 x is accepted (two lost in a row then stop it: ~36/h at 1% loss,
// docs/hardware.md); the project file uses 3.5 x.
TEST(RemoteConfig, HeartbeatConsumerBelowThreeProducerPeriodsIsRefused) {
  auto with_heartbeat = [](const std::string& hb) {
    std::string y = base_yaml(drive("joint1", "a", 1));
    const std::string from = "heartbeat: {producer_ms: 50, consumer_ms: 150}";
    return y.replace(y.find(from), from.size(), hb);
  };
  EXPECT_EQ(error_of(with_heartbeat("heartbeat: {producer_ms: 50, consumer_ms: 149}")),
            "remote.yaml: heartbeat.consumer_ms 149 is below 3 x producer_ms 50 (150 ms): one lost heartbeat and "
            "the jitter of the next would stop the arm; use >= 3.5 x (175 ms)");
  EXPECT_EQ(error_of(with_heartbeat("heartbeat: {producer_ms: 100, consumer_ms: 250}")),
            "remote.yaml: heartbeat.consumer_ms 250 is below 3 x producer_ms 100 (300 ms): one lost heartbeat and "
            "the jitter of the next would stop the arm; use >= 3.5 x (350 ms)");
  EXPECT_EQ(error_of(with_heartbeat("heartbeat: {producer_ms: 50, consumer_ms: 150}")), "no error");
  EXPECT_EQ(error_of(with_heartbeat("heartbeat: {producer_ms: 50, consumer_ms: 175}")), "no error");
  // The project file: the production timing defaults.
  const RemoteConfig c = load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_DOUBLE_EQ(c.heartbeat_producer_s, 0.050);
  EXPECT_DOUBLE_EQ(c.heartbeat_consumer_s, 0.175);
  EXPECT_DOUBLE_EQ(c.sdo_timeout_s, 0.5);
  EXPECT_EQ(c.tpdo_miss_limit, 5);
}

TEST(VideoSwitchSection, TheProjectFileNamesTheSceneCamerasInSwitchOrder) {
  const auto s = foresight::hw::load_video_switch_section(FORESIGHT_CONFIG_DIR "/remote.yaml");
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->camera_names, (std::vector<std::string>{"side", "oblique", "overhead_wide", "overhead_zoom"}));
  EXPECT_EQ(s->link.port, 1503);
  EXPECT_DOUBLE_EQ(s->link.response_timeout_s, 0.1);
  EXPECT_EQ(s->link.retries, 2);
  // The section is a known top-level key of remote.yaml.
  EXPECT_NO_THROW(load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml"));
}

TEST(VideoSwitchSection, AbsentIsNoneAndBadValuesAreNamed) {
  EXPECT_FALSE(foresight::hw::parse_video_switch_section("cycle_rate_hz: 500\n", "remote.yaml").has_value());
  const std::string head = "cycle_rate_hz: 500\nvideo_switch:\n";
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  port: 70000\n  cameras: [a]\n"),
            "remote.yaml:4: video_switch.port: 70000 is outside [1, 65535] (TCP port)");
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  cameras: []\n"),
            "remote.yaml:4: video_switch.cameras: must be a non-empty list of camera names (index = switch input)");
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  cameras: [a, b, a]\n"),
            "remote.yaml:4: video_switch.cameras: 'a' is listed twice");
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  zoom: 3\n  cameras: [a]\n"),
            "remote.yaml:4: video_switch.zoom: unknown key (expected one of: host, port, unit_id, response_timeout_ms, "
            "retries, cameras)");
  EXPECT_EQ(video_error(head + "  port: 502\n  cameras: [a]\n"),
            "remote.yaml:3: video_switch: missing 'host' (the switch's address)");
  EXPECT_EQ(video_error(head + "  host: [a]\n  cameras: [a]\n"), "remote.yaml:3: video_switch.host: not a string (a list)");
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  cameras: [a, [b]]\n"),
            "remote.yaml:4: video_switch.cameras: a name must be a non-empty string");
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  retries: 11\n  cameras: [a]\n"),
            "remote.yaml:4: video_switch.retries: 11 is outside [0, 10] retries");
  EXPECT_EQ(video_error(head + "  host: 10.0.0.2\n  response_timeout_ms: 0\n  cameras: [a]\n"),
            "remote.yaml:4: video_switch.response_timeout_ms: 0 is outside [1, 10000] ms");
  EXPECT_EQ(video_error("video_switch: 5\n"), "remote.yaml:1: video_switch: expected a map");
}
