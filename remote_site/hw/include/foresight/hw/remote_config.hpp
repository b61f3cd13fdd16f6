#pragma once
// config/remote.yaml: CAN buses, CiA 402 drives (joint -> bus, node id,
// scaling), the wrist F/T sensor, cycle rate, heartbeat times, following-error
// limits. Loading validates everything (duplicate node ids, missing scaling,
// unknown bus, bus load); a bad file throws InputError naming the file, line
// and element, and nothing is ever enabled from it. Set-up code only.
//
// The `tool:` section belongs to the LST tool (Modbus) and is parsed by its
// own loader; this loader skips it.
//
// Joint position/velocity limits are not here: they come from the URDF
// (RobotModel) and are handed to DriveSystem.

#include <cstdint>
#include <string>
#include <vector>

#include "foresight/hw/sdo_list.hpp"

namespace foresight::hw {

struct BusConfig {
  std::string name;       ///< referred to by drives and the F/T sensor
  std::string interface;  ///< "can0"... (SocketCAN), or "mock" (socketpair + simulator)
  std::uint32_t bitrate_bps = 1000000;
  int line = 0;           ///< line in the file, for messages
  bool is_mock() const { return interface == "mock"; }
};

/// Optional homing at bring-up (incremental encoders; absolute encoders keep
/// offset_rad and have no block): CiA 402 homing mode 6.
struct HomingConfig {
  bool enabled = false;
  int method = 0;                   ///< 0x6098 (CiA 402 1..35, 37)
  double speed_switch_rad_s = 0.0;  ///< 0x6099:01, search for the switch, joint side
  double speed_zero_rad_s = 0.0;    ///< 0x6099:02, search for the index/zero, joint side
  double acceleration_rad_s2 = 0.0; ///< 0x609A, joint side
  double timeout_s = 30.0;          ///< homing attained (statusword bit 12) within this
};

struct DriveConfig {
  std::string joint;  ///< URDF joint name
  std::string bus;
  int bus_index = -1;  ///< index into RemoteConfig::buses
  std::uint8_t node_id = 0;
  double counts_per_rev = 0.0;  ///< encoder counts per motor revolution
  double gear_ratio = 0.0;      ///< motor revolutions per joint revolution
  int direction = 1;            ///< +1 or -1: sign of joint angle vs counts
  double offset_rad = 0.0;      ///< joint angle at 0 counts
  double following_error_limit_rad = 0.0;  ///< drive faults above this |target - actual|
  double following_error_timeout_s = 0.0;  ///< 0x6066 (0: leave the drive's own)
  std::string sdo_file;                    ///< the drive's SDO list (resolved path), "" = none
  std::vector<SdoEntry> sdo_entries;       ///< parsed from sdo_file at load (sdo_list.hpp)
  HomingConfig homing;                     ///< `homing:` block (enabled when present)
  int line = 0;

  /// Counts per radian of joint angle (signed by direction).
  double counts_per_rad() const;
  /// Joint angle -> drive counts; false when not finite or outside int32.
  bool to_counts(double q_rad, std::int32_t& counts) const noexcept;
  double to_rad(std::int32_t counts) const noexcept;
};

struct FtConfig {
  bool present = false;
  std::string bus;
  int bus_index = -1;
  std::uint8_t node_id = 0;
  double force_counts_per_n = 0.0;    ///< int16 counts per newton
  double torque_counts_per_nm = 0.0;  ///< int16 counts per newton-metre
  int line = 0;
};

struct RemoteConfig {
  std::string source;  ///< file name (for messages)
  double cycle_rate_hz = 500.0;
  double heartbeat_producer_s = 0.05;  ///< period each node (and the master) sends its heartbeat
  double heartbeat_consumer_s = 0.175; ///< a node silent longer than this is a fault (both ways); >= 3 x producer
                                       ///< (validate() refuses less), 3.5 x recommended
  std::uint8_t master_node_id = 127;  ///< node id of the master's own heartbeat (0x700 + id)
  double sdo_timeout_s = 0.5;          ///< per SDO transfer (set-up only); a timed-out transfer is retried once
  double enable_timeout_s = 2.0;      ///< power state machine to Operation enabled
  /// One step of it: a drive that stays in one CiA 402 state (not the goal)
  /// longer than this during an enable or disable fails it (PowerStepTimeout).
  double power_step_timeout_s = 0.5;
  int tpdo_miss_limit = 5;            ///< consecutive cycles without a TPDO before a fault (1% loss: 3 gives
                                      ///< ~140 false stops/h, 5 about one per 12 h)
  int velocity_tpdo_every = 5;        ///< TPDO2 (velocity actual 0x606C) on every n-th SYNC (0x1801:02); 0 = not mapped
  int bus_off_restart_limit = 3;      ///< controller restarts after bus-off (restart-ms) tolerated per configure()
  double bus_off_restart_delay_s = 0.1;  ///< bus-off this long: the master requests a restart (netlink), at most
                                         ///< bus_off_restart_limit times per configure()
  int sync_counter_overflow = 0;      ///< 0x1019: SYNC carries a counter 1..this (CiA 301: 2..240), 0 = none
  /// The cabinet's E-stop as the drives see it: the statusword bit a drive
  /// sets while its safe torque off (STO) input is active (CiA 402 leaves
  /// bits 8, 14 and 15 to the manufacturer); -1 = not wired. Any drive
  /// reporting it is an E-stop, category 0, as the E-stop file is.
  int sto_status_bit = -1;
  int interpolation_exponent = -4;    ///< 0x60C2:02, the unit of 0x60C2:01 (10^exp s); -3 where the drive requires ms
  double max_bus_load = 0.70;
  std::vector<BusConfig> buses;
  std::vector<DriveConfig> drives;
  FtConfig ft;

