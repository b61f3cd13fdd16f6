#pragma once
// A simulated CiA 402 servo drive (CANopen node): the power state machine,
// cyclic synchronous position mode with second-order position tracking
// (velocity feed-forward from successive targets), following-error and
// position-limit faults with their EMCY codes, a consumer of the master's
// heartbeat (0x1016; a silent master faults the drive, EMCY 0x8130), PDOs exactly as mapped by the
// master over SDO (a wrong mapping gives wrong frames), heartbeat, and fault
// injection. Positions are drive counts (motor encoder); physics advances by
// the wall time between SYNCs (the first: one period 0x1006; bounded to
// 0.1..5 periods), so late, lost or irregular SYNCs show in the motion.
// At each SYNC, as a csp drive does: the period that ended ran toward the
// target latched at the previous SYNC; the TPDOs sample the state at this
// SYNC; then the RPDO received since the previous SYNC is latched (power
// state machine, new target reached at the next SYNC). A target the master
// sends after SYNC k (SYNC first) shows in the TPDO of SYNC k+2.
// Stop reactions follow the codes the master writes: quick stop option 0x605A
// (0 coast, 1/2 ramp then Switch on disabled, 5/6 ramp and hold in Quick stop
// active; ramps at 0x6084 slow-down / 0x6085 quick-stop deceleration), fault
// reaction 0x605E (0 coast, 1/2 ramp in Fault reaction active, then Fault),
// abort connection 0x6007 on a lost master heartbeat (0 nothing but the EMCY,
// 1 fault, 2 disable voltage, 3 quick stop). Identity 0x1018, supported
// modes 0x6502 (CSP, homing; homing mode 6 runs to a simulated home switch
// and sets statusword bit 12), and RPDO2-4 / TPDO2-4 enabled by default as the
// predefined connection set has them (the master must switch them off).

#include <array>
#include <chrono>
#include <cstdint>
#include <string>

#include "foresight/sim/sim_node.hpp"

namespace foresight::sim {

struct SimDriveParams {
  std::uint8_t node_id = 1;
  std::string name = "joint";         ///< for the device name 0x1008
  double counts_per_rev = 131072.0;   ///< motor encoder, for torque from acceleration
  double natural_frequency_hz = 40.0; ///< position loop bandwidth
  double damping = 1.0;
  std::uint32_t rated_torque_mnm = 2000;   ///< 0x6076, motor side
  double rotor_inertia_kgm2 = 2e-4;        ///< motor side, reflected load included
  std::int32_t initial_counts = 0;          ///< power-on position
  double max_motor_speed_counts_s = 6000.0 / 60.0 * 131072.0;  ///< the motor's speed limit (6000 rpm)
  std::uint32_t vendor_id = 0x00F0E5E7;     ///< 0x1018:01 (the identity a drive file expects)
  std::uint32_t product_code = 0x00000402;  ///< 0x1018:02
  std::uint32_t revision = 0x00010000;      ///< 0x1018:03
  int sto_status_bit = 14;                  ///< statusword bit set while safe torque off is active
};

/// The drive's own record of its power stage: what it did, not what the
/// master believes (tests of the stop categories check this).
struct DrivePowerRecord {
  hw::canopen::PowerState state = hw::canopen::PowerState::NotReadyToSwitchOn;
  bool powered = false;            ///< hw::canopen::power_enabled(state): the motor gets torque
  std::uint32_t states_seen = 0;   ///< bit (1 << PowerState) for every state since clear_power_record()
  std::uint64_t syncs = 0;         ///< SYNCs received
  std::uint64_t power_off_sync = 0;  ///< sync count at the last powered -> unpowered change (0: none)
  std::chrono::steady_clock::time_point power_off_at{};  ///< and its time
};

class SimDrive final : public SimNode {
 public:
  explicit SimDrive(const SimDriveParams& p);

