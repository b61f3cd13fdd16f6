#include "foresight/hw/drive_system.hpp"

#include <poll.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <thread>

#include "cia402_drive.hpp"
#include "foresight/common/error.hpp"
#include "ft_node.hpp"

namespace foresight::hw {

using namespace canopen;

namespace {
constexpr std::size_t kMaxFramesPerRead = 512;

std::string hex(std::uint32_t v, int digits) { return hex_text(v, digits); }
}  // namespace

const char* to_string(HwFault f) noexcept {
  switch (f) {
    case HwFault::None: return "none";
    case HwFault::HeartbeatLost: return "heartbeat lost";
    case HwFault::NodeRebooted: return "node rebooted (boot-up while operational)";
    case HwFault::NodeNotOperational: return "node left NMT operational";
    case HwFault::Emergency: return "emergency (EMCY)";
    case HwFault::EmergencyCleared: return "emergency cleared (EMCY 0x0000)";
    case HwFault::DriveFault: return "drive fault (CiA 402 Fault state)";
    case HwFault::QuickStopActive: return "drive in quick stop";
    case HwFault::TpdoMissing: return "TPDO missing";
    case HwFault::FtMissing: return "F/T sample missing";
    case HwFault::FtSaturated: return "F/T channel saturated";
    case HwFault::FtSensorFault: return "F/T sensor fault";
    case HwFault::FtFrameMismatch: return "F/T frames of different samples";
    case HwFault::BusOff: return "CAN bus-off";
    case HwFault::BusErrorPassive: return "CAN error passive";
    case HwFault::BusRestarted: return "CAN controller restarted after bus-off";
    case HwFault::BusOffRepeated: return "CAN bus-off again and again (restart limit reached)";
    case HwFault::BusRestartRequested: return "CAN bus-off";
    case HwFault::TxFailed: return "CAN transmit failed";
    case HwFault::RxFailed: return "CAN receive failed";
    case HwFault::MalformedFrame: return "malformed frame";
    case HwFault::UnknownCobId: return "unknown COB-ID";
    case HwFault::UnexpectedSdo: return "unexpected SDO frame";
    case HwFault::InvalidTarget: return "invalid joint target (not finite or out of range)";
    case HwFault::EmergencyWarning: return "emergency message, a warning (EMCY, error register 0)";
    case HwFault::PowerStateChanged: return "power state changed";
    case HwFault::PowerStepTimeout: return "power state machine timed out";
    case HwFault::FaultAfterReset: return "in Fault again after its fault reset";
    case HwFault::PowerChangeAborted: return "enable aborted by a category 0 power off";
    case HwFault::NodeUnconfigured: return "not configured (rebooted or left NMT operational since configure)";
  }
  return "?";
}

bool requires_stop(HwFault f) noexcept {
  switch (f) {
    case HwFault::None:
    case HwFault::EmergencyCleared:
    case HwFault::EmergencyWarning:
    case HwFault::FtFrameMismatch:
    case HwFault::BusErrorPassive:
    case HwFault::BusRestarted:
    case HwFault::BusRestartRequested:
    case HwFault::MalformedFrame:
    case HwFault::UnknownCobId:
    case HwFault::UnexpectedSdo:
    case HwFault::PowerStateChanged:
    case HwFault::PowerChangeAborted:
      return false;
    default:
      return true;
  }
}

// ---- set-up -------------------------------------------------------------------

DriveSystem::DriveSystem(RemoteConfig config, std::vector<std::unique_ptr<CanBus>> buses,
                         std::map<std::string, JointLimits> joint_limits)
    : config_(std::move(config)), buses_(std::move(buses)), limits_(std::move(joint_limits)) {
  validate(config_);  // throws InputError, bus load included: nothing is sent on a bad config
  if (buses_.size() != config_.buses.size())
    throw HwError("DriveSystem: " + std::to_string(buses_.size()) + " buses given for " +
                  std::to_string(config_.buses.size()) + " in " + config_.source);
  for (std::size_t i = 0; i < buses_.size(); ++i)
    if (!buses_[i]) throw HwError("DriveSystem: bus " + config_.buses[i].name + " is not open");
  if (config_.buses.size() > kMaxBuses) throw HwError("DriveSystem: more than 8 buses");
  if (config_.drives.size() > kMaxJoints) throw HwError("DriveSystem: more than " + std::to_string(kMaxJoints) + " drives");

  bus_state_.resize(buses_.size());
  drives_.reserve(config_.drives.size());
  for (std::size_t j = 0; j < config_.drives.size(); ++j) {
    const Cia402Drive& d = drives_.emplace_back(config_.drives[j], j);
    if (!limits_.empty() && !limits_.count(d.cfg.joint))
      throw InputError(config_.source, d.cfg.line,
                       "drives[" + std::to_string(j) + "]: joint '" + d.cfg.joint + "' is not in the robot model");
    BusState& b = bus_state_[d.bus];
    b.drives.push_back(j);
    b.router.add_drive(d.node, static_cast<std::uint8_t>(j), config_.velocity_tpdo_every > 0);
  }
  if (config_.ft.present) {
    ft_ = std::make_unique<FtNode>(config_.ft);
    bus_state_[ft_->bus].router.add_ft(ft_->node);
  }
  for (std::size_t bi = 0; bi < buses_.size(); ++bi)
    sdo_.push_back(std::make_unique<SdoClient>(
        *buses_[bi], config_.buses[bi].name, config_.sdo_timeout_s,
        [this, bi](const can_frame& f) { handle_frame(bi, f, Clock::now()); },
        [this, bi](std::uint8_t node) { return node_label(bi, node); }));
  for (BusState& b : bus_state_) b.router.add_master(config_.master_node_id);
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) reconfig_.push_back(std::make_unique<Reconfig>());
  // Every node, drives first: the set-up steps that treat them all alike
  // (NMT, boot-up, heartbeat) in this order. drives_ is not resized again.
  for (Cia402Drive& d : drives_) nodes_.push_back(&d);
  if (ft_) nodes_.push_back(ft_.get());
  heartbeat_timeout_ = std::chrono::nanoseconds(static_cast<std::int64_t>(config_.heartbeat_consumer_s * 1e9));
  master_hb_period_ = std::chrono::nanoseconds(static_cast<std::int64_t>(config_.heartbeat_producer_s * 1e9));
  overall_cycles_ = static_cast<std::uint32_t>(std::max(1L, std::lround(config_.enable_timeout_s * config_.cycle_rate_hz)));
  step_cycles_ = static_cast<std::uint32_t>(std::max(1L, std::lround(config_.power_step_timeout_s * config_.cycle_rate_hz)));
}

