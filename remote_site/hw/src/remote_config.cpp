#include "foresight/hw/remote_config.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <set>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/hw/canopen.hpp"

namespace foresight::hw {

double DriveConfig::counts_per_rad() const {
  return direction * counts_per_rev * gear_ratio / (2.0 * std::numbers::pi);
}

bool DriveConfig::to_counts(double q_rad, std::int32_t& counts) const noexcept {
  const double c = std::round((q_rad - offset_rad) * direction * counts_per_rev * gear_ratio /
                              (2.0 * std::numbers::pi));
  if (!std::isfinite(c) || c > std::numeric_limits<std::int32_t>::max() ||
      c < std::numeric_limits<std::int32_t>::min())
    return false;
  counts = static_cast<std::int32_t>(c);
  return true;
}

double DriveConfig::to_rad(std::int32_t counts) const noexcept {
  return offset_rad + static_cast<double>(counts) * 2.0 * std::numbers::pi /
                          (direction * counts_per_rev * gear_ratio);
}

int RemoteConfig::bus_index(const std::string& name) const {
  for (std::size_t i = 0; i < buses.size(); ++i)
    if (buses[i].name == name) return static_cast<int>(i);
  return -1;
}

namespace {

std::string drive_name(std::size_t i, const std::string& joint) {
  return "drives[" + std::to_string(i) + "]" + (joint.empty() ? "" : " (" + joint + ")");
}

}  // namespace

RemoteConfig parse_remote_config(const std::string& yaml_text, const std::string& source_name) {
  // The project's one YAML reader and its wording (yaml::parse, yaml::MapReader).
  const yaml::MapReader top(yaml::parse(yaml_text, source_name), source_name, "");
  top.check_keys({"cycle_rate_hz", "heartbeat", "sdo_timeout_ms", "enable_timeout_ms", "power_step_timeout_ms", "tpdo_miss_limit",
                  "max_bus_load", "interpolation_exponent", "sync_counter_overflow", "sto_status_bit", "bus_off_restart_limit",
                  "velocity_tpdo_every", "buses",
                  "drives", "ft_sensor", "tool", "video_switch", "controller"});

  RemoteConfig c;
  c.source = source_name;
  // Every number with a physical meaning in its range, with its unit, in the
  // one wording of the YAML reader (get_in / get_int_in): the file, line and key.
  c.cycle_rate_hz = top.get_in("cycle_rate_hz", 40, 4000, "Hz");
  {
    const yaml::MapReader hb = top.map("heartbeat", "producer_ms, consumer_ms");
    hb.check_keys({"producer_ms", "consumer_ms", "master_node_id"});
    // CiA 301: producer 0x1017 and consumer 0x1016 times are 16-bit milliseconds.
    c.heartbeat_producer_s = hb.get_in("producer_ms", 1, 65000, "ms") * 1e-3;
    c.heartbeat_consumer_s = hb.get_in("consumer_ms", 1, 65535, "ms (0x1016 holds 16 bits)") * 1e-3;
    c.master_node_id =
        static_cast<std::uint8_t>(hb.get_or_int_in("master_node_id", 127, 1, canopen::kMaxNodeId, "(CANopen node id)"));
  }
  c.sdo_timeout_s = top.get_or_in("sdo_timeout_ms", 500.0, 1, 10000, "ms") * 1e-3;
  c.enable_timeout_s = top.get_or_in("enable_timeout_ms", 2000.0, 1, 60000, "ms") * 1e-3;
  c.power_step_timeout_s = top.get_or_in("power_step_timeout_ms", 500.0, 1, 60000, "ms") * 1e-3;
  c.tpdo_miss_limit = static_cast<int>(top.get_or_int_in("tpdo_miss_limit", 5, 1, 1000, "cycles"));
  c.sto_status_bit = static_cast<int>(top.get_or_int_in("sto_status_bit", -1, -1, 15, "(a statusword bit)"));
  if (c.sto_status_bit != -1 && c.sto_status_bit != 8 && c.sto_status_bit != 14 && c.sto_status_bit != 15)
    top.fail_key("sto_status_bit", std::to_string(c.sto_status_bit) +
                                       " is a bit CiA 402 defines itself: the drive's STO status is one of the "
                                       "manufacturer-specific bits 8, 14 or 15 (or -1: not wired)");
  c.max_bus_load = top.get_or_in("max_bus_load", 0.70, 0.01, 1.0, "(fraction of the bit rate)");
  c.interpolation_exponent =
      static_cast<int>(top.get_or_int_in("interpolation_exponent", -4, -6, 0, "(0x60C2:02, 10^x s)"));
  c.sync_counter_overflow = static_cast<int>(
      top.get_or_int_in("sync_counter_overflow", 0, 0, 240, "(CiA 301 0x1019: 2..240, or 0 for no counter)"));
  if (c.sync_counter_overflow == 1)
    top.fail_key("sync_counter_overflow", "1 is not a counter overflow (CiA 301 0x1019: 2..240, or 0 for no counter)");
  c.bus_off_restart_limit = static_cast<int>(top.get_or_int_in("bus_off_restart_limit", 3, 0, 100, "restarts"));
  c.velocity_tpdo_every = static_cast<int>(top.get_or_int_in(
      "velocity_tpdo_every", 5, 0, 240, "SYNCs per TPDO2 (CiA 301 0x1801:02), or 0 for no velocity"));
  std::string base_dir;
  if (const auto slash = source_name.rfind('/'); slash != std::string::npos) base_dir = source_name.substr(0, slash + 1);

  const YAML::Node buses = top["buses"];
  if (!buses || !buses.IsSequence() || buses.size() == 0)
    top.fail(buses, "top level: 'buses' must be a non-empty list");
  for (std::size_t i = 0; i < buses.size(); ++i) {
    const yaml::MapReader b(buses[i], source_name, "buses[" + std::to_string(i) + "]");
    b.check_keys({"name", "interface", "bitrate"});
    BusConfig bc;
    bc.name = b.get<std::string>("name");
    bc.interface = b.get<std::string>("interface", "SocketCAN name like can0, or mock");
    bc.bitrate_bps = static_cast<std::uint32_t>(b.get_int_in("bitrate", 10000, 1000000, "bit/s"));  // CiA 301's set: validate
    bc.line = b.line();
    c.buses.push_back(bc);
  }

  const YAML::Node drives = top["drives"];
  if (!drives || !drives.IsSequence() || drives.size() == 0)
    top.fail(drives, "top level: 'drives' must be a non-empty list");
  for (std::size_t i = 0; i < drives.size(); ++i) {
    DriveConfig dc;
    dc.joint = yaml::MapReader(drives[i], source_name, drive_name(i, "")).get_or<std::string>("joint", "");
    const yaml::MapReader d(drives[i], source_name, drive_name(i, dc.joint));  // named by its joint from here on
    d.check_keys({"joint", "bus", "node_id", "counts_per_rev", "gear_ratio", "direction", "offset_rad",
                  "following_error_limit_rad", "following_error_timeout_ms", "sdo_file", "homing"});
    if (dc.joint.empty()) d.fail(d.node(), d.label() + ": missing 'joint' (URDF joint name)");
    dc.bus = d.get<std::string>("bus");
    dc.node_id = static_cast<std::uint8_t>(d.get_int_in("node_id", 1, canopen::kMaxNodeId, "(CANopen node id)"));
    dc.counts_per_rev = d.get_in("counts_per_rev", 1, 2147483648.0, "counts per motor revolution",
                                 "scaling: encoder counts per motor revolution");
    dc.gear_ratio = d.get_in("gear_ratio", 0.001, 100000, "motor revolutions per joint revolution",
                             "scaling: motor revolutions per joint revolution");
    dc.direction = static_cast<int>(d.get_or_int_in("direction", 1, -1, 1, "(1 or -1)"));
    dc.offset_rad = d.get_or_in("offset_rad", 0.0, -2.0 * std::numbers::pi, 2.0 * std::numbers::pi, "rad");
    // 0x6065, in counts: a window as wide as half a radian is no window.
    dc.following_error_limit_rad = d.get_in("following_error_limit_rad", 1e-5, 0.5, "rad (0x6065)");
    dc.following_error_timeout_s = d.get_or_in("following_error_timeout_ms", 0.0, 0, 65535, "ms (0x6066, 16 bits)") * 1e-3;
    if (d["sdo_file"]) {
      const std::string f = d.get<std::string>("sdo_file");
      dc.sdo_file = (!f.empty() && f[0] == '/') ? f : base_dir + f;
      dc.sdo_entries = load_sdo_list(dc.sdo_file);  // InputError names the list's own file and line
    }
    if (d["homing"]) {  // incremental encoder: CiA 402 homing at bring-up (DriveSystem::home)
      const yaml::MapReader h = d.map("homing");
      h.check_keys({"method", "speed_switch_rad_s", "speed_zero_rad_s", "acceleration_rad_s2", "timeout_ms"});
      HomingConfig& hc = dc.homing;
      hc.enabled = true;
      hc.method = h.get<int>("method", "CiA 402 homing method, 0x6098");
      if (hc.method < 1 || (hc.method > 35 && hc.method != 37))
        h.fail_key("method", std::to_string(hc.method) + " is not a CiA 402 homing method (1..35, 37)");
      const std::pair<const char*, double*> positive[] = {{"speed_switch_rad_s", &hc.speed_switch_rad_s},
                                                          {"speed_zero_rad_s", &hc.speed_zero_rad_s},
                                                          {"acceleration_rad_s2", &hc.acceleration_rad_s2}};
      for (const auto& [key, out] : positive) {
        *out = h.get<double>(key);
        if (!(*out > 0.0) || !std::isfinite(*out)) h.fail_key(key, "must be a positive finite number");
      }
      hc.timeout_s = h.get_or_in("timeout_ms", 30000.0, 1, 600000, "ms") * 1e-3;
    }
    dc.line = d.line();
    c.drives.push_back(dc);
  }

  if (top["ft_sensor"]) {
    const yaml::MapReader f = top.map("ft_sensor");
    f.check_keys({"bus", "node_id", "force_counts_per_n", "torque_counts_per_nm"});
    c.ft.present = true;
    c.ft.bus = f.get<std::string>("bus");
    c.ft.node_id = static_cast<std::uint8_t>(f.get_int_in("node_id", 1, canopen::kMaxNodeId, "(CANopen node id)"));
    // int16 counts: below 1 count per 100 N the sensor reads nothing, above 10^5 it saturates at 0.3 N.
    c.ft.force_counts_per_n = f.get_in("force_counts_per_n", 0.01, 100000, "int16 counts per N", "scaling: int16 counts per N");
    c.ft.torque_counts_per_nm =
        f.get_in("torque_counts_per_nm", 0.01, 100000, "int16 counts per N*m", "scaling: int16 counts per N*m");
    c.ft.line = f.line();
  }

  validate(c);
  return c;
}

RemoteConfig load_remote_config(const std::string& path) {
  return parse_remote_config(read_text_file(path, "cannot open the remote configuration file"), path);
}

void validate(RemoteConfig& c) {
  const std::string& src = c.source.empty() ? std::string("<remote config>") : c.source;
  auto fail = [&](int line, const std::string& msg) { throw InputError(src, line, msg); };
  char buf[256];

  if (!(c.cycle_rate_hz >= 40.0 && c.cycle_rate_hz <= 4000.0))
    fail(0, "cycle_rate_hz " + std::to_string(c.cycle_rate_hz) + " is outside 40..4000 Hz");
  const double period_100us = 1e4 / c.cycle_rate_hz;
  if (std::abs(period_100us - std::round(period_100us)) > 1e-6) {
    std::snprintf(buf, sizeof buf, "cycle_rate_hz %g: the period %.6g ms is not a multiple of 0.1 ms "
                  "(interpolation period 0x60C2 is set in 100 us units)", c.cycle_rate_hz, 1e3 / c.cycle_rate_hz);
    fail(0, buf);
  }
  if (!(c.heartbeat_producer_s >= 0.001 && c.heartbeat_producer_s <= 65.0))
    fail(0, "heartbeat.producer_ms must be 1..65000");
  if (!(c.heartbeat_consumer_s <= 65.535))  // 0x1016's 16 bits: 65536 ms would become 0 (not watched)
    fail(0, "heartbeat.consumer_ms must be at most 65535 (0x1016 holds 16 bits)");
  if (!(c.heartbeat_consumer_s > c.heartbeat_producer_s))
    fail(0, "heartbeat.consumer_ms must be larger than heartbeat.producer_ms (a margin for jitter)");
  // Below 3 x, two heartbeats lost in a row (or one lost and the next late by
  // the bus's jitter) leave a node silent past the consumer time: a false
  // HeartbeatLost stop on the master, EMCY 0x8130 faulting the drives. At
  // exactly 3 x it still happens whenever two lost heartbeats meet jitter
  // (~36/h at 1% loss); the project uses 3.5 x (docs/hardware.md).
  if (c.heartbeat_consumer_s < 3.0 * c.heartbeat_producer_s - 1e-9) {
    std::snprintf(buf, sizeof buf,
                  "heartbeat.consumer_ms %g is below 3 x producer_ms %g (%g ms): one lost heartbeat and the "
                  "jitter of the next would stop the arm; use >= 3.5 x (%g ms)",
                  c.heartbeat_consumer_s * 1e3, c.heartbeat_producer_s * 1e3, 3.0 * c.heartbeat_producer_s * 1e3,
                  3.5 * c.heartbeat_producer_s * 1e3);
    fail(0, buf);
  }
  if (!(c.sdo_timeout_s > 0.0 && c.sdo_timeout_s <= 10.0)) fail(0, "sdo_timeout_ms must be in (0, 10000]");
  if (!(c.enable_timeout_s > 0.0 && c.enable_timeout_s <= 60.0)) fail(0, "enable_timeout_ms must be in (0, 60000]");
  if (!(c.power_step_timeout_s > 0.0 && c.power_step_timeout_s <= 60.0))
    fail(0, "power_step_timeout_ms must be in (0, 60000]");
  if (c.tpdo_miss_limit < 1 || c.tpdo_miss_limit > 1000) fail(0, "tpdo_miss_limit must be 1..1000");
  if (!(c.max_bus_load > 0.0 && c.max_bus_load <= 1.0)) fail(0, "max_bus_load must be in (0, 1]");

  static const std::set<std::uint32_t> kBitrates = {10000, 20000, 50000, 125000, 250000, 500000, 800000, 1000000};
  std::set<std::string> bus_names;
  for (std::size_t i = 0; i < c.buses.size(); ++i) {
    const BusConfig& b = c.buses[i];
    const std::string where = "buses[" + std::to_string(i) + "] (" + b.name + ")";
    if (b.name.empty()) fail(b.line, "buses[" + std::to_string(i) + "]: empty name");
    if (!bus_names.insert(b.name).second) fail(b.line, where + ": duplicate bus name '" + b.name + "'");
    if (b.interface.empty()) fail(b.line, where + ": empty interface (use can0... or mock)");
    // Two buses on one interface would share its frames: two masters' worth of
    // SYNCs and two drives answering each node id (each mock bus is its own).
    if (b.interface != "mock")
      for (std::size_t k = 0; k < i; ++k)
        if (c.buses[k].interface == b.interface)
          fail(b.line, where + ": interface '" + b.interface + "' is already bus '" + c.buses[k].name + "'");
    if (!kBitrates.count(b.bitrate_bps))
      fail(b.line, where + ": bitrate " + std::to_string(b.bitrate_bps) +
                       " is not a CiA 301 bit rate (10k, 20k, 50k, 125k, 250k, 500k, 800k, 1M)");
  }

  if (c.drives.empty()) fail(0, "no drives configured");
  std::set<std::string> joints;
  for (std::size_t i = 0; i < c.drives.size(); ++i) {
    DriveConfig& d = c.drives[i];
    const std::string where = drive_name(i, d.joint);
    if (d.joint.empty()) fail(d.line, where + ": empty joint name");
    if (!joints.insert(d.joint).second) fail(d.line, where + ": joint '" + d.joint + "' has two drives");
    d.bus_index = c.bus_index(d.bus);
    if (d.bus_index < 0) fail(d.line, where + ": bus '" + d.bus + "' is not defined in buses");
    if (d.node_id < 1 || d.node_id > canopen::kMaxNodeId)
      fail(d.line, where + ": node_id " + std::to_string(d.node_id) + " is outside 1..127");
    if (!(d.counts_per_rev > 0.0 && std::isfinite(d.counts_per_rev)))
      fail(d.line, where + ": counts_per_rev must be > 0 (missing or bad scaling)");
    if (!(d.gear_ratio > 0.0 && std::isfinite(d.gear_ratio)))
      fail(d.line, where + ": gear_ratio must be > 0 (missing or bad scaling; use direction for the sign)");
    if (d.counts_per_rev * d.gear_ratio > 2147483648.0)
      fail(d.line, where + ": counts_per_rev x gear_ratio exceeds 2^31 counts per joint revolution "
                          "(position would overflow the drive's int32)");
    if (d.direction != 1 && d.direction != -1)
      fail(d.line, where + ": direction must be 1 or -1, not " + std::to_string(d.direction));
    if (!std::isfinite(d.offset_rad) || std::abs(d.offset_rad) > 2.0 * std::numbers::pi)
      fail(d.line, where + ": offset_rad must be finite and within +-2 pi");
    if (!(d.following_error_limit_rad > 0.0 && d.following_error_limit_rad < 1.0))
      fail(d.line, where + ": following_error_limit_rad must be in (0, 1) rad");
    if (d.node_id == c.master_node_id)
      fail(d.line, where + ": node_id " + std::to_string(d.node_id) + " is the master's heartbeat id (heartbeat.master_node_id)");
    for (std::size_t j = 0; j < i; ++j) {
      const DriveConfig& o = c.drives[j];
      if (o.bus_index == d.bus_index && o.node_id == d.node_id)
        fail(d.line, where + ": node_id " + std::to_string(d.node_id) + " on bus '" + d.bus +
                         "' is already used by " + drive_name(j, o.joint));
    }
  }
  if (c.ft.present) {
    FtConfig& f = c.ft;
    f.bus_index = c.bus_index(f.bus);
    if (f.bus_index < 0) fail(f.line, "ft_sensor: bus '" + f.bus + "' is not defined in buses");
    if (f.node_id < 1 || f.node_id > canopen::kMaxNodeId)
      fail(f.line, "ft_sensor: node_id " + std::to_string(f.node_id) + " is outside 1..127");
    if (!(f.force_counts_per_n > 0.0 && std::isfinite(f.force_counts_per_n)))
      fail(f.line, "ft_sensor: force_counts_per_n must be > 0 (missing or bad scaling)");
    if (!(f.torque_counts_per_nm > 0.0 && std::isfinite(f.torque_counts_per_nm)))
      fail(f.line, "ft_sensor: torque_counts_per_nm must be > 0 (missing or bad scaling)");
    if (f.node_id == c.master_node_id)
      fail(f.line, "ft_sensor: node_id " + std::to_string(f.node_id) + " is the master's heartbeat id (heartbeat.master_node_id)");
    for (std::size_t j = 0; j < c.drives.size(); ++j)
      if (c.drives[j].bus_index == f.bus_index && c.drives[j].node_id == f.node_id)
        fail(f.line, "ft_sensor: node_id " + std::to_string(f.node_id) + " on bus '" + f.bus +
                         "' is already used by " + drive_name(j, c.drives[j].joint));
  }

  // A start-up systemd would kill half-way (TimeoutStartSec) is refused here,
  // with what it is made of.
  if (const StartupEstimate st = estimate_startup(c); !(st.total_s() <= kStartupBudget_s)) {
    std::snprintf(buf, sizeof buf, "%.0f", kStartupBudget_s);
    fail(0, "start-up: the drives' bring-up could take " + st.describe() + ", over the " + buf +
                " s the daemon has to start within the systemd unit's TimeoutStartSec (60 s): shorten "
                "heartbeat.consumer_ms, enable_timeout_ms or the SDO files");
  }

  for (const BusLoad& l : compute_bus_loads(c)) {
    if (l.load > c.max_bus_load) {
      std::snprintf(buf, sizeof buf, " exceeds the %.0f%% limit: lower cycle_rate_hz or split the drives over more buses",
                    c.max_bus_load * 100.0);
      fail(c.buses[static_cast<std::size_t>(c.bus_index(l.bus))].line, l.describe() + buf);
    }
  }
}

StartupEstimate estimate_startup(const RemoteConfig& c) {
  StartupEstimate e;
  e.boot_s = c.enable_timeout_s;
  for (const DriveConfig& d : c.drives)
    e.sdo_transfers += kMasterSdoTransfersPerDrive + 2 * static_cast<int>(d.sdo_entries.size());
  if (c.ft.present) e.sdo_transfers += 4;
  e.sdo_s = e.sdo_transfers * kSdoTransferDesign_s;
  e.heartbeat_s = c.heartbeat_consumer_s;
  return e;
}

std::string StartupEstimate::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "up to %.1f s (boot-up wait %.3g s, %d SDO transfers %.3g s, the first operational heartbeat %.3g s)",
                total_s(), boot_s, sdo_transfers, sdo_s, heartbeat_s);
  return buf;
}

