#include "foresight/daemon/sim_faults.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "foresight/protocol/codec.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/sim/lst_server.hpp"
#include "foresight/sim/plant.hpp"
#include "foresight/sim/video_switch_server.hpp"

namespace foresight::daemon {

namespace fs = std::filesystem;

SimFaultWatcher::SimFaultWatcher(Site& site, std::string dir) : site_(site), dir_(std::move(dir)) {
  if (!site_.simulated) throw std::invalid_argument("--sim-faults needs --sim");
  fs::create_directories(dir_);
  emcy_present_.assign(site_.simulated->can->drive_count(), false);
  silent_present_.assign(site_.simulated->can->drive_count(), false);
  reboot_present_.assign(site_.simulated->can->drive_count(), false);
  bus_loss_present_.assign(site_.hw_config.buses.size(), false);
  q_.assign(site_.simulated->can->drive_count(), 0.0);
  site_.simulated->can->joint_positions_rad(q_);
  lo_ = q_;
  hi_ = q_;
  thread_ = std::thread([this] { run(); });
}

SimFaultWatcher::~SimFaultWatcher() {
  quit_.store(true);
  if (thread_.joinable()) thread_.join();
}

void SimFaultWatcher::run() {
  auto& sim = *site_.simulated;
  auto level = [&](const char* name, bool& state, const auto& apply) {
    std::error_code ec;
    const bool now = fs::exists(fs::path(dir_) / name, ec);
    if (now == state) return;
    state = now;
    spdlog::warn("simulated fault {}: {}", name, now ? "on" : "off");
    apply(now);
  };
  while (!quit_.load()) {
    level("tool_jam", jam_, [&](bool on) { sim.lst->set_jam(on); });
    level("ft_fault", ft_fault_, [&](bool on) {
      if (sim.can->ft_sensor()) sim.can->ft_sensor()->inject_sensor_fault(on);
    });
    level("oru_stuck", stuck_, [&](bool on) { sim.plant->set_oru_stuck(on); });
    level("estop_circuit", sto_, [&](bool on) {
      for (std::size_t j = 0; j < sim.can->drive_count(); ++j) sim.can->drive(j).set_safe_torque_off(on);
    });
    level("video_silent", video_silent_, [&](bool on) {
      if (sim.video) sim.video->set_silent(on);
    });
    for (std::size_t j = 0; j < emcy_present_.size(); ++j) {
      const fs::path p = fs::path(dir_) / ("drive_emcy_" + std::to_string(j + 1));
      std::error_code ec;
      const bool now = fs::exists(p, ec);
      if (now && !emcy_present_[j]) {
        std::uint16_t code = 0x2310;
        std::ifstream in(p);
        std::string text;
        if (in >> text) {
          try {
            code = static_cast<std::uint16_t>(std::stoul(text, nullptr, 16));
          } catch (const std::exception&) {
          }
        }
        spdlog::warn("simulated fault: joint {} EMCY 0x{:04x}", j + 1, code);
        sim.can->drive(j).inject_fault(code);
      }
      emcy_present_[j] = now;
    }
    for (std::size_t j = 0; j < silent_present_.size(); ++j) {
      std::error_code ec;
      const bool now = fs::exists(fs::path(dir_) / ("drive_silent_" + std::to_string(j + 1)), ec);
      if (now == silent_present_[j]) continue;
      silent_present_[j] = now;
      spdlog::warn("simulated fault: joint {} heartbeat {}", j + 1, now ? "silent" : "back");
      sim.can->drive(j).silence_heartbeat(now);
    }
    for (std::size_t j = 0; j < reboot_present_.size(); ++j) {
      std::error_code ec;
      const bool now = fs::exists(fs::path(dir_) / ("drive_reboot_" + std::to_string(j + 1)), ec);
      if (now && !reboot_present_[j]) {
        spdlog::warn("simulated fault: joint {} reboots", j + 1);
        sim.can->drive(j).inject_reboot();
      }
      reboot_present_[j] = now;
    }
    for (std::size_t b = 0; b < bus_loss_present_.size(); ++b) {
      std::error_code ec;
      const bool now = fs::exists(fs::path(dir_) / ("bus_loss_" + std::to_string(b)), ec);
      if (now == bus_loss_present_[b]) continue;
      bus_loss_present_[b] = now;
      spdlog::warn("simulated fault: bus {} {}", b, now ? "loses every frame" : "passes frames again");
      sim::BusImpairment imp;
      if (now) imp.loss = 1.0;
      sim.can->set_impairment(b, imp);
    }
    write_record();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

void SimFaultWatcher::write_record() {
  site_.simulated->can->joint_positions_rad(q_);
  std::error_code ec;
  auto& can = *site_.simulated->can;
  if (fs::remove(fs::path(dir_) / "drive_record_mark", ec)) {
    lo_ = q_;
    hi_ = q_;
    for (std::size_t j = 0; j < can.drive_count(); ++j) can.drive(j).clear_power_record();
    ++marks_;
  }
  for (std::size_t j = 0; j < q_.size(); ++j) {
    lo_[j] = std::min(lo_[j], q_[j]);
    hi_[j] = std::max(hi_[j], q_[j]);
  }
  ++seq_;
  const fs::path tmp = fs::path(dir_) / ".drive_record.tmp";
  {
    std::ofstream out(tmp);
    out.precision(9);
    out << seq_ << ' ' << marks_;
    for (const auto* v : {&q_, &lo_, &hi_})
      for (double x : *v) out << ' ' << x;
    out << "\npower";
    for (std::size_t j = 0; j < can.drive_count(); ++j) {
      const sim::DrivePowerRecord r = can.drive(j).power_record();
      out << ' ' << protocol::drive_state_name(static_cast<protocol::msg::DriveState>(r.state)) << ' '
          << (r.powered ? 1 : 0) << ' ' << r.states_seen;
    }
    out << '\n';
    if (!out) return;
  }
  fs::rename(tmp, fs::path(dir_) / "drive_record", ec);
}

}  // namespace foresight::daemon