DriveSystem::~DriveSystem() {
  // Best effort, never throws: leave enabled drives in quick stop (they ramp
  // down, then power off: 0x605A is 1 or 2, sdo_list.cpp) rather than
  // following a target nobody updates.
  if (!configured_ || !enabled_) return;
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) {
    for (std::size_t j : bus_state_[bi].drives) (void)buses_[bi]->write(drives_[j].rpdo(controlword::kQuickStop));
    (void)buses_[bi]->write(make_frame(kSync, {}));
  }
}

std::string DriveSystem::node_label(std::size_t bus, std::uint8_t node) const {
  const std::string where = "(bus " + config_.buses[bus].name + " node " + std::to_string(node) + ")";
  for (const Cia402Drive& d : drives_)
    if (d.bus == bus && d.node == node) return d.name + " " + where;
  if (ft_ && ft_->bus == bus && ft_->node == node) return "F/T sensor " + where;
  return "node " + where;
}

std::size_t DriveSystem::joint_count() const noexcept { return drives_.size(); }

const std::string& DriveSystem::device_name(std::size_t joint) const { return drives_.at(joint).info.device_name; }
double DriveSystem::rated_torque_nm(std::size_t joint) const { return drives_.at(joint).info.rated_torque_nm; }
const DriveInfo& DriveSystem::drive_info(std::size_t joint) const { return drives_.at(joint).info; }

std::vector<std::string> DriveSystem::setup_notices() const {
  std::vector<std::string> out;
  for (const auto& c : sdo_) out.insert(out.end(), c->notices().begin(), c->notices().end());
  return out;
}

void DriveSystem::nmt(std::size_t bus, NmtCommand cmd, std::uint8_t node) {
  write_setup_frame(*buses_[bus], config_.buses[bus].name, make_frame(kNmt, {static_cast<std::uint8_t>(cmd), node}));
}

std::uint32_t DriveSystem::sdo_read(std::size_t bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  return sdo_.at(bus)->read(node, index, sub);
}

void DriveSystem::sdo_write(std::size_t bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                            std::uint32_t value, int size) {
  sdo_.at(bus)->write(node, index, sub, value, size);
}

std::string DriveSystem::sdo_read_string(std::size_t bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  return sdo_.at(bus)->read_string(node, index, sub);
}

void DriveSystem::drain_buses() {
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) {
    can_frame f{};
    for (std::size_t k = 0; k < 4 * kMaxFramesPerRead; ++k) {
      const CanIo io = buses_[bi]->read(f);
      if (io != CanIo::Ok && io != CanIo::ErrorFrame && io != CanIo::Malformed) break;
    }
  }
}

void DriveSystem::poll_and_handle(std::vector<pollfd>& fds, int timeout_ms) {
  ::poll(fds.data(), fds.size(), timeout_ms);
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) {
    can_frame f{};
    for (std::size_t k = 0; k < 4 * kMaxFramesPerRead && buses_[bi]->read(f) == CanIo::Ok; ++k)
      handle_frame(bi, f, Clock::now());
  }
}

DriveSetup DriveSystem::drive_setup(std::size_t j) const {
  const Cia402Drive& d = drives_[j];
  DriveSetup s;
  s.node = d.node;
  s.period_us = static_cast<std::uint32_t>(std::lround(1e6 / config_.cycle_rate_hz));
  s.interpolation_exponent = config_.interpolation_exponent;
  s.sync_counter_overflow = static_cast<std::uint8_t>(config_.sync_counter_overflow);
  s.producer_heartbeat_ms = static_cast<std::uint16_t>(std::lround(config_.heartbeat_producer_s * 1e3));
  s.master_node_id = config_.master_node_id;
  s.consumer_heartbeat_ms = static_cast<std::uint16_t>(std::lround(config_.heartbeat_consumer_s * 1e3) & 0xFFFF);
  s.following_error_counts = static_cast<std::uint32_t>(std::lround(std::abs(d.cfg.following_error_limit_rad * d.cfg.counts_per_rad())));
  s.following_error_timeout_ms = static_cast<std::uint16_t>(std::lround(d.cfg.following_error_timeout_s * 1e3));
  if (auto it = limits_.find(d.name); it != limits_.end()) {
    std::int32_t c1 = 0, c2 = 0;
    if (!d.cfg.to_counts(it->second.lower_rad, c1) || !d.cfg.to_counts(it->second.upper_rad, c2))
      throw HwError(node_label(d.bus, d.node) + ": URDF limits do not fit the drive's int32 counts");
    s.limits_counts = std::make_pair(std::min(c1, c2), std::max(c1, c2));
    const double v = std::abs(it->second.velocity_rad_s * d.cfg.counts_per_rad());
    if (v > 0.0 && v < 4.29e9) s.max_velocity_counts_s = static_cast<std::uint32_t>(std::lround(v));
  }
  s.file_entries = d.cfg.sdo_entries;
  s.velocity_tpdo_every = static_cast<std::uint8_t>(config_.velocity_tpdo_every);
  return s;
}

void DriveSystem::configure() {
  // 1. NMT reset node, then wait for every node's boot-up message. Frames
  // already queued (a power-on boot-up, heartbeats) are drained first: a
  // boot-up sent before the reset must not count as its answer, or the first
  // SDO reaches a node that is still booting.
  drain_buses();
  for (auto& c : sdo_) c->clear_notices();
  for (CanNode* n : nodes_) n->booted = n->unconfigured = false;
  unconfigured_mask_.store(0);
  configured_ = false;
  power_ = PowerStatus{};
  enabled_ = false;
  for (const CanNode* n : nodes_) nmt(n->bus, NmtCommand::ResetNode, n->node);
  std::vector<pollfd> fds;
  for (auto& b : buses_) fds.push_back({b->fd(), POLLIN, 0});
  wait_for_boot_up(fds);

  // 2. SDO configuration of every node (pre-operational): node_config.hpp.
  for (std::size_t j = 0; j < drives_.size(); ++j) {
    Cia402Drive& d = drives_[j];
    NodeConfigurator nc(*sdo_[d.bus], [this, b = d.bus](std::uint8_t node) { return node_label(b, node); });
    d.info = nc.configure_drive(drive_setup(j));
  }
  if (ft_) {
    const std::size_t b = ft_->bus;
    NodeConfigurator nc(*sdo_[b], [this, b](std::uint8_t node) { return node_label(b, node); });
    nc.configure_ft(ft_->node, static_cast<std::uint16_t>(std::lround(config_.heartbeat_producer_s * 1e3)));
  }

  // 3. NMT start: PDOs flow from the next SYNC. Heartbeat monitoring starts now.
  const auto now = Clock::now();
  for (Cia402Drive& d : drives_) {
    nmt(d.bus, NmtCommand::Start, d.node);
    d.restart(now);
  }
  if (ft_) {
    nmt(ft_->bus, NmtCommand::Start, ft_->node);
    ft_->start_monitoring(now);
  }
  // 4. Confirm: every node's next heartbeat must say operational.
  wait_for_operational(fds, now + heartbeat_timeout_);
  for (BusState& b : bus_state_) {
    b.sync_sent = false;
    b.bus_off_reported = b.passive_reported = b.closed_reported = b.tx_fail_reported = false;
    b.sync_seen = b.sync_counter;
    b.restarts = 0;
    b.restart_limit_hit = false;
    b.restart_requests = 0;
    b.bus_off_cycles = 0;
  }
  events_.discard();
  configured_ = true;
}