int worst_case_frame_bits(int n) noexcept {
  const int data_bits = 8 * n;
  return data_bits + 47 + (34 + data_bits - 1) / 4;
}

std::vector<BusLoad> compute_bus_loads(const RemoteConfig& c) {
  std::vector<BusLoad> out;
  constexpr int kRpdoBytes = 6;  // controlword + target position
  constexpr int kTpdoBytes = 8;  // statusword + position actual + torque actual
  constexpr int kFtBytes = 8;
  for (std::size_t bi = 0; bi < c.buses.size(); ++bi) {
    BusLoad l;
    l.bus = c.buses[bi].name;
    l.bitrate_bps = c.buses[bi].bitrate_bps;
    for (const DriveConfig& d : c.drives)
      if (d.bus == l.bus) ++l.drives;
    l.ft = c.ft.present && c.ft.bus == l.bus;
    const int nodes = l.drives + (l.ft ? 1 : 0);
    if (nodes > 0) {
      l.frames_per_cycle = 1 + 2 * l.drives + (l.ft ? 2 : 0);
      l.bits_per_cycle = worst_case_frame_bits(c.sync_counter_overflow > 0 ? 1 : 0) +
                         l.drives * (worst_case_frame_bits(kRpdoBytes) + worst_case_frame_bits(kTpdoBytes)) +
                         (l.ft ? 2 * worst_case_frame_bits(kFtBytes) : 0);
      l.heartbeat_bits_per_s = (nodes + 1) * worst_case_frame_bits(1) / c.heartbeat_producer_s;  // + master
      if (c.velocity_tpdo_every > 0)  // TPDO2: velocity actual, 4 bytes
        l.velocity_bits_per_s = l.drives * worst_case_frame_bits(4) * c.cycle_rate_hz / c.velocity_tpdo_every;
    }
    l.bits_per_s = l.bits_per_cycle * c.cycle_rate_hz + l.velocity_bits_per_s + l.heartbeat_bits_per_s;
    l.load = l.bits_per_s / l.bitrate_bps;
    out.push_back(l);
  }
  return out;
}

std::string BusLoad::describe() const {
  char buf[320];
  char velocity[64] = "";
  if (velocity_bits_per_s > 0.0) std::snprintf(velocity, sizeof velocity, " + velocity TPDOs %.0f bit/s", velocity_bits_per_s);
  std::snprintf(buf, sizeof buf,
                "bus %s: %d drive%s%s, %d frames/cycle (SYNC + %d PDOs), %d bits/cycle worst case "
                "x %.0f Hz%s + heartbeats %.0f bit/s = %.1f kbit/s = %.1f%% of %.0f kbit/s",
                bus.c_str(), drives, drives == 1 ? "" : "s", ft ? " + F/T" : "", frames_per_cycle,
                frames_per_cycle > 0 ? frames_per_cycle - 1 : 0, bits_per_cycle,
                bits_per_cycle > 0 ? (bits_per_s - heartbeat_bits_per_s - velocity_bits_per_s) / bits_per_cycle : 0.0,
                velocity, heartbeat_bits_per_s, bits_per_s / 1000.0, load * 100.0, bitrate_bps / 1000.0);
  return buf;
}

}  // namespace foresight::hw
