#pragma once
// The CANopen master for the arm: every CiA 402 drive and the F/T sensor, on
// one or more CAN buses, driven in cyclic synchronous position mode.
//
// The SDO client (sdo_client.hpp) and what is written to each node
// (node_config.hpp) live in their own files, and so do, as in Lely's split of
// master and drivers, the handler of each node (src/cia402_drive.hpp per
// drive, src/ft_node.hpp for the F/T sensor: their frames' meaning, their
// state, their supervision) and the COB-ID router that gives a received frame
// to its handler (cob_id_router.hpp). This class is the orchestrator: it owns
// the buses, the router and the handlers, runs the boot sequence, enable/
// disable/homing and the cycle.
//
// Two phases:
//  * set-up (NOT real-time: may block, allocate, throw HwError/SdoError):
//      constructor (validates the config and bus load; sends nothing),
//      configure() (NMT reset, boot-up, SDO: device type, PDO mapping, mode,
//      periods, limits, heartbeat; NMT start), configure_nodes() (the same
//      for a node that rebooted, while another thread cycles), enable() and
//      disable() (the cycle's power state machine, with their own cycles),
//      sdo_read()/sdo_write().
//  * real-time cycle (noexcept, no allocation, no locks, no blocking):
//      cycle_read() then cycle_write() once per period, from one thread:
//        cycle_read:  drain every bus; TPDOs -> feedback; heartbeats, EMCY,
//                     error frames -> events; heartbeat/TPDO timeouts.
//        cycle_write: SYNC first (with the CiA 301 counter when
//                     sync_counter_overflow > 0), then one RPDO (controlword +
//                     target position) per drive, on every bus; the master's own heartbeat
//                     (0x700 + heartbeat.master_node_id) every producer period,
//                     which the drives consume (0x1016): a master that stops
//                     cycling faults the drives (EMCY 0x8130).
//      begin_enable()/begin_disable(): the power state machine, stepped by the
//      following cycle_writes, judged by each cycle_read (CycleStatus::power).
//      request_power_off(), request_quick_stop() and request_tare() may be
//      called from any thread.
// Stops as the drives see them (docs/control.md, the stop table):
//   request_power_off()  category 0: from the next cycle_write on, every drive
//                        gets Disable Voltage (controlword 0x0000) and goes to
//                        Switch on disabled at the next SYNC: no torque, never
//                        Quick stop active. Latched until enable().
//   begin_disable()      power off after a controlled stop (category 1), the
//                        same command, confirmed: every drive must report a
//                        state without power (canopen::power_enabled false).
//   request_quick_stop() the drives' own ramp (0x605A, which must be 1 or 2:
//                        ramp, then Switch on disabled); what the destructor
//                        sends when the master goes away with drives enabled.
// Errors in the cycle are values (CycleStatus events), never exceptions.
// Set-up calls and cycle calls must not overlap: run set-up before the
// real-time thread starts, or from it while it is not cycling.

#include <poll.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/common/joints.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/hw/can_bus.hpp"
#include "foresight/hw/canopen.hpp"
#include "foresight/hw/cob_id_router.hpp"
#include "foresight/hw/ft_sensor.hpp"
#include "foresight/hw/node_config.hpp"
#include "foresight/hw/sdo_client.hpp"
#include "foresight/hw/remote_config.hpp"

