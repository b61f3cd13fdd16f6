#include "foresight/daemon/tool_worker.hpp"

#include <spdlog/spdlog.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "foresight/common/format.hpp"
#include "foresight/protocol/codec.hpp"
#include "foresight/daemon/algorithm_params.hpp"

namespace foresight::daemon {

using protocol::Reason;
using Clock = std::chrono::steady_clock;

const char* to_string(ToolStepKind kind) noexcept {
  switch (kind) {
    case ToolStepKind::Latch: return "latch";
    case ToolStepKind::Unlatch: return "unlatch";
    case ToolStepKind::Loosen: return "loosen";
    case ToolStepKind::Tighten: return "tighten";
  }
  return "?";
}

std::optional<ToolStepKind> tool_step_from_name(const std::string& name) noexcept {
  for (ToolStepKind k : {ToolStepKind::Latch, ToolStepKind::Unlatch, ToolStepKind::Loosen, ToolStepKind::Tighten})
    if (name == to_string(k)) return k;
  return std::nullopt;
}

std::string parse_tool_step(const protocol::InvokeAlgorithm& invoke, ToolStepKind kind,
                            const hw::LstToolConfig& tool, ToolStep& step) {
  step.kind = kind;
  step.timeout_s = invoke.timeout_s;
  step.speed_rad_s = tool.speed_rad_s;
  step.torque_nm = kind == ToolStepKind::Tighten ? tool.tighten_torque_nm : tool.loosen_torque_limit_nm;
  std::vector<const char*> allowed;
  if (kind == ToolStepKind::Loosen) allowed = {"turns", "torque_limit_nm", "speed_rad_s"};
  if (kind == ToolStepKind::Tighten) allowed = {"torque_nm", "speed_rad_s"};
  const std::string name = to_string(kind);
  for (const auto& p : invoke.params) {
    bool known = false;
    for (const char* a : allowed) known = known || p.name == a;
    if (!known) {
      std::string list;
      for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
      return name + ": unknown parameter '" + p.name + "'" +
             (list.empty() ? " (it takes none)" : " (expected one of: " + list + ")");
    }
    if (!std::isfinite(p.value)) return name + ": parameter '" + p.name + "' is not finite";
    if (p.name == "turns") step.turns = p.value;
    if (p.name == "torque_limit_nm" || p.name == "torque_nm") step.torque_nm = p.value;
    if (p.name == "speed_rad_s") step.speed_rad_s = p.value;
  }
  if (!(step.timeout_s >= 0.0 && step.timeout_s <= kMaxAlgorithmTimeoutS)) return name + fmt_timeout(step.timeout_s);
  if (kind == ToolStepKind::Loosen && !(step.turns > 0.0 && step.turns <= 50.0))
    return name + printf_text(": turns %g out of range (0, 50]", step.turns);
  if ((kind == ToolStepKind::Loosen || kind == ToolStepKind::Tighten)) {
    if (!(step.speed_rad_s > 0.0 && step.speed_rad_s <= tool.max_speed_rad_s))
      return name + printf_text(": speed_rad_s %g out of range (0, %g]", step.speed_rad_s, tool.max_speed_rad_s);
    if (!(step.torque_nm > 0.0 && step.torque_nm <= tool.max_torque_nm))
      return name + printf_text(": torque %g N m out of range (0, %g]", step.torque_nm, tool.max_torque_nm);
  }
  return {};
}

ToolWorker::ToolWorker(hw::LstToolConfig config, double poll_hz)
    : config_(config), poll_period_s_(1.0 / poll_hz), tool_(std::move(config)) {
  thread_ = std::thread([this] { run(); });
}

ToolWorker::~ToolWorker() {
  {
    std::lock_guard lock(mu_);
    quit_ = true;
  }
  cancel_.store(true, std::memory_order_release);
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool ToolWorker::start_step(const ToolStep& step) {
  std::lock_guard lock(mu_);
  if (busy_.load(std::memory_order_acquire) || pending_) return false;
  pending_ = step;
  running_id_.store(step.command_id, std::memory_order_release);
  cancel_.store(false, std::memory_order_release);
  busy_.store(true, std::memory_order_release);
  cv_.notify_all();
  return true;
}

void ToolWorker::cancel(std::uint64_t command_id) noexcept {
  if (!busy_.load(std::memory_order_acquire)) return;
  if (command_id != 0 && command_id != running_id_.load(std::memory_order_acquire)) return;
  cancel_.store(true, std::memory_order_release);
  cv_.notify_all();
}

std::optional<ToolStepResult> ToolWorker::poll_result() {
  std::lock_guard lock(mu_);
  auto r = std::move(result_);
  result_.reset();
  return r;
}

ToolWorker::Latest ToolWorker::latest() const {
  std::lock_guard lock(mu_);
  return latest_;
}

void ToolWorker::read_status() {
  hw::LstStatus st;
  const std::error_code ec = tool_.read_status(st);
  std::lock_guard lock(mu_);
  latest_.stamp_ns = protocol::now_ns();
  latest_.link_ok = !ec;
  if (!ec) {
    latest_.status = st;
    latest_.error.clear();
  } else {
    latest_.error = tool_.last_error_message();
  }
}

void ToolWorker::run() {
  std::unique_lock lock(mu_);
  while (!quit_) {
    if (pending_) {
      const ToolStep step = *pending_;
      pending_.reset();
      lock.unlock();
      ToolStepResult r = execute(step);
      r.command_id = step.command_id;
      read_status();
      lock.lock();
      result_ = std::move(r);
      busy_.store(false, std::memory_order_release);
      continue;
    }
    lock.unlock();
    read_status();
    lock.lock();
    cv_.wait_for(lock, std::chrono::duration<double>(poll_period_s_), [this] { return quit_ || pending_; });
  }
}

ToolStepResult ToolWorker::execute(const ToolStep& step) {
  ToolStepResult r;
  const std::string name = to_string(step.kind);
  auto fail = [&](Reason code, std::string text) {
    r.ok = false;
    r.code = code;
    r.text = name + ": " + std::move(text);
    return r;
  };
  auto link_fail = [&](const std::error_code&) { return fail(Reason::ToolFault, tool_.last_error_message()); };

  const bool run_step = step.kind == ToolStepKind::Loosen || step.kind == ToolStepKind::Tighten;
  const double timeout_s = step.timeout_s > 0.0 ? step.timeout_s : (run_step ? 30.0 : 5.0);
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout_s));

