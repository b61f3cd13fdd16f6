#include "foresight/daemon/reports.hpp"

#include <algorithm>
#include <climits>

#include "foresight/hw/canopen.hpp"
#include "foresight/journal/journal.hpp"

// Telemetry's drive_state is the PowerState value (protocol DriveState numbering, remote_link/convert.cpp).
static_assert(static_cast<int>(foresight::hw::canopen::PowerState::OperationEnabled) == 4 &&
              static_cast<int>(foresight::hw::canopen::PowerState::QuickStopActive) == 5 &&
              static_cast<int>(foresight::hw::canopen::PowerState::Fault) == 7);

namespace foresight::daemon {

using protocol::AckState;
using protocol::ControllerMode;

Reports::Reports(const ReportRates& rates, const Outbox& outbox, std::vector<int> drive_nodes, Sources sources)
    : rates_(rates), outbox_(outbox), drive_nodes_(std::move(drive_nodes)), s_(sources) {
  const auto now = Clock::now();
  next_joints_ = next_wrench_ = next_tool_ = next_status_ = now;
}

protocol::StatusReport Reports::status() const {
  const control::TelemetrySample& latest = s_.bridge.latest();
  const control::StopEvent* last_stop = s_.bridge.last_stop();
  const Job* running = s_.jobs.running();
  protocol::StatusReport s;
  s.stamp_ns = journal::Journal::now_ns();
  s.mode = latest.mode;
  s.active_command_id = running ? running->command.command_id : 0;
  if (running && running->kind == JobKind::Trajectory)
    s.active_trajectory_id = std::get<protocol::RunTrajectory>(running->command.payload).trajectory_id;
  s.last_sequence = s_.site.last_sequence;
  s.stop_category = latest.stop_category;
  if (last_stop && latest.stop_category != protocol::StopCategory::None) s.stop_reason = last_stop->text.data();
  std::uint32_t bits = 0;
  std::string text;
  if (s_.site.estop) {
    bits |= 1u;
    text += "E-stop pressed; ";
  }
  if (s_.site.link_lost) {
    bits |= 2u;
    text += "link lost; ";
  }
  if (latest.mode == ControllerMode::Fault || latest.mode == ControllerMode::Stopped) {
    bits |= 4u;
    text += std::string(last_stop ? last_stop->text.data() : "") + "; ";
  }
  if (!text.empty()) text.resize(text.size() - 2);
  s.fault_bits = bits;
  s.fault_text = text;
  // The drives as they reported themselves (their statusword), not the
  // controller's belief: what a category 0 stop must show unpowered.
  const std::size_t joints =
      std::min<std::size_t>(s_.bridge.have_telemetry() ? latest.joints : 0, control::kMaxJoints);
  for (std::size_t j = 0; j < joints; ++j) {
    protocol::DriveReport d;
    d.joint = static_cast<int>(j + 1);
    d.node_id = j < drive_nodes_.size() ? drive_nodes_[j] : 0;
    d.state = latest.drive_state[j] < protocol::kDriveStateUnknown ? latest.drive_state[j]
                                                                   : protocol::kDriveStateUnknown;
    d.powered = d.state != protocol::kDriveStateUnknown &&
                hw::canopen::power_enabled(static_cast<hw::canopen::PowerState>(d.state));
    s.drives.push_back(d);
  }
  s.rate_limit = s_.bridge.rate_limit();
  if (running)
    s.queue.push_back({running->command.command_id, running->command.kind, running->command.after_command_id,
                       AckState::Executing});
  for (const auto& job : s_.jobs.queued())  // at most controller.max_queued_commands (<= the IDL's MAX_QUEUE)
    s.queue.push_back({job->command.command_id, job->command.kind, job->command.after_command_id, AckState::Queued});
  const control::LoopStats st = s_.loop.stats();
  using LS = control::LoopStats;
  s.loop.realtime = st.realtime;
  s.loop.memory_locked = st.memory_locked;
  s.loop.realtime_required = s_.loop.options().require_realtime;
  s.loop.cycles = st.cycles;
  s.loop.overruns = st.overruns;
  s.loop.missed_streak_max = static_cast<std::uint32_t>(std::min<std::uint64_t>(st.missed_streak_max, UINT32_MAX));
  s.loop.max_missed_cycles = static_cast<std::uint32_t>(s_.loop.options().max_missed_cycles);
  s.loop.wakeup_latency_p99_us = LS::percentile_us(st.latency_hist, 0.99);
  s.loop.wakeup_latency_max_us = st.wakeup_latency_us_max;
  s.loop.compute_p99_us = LS::percentile_us(st.compute_hist, 0.99);
  s.loop.compute_max_us = st.compute_us_max;
  return s;
}

void Reports::publish(bool force_status) {
  const auto now = Clock::now();
  auto period = [](double hz) {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
  };
  const control::TelemetrySample& latest = s_.bridge.latest();
  const bool have_telemetry = s_.bridge.have_telemetry();
  const std::size_t n = std::min<std::size_t>(latest.joints, control::kMaxJoints);
  if (have_telemetry && now >= next_joints_ && outbox_.joints) {
    next_joints_ = now + period(rates_.joint_state_hz);
    protocol::JointReport r;
    r.stamp_ns = LoopBridge::to_wall_ns(latest.stamp_ns);
    r.cycle = latest.cycle;
    r.q_rad.assign(latest.q.begin(), latest.q.begin() + static_cast<std::ptrdiff_t>(n));
    r.dq_rad_s.assign(latest.dq.begin(), latest.dq.begin() + static_cast<std::ptrdiff_t>(n));
    r.torque_nm.assign(latest.torque.begin(), latest.torque.begin() + static_cast<std::ptrdiff_t>(n));
    outbox_.joints(r);
  }
  if (have_telemetry && now >= next_wrench_ && outbox_.wrench) {
    next_wrench_ = now + period(rates_.wrench_hz);
    protocol::WrenchReport w;
    w.stamp_ns = LoopBridge::to_wall_ns(latest.stamp_ns);
    for (int i = 0; i < 3; ++i) {
      w.force_tool_n[i] = latest.wrench_tool[i];
      w.torque_tool_nm[i] = latest.wrench_tool[i + 3];
    }
    w.saturated = latest.ft_saturated;
    outbox_.wrench(w);
  }
  if (s_.tool != nullptr && now >= next_tool_ && outbox_.tool) {
    next_tool_ = now + period(rates_.tool_hz);
    const auto t = s_.tool->latest();
    protocol::ToolReport r;
    r.stamp_ns = t.stamp_ns;
    r.latched = t.status.latched();
    r.running = t.status.running();
    r.direction = !t.status.running() ? 0 : t.status.speed_rad_s >= 0.0 ? 1 : 2;
    r.turns = t.status.turns;
    r.torque_nm = t.status.torque_nm;
    r.fault_bits = t.link_ok ? t.status.fault_bits : 0x8000u;  // 0x8000: the tool does not answer
    outbox_.tool(r);
  }
  if ((force_status || now >= next_status_) && outbox_.status) {
    next_status_ = now + period(rates_.status_hz);
    reported_mode_ = latest.mode;
    outbox_.status(status());
  }
}

}  // namespace foresight::daemon