namespace foresight::hw {

using foresight::kMaxJoints;  // common/joints.hpp
inline constexpr std::size_t kMaxBuses = 8;

/// Joint position targets, radians, in config drive order (= joint index).
struct JointTargets {
  std::array<double, kMaxJoints> position_rad{};
};

struct JointState {
  double position_rad = 0.0;
  double torque_nm = 0.0;  ///< joint side: torque actual x rated torque x gear ratio
  double velocity_rad_s = 0.0;   ///< velocity actual 0x606C (TPDO2, every velocity_tpdo_every-th SYNC), joint side
  std::int32_t velocity_counts_s = 0;
  std::uint64_t velocity_cycle = 0;  ///< master cycle whose SYNC the last velocity answered (0: none yet)
  std::int32_t position_counts = 0;
  std::uint16_t statusword = 0;
  canopen::PowerState state = canopen::PowerState::NotReadyToSwitchOn;
  canopen::NmtState nmt = canopen::NmtState::PreOperational;
  std::uint16_t last_emcy = 0;  ///< last EMCY error code (0: none / reset)
  bool fresh = false;           ///< a TPDO for the last SYNC arrived
  bool heartbeat_lost = false;
  /// `state` is the drive's present state: a TPDO arrived since configure()
  /// and neither its TPDOs (tpdo_miss_limit) nor its heartbeat went missing
  /// since. False: the drive is silent and its state unknown.
  bool state_known = false;
};

struct JointFeedback {
  std::size_t count = 0;
  std::array<JointState, kMaxJoints> joints{};
};

/// Named faults and notices reported by the cycle.
enum class HwFault : std::uint8_t {
  None,
  HeartbeatLost,      ///< node silent longer than heartbeat.consumer_ms (stop)
  NodeRebooted,       ///< boot-up message from an operational node (stop)
  NodeNotOperational, ///< heartbeat says stopped / pre-operational (stop)
  Emergency,          ///< EMCY with a non-zero code and an error register bit set; code = error code (stop)
  EmergencyCleared,   ///< EMCY 0x0000 (notice)
  DriveFault,         ///< statusword went to Fault / fault reaction (stop)
  QuickStopActive,    ///< statusword left Operation enabled to Quick stop (stop)
  TpdoMissing,        ///< no TPDO for tpdo_miss_limit consecutive cycles (stop)
  FtMissing,          ///< no F/T sample for tpdo_miss_limit cycles (stop)
  FtSaturated,        ///< a channel clipped; code = mask (stop)
  FtSensorFault,      ///< status bit 6 (stop)
  FtFrameMismatch,    ///< frames A and B of different samples (notice)
  BusOff,             ///< controller bus-off (stop)
  BusErrorPassive,    ///< controller error passive (notice)
  BusRestarted,       ///< the controller left bus-off (CAN_ERR_RESTARTED: restart-ms); code = restarts so far (notice)
  BusOffRepeated,     ///< more bus-off restarts than bus_off_restart_limit: stays a fault until configure() (stop)
  BusRestartRequested,///< bus-off for bus_off_restart_delay_s: the master asked the controller to restart
                      ///< (CanBus::request_restart, rtnetlink); code = attempt (1..bus_off_restart_limit),
                      ///< detail = RestartResult (notice; BusOff is the stop)
  TxFailed,           ///< a frame could not be queued; code = CanIo; once per episode (stop)
  RxFailed,           ///< read error / bus closed; code = CanIo (stop)
  MalformedFrame,     ///< wrong DLC / RTR / not a can_frame; code = COB-ID, detail = DLC (notice)
  UnknownCobId,       ///< a frame nobody on this bus should send; code = COB-ID; once per COB-ID (notice)
  UnexpectedSdo,      ///< SDO traffic during the cycle (notice)
  InvalidTarget,      ///< NaN or out-of-range target (detail 0), or a step from the last target larger
                      ///< than the following-error window (detail 1, code = step in counts):
                      ///< refused before it reaches the drive, previous target kept (stop)
  EmergencyWarning,   ///< EMCY with a code but an empty error register (CiA 301: no error
                      ///< is present, a warning); code = error code (notice, not a stop)
  // The power state machine stepped by the cycle (begin_enable/begin_disable):
  PowerStateChanged,  ///< a drive's CiA 402 state changed during an enable or disable;
                      ///< code = new state, detail = previous state (kUnknownState: none seen yet) (notice)
  PowerStepTimeout,   ///< a drive stayed in one state longer than the step deadline
                      ///< (power_step_timeout_ms), or the whole change took longer than
                      ///< enable_timeout_ms (detail bit 16); code = its state (kUnknownState:
                      ///< it never answered), detail low 16 bits = statusword (stop)
  FaultAfterReset,    ///< a drive in Fault again after this enable's one fault reset;
                      ///< code = its last EMCY code, detail = statusword (stop)
  PowerChangeAborted, ///< an enable ended by a category 0 power off (request_power_off) (notice)
  NodeUnconfigured,   ///< an enable refused: the node rebooted or left NMT operational since
                      ///< configure(): configure_nodes() first (code = the NMT state seen) (stop)
};
/// PowerStepTimeout / PowerStateChanged: no state seen.
inline constexpr std::uint32_t kUnknownState = 0xFF;
/// PowerStepTimeout's detail bit: the overall deadline (enable_timeout_ms), not a step's.
inline constexpr std::uint32_t kOverallDeadline = 1u << 16;
const char* to_string(HwFault f) noexcept;
/// True for faults that require the controller to stop the arm.
bool requires_stop(HwFault f) noexcept;

struct HwEvent {
  HwFault fault = HwFault::None;
  std::uint8_t bus = 0;
  std::uint8_t node = 0;
  std::int8_t joint = -1;  ///< joint index, -1 when not a drive (F/T, bus)
  std::uint32_t code = 0;
  std::uint32_t detail = 0;
};

/// The power state machine stepped by the cycle (DriveSystem::begin_enable,
/// begin_disable): where it is.
enum class PowerPhase : std::uint8_t {
  Idle,       ///< no change asked since configure()
  Enabling,   ///< stepping every drive toward Operation enabled
  Disabling,  ///< Disable Voltage to every drive until each confirms a state without power
  Enabled,    ///< the last enable succeeded
  Disabled,   ///< the last disable succeeded
  Failed,     ///< the last change failed: `cause` says why
};

struct PowerStatus {
  PowerPhase phase = PowerPhase::Idle;
  bool finished = false;     ///< the change ended in this cycle_read (Enabled, Disabled or Failed)
  bool was_enable = false;   ///< the change that is running or ended was an enable
  std::uint32_t cycles = 0;  ///< cycles since it began
  HwEvent cause{};           ///< Failed: the drive and why (a PowerStepTimeout, FaultAfterReset, ... event)
};

/// Result of one cycle_read. Events are edges (reported once, when they
/// happen); active_faults counts faults that persist (drive in Fault,
/// heartbeat lost, bus-off...).
struct CycleStatus {
  static constexpr std::size_t kMaxEvents = 16;
  std::uint64_t cycle = 0;
  bool stop_required = false;
  std::uint8_t active_faults = 0;
  std::uint8_t event_count = 0;
  std::uint16_t events_dropped = 0;
  std::uint16_t frames_received = 0;
  std::array<HwEvent, kMaxEvents> events{};
  /// The first persisting fault counted in active_faults (drive, F/T, then
  /// bus order), so a stop that persists without a new event this cycle
  /// still names its cause. fault = None when active_faults == 0.
  HwEvent first_active{};
  /// A drive's statusword carries RemoteConfig::sto_status_bit: its safe
  /// torque off input is active (the cabinet's E-stop circuit is open).
  bool safe_torque_off = false;
  std::int8_t sto_joint = -1;  ///< the first joint reporting it (0-based)
  /// The power state machine (begin_enable / begin_disable), after this read.
  PowerStatus power{};
  bool ok() const noexcept { return !stop_required && event_count == 0 && active_faults == 0; }
};

/// The events of the cycle so far, until cycle_read hands them over in its
/// CycleStatus: a fixed array (real-time safe); beyond kMaxEvents they are
/// counted as dropped.
class EventQueue {
 public:
  void push(const HwEvent& e) noexcept {
    if (count_ < events_.size())
      events_[count_++] = e;
    else
      ++dropped_;
  }
  /// Into `s` (events, event_count, events_dropped, stop_required for a
  /// stopping event); the queue is then empty.
  void take(CycleStatus& s) noexcept;
  /// Forget the queued events (configure(): set-up's events are not the
  /// cycle's); the drop count is still reported by the next take().
  void discard() noexcept { count_ = 0; }
  std::size_t size() const noexcept { return count_; }
  const HwEvent& operator[](std::size_t i) const noexcept { return events_[i]; }