  // ---- queries (any thread) -----------------------------------------------------
  hw::canopen::PowerState power_state() const;
  double position_counts() const;
  double velocity_counts_s() const;
  std::int32_t target_counts() const;
  std::uint16_t controlword() const;
  std::uint64_t sync_count() const;
  std::uint32_t following_error_window() const;
  DrivePowerRecord power_record() const;
  /// Starts a new record of the states seen (states_seen = the present state).
  void clear_power_record();

  // ---- fault injection / plant inputs (any thread) ----------------------------------
  /// Go to Fault and send EMCY `code` (e.g. 0x2310 over-current) at the next tick.
  void inject_fault(std::uint16_t emcy_code);
  /// The safe torque off input (the cabinet's E-stop circuit opened): while
  /// active the power stage has no torque (the drive leaves Operation enabled
  /// for Switch on disabled at the next SYNC and cannot be switched on) and
  /// the statusword carries params.sto_status_bit. Any thread.
  void set_safe_torque_off(bool active);
  /// External load torque at the motor shaft, N*m (shows in torque actual).
  void set_load_torque_nm(double motor_torque_nm);
  /// Move the shaft (as if pushed) to `counts`, velocity 0.
  void set_position_counts(double counts);
  /// Where the home switch is, in the drive's current counts (default 0).
  /// Homing (mode 6, methods 17-30) moves there at 0x6099:01, then the last
  /// stretch at 0x6099:02, and the position becomes the home offset 0x607C;
  /// methods 35/37 take the current position as home at once.
  void set_home_switch_counts(double counts);
  bool homing_attained() const;

 protected:
  void reset_application() override;
  void on_sync(Clock::time_point now, FrameSink& out) override;
  void on_frame(const can_frame& f, FrameSink& out) override;
  void on_tick(Clock::time_point now, FrameSink& out) override;
  std::uint32_t check_sdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value) override;
  void on_sdo_written(std::uint16_t index, std::uint8_t sub) override;

 private:
  void apply_command(std::uint16_t cw, FrameSink& out);
  void fault(std::uint16_t emcy_code, FrameSink& out);
  void quick_stop();                 // enter Quick stop active per 0x605A
  void ramp(double dt_s, double decel);  // decelerate v_ toward 0, move x_
  void step_physics(double dt_s);
  void step_homing(double dt_s);  // mode 6
  void update_statusword();  // also notes the power state in the record
  std::uint32_t check_mapping(std::uint16_t map_index, std::uint8_t count) const;

  SimDriveParams p_;
  hw::canopen::PowerState state_ = hw::canopen::PowerState::NotReadyToSwitchOn;
  double x_ = 0.0;   // counts
  double v_ = 0.0;   // counts/s
  double a_ = 0.0;   // counts/s^2
  double demand_ = 0.0;
  double demand_prev_ = 0.0;
  bool following_error_ = false;
  bool internal_limit_ = false;
  std::uint16_t prev_cw_ = 0;
  std::uint64_t syncs_ = 0;
  double load_torque_nm_ = 0.0;
  bool have_rpdo_ = false;
  std::array<std::uint8_t, 8> rpdo_{};
  std::uint8_t rpdo_len_ = 0;
  bool master_hb_armed_ = false;  // heartbeat consumer (0x1016): armed by the first heartbeat
  Clock::time_point master_hb_{};
  double ramp_v_ = 0.0;  // velocity of the quick-stop / fault-reaction ramp, counts/s
  Clock::time_point last_tick_{};
  Clock::time_point last_sync_{};
  double fe_time_s_ = 0.0;  // how long the following error has been beyond the window  // wall time of the previous SYNC (physics dt)
  bool homing_active_ = false;
  bool homing_attained_ = false;
  bool homing_slow_ = false;
  bool homing_start_prev_ = false;  // within the last stretch: zero search speed
  double home_switch_ = 0.0;  // counts
  std::uint32_t states_seen_ = 0;
  bool powered_ = false;
  std::uint64_t power_off_sync_ = 0;
  Clock::time_point power_off_at_{};
  bool injected_fault_ = false;
  bool sto_ = false;
  std::uint16_t injected_code_ = 0;
};

}  // namespace foresight::sim
