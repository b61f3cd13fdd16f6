#include "foresight/daemon/loop_bridge.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <ctime>

#include "foresight/common/format.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/control/command.hpp"

namespace foresight::daemon {

namespace {

std::int64_t clock_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

/// The 1-based joints of a bit mask (bit j = joint j + 1).
std::vector<std::size_t> joint_numbers(std::uint32_t mask) {
  std::vector<std::size_t> out;
  for (std::size_t j = 0; j < control::kMaxJoints; ++j)
    if ((mask >> j) & 1u) out.push_back(j + 1);
  return out;
}

std::string joint_list(std::uint32_t mask) {
  std::string s;
  for (const std::size_t j : joint_numbers(mask)) s += (s.empty() ? "" : ", ") + std::to_string(j);
  return s;
}

}  // namespace

LoopBridge::LoopBridge(control::ControlLoop& loop, Ledger& ledger, std::size_t joints) : loop_(loop), ledger_(ledger) {
  latest_.joints = joints;
}

std::int64_t LoopBridge::to_wall_ns(std::int64_t mono_ns) noexcept {
  return clock_ns(CLOCK_REALTIME) - (clock_ns(CLOCK_MONOTONIC) - mono_ns);
}

std::vector<double> LoopBridge::current_q() const {
  const std::size_t n = std::min<std::size_t>(latest_.joints, control::kMaxJoints);
  return std::vector<double>(latest_.q.begin(), latest_.q.begin() + static_cast<std::ptrdiff_t>(n));
}

void LoopBridge::drain_telemetry(std::uint64_t command_id) {
  control::TelemetrySample t;
  while (loop_.poll_telemetry(t)) {
    latest_ = t;
    have_telemetry_ = true;
    journal::TelemetryRow row;
    row.stamp_ns = to_wall_ns(t.stamp_ns);
    row.cycle = t.cycle;
    row.mode = static_cast<std::uint8_t>(t.mode);
    row.joint_count = static_cast<std::uint8_t>(std::min<std::size_t>(t.joints, journal::TelemetryRow::kMaxJoints));
    for (std::size_t j = 0; j < row.joint_count && j < control::kMaxJoints; ++j) {
      row.q_rad[j] = t.q[j];
      row.q_cmd_rad[j] = t.q_cmd[j];
    }
    for (std::size_t i = 0; i < 6; ++i) row.wrench[i] = t.wrench_tool[i];
    ledger_.telemetry(row);
    track_rate_limiter(t, command_id);
  }
}

void LoopBridge::drain_drive_events() {
  control::DriveEventRecord r;
  while (loop_.poll_drive_event(r)) {
    const hw::HwEvent& e = r.event;
    nlohmann::json d;
    d["cycle"] = r.cycle;
    d["stamp_ns"] = to_wall_ns(r.stamp_ns);
    d["fault"] = hw::to_string(e.fault);
    d["hw_fault"] = static_cast<int>(e.fault);
    d["bus"] = e.bus;
    d["node"] = e.node;
    d["joint"] = e.joint + 1;  // 1-based; 0: not a drive
    d["code"] = e.code;
    d["detail"] = e.detail;
    d["stop"] = hw::requires_stop(e.fault);
    ledger_.event("drive_event", loop_.drives().describe(e), d.dump());
  }
  const std::uint64_t dropped = loop_.stats().drive_events_dropped;
  if (dropped != drive_events_dropped_) {
    ledger_.event("drive_event", std::to_string(dropped - drive_events_dropped_) +
                                     " drive events lost (the loop's ring or a cycle's event queue was full)");
    drive_events_dropped_ = dropped;
  }
}

bool LoopBridge::next_stop(const Job* running, control::StopEvent& s) {
  if (!loop_.poll_stop(s)) return false;
  last_stop_ = s;
  have_stop_ = true;
  journal::FaultRow row;
  row.stamp_ns = to_wall_ns(s.stamp_ns);
  row.cycle = s.cycle;
  row.category = s.category == protocol::StopCategory::Cat0 ? 0 : s.category == protocol::StopCategory::Cat1 ? 1 : 2;
  row.cause = control::to_string(s.cause);
  row.text = s.text.data();
  nlohmann::json ev;
  // The running command as the ground knows it (the loop knows it by its loop id).
  const bool ours = running != nullptr && s.command_id != 0 && running->loop_id == s.command_id;
  ev["command_id"] = ours ? running->command.command_id : 0;
  ev["session_id"] = ours ? running->command.session_id : 0;
  ev["joint"] = s.joint;
  ev["value"] = s.value;
  ev["limit"] = s.limit;
  ev["hw_fault"] = s.hw_fault;
  ev["hw_node"] = s.hw_node;
  ev["hw_code"] = s.hw_code;
  nlohmann::json samples = nlohmann::json::array();
  for (std::size_t i = 0; i < s.evidence_count && i < s.evidence.size(); ++i) {
    const auto& e = s.evidence[i];
    std::vector<double> q(e.q.begin(), e.q.begin() + static_cast<std::ptrdiff_t>(s.joints));
    std::vector<double> qc(e.q_cmd.begin(), e.q_cmd.begin() + static_cast<std::ptrdiff_t>(s.joints));
    samples.push_back({{"cycle", e.cycle}, {"q", q}, {"q_cmd", qc}, {"wrench_tool", e.wrench_tool}});
  }
  ev["samples"] = samples;
  row.evidence = json_text(ev);
  ledger_.fault(row);
  spdlog::warn("stop {} ({}): {} at cycle {}", control::to_string(s.category), control::to_string(s.cause),
               s.text.data(), s.cycle);
  return true;
}

void LoopBridge::track_rate_limiter(const control::TelemetrySample& t, std::uint64_t command_id) {
  const std::size_t n = std::min<std::size_t>(t.joints, control::kMaxJoints);
  std::uint32_t joints = 0;
  double lag = 0.0;
  for (std::size_t j = 0; j < n; ++j) {
    if (t.rate_limited_joint_cycles[j] != rate_limited_joint_cycles_[j]) joints |= std::uint32_t{1} << j;
    lag = std::max(lag, std::abs(t.rate_limit_lag[j]));
  }
  rate_limited_joint_cycles_ = t.rate_limited_joint_cycles;
  RateLimitEpisode& e = rate_limit_;
  auto detail = [&](bool end) {
    nlohmann::json d;
    d["joints"] = joint_numbers(e.joints);
    d["command_id"] = e.command_id;
    d["max_lag_rad"] = e.max_lag_rad;
    if (end) d["cycles"] = t.rate_limited_cycles - e.first_cycles;
    return d.dump();
  };
  if (joints != 0) {
    const bool begins = !e.active;
    if (begins) {
      e = RateLimitEpisode{};
      e.active = true;
      e.first_cycles = rate_limit_report_.cycles;  // the count before this episode
      e.command_id = command_id;
    }
    e.joints |= joints;
    e.max_lag_rad = std::max(e.max_lag_rad, lag);
    e.last_limited_ns = t.stamp_ns;
    if (begins) {
      ledger_.event("rate_limit",
                    "the rate limiter limits joint(s) " + joint_list(e.joints) +
                        (e.command_id != 0 ? " of command " + std::to_string(e.command_id) : std::string()),
                    detail(false));
      spdlog::warn("rate limiter: limiting joint(s) {}", joint_list(e.joints));
    }
  } else if (e.active && t.stamp_ns - e.last_limited_ns >= 200'000'000) {
    e.active = false;
    ledger_.event("rate_limit",
                  "the rate limiter let go of joint(s) " + joint_list(e.joints) + " after " +
                      std::to_string(t.rate_limited_cycles - e.first_cycles) + " limited cycles, lag up to " +
                      printf_text("%.4f", e.max_lag_rad) + " rad",
                  detail(true));
  }
  rate_limit_report_.cycles = t.rate_limited_cycles;
  rate_limit_report_.limiting = e.active;
  if (e.joints != 0) {
    rate_limit_report_.last_joint_mask = e.joints;
    rate_limit_report_.last_command_id = e.command_id;
    rate_limit_report_.last_max_lag_rad = e.max_lag_rad;
  }
}

}  // namespace foresight::daemon