 private:
  std::array<HwEvent, CycleStatus::kMaxEvents> events_{};
  std::size_t count_ = 0;
  std::uint16_t dropped_ = 0;
};

class CanNode;
class Cia402Drive;
class FtNode;

/// Joint limits by joint name from the robot model (URDF), for DriveSystem.
inline std::map<std::string, JointLimits> joint_limits_by_name(const RobotModel& model) {
  std::map<std::string, JointLimits> out;
  for (std::size_t i = 0; i < model.joint_names().size(); ++i) out[model.joint_names()[i]] = model.limits()[i];
  return out;
}

class DriveSystem {
 public:
  using Clock = std::chrono::steady_clock;

  /// Set-up. `buses[i]` is the opened bus for config.buses[i]. `joint_limits`
  /// (from the URDF) by joint name: when non-empty, every drive's joint must
  /// be in it and its position limits are written to the drive (0x607D).
  /// Validates the configuration again (bus load included). Sends nothing.
  /// Throws InputError (config) or HwError.
  DriveSystem(RemoteConfig config, std::vector<std::unique_ptr<CanBus>> buses,
              std::map<std::string, JointLimits> joint_limits = {});
  /// If drives are enabled, sends quick stop (one RPDO each + SYNC), best effort.
  ~DriveSystem();
  DriveSystem(const DriveSystem&) = delete;
  DriveSystem& operator=(const DriveSystem&) = delete;

