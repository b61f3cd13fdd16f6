#pragma once
// One CiA 402 drive (one joint) as the master sees it, in cyclic synchronous
// position mode: what its frames mean (TPDO1 statusword + position + torque,
// TPDO2 velocity, EMCY, heartbeat), what the master sends it (RPDO1
// controlword + target position), the power state machine's steps towards
// Operation enabled, and the supervision of its TPDOs and heartbeat. The
// master (DriveSystem) routes its frames here (CobIdRouter) and runs the
// cycle; the handler keeps the drive's state. Internal to foresight_hw.

#include <linux/can.h>

#include <chrono>
#include <cstdint>
#include <string>

#include "can_node.hpp"
#include "foresight/hw/drive_system.hpp"
#include "foresight/hw/node_config.hpp"
#include "foresight/hw/remote_config.hpp"

namespace foresight::hw {

class Cia402Drive : public CanNode {
 public:
  /// Set-up: drive `cfg` as joint `joint_index` (validated config: bus_index set).
  Cia402Drive(const DriveConfig& cfg, std::size_t joint_index);

  // ---- real-time ----------------------------------------------------------------
  /// A frame the router gave this drive (DriveTpdo, DriveVelocity, DriveEmcy,
  /// DriveHeartbeat).
  Rx on_frame(Kind kind, const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept;
  /// Takes `target_rad` as the next target unless it is not finite, out of the
  /// drive's counts, or (when `enabled`) a step beyond the following-error
  /// window: then InvalidTarget, and the previous target is kept.
  void take_target(double target_rad, bool enabled, EventQueue& events) noexcept;
  /// The stop requests override the controlword: quick stop (only when the
  /// drives are enabled), then power off (category 0 wins over everything).
  void apply_stops(bool quick_stop, bool power_off) noexcept;
  /// RPDO1: `cw` and the present target.
  can_frame rpdo(std::uint16_t cw) const noexcept;
  /// After the cycle's frames: TPDO (when the bus sent a SYNC) and heartbeat
  /// timeouts as events. Returns the persisting fault (fault None: none).
  HwEvent supervise(Clock::time_point now, std::chrono::nanoseconds hb_timeout, bool sync_sent, bool configured,
                    int miss_limit, EventQueue& events) noexcept;
  /// The joint's feedback for JointFeedback.
  void feedback(JointState& out) const noexcept;

  // ---- set-up (the master's enable(), disable(), configure()) -------------------
  /// configure(): NMT start sent; TPDOs and heartbeat supervised from now,
  /// power commanded off, state unknown until a TPDO arrives.
  void restart(Clock::time_point now) noexcept;
  /// A power change begins: fresh states only, no fault reset sent yet.
  void begin_power_change() noexcept;
  /// One cycle of an enable: once the drive has reported (have_actual), hold
  /// the actual position as target and command the transition from its state
  /// towards Operation enabled. A drive in Fault gets one fault reset per
  /// change (a rising edge of bit 7, held until it leaves Fault).
  void step_to_enabled() noexcept;
  /// One cycle of a disable: Disable Voltage, holding the actual position.
  void step_to_disabled() noexcept;
  /// After the cycle's frames, during a change: a state change as an event
  /// (PowerStateChanged), counting the cycles in the present state.
  void note_power_state(EventQueue& events) noexcept;
  /// The target held now, radians.
  double held_target_rad() const noexcept { return cfg.to_rad(target_counts); }
  bool enabled() const noexcept { return have_actual && st.state == canopen::PowerState::OperationEnabled; }

  DriveConfig cfg;
  std::string name;  ///< the joint's name
  DriveInfo info;    ///< read at configure()
  std::uint16_t controlword = canopen::controlword::kDisableVoltage;
  std::int32_t target_counts = 0;
  /// The drive's state from its TPDOs. Its nmt, heartbeat_lost and last_emcy
  /// are kept by CanNode (shared with the F/T node); feedback() fills them in.
  JointState st;
  bool have_actual = false;  ///< a TPDO arrived since the set-up step began
  // The power change running (DriveSystem::begin_enable / begin_disable):
  bool run_seen = false;      ///< a state was seen in this change
  canopen::PowerState run_state = canopen::PowerState::NotReadyToSwitchOn;  ///< the last one
  std::uint32_t state_cycles = 0;  ///< cycles in it (or without an answer)
  bool reset_sent = false;    ///< this change's one fault reset went out
  bool left_fault = false;    ///< and the drive left Fault after it
  std::int64_t fe_counts = 0;  ///< following-error window, counts

 private:
  Rx on_tpdo(const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept;
  Rx on_velocity(const can_frame& f, const RxContext& ctx) noexcept;
};

}  // namespace foresight::hw