void DriveSystem::wait_for_boot_up(std::vector<pollfd>& fds) {
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(config_.enable_timeout_s));
  auto all_booted = [&] {
    return std::all_of(nodes_.begin(), nodes_.end(), [](const CanNode* n) { return n->booted; });
  };
  while (!all_booted()) {
    if (Clock::now() > deadline) {
      std::string missing;
      for (const CanNode* n : nodes_)
        if (!n->booted) missing += (missing.empty() ? "" : ", ") + node_label(n->bus, n->node);
      throw HwError("no boot-up message after NMT reset node within " +
                    std::to_string(static_cast<int>(config_.enable_timeout_s * 1000)) + " ms from: " + missing +
                    " (powered? node id right? bus wired?)");
    }
    poll_and_handle(fds, 10);
  }
}

void DriveSystem::wait_for_operational(std::vector<pollfd>& fds, Clock::time_point deadline) {
  for (CanNode* n : nodes_) n->nmt = NmtState::PreOperational;
  auto all_operational = [&] {
    return std::all_of(nodes_.begin(), nodes_.end(),
                       [](const CanNode* n) { return n->nmt == NmtState::Operational; });
  };
  while (!all_operational()) {
    if (Clock::now() > deadline) {
      std::string missing;
      for (const CanNode* n : nodes_)
        if (n->nmt != NmtState::Operational)
          missing += (missing.empty() ? "" : ", ") + node_label(n->bus, n->node) + " (" + to_string(n->nmt) + ")";
      throw HwError("no heartbeat reporting NMT operational within " +
                    std::to_string(static_cast<int>(config_.heartbeat_consumer_s * 1000)) +
                    " ms after NMT start from: " + missing);
    }
    poll_and_handle(fds, 5);
  }
}

void DriveSystem::run_cycle_blocking(Clock::time_point& deadline, JointFeedback& fb,
                                     CycleStatus& status) {
  std::this_thread::sleep_until(deadline);
  deadline += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config_.cycle_period_s()));
  FtReading ft;
  status = cycle_read(fb, ft);
}

void DriveSystem::enable() {
  HwEvent refused;
  if (!begin_enable(&refused)) {
    if (!configured_) throw HwError("enable(): configure() has not succeeded");
    if (refused.fault == HwFault::HeartbeatLost)
      throw HwError(node_label(refused.bus, refused.node) + ": heartbeat lost; cannot enable");
    throw HwError("enable(): " + describe(refused));
  }
  run_power_change("enable");
}

void DriveSystem::run_power_change(const char* verb) {
  Clock::time_point deadline = Clock::now();
  JointFeedback fb;
  CycleStatus status;
  JointTargets t;
  for (;;) {
    held_targets(t);  // not taken while the change runs: the stepper holds
    cycle_write(t);
    run_cycle_blocking(deadline, fb, status);
    if (!status.power.finished) continue;
    if (status.power.phase != PowerPhase::Failed) return;
    const HwEvent& cause = status.power.cause;
    if (cause.fault != HwFault::PowerStepTimeout || !(cause.detail & kOverallDeadline))
      throw HwError(std::string(verb) + "(): " + describe(cause));
    // The whole change too long: every drive not there, with its state.
    const bool enabling = status.power.was_enable;
    std::string msg = std::string(verb) + "(): " + (enabling ? "not Operation enabled" : "not confirmed") +
                      " after " + std::to_string(static_cast<int>(config_.enable_timeout_s * 1000)) + " ms:";
    for (const Cia402Drive& d : drives_) {
      if (enabling ? d.enabled() : (d.have_actual && !power_enabled(d.st.state))) continue;
      if (!enabling && !d.have_actual) {
        msg += " " + node_label(d.bus, d.node) + " never answered (no TPDO; state unknown, may still be enabled);";
        continue;
      }
      msg += " " + node_label(d.bus, d.node) + (enabling ? " stayed in '" : " still powered in '") +
             to_string(d.st.state) + "' (statusword " + hex(d.st.statusword, 4) +
             (d.have_actual ? "" : ", no TPDO received") + ")";
      if (enabling && d.last_emcy)
        msg += std::string(", last EMCY ") + hex(d.last_emcy, 4) + " " + to_string(classify_emcy(d.last_emcy));
      msg += ";";
    }
    throw HwError(msg);
  }
}

bool DriveSystem::begin_enable(HwEvent* refused) noexcept {
  HwEvent why{};
  if (!configured_) {
    why.fault = HwFault::NodeUnconfigured;
  } else {
    const auto now = Clock::now();
    for (CanNode* n : nodes_) {
      if (n->unconfigured) {
        why = n->event(HwFault::NodeUnconfigured, static_cast<std::uint32_t>(n->nmt), 0);
        break;
      }
      // A heartbeat lost while the bus was silent stays lost (a stop on every
      // cycle) until the node is heard again.
      if (!n->heartbeat_heard(now, heartbeat_timeout_)) {
        why = n->event(HwFault::HeartbeatLost, 0, 0);
        break;
      }
    }
  }
  if (why.fault != HwFault::None) {
    if (refused != nullptr) *refused = why;
    return false;
  }
  quick_stop_.store(false);
  power_off_.store(false);
  for (Cia402Drive& d : drives_) d.begin_power_change();
  power_ = PowerStatus{};
  power_.phase = PowerPhase::Enabling;
  power_.was_enable = true;
  return true;
}

bool DriveSystem::begin_disable() noexcept {
  if (!configured_) return false;
  for (Cia402Drive& d : drives_) d.begin_power_change();
  power_ = PowerStatus{};
  power_.phase = PowerPhase::Disabling;
  return true;
}

void DriveSystem::end_power(PowerPhase phase, const HwEvent& cause) noexcept {
  power_.phase = phase;
  power_.finished = true;
  power_.cause = cause;
  if (phase == PowerPhase::Enabled) enabled_ = true;
  if (phase == PowerPhase::Disabled) enabled_ = false;
  if (phase == PowerPhase::Failed && power_.was_enable)
    for (Cia402Drive& d : drives_) d.controlword = controlword::kDisableVoltage;  // a failed enable leaves them off
  // A failed disable leaves enabled_ as it was: the destructor still sends quick stop.
}