  /// Set-up: bring every node from power-on to NMT operational with PDOs mapped
  /// (see docs/hardware.md for the sequence). Throws HwError/SdoError naming
  /// the bus, node and joint. Drives stay disabled.
  void configure();
  /// Set-up: begin_enable(), then cycles at the configured rate until the
  /// change ends (the same stepper as the control loop's). Throws HwError
  /// naming each drive that did not get there, and its state.
  void enable();
  /// Set-up, after configure() and before the CSP enable(): homing for every
  /// drive with a `homing:` block (incremental encoders), all at once: mode 6
  /// (read back in 0x6061), method 0x6098, speeds 0x6099:01/02, acceleration
  /// 0x609A (each written and read back), enable(), start (controlword bit 4)
  /// until statusword bit 12 (homing attained) within the drive's timeout;
  /// then disable() and back to CSP (0x6060 = 8, read back). Drives without a
  /// block (absolute encoders: offset_rad) are not touched beyond enable/
  /// disable. Returns the number of drives homed. Throws HwError naming each
  /// drive with a homing error (bit 13) or not homed in time.
  std::size_t home();
  /// The targets the drives hold right now (after enable(): their actual
  /// positions at enable time, then the last cycle_write). The controller's
  /// first cycle_write starts from these, so nothing jumps.
  void held_targets(JointTargets& out) const noexcept;
  /// Set-up: begin_disable(), then cycles until every drive reports a state
  /// without power (canopen::power_enabled false); throws HwError naming
  /// each drive still powered, with its state and statusword, or silent,
  /// after enable_timeout_s.
  void disable();
  /// Set-up: send an NMT command to every configured node (e.g. Stop after
  /// disable(); EnterPreOperational for SDO-only service). The heartbeat
  /// consumer then reports nodes leaving operational as NodeNotOperational;
  /// configure() is needed to start again.
  void nmt_all(canopen::NmtCommand cmd);