  double cycle_period_s() const { return 1.0 / cycle_rate_hz; }
  int bus_index(const std::string& name) const;
};

/// Load and validate. Throws InputError("<file>:<line>: ...").
RemoteConfig load_remote_config(const std::string& path);
/// As load_remote_config, from YAML text; `source_name` is used in messages.
RemoteConfig parse_remote_config(const std::string& yaml_text, const std::string& source_name);

/// Validate a configuration built in code (the loader calls it too): names,
/// duplicates, scaling, rates, bus load; fills the bus_index fields. Throws
/// InputError naming the element.
void validate(RemoteConfig& config);

// ---- start-up time ------------------------------------------------------------

/// What the daemon's start-up may take before it reports ready to systemd: the
/// unit's TimeoutStartSec (60 s) less what the rest of the start-up needs
/// (DDS discovery, the journal, the loop's start: seconds).
inline constexpr double kStartupBudget_s = 45.0;
/// An SDO transfer at set-up, as designed for: a request and a response frame
/// and the drive's processing (CiA 301 devices answer in 1-5 ms).
inline constexpr double kSdoTransferDesign_s = 0.005;
/// Transfers the master makes per drive besides its SDO file (identity,
/// heartbeats, PDO mapping, mode, timing, limits: node_config.cpp, read-backs included).
inline constexpr int kMasterSdoTransfersPerDrive = 64;

/// The longest a successful bring-up (DriveSystem::configure) of a
/// configuration may take: every node's boot-up just inside its wait
/// (enable_timeout_ms), every SDO transfer at its design time (each file entry
/// written and read back), the operational heartbeats just inside the
/// consumer time.
struct StartupEstimate {
  double boot_s = 0.0;
  double sdo_s = 0.0;
  int sdo_transfers = 0;
  double heartbeat_s = 0.0;
  double total_s() const { return boot_s + sdo_s + heartbeat_s; }
  /// "up to 67.6 s (boot-up wait 2 s, 504 SDO transfers 2.5 s, the first operational heartbeat 65 s)"
  std::string describe() const;
};
StartupEstimate estimate_startup(const RemoteConfig& config);

// ---- bus load -----------------------------------------------------------------

/// Worst-case length in bits of a standard (11-bit id) data frame with
/// `data_bytes` bytes, including stuff bits and the 3-bit interframe space:
/// 8n + 47 + floor((34 + 8n - 1) / 4)  (Davis et al. 2007). 0 bytes: 55, 8: 135.
int worst_case_frame_bits(int data_bytes) noexcept;

struct BusLoad {
  std::string bus;
  int drives = 0;
  bool ft = false;
  int frames_per_cycle = 0;     ///< SYNC + RPDO + TPDO per drive + 2 F/T frames
  int bits_per_cycle = 0;       ///< worst case, stuffing included
  double heartbeat_bits_per_s = 0.0;
  double velocity_bits_per_s = 0.0; ///< TPDO2 (0x606C) of every drive on every velocity_tpdo_every-th SYNC
  double bits_per_s = 0.0;      ///< cycle traffic x rate + heartbeats
  std::uint32_t bitrate_bps = 0;
  double load = 0.0;            ///< bits_per_s / bitrate
  /// "bus arm_a: 4 drives, 9 frames/cycle (SYNC + 8 PDOs), 1055 bits/cycle worst case x 500 Hz + heartbeats
  /// 6500 bit/s = 534.0 kbit/s = 53.4% of 1000 kbit/s" (heartbeats: every node and the master)
  std::string describe() const;
};
std::vector<BusLoad> compute_bus_loads(const RemoteConfig& config);

}  // namespace foresight::hw