void DriveSystem::judge_power() noexcept {
  power_.finished = false;
  const bool enabling = power_.phase == PowerPhase::Enabling;
  if (!enabling && power_.phase != PowerPhase::Disabling) return;
  ++power_.cycles;
  for (Cia402Drive& d : drives_) d.note_power_state(events_);
  if (enabling) {
    // A node lost, the bus gone: the enable cannot go on.
    for (std::size_t i = 0; i < events_.size(); ++i) {
      const HwFault f = events_[i].fault;
      if (f == HwFault::HeartbeatLost || f == HwFault::NodeRebooted || f == HwFault::BusOff ||
          f == HwFault::TxFailed || f == HwFault::RxFailed || f == HwFault::NodeNotOperational)
        return end_power(PowerPhase::Failed, events_[i]);
    }
    if (power_off_.load(std::memory_order_acquire)) {
      const HwEvent e{HwFault::PowerChangeAborted, 0, 0, -1, 0, 0};
      events_.push(e);
      return end_power(PowerPhase::Failed, e);
    }
  }
  bool all = true;
  for (Cia402Drive& d : drives_) {
    const bool there = enabling ? d.enabled() : d.have_actual && !power_enabled(d.st.state);
    all = all && there;
    if (there) continue;
    const auto state = d.have_actual ? static_cast<std::uint32_t>(d.st.state) : kUnknownState;
    const bool faulted = d.st.state == PowerState::Fault || d.st.state == PowerState::FaultReactionActive;
    if (enabling && d.have_actual && d.left_fault && faulted) {
      const HwEvent e = d.event(HwFault::FaultAfterReset, d.last_emcy, d.st.statusword);
      events_.push(e);
      return end_power(PowerPhase::Failed, e);
    }
    if (d.state_cycles > step_cycles_ && step_cycles_ < overall_cycles_) {
      const HwEvent e = d.event(HwFault::PowerStepTimeout, state, d.st.statusword);
      events_.push(e);
      return end_power(PowerPhase::Failed, e);
    }
  }
  if (all) return end_power(enabling ? PowerPhase::Enabled : PowerPhase::Disabled, HwEvent{});
  if (power_.cycles > overall_cycles_) {
    HwEvent e{HwFault::PowerStepTimeout, 0, 0, -1, kUnknownState, kOverallDeadline};
    for (const Cia402Drive& d : drives_)
      if (!(enabling ? d.enabled() : d.have_actual && !power_enabled(d.st.state))) {
        e = d.event(HwFault::PowerStepTimeout, d.have_actual ? static_cast<std::uint32_t>(d.st.state) : kUnknownState,
                    kOverallDeadline | d.st.statusword);
        break;
      }
    events_.push(e);
    end_power(PowerPhase::Failed, e);
  }
}

void DriveSystem::describe_power_failure(const HwEvent& e, char* buf, std::size_t size) const noexcept {
  if (size == 0) return;
  const char* joint = e.joint >= 0 && static_cast<std::size_t>(e.joint) < drives_.size()
                          ? drives_[static_cast<std::size_t>(e.joint)].name.c_str()
                          : (ft_ && e.node == ft_->node && e.bus == ft_->bus ? "F/T sensor" : "node");
  const auto state_name = [](std::uint32_t s) {
    return s == kUnknownState ? "no answer" : to_string(static_cast<PowerState>(s));
  };
  switch (e.fault) {
    case HwFault::FaultAfterReset:
      std::snprintf(buf, size, "%s (node %u): in Fault again after its fault reset, EMCY 0x%04X (statusword 0x%04X)",
                    joint, e.node, e.code, e.detail & 0xFFFF);
      break;
    case HwFault::PowerStepTimeout:
      if (e.code == kUnknownState)
        std::snprintf(buf, size, "%s (node %u): no answer for %d ms (%s)", joint, e.node,
                      static_cast<int>(((e.detail & kOverallDeadline) ? config_.enable_timeout_s : config_.power_step_timeout_s) * 1000),
                      (e.detail & kOverallDeadline) ? "enable_timeout_ms" : "power_step_timeout_ms");
      else if (e.detail & kOverallDeadline)
        std::snprintf(buf, size, "%s (node %u): in '%s' after %d ms (enable_timeout_ms)", joint, e.node,
                      state_name(e.code), static_cast<int>(config_.enable_timeout_s * 1000));
      else
        std::snprintf(buf, size, "%s (node %u): in '%s' for %d ms (power_step_timeout_ms) (statusword 0x%04X)",
                      joint, e.node, state_name(e.code), static_cast<int>(config_.power_step_timeout_s * 1000),
                      e.detail & 0xFFFF);
      break;
    case HwFault::NodeUnconfigured:
      if (e.node == 0)
        std::snprintf(buf, size, "the drives are not configured");
      else
        std::snprintf(buf, size, "%s (node %u): rebooted or left NMT operational: not configured", joint, e.node);
      break;
    case HwFault::HeartbeatLost:
      std::snprintf(buf, size, "%s (node %u): heartbeat lost; cannot enable", joint, e.node);
      break;
    case HwFault::PowerChangeAborted: std::snprintf(buf, size, "%s", to_string(e.fault)); break;
    default:
      std::snprintf(buf, size, "%s (node %u): %s (code 0x%04X)", joint, e.node, to_string(e.fault), e.code);
      break;
  }
}

std::size_t DriveSystem::unconfigured_nodes() const noexcept {
  return static_cast<std::size_t>(std::popcount(unconfigured_mask_.load(std::memory_order_acquire)));
}

void DriveSystem::take_back_reconfigured(Clock::time_point now) noexcept {
  for (std::size_t bi = 0; bi < reconfig_.size(); ++bi) {
    Reconfig& rc = *reconfig_[bi];
    if (!rc.restart.load(std::memory_order_acquire)) continue;
    const std::uint8_t rn = rc.node.load(std::memory_order_relaxed);
    for (Cia402Drive& d : drives_)
      if (d.bus == bi && d.node == rn) {
        d.restart(now);  // TPDOs and heartbeat supervised again, state unknown until a TPDO
        d.unconfigured = false;
      }
    if (ft_ && ft_->bus == bi && ft_->node == rn) {
      ft_->start_monitoring(now);
      ft_->unconfigured = false;
    }
    rc.restart.store(false, std::memory_order_relaxed);
    rc.node.store(0, std::memory_order_release);
  }
}