  // ---- drive power, stepped by the cycle (real-time: noexcept, no allocation) --------
  /// Enable as a state machine the cycle steps: from the next cycle_write,
  /// every drive is stepped once per cycle through the CiA 402 sequence
  /// (fault reset, shutdown, switch on, enable operation) holding target =
  /// actual position (the targets given to cycle_write are not taken
  /// meanwhile); cycle_read judges the drives' answers and reports in
  /// CycleStatus::power: Enabled once every drive reports Operation enabled,
  /// Failed on a drive in one state beyond the step deadline
  /// (power_step_timeout_ms) or the whole past enable_timeout_ms
  /// (PowerStepTimeout), a drive in Fault again after this enable's one fault
  /// reset (FaultAfterReset: a drive gets one fault reset per enable), a node
  /// lost (heartbeat, boot-up, NMT state, bus) or request_power_off()
  /// (PowerChangeAborted). Every state change is an event (PowerStateChanged).
  /// Clears the category 0 and quick stop latches. Refused (false, `*refused`
  /// the reason as an event) before configure(), while a node is not
  /// configured (NodeUnconfigured: it rebooted or left NMT operational;
  /// configure() again) or silent (HeartbeatLost): nothing is sent then.
  bool begin_enable(HwEvent* refused = nullptr) noexcept;
  /// Disable as a state machine the cycle steps: Disable Voltage to every
  /// drive (holding the actual positions) until each reports a state without
  /// power; Failed (PowerStepTimeout) after enable_timeout_ms. False before configure().
  bool begin_disable() noexcept;
  /// The state machine as the last cycle_read left it.
  const PowerStatus& power_status() const noexcept { return power_; }
  /// A failed or refused change's cause as one line for a command's answer,
  /// into `buf` (snprintf; no allocation): "joint3 (node 3): in Fault again
  /// after its fault reset, EMCY 0x2310 (statusword 0x0008)".
  void describe_power_failure(const HwEvent& cause, char* buf, std::size_t size) const noexcept;
  /// Nodes that rebooted or left NMT operational since configure() (NodeRebooted,
  /// NodeNotOperational): begin_enable() refuses until they are configured
  /// again. Any thread (as the last cycle_read saw them).
  std::size_t unconfigured_nodes() const noexcept;
  /// NOT real-time (blocking SDO, allocates, throws HwError/SdoError naming
  /// the node): configure again every node unconfigured_nodes() counts, from
  /// its configuration file, while the cycle goes on in another thread (the
  /// control loop: heartbeat, SYNC and the other drives' supervision do not
  /// stop). Per node, one at a time: NMT reset node, its boot-up, the SDO
  /// configuration configure() writes (node_config.hpp; the cycle hands the
  /// node's SDO answers over instead of reading them as unexpected), NMT
  /// start, its heartbeat saying operational; then the cycle takes it back
  /// (TPDO and heartbeat supervision restart, state unknown until its next
  /// TPDO). Returns the nodes configured. Call it from one thread, with no
  /// power change running and the drives not enabled (a RECOVER from a stop),
  /// and only while something calls cycle_read.
  std::size_t configure_nodes();

  // ---- real-time cycle -------------------------------------------------------
  /// The cycle's SYNC on every bus, sent by the control loop right after it
  /// wakes and reads (before its computation), so the drives latch the last
  /// targets and sample their TPDOs at a steady time whatever the
  /// computation takes. The cycle_write that follows sends only the RPDOs.
  /// Does nothing before configure() has succeeded.
  void send_sync() noexcept;
  /// Queue RPDOs (controlword + target) for all drives, after a SYNC per bus
  /// unless send_sync() already sent this cycle's (the set-up loops).
  /// Does nothing before configure() has succeeded. After enable(), start
  /// from held_targets(): a target step beyond the following-error window is
  /// refused here (InvalidTarget, the previous target is kept) before it can
  /// fault the drive.
  void cycle_write(const JointTargets& targets) noexcept;
  /// The same at a given time (the master heartbeat's producer period counts
  /// from it): with cycle_read(..., now), a caller stepping simulated time.
  void cycle_write(const JointTargets& targets, Clock::time_point now) noexcept;
  /// Drain the buses and decode; fills `joints` and `ft`.
  CycleStatus cycle_read(JointFeedback& joints, FtReading& ft) noexcept;
  CycleStatus cycle_read(JointFeedback& joints, FtReading& ft, Clock::time_point now) noexcept;
  /// Category 0: the next cycle_write, and every one after it until enable(),
  /// commands Disable Voltage to every drive (powered or not). Any thread.
  void request_power_off() noexcept { power_off_.store(true, std::memory_order_release); }
  /// The next cycle_write commands Quick stop to every enabled drive (their
  /// own ramp per 0x605A, then power off). Any thread.
  void request_quick_stop() noexcept { quick_stop_.store(true, std::memory_order_release); }
  /// Tare the F/T sensor with the next `samples` samples. Any thread.
  void request_tare(int samples) noexcept { tare_request_.store(samples, std::memory_order_release); }