  hw::LstStatus st;
  if (auto ec = tool_.read_status(st)) return link_fail(ec);
  if (st.fault()) {
    // A latched fault from an earlier step: clear it once; if it stays, refuse.
    if (auto ec = tool_.reset_fault()) return link_fail(ec);
    if (auto ec = tool_.read_status(st)) return link_fail(ec);
    if (st.fault()) return fail(Reason::ToolFault, "tool reports a fault: " + st.describe());
  }

  std::error_code ec;
  switch (step.kind) {
    case ToolStepKind::Latch: ec = tool_.latch(); break;
    case ToolStepKind::Unlatch: ec = tool_.unlatch(); break;
    case ToolStepKind::Loosen:
      if ((ec = tool_.reset_turns())) break;
      ec = tool_.run(hw::LstDirection::Loosen, step.speed_rad_s, step.torque_nm);
      break;
    case ToolStepKind::Tighten: ec = tool_.run(hw::LstDirection::Tighten, step.speed_rad_s, step.torque_nm); break;
  }
  if (ec) {
    if (run_step) (void)tool_.stop();
    return link_fail(ec);
  }
  const double turns0 = st.turns;  // loosen zeroed the counter; tighten counts from here
  bool seen_running = false;
  while (true) {
    if (canceled()) {
      if (run_step) (void)tool_.stop();
      return fail(Reason::Aborted, "canceled");
    }
    if (Clock::now() > deadline) {
      if (run_step) (void)tool_.stop();
      return fail(Reason::Timeout, printf_text("not done after %.1f s", timeout_s) + " (" + st.describe() + ")");
    }
    if ((ec = tool_.read_status(st))) {
      if (run_step) (void)tool_.stop();
      return link_fail(ec);
    }
    {
      std::lock_guard lock(mu_);
      latest_.stamp_ns = protocol::now_ns();
      latest_.status = st;
      latest_.link_ok = true;
    }
    r.turns = st.turns - (step.kind == ToolStepKind::Loosen ? 0.0 : turns0);
    r.peak_torque_nm = st.peak_torque_nm;
    if (st.fault()) {
      if (run_step) (void)tool_.stop();
      return fail(Reason::ToolFault, std::string(st.jammed() ? "tool jammed" : st.latch_fault() ? "latch fault" : "tool fault") +
                                         " (" + st.describe() + ")");
    }
    seen_running = seen_running || st.running();
    switch (step.kind) {
      case ToolStepKind::Latch:
        if (st.latched()) {
          r.ok = true;
          r.text = "latch: latched";
          return r;
        }
        break;
      case ToolStepKind::Unlatch:
        if (st.unlatched()) {
          r.ok = true;
          r.text = "unlatch: unlatched";
          return r;
        }
        break;
      case ToolStepKind::Loosen:
        if (-st.turns >= step.turns) {
          (void)tool_.stop();
          r.ok = true;
          r.turns = -st.turns;
          r.text = printf_text("loosen: %.2f turns, peak %.1f N m", -st.turns, std::abs(st.peak_torque_nm));
          return r;
        }
        if (st.torque_reached() && !st.running())
          return fail(Reason::ToolFault, printf_text("the screw did not break loose: stopped at the %.1f N m limit after %.2f turns",
                                             step.torque_nm, -st.turns));
        break;
      case ToolStepKind::Tighten:
        if (st.torque_reached() && !st.running()) {
          r.ok = true;
          r.text = printf_text("tighten: %.1f N m reached after %.2f turns", std::abs(st.peak_torque_nm), st.turns - turns0);
          return r;
        }
        if (seen_running && !st.running() && !st.torque_reached()) {
          (void)tool_.stop();
          return fail(Reason::ToolFault, "the run ended before the torque was reached (" + st.describe() + ")");
        }
        break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // the tool's polling period
  }
}

}  // namespace foresight::daemon