std::size_t DriveSystem::configure_nodes() {
  if (!configured_) throw HwError("configure_nodes(): configure() has not succeeded");
  const std::uint32_t mask = unconfigured_mask_.load(std::memory_order_acquire);
  const auto ms = [](double s) { return std::to_string(static_cast<int>(std::lround(s * 1000))); };
  // Polls what the cycle reports, with a deadline.
  const auto wait_for = [](const std::atomic<bool>& flag, Clock::time_point deadline) {
    while (!flag.load(std::memory_order_acquire)) {
      if (Clock::now() > deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return true;
  };
  const auto secs = [](double s) {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
  };
  std::size_t done = 0;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (!(mask & (1u << i))) continue;
    const CanNode& n = *nodes_[i];
    const std::size_t b = n.bus;
    const std::string label = node_label(b, n.node);
    Reconfig& rc = *reconfig_[b];
    can_frame stale{};
    while (rc.inbox.try_pop(stale)) {
    }
    rc.booted.store(false);
    rc.operational.store(false);
    rc.restart.store(false);
    rc.node.store(n.node, std::memory_order_release);
    struct Release {  // whatever happens, the cycle stops handing this node's frames over
      Reconfig& rc;
      ~Release() {
        if (rc.restart.load(std::memory_order_acquire)) return;  // the cycle clears it
        rc.node.store(0, std::memory_order_release);
      }
    } release{rc};
    nmt(b, NmtCommand::ResetNode, n.node);
    if (!wait_for(rc.booted, Clock::now() + secs(config_.enable_timeout_s)))
      throw HwError("configure_nodes(): no boot-up message after NMT reset node within " + ms(config_.enable_timeout_s) +
                    " ms from " + label);
    SdoClient client(*buses_[b], config_.buses[b].name, config_.sdo_timeout_s, {},
                     [this, b](std::uint8_t node) { return node_label(b, node); });
    client.receive_from(&rc.inbox);
    NodeConfigurator nc(client, [this, b](std::uint8_t node) { return node_label(b, node); });
    if (n.joint >= 0) {
      const auto j = static_cast<std::size_t>(n.joint);
      // The node is pre-operational (no TPDO): the cycle does not read its info meanwhile.
      drives_[j].info = nc.configure_drive(drive_setup(j));
    } else {
      nc.configure_ft(n.node, static_cast<std::uint16_t>(std::lround(config_.heartbeat_producer_s * 1e3)));
    }
    nmt(b, NmtCommand::Start, n.node);
    if (!wait_for(rc.operational, Clock::now() + heartbeat_timeout_))
      throw HwError("configure_nodes(): no heartbeat reporting NMT operational within " +
                    ms(config_.heartbeat_consumer_s) + " ms after NMT start from " + label);
    rc.restart.store(true, std::memory_order_release);
    const auto deadline = Clock::now() + std::chrono::seconds(1);
    while (rc.node.load(std::memory_order_acquire) != 0) {
      if (Clock::now() > deadline)
        throw HwError("configure_nodes(): " + label + " configured, but no cycle took it back within 1 s (is the loop cycling?)");
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ++done;
  }
  return done;
}

std::size_t DriveSystem::home() {
  if (!configured_) throw HwError("home(): configure() has not succeeded");
  constexpr std::uint16_t kHomingMethod = 0x6098, kHomingSpeeds = 0x6099, kHomingAcceleration = 0x609A;
  constexpr std::int8_t kModeHoming = 6;
  constexpr std::uint16_t kHomingStart = 1u << 4, kHomingAttained = 1u << 12, kHomingError = 1u << 13;
  std::vector<std::size_t> homing;
  double timeout_s = 0.0;
  auto write_back = [&](const Cia402Drive& d, std::uint16_t index, std::uint8_t sub, std::uint32_t value, int size,
                        const char* what) {
    sdo_write(d.bus, d.node, index, sub, value, size);
    const std::uint32_t mask = size == 4 ? 0xFFFFFFFFu : (1u << (8 * size)) - 1;
    const std::uint32_t back = sdo_read(d.bus, d.node, index, sub) & mask;
    if (back != (value & mask))
      throw HwError(node_label(d.bus, d.node) + ": homing " + what + " read back " + std::to_string(back) +
                    " after writing " + std::to_string(value & mask));
  };
  for (std::size_t j = 0; j < drives_.size(); ++j) {
    const Cia402Drive& d = drives_[j];
    const HomingConfig& h = d.cfg.homing;
    if (!h.enabled) continue;
    const double cpr = std::abs(d.cfg.counts_per_rad());
    write_back(d, od::kModesOfOperation, 0, static_cast<std::uint8_t>(kModeHoming), 1, "mode 0x6060");
    if (static_cast<std::int8_t>(sdo_read(d.bus, d.node, od::kModesDisplay, 0)) != kModeHoming)
      throw HwError(node_label(d.bus, d.node) + ": modes of operation display 0x6061 is not 6 (homing) after 0x6060 = 6");
    write_back(d, kHomingMethod, 0, static_cast<std::uint8_t>(static_cast<std::int8_t>(h.method)), 1, "method 0x6098");
    write_back(d, kHomingSpeeds, 1, static_cast<std::uint32_t>(std::lround(h.speed_switch_rad_s * cpr)), 4,
               "speed 0x6099:01");
    write_back(d, kHomingSpeeds, 2, static_cast<std::uint32_t>(std::lround(h.speed_zero_rad_s * cpr)), 4,
               "speed 0x6099:02");
    write_back(d, kHomingAcceleration, 0, static_cast<std::uint32_t>(std::lround(h.acceleration_rad_s2 * cpr)), 4,
               "acceleration 0x609A");
    homing.push_back(j);
    timeout_s = std::max(timeout_s, h.timeout_s);
  }
  if (homing.empty()) return 0;
  enable();
  JointTargets t;
  held_targets(t);
  JointFeedback fb;
  CycleStatus status;
  std::vector<bool> done(drives_.size(), false);
  const auto start = Clock::now();
  Clock::time_point deadline = start;
  for (int cycle = 0;; ++cycle) {
    for (std::size_t j : homing)
      drives_[j].controlword = static_cast<std::uint16_t>(controlword::kEnableOperation | (cycle > 0 ? kHomingStart : 0));
    cycle_write(t);
    run_cycle_blocking(deadline, fb, status);
    bool all = true;
    std::string errors;
    for (std::size_t j : homing) {
      const Cia402Drive& d = drives_[j];
      // Two cycles after the start edge: the TPDO answers a SYNC after it.
      if (cycle >= 3 && d.st.fresh && (d.st.statusword & kHomingError))
        errors += " " + node_label(d.bus, d.node) + " homing error (statusword " + hex(d.st.statusword, 4) + ");";
      if (cycle >= 3 && d.st.fresh && (d.st.statusword & kHomingAttained) && d.st.state == PowerState::OperationEnabled)
        done[j] = true;
      all = all && done[j];
    }
    if (!errors.empty()) {
      disable();
      throw HwError("home():" + errors);
    }
    if (all) break;
    if (std::chrono::duration<double>(Clock::now() - start).count() > timeout_s) {
      std::string msg = "home(): not homed within " + std::to_string(static_cast<int>(timeout_s * 1000)) + " ms:";
      for (std::size_t j : homing)
        if (!done[j])
          msg += " " + node_label(drives_[j].bus, drives_[j].node) + " (statusword " + hex(drives_[j].st.statusword, 4) + ");";
      disable();
      throw HwError(msg);
    }
  }
  for (std::size_t j : homing) drives_[j].controlword = controlword::kEnableOperation;
  disable();  // holds the new actual positions as targets
  for (std::size_t j : homing) {
    const Cia402Drive& d = drives_[j];
    write_back(d, od::kModesOfOperation, 0, static_cast<std::uint8_t>(kModeCyclicSyncPosition), 1, "mode 0x6060");
    if (static_cast<std::int8_t>(sdo_read(d.bus, d.node, od::kModesDisplay, 0)) != kModeCyclicSyncPosition)
      throw HwError(node_label(d.bus, d.node) + ": modes of operation display 0x6061 is not 8 (CSP) after homing");
  }
  return homing.size();
}

void DriveSystem::held_targets(JointTargets& out) const noexcept {
  for (std::size_t j = 0; j < drives_.size(); ++j) out.position_rad[j] = drives_[j].held_target_rad();
}

void DriveSystem::disable() {
  if (!begin_disable()) return;
  run_power_change("disable");
}

void DriveSystem::nmt_all(NmtCommand cmd) {
  for (const CanNode* n : nodes_) nmt(n->bus, cmd, n->node);
  if (cmd != NmtCommand::Start) enabled_ = false;
}

// ---- real-time cycle ---------------------------------------------------------------

void EventQueue::take(CycleStatus& s) noexcept {
  s.event_count = static_cast<std::uint8_t>(count_);
  s.events_dropped = dropped_;
  for (std::size_t e = 0; e < count_; ++e) {
    s.events[e] = events_[e];
    s.stop_required = s.stop_required || requires_stop(events_[e].fault);
  }
  count_ = 0;
  dropped_ = 0;
}

void DriveSystem::write_sync(std::size_t bi) noexcept {
  CanBus& bus = *buses_[bi];
  BusState& bs = bus_state_[bi];
  can_frame sync{};
  sync.can_id = kSync;
  sync.can_dlc = 0;
  if (config_.sync_counter_overflow > 0) {  // CiA 301 counter 1..overflow
    bs.sync_counter = static_cast<std::uint8_t>(bs.sync_counter >= config_.sync_counter_overflow ? 1 : bs.sync_counter + 1);
    sync.can_dlc = 1;
    sync.data[0] = bs.sync_counter;
  } else {
    bs.sync_counter = static_cast<std::uint8_t>(bs.sync_counter + 1);  // echo matching without a counter on the wire
  }
  const CanIo sync_io = bus.write(sync);
  if (sync_io != CanIo::Ok) {
    if (!bs.tx_fail_reported)
      push_event({HwFault::TxFailed, static_cast<std::uint8_t>(bi), 0, -1, static_cast<std::uint32_t>(sync_io), kSync});
    bs.tx_fail_reported = true;
  } else {
    bs.sync_sent = true;
  }
}

void DriveSystem::send_sync() noexcept {
  if (!configured_) return;
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) write_sync(bi);
  sync_sent_this_cycle_ = true;
}

void DriveSystem::cycle_write(const JointTargets& targets) noexcept { cycle_write(targets, Clock::now()); }

void DriveSystem::cycle_write(const JointTargets& targets, Clock::time_point now) noexcept {
  if (!configured_) return;  // nothing is sent to nodes that configure() has not checked
  const bool quick_stop = quick_stop_.load(std::memory_order_acquire);
  const bool power_off = power_off_.load(std::memory_order_acquire);
  const bool send_heartbeat = now - last_master_hb_ >= master_hb_period_;
  if (send_heartbeat) last_master_hb_ = now;
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) {
    CanBus& bus = *buses_[bi];
    BusState& bs = bus_state_[bi];
    // SYNC first (CiA 301 synchronous PDOs): the nodes sample their TPDOs at
    // this SYNC and latch the RPDOs that follow at the next one, so the whole
    // synchronous window is left for the RPDOs and a late RPDO cannot split
    // a cycle's targets across two SYNCs. The control loop sends it earlier
    // (send_sync), at its wake-up.
    if (!sync_sent_this_cycle_) write_sync(bi);
    const bool sync_ok = bs.sync_sent;
    bool all_sent = true;
    for (std::size_t j : bs.drives) {
      Cia402Drive& d = drives_[j];
      // A power change steps every drive and holds its actual position.
      if (power_.phase == PowerPhase::Enabling)
        d.step_to_enabled();
      else if (power_.phase == PowerPhase::Disabling)
        d.step_to_disabled();
      else
        d.take_target(targets.position_rad[j], enabled_, events_);
      d.apply_stops(quick_stop && enabled_, power_off);
      const can_frame f = d.rpdo(d.controlword);
      const CanIo io = bus.write(f);
      if (io != CanIo::Ok) {
        all_sent = false;
        if (!bs.tx_fail_reported) push_event(d.event(HwFault::TxFailed, static_cast<std::uint32_t>(io), f.can_id));
        bs.tx_fail_reported = true;
      }
    }
    if (send_heartbeat)  // the master's own heartbeat (NMT state operational)
      (void)bus.write(make_frame(kHeartbeatBase + config_.master_node_id, {static_cast<std::uint8_t>(NmtState::Operational)}));
    if (sync_ok && all_sent) bs.tx_fail_reported = false;  // reported once per episode, not every cycle
  }
  sync_sent_this_cycle_ = false;
  ++cycle_;
}