  // ---- information (set-up side) -------------------------------------------------
  const RemoteConfig& config() const noexcept { return config_; }
  std::size_t joint_count() const noexcept;
  std::vector<BusLoad> bus_loads() const { return compute_bus_loads(config_); }
  /// "joint3 (bus arm_a node 3): Emergency 0x8611 following error"
  std::string describe(const HwEvent& e) const;
  /// Device name (0x1008) read at configure().
  const std::string& device_name(std::size_t joint) const;
  double rated_torque_nm(std::size_t joint) const;
  /// Identity, device name, rated torque and how many objects were verified, read at configure().
  const DriveInfo& drive_info(std::size_t joint) const;
  /// What the last configure() (and SDO calls since) recovered from, one line
  /// each, bus by bus: an SDO transfer that timed out once and whose retry was
  /// answered ("SDO read 0x1000:00 of joint3 (bus arm_a node 3): no response
  /// within 500 ms; the retry was answered"). Empty on a clean bring-up.
  std::vector<std::string> setup_notices() const;
  const CanBus& bus(std::size_t i) const { return *buses_.at(i); }
  /// Frames with a COB-ID nobody on bus `i` should send, counted since
  /// construction (each COB-ID is reported as an UnknownCobId event once).
  std::uint32_t unexpected_frames(std::size_t i) const { return bus_state_.at(i).unknown_frames; }
  /// TPDOs read before the echo of the last SYNC sent on bus `i` (they answer
  /// an earlier SYNC: late, or that SYNC was lost), not taken as fresh.
  std::uint32_t stale_tpdos(std::size_t i) const { return bus_state_.at(i).stale_tpdos; }

  // ---- SDO (set-up only; blocking with the configured timeout) ---------------------
  std::uint32_t sdo_read(std::size_t bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub);
  void sdo_write(std::size_t bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                 std::uint32_t value, int size_bytes);
  /// Segmented (or expedited) upload of a visible string.
  std::string sdo_read_string(std::size_t bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub);

 private:
  struct BusState {
    std::vector<std::size_t> drives;
    CobIdRouter router;  // filled by the constructor
    bool sync_sent = false;
    bool bus_off_reported = false;
    bool passive_reported = false;
    bool closed_reported = false;
    bool tx_fail_reported = false;
    std::array<std::uint64_t, 32> unknown_seen{};  // one bit per 11-bit COB-ID: reported once
    bool unknown_ext_seen = false;
    std::uint32_t unknown_frames = 0;
    std::uint8_t sync_counter = 0;   // of the last SYNC sent
    std::uint8_t sync_seen = 0;      // of the last SYNC echo read
    bool sync_echo_active = false;   // this bus loops our SYNCs back
    std::uint32_t stale_tpdos = 0;
    std::uint16_t restarts = 0;      // bus-off -> restarted, since configure()
    std::uint16_t restart_requests = 0;  // request_restart() calls since configure()
    std::uint32_t bus_off_cycles = 0;    // cycles in the present bus-off
    bool restart_limit_hit = false;
  };