void DriveSystem::handle_frame(std::size_t bi, const can_frame& f, Clock::time_point now) noexcept {
  const auto bus8 = static_cast<std::uint8_t>(bi);
  ++frames_this_cycle_;
  BusState& bs = bus_state_[bi];
  if (f.can_id & CAN_EFF_FLAG) {
    ++bs.unknown_frames;
    if (!bs.unknown_ext_seen) push_event({HwFault::UnknownCobId, bus8, 0, -1, f.can_id & CAN_EFF_MASK, f.can_dlc});
    bs.unknown_ext_seen = true;
    return;
  }
  const std::uint32_t id = f.can_id & CAN_SFF_MASK;
  if (f.can_id & CAN_RTR_FLAG) {
    push_event({HwFault::MalformedFrame, bus8, node_of(id), -1, id, f.can_dlc});
    return;
  }
  // A node configure_nodes() is configuring again: its SDO answers are that
  // thread's, its boot-up and heartbeat tell it how far the node is.
  Reconfig& rc = *reconfig_[bi];
  if (const std::uint8_t rn = rc.node.load(std::memory_order_acquire); rn != 0) {
    if (id == kSdoTxBase + rn) {
      (void)rc.inbox.try_push(f);  // full: the transfer times out and says so
      return;
    }
    if (id == kHeartbeatBase + rn && f.can_dlc == 1) {
      const auto state = static_cast<NmtState>(f.data[0] & 0x7F);
      if (state == NmtState::BootUp) rc.booted.store(true, std::memory_order_release);
      if (state == NmtState::Operational) rc.operational.store(true, std::memory_order_release);
    }
  }
  if (id == kSync) {  // our own SYNC, looped back by the controller (or the simulator): a marker in the stream
    bs.sync_echo_active = true;
    bs.sync_seen = f.can_dlc >= 1 && config_.sync_counter_overflow > 0 ? f.data[0] : static_cast<std::uint8_t>(bs.sync_seen + 1);
    return;
  }
  using Kind = CobIdRouter::Kind;
  const CobIdRouter::Route r = bs.router.route(id);
  // A TPDO read before the echo of the last SYNC we sent answers an earlier
  // SYNC (late, or that SYNC was lost): the handlers do not take it as fresh.
  const CanNode::RxContext ctx{now, cycle_, configured_, bs.sync_echo_active && bs.sync_seen != bs.sync_counter,
                               &quick_stop_};
  CanNode::Rx rx = CanNode::Rx::Taken;
  std::int8_t joint = -1;
  switch (r.kind) {
    case Kind::DriveTpdo:
    case Kind::DriveVelocity:
    case Kind::DriveEmcy:
    case Kind::DriveHeartbeat:
      joint = static_cast<std::int8_t>(r.slot);
      rx = drives_[r.slot].on_frame(r.kind, f, ctx, events_);
      break;
    case Kind::FtForce:
    case Kind::FtTorque:
    case Kind::FtEmcy:
    case Kind::FtHeartbeat: rx = ft_->on_frame(r.kind, f, ctx, events_); break;
    case Kind::Own: return;
    case Kind::DriveSdo:
    case Kind::FtSdo: push_event({HwFault::UnexpectedSdo, bus8, node_of(id), -1, id, f.data[0]}); return;
    case Kind::None: {
      ++bs.unknown_frames;
      std::uint64_t& word = bs.unknown_seen[id / 64];
      const std::uint64_t bit = std::uint64_t{1} << (id % 64);
      if (!(word & bit)) push_event({HwFault::UnknownCobId, bus8, node_of(id), -1, id, f.can_dlc});
      word |= bit;
      return;
    }
  }
  if (rx == CanNode::Rx::Malformed) push_event({HwFault::MalformedFrame, bus8, node_of(id), joint, id, f.can_dlc});
  if (rx == CanNode::Rx::Stale) ++bs.stale_tpdos;
}

CycleStatus DriveSystem::cycle_read(JointFeedback& joints, FtReading& ft) noexcept {
  return cycle_read(joints, ft, Clock::now());
}

CycleStatus DriveSystem::cycle_read(JointFeedback& joints, FtReading& ft_out, Clock::time_point now) noexcept {
  frames_this_cycle_ = 0;
  for (Cia402Drive& d : drives_) d.st.fresh = false;
  if (ft_) ft_->reading.fresh = false;
  if (const int tare = tare_request_.exchange(0, std::memory_order_acq_rel); tare > 0 && ft_)
    ft_->decoder.request_tare(tare);
  for (std::size_t bi = 0; bi < buses_.size(); ++bi) read_bus(bi, now);
  take_back_reconfigured(now);
  std::uint8_t active = 0;
  HwEvent first_active{};
  supervise_drives(now, active, first_active);
  supervise_ft(now, active, first_active, ft_out);
  supervise_buses(active, first_active);
  judge_power();
  std::uint32_t mask = 0;
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (nodes_[i]->unconfigured) mask |= 1u << i;
  unconfigured_mask_.store(mask, std::memory_order_release);

  joints.count = drives_.size();
  for (std::size_t j = 0; j < drives_.size(); ++j) drives_[j].feedback(joints.joints[j]);

  CycleStatus s;
  if (config_.sto_status_bit >= 0) {
    const auto bit = static_cast<std::uint16_t>(1u << config_.sto_status_bit);
    for (std::size_t j = 0; j < drives_.size() && !s.safe_torque_off; ++j)
      if (drives_[j].st.state_known && (drives_[j].st.statusword & bit) != 0) {
        s.safe_torque_off = true;
        s.sto_joint = static_cast<std::int8_t>(j);
      }
  }
  s.cycle = cycle_;
  s.active_faults = active;
  s.first_active = first_active;
  s.frames_received = frames_this_cycle_;
  s.power = power_;
  events_.take(s);
  s.stop_required = s.stop_required || active > 0;
  return s;
}