  void handle_frame(std::size_t bus, const can_frame& f, Clock::time_point now) noexcept;
  // cycle_read's steps, in its order. The supervision ones count the nodes
  // and buses in fault (`active`) and keep the first (`first`).
  /// Drains bus `bi` into the nodes' state; its health's transitions as events.
  void read_bus(std::size_t bi, Clock::time_point now) noexcept;
  void supervise_drives(Clock::time_point now, std::uint8_t& active, HwEvent& first) noexcept;
  void supervise_ft(Clock::time_point now, std::uint8_t& active, HwEvent& first, FtReading& ft_out) noexcept;
  void supervise_buses(std::uint8_t& active, HwEvent& first) noexcept;
  void push_event(const HwEvent& e) noexcept { events_.push(e); }
  /// cycle_read's last step: judge the drives' answers to a power change.
  void judge_power() noexcept;
  void end_power(PowerPhase phase, const HwEvent& cause) noexcept;
  /// enable()/disable(): cycles until the change ends; throws its failure.
  void run_power_change(const char* verb);
  void run_cycle_blocking(Clock::time_point& deadline, JointFeedback& fb, CycleStatus& status);
  void nmt(std::size_t bus, canopen::NmtCommand cmd, std::uint8_t node);
  std::string node_label(std::size_t bus, std::uint8_t node) const;
  DriveSetup drive_setup(std::size_t joint) const;
  void drain_buses();
  /// configure()'s waits: every node's boot-up after NMT reset, then a
  /// heartbeat saying operational after NMT start (by `deadline`).
  void wait_for_boot_up(std::vector<pollfd>& fds);
  void wait_for_operational(std::vector<pollfd>& fds, Clock::time_point deadline);
  void poll_and_handle(std::vector<pollfd>& fds, int timeout_ms);

  RemoteConfig config_;
  std::vector<std::unique_ptr<CanBus>> buses_;
  std::vector<std::unique_ptr<SdoClient>> sdo_;
  std::map<std::string, JointLimits> limits_;
  std::vector<Cia402Drive> drives_;
  std::unique_ptr<FtNode> ft_;
  std::vector<CanNode*> nodes_;  ///< drives_ then ft_: the set-up steps common to every node
  std::vector<BusState> bus_state_;
  std::chrono::nanoseconds heartbeat_timeout_;
  std::chrono::nanoseconds master_hb_period_;
  Clock::time_point last_master_hb_{};

  /// configure_nodes(): the node of a bus being configured again while the
  /// cycle runs (0: none), what the cycle saw of it, and its SDO answers.
  struct Reconfig {
    std::atomic<std::uint8_t> node{0};
    std::atomic<bool> booted{false};       ///< boot-up seen since the NMT reset
    std::atomic<bool> operational{false};  ///< a heartbeat saying operational since the NMT start
    std::atomic<bool> restart{false};      ///< configured: the cycle restarts its supervision, then node = 0
    SpscRing<can_frame> inbox{64};         ///< the cycle's read -> the SDO client
  };
  std::vector<std::unique_ptr<Reconfig>> reconfig_;  ///< per bus
  std::atomic<std::uint32_t> unconfigured_mask_{0};  ///< bit i: nodes_[i]->unconfigured (the last cycle_read)
  /// cycle_read: nodes configure_nodes() finished, back under supervision.
  void take_back_reconfigured(Clock::time_point now) noexcept;

  EventQueue events_;
  std::uint16_t frames_this_cycle_ = 0;
  std::uint64_t cycle_ = 0;
  bool configured_ = false;
  bool enabled_ = false;
  bool sync_sent_this_cycle_ = false;  ///< send_sync() ran since the last cycle_write
  PowerStatus power_{};
  std::uint32_t step_cycles_ = 1;     ///< power_step_timeout_ms in cycles
  std::uint32_t overall_cycles_ = 1;  ///< enable_timeout_ms in cycles
  void write_sync(std::size_t bus) noexcept;
  std::atomic<bool> quick_stop_{false};
  std::atomic<bool> power_off_{false};
  std::atomic<int> tare_request_{0};
};

}  // namespace foresight::hw