void DriveSystem::read_bus(std::size_t bi, Clock::time_point now) noexcept {
  CanBus& bus = *buses_[bi];
  BusState& bs = bus_state_[bi];
  const auto bus8 = static_cast<std::uint8_t>(bi);
  for (std::size_t k = 0; k < kMaxFramesPerRead; ++k) {
    can_frame f{};
    const CanIo io = bus.read(f);
    if (io == CanIo::Ok) {
      handle_frame(bi, f, now);
      continue;
    }
    if (io == CanIo::ErrorFrame) continue;
    if (io == CanIo::WouldBlock) break;
    if (io == CanIo::Malformed) {
      push_event({HwFault::MalformedFrame, bus8, 0, -1, 0, 0});
      continue;
    }
    if (!bs.closed_reported) push_event({HwFault::RxFailed, bus8, 0, -1, static_cast<std::uint32_t>(io), 0});
    bs.closed_reported = true;
    break;
  }
  const BusHealth& h = bus.health();
  if (h.bus_off && !bs.bus_off_reported) push_event({HwFault::BusOff, bus8, 0, -1, h.error_frames, 0});
  if (!h.bus_off && bs.bus_off_reported) {  // restarted (the interface's restart-ms, or by hand)
    ++bs.restarts;
    push_event({HwFault::BusRestarted, bus8, 0, -1, bs.restarts, 0});
    if (bs.restarts > config_.bus_off_restart_limit && !bs.restart_limit_hit) {
      bs.restart_limit_hit = true;
      push_event({HwFault::BusOffRepeated, bus8, 0, -1, bs.restarts, static_cast<std::uint32_t>(config_.bus_off_restart_limit)});
    }
  }
  // Bus-off that lasts: ask the controller to restart (the interface's
  // restart-ms may do it first), every bus_off_restart_delay_s, at most
  // bus_off_restart_limit times per configure().
  if (h.bus_off) {
    const auto delay_cycles = static_cast<std::uint32_t>(std::max(1.0, config_.bus_off_restart_delay_s * config_.cycle_rate_hz));
    if (++bs.bus_off_cycles >= delay_cycles &&
        bs.restart_requests < static_cast<std::uint32_t>(std::max(0, config_.bus_off_restart_limit))) {
      bs.bus_off_cycles = 0;
      const RestartResult r = bus.request_restart();
      ++bs.restart_requests;
      push_event({HwFault::BusRestartRequested, bus8, 0, -1, bs.restart_requests, static_cast<std::uint32_t>(r)});
    }
  } else {
    bs.bus_off_cycles = 0;
  }
  bs.bus_off_reported = h.bus_off;
  if (h.error_passive && !bs.passive_reported) push_event({HwFault::BusErrorPassive, bus8, 0, -1, h.error_frames, 0});
  bs.passive_reported = h.error_passive;
}

void DriveSystem::supervise_drives(Clock::time_point now, std::uint8_t& active, HwEvent& first_active) noexcept {
  for (Cia402Drive& d : drives_) {
    const HwEvent fault = d.supervise(now, heartbeat_timeout_, bus_state_[d.bus].sync_sent, configured_,
                                      config_.tpdo_miss_limit, events_);
    if (fault.fault != HwFault::None && active++ == 0) first_active = fault;
  }
}

void DriveSystem::supervise_ft(Clock::time_point now, std::uint8_t& active, HwEvent& first_active,
                               FtReading& ft_out) noexcept {
  if (!ft_) {
    ft_out = FtReading{};
    return;
  }
  const HwEvent fault = ft_->supervise(now, heartbeat_timeout_, bus_state_[ft_->bus].sync_sent, configured_,
                                       config_.tpdo_miss_limit, events_, ft_out);
  if (fault.fault != HwFault::None && active++ == 0) first_active = fault;
}

void DriveSystem::supervise_buses(std::uint8_t& active, HwEvent& first_active) noexcept {
  for (BusState& bs : bus_state_) {
    bs.sync_sent = false;
    if (bs.bus_off_reported || bs.closed_reported || bs.restart_limit_hit) {
      if (active++ == 0) {
        const HwFault why = bs.restart_limit_hit ? HwFault::BusOffRepeated
                            : bs.bus_off_reported ? HwFault::BusOff
                                                  : HwFault::RxFailed;
        first_active = {why, static_cast<std::uint8_t>(&bs - bus_state_.data()), 0, -1, 0, 0};
      }
    }
  }

}

std::string DriveSystem::describe(const HwEvent& e) const {
  std::string who;
  if (e.fault == HwFault::PowerChangeAborted)
    who = "drives";
  else if (e.joint >= 0)
    who = node_label(drives_[static_cast<std::size_t>(e.joint)].bus, e.node);
  else if (e.node != 0 && e.bus < buses_.size())
    who = node_label(e.bus, e.node);
  else if (e.bus < config_.buses.size())
    who = "bus " + config_.buses[e.bus].name;
  std::string msg = who + ": " + to_string(e.fault);
  switch (e.fault) {
    case HwFault::Emergency:
    case HwFault::EmergencyWarning:
      msg += " " + hex(e.code, 4) + " " + to_string(classify_emcy(static_cast<std::uint16_t>(e.code))) +
             " (error register " + hex(e.detail, 2) + ")";
      break;
    case HwFault::HeartbeatLost: msg += " (silent for " + std::to_string(e.code) + " ms)"; break;
    case HwFault::DriveFault:
      msg += " (statusword " + hex(e.code, 4) + ")";
      if (e.detail)
        msg += ", last EMCY " + hex(e.detail, 4) + " " + to_string(classify_emcy(static_cast<std::uint16_t>(e.detail)));
      break;
    case HwFault::MalformedFrame:
      msg += " COB-ID " + hex(e.code, 3) + " with DLC " + std::to_string(e.detail);
      break;
    case HwFault::UnknownCobId: msg += " " + hex(e.code, 3) + " (further frames counted, not reported)"; break;
    case HwFault::InvalidTarget:
      if (e.detail == 1) msg += ": a step of " + std::to_string(e.code) + " counts exceeds the following-error window";
      break;
    case HwFault::TxFailed:
    case HwFault::RxFailed: msg += std::string(": ") + to_string(static_cast<CanIo>(e.code)); break;
    case HwFault::TpdoMissing:
    case HwFault::FtMissing: msg += " for " + std::to_string(e.code) + " cycles"; break;
    case HwFault::BusRestarted: msg += " (" + std::to_string(e.code) + " since configure)"; break;
    case HwFault::BusRestartRequested:
      msg += std::string(": ") + to_string(static_cast<RestartResult>(e.detail)) + " (attempt " + std::to_string(e.code) +
             " of " + std::to_string(config_.bus_off_restart_limit) + ")";
      break;
    case HwFault::BusOffRepeated:
      msg += " (" + std::to_string(e.code) + " restarts, limit " + std::to_string(e.detail) +
             "): check wiring, termination and bit rate";
      break;
    case HwFault::FtSaturated: msg += " (mask " + hex(e.code, 2) + ", bits Fx Fy Fz Tx Ty Tz)"; break;
    case HwFault::NodeNotOperational:
      msg += std::string(" (now ") + to_string(static_cast<NmtState>(e.code)) + ")";
      break;
    case HwFault::PowerStateChanged:
      msg += std::string(": '") + (e.detail == kUnknownState ? "unknown" : to_string(static_cast<PowerState>(e.detail))) +
             "' -> '" + to_string(static_cast<PowerState>(e.code)) + "'";
      break;
    case HwFault::PowerStepTimeout:
    case HwFault::FaultAfterReset: {
      char buf[160];
      describe_power_failure(e, buf, sizeof buf);
      const char* colon = std::strchr(buf, ':');
      msg = who + (colon != nullptr ? colon : buf);
      if (e.fault == HwFault::FaultAfterReset && e.code != 0)
        msg += std::string(" ") + to_string(classify_emcy(static_cast<std::uint16_t>(e.code)));
      break;
    }
    default: break;
  }
  return msg;
}

}  // namespace foresight::hw
