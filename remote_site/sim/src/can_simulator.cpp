#include "foresight/sim/can_simulator.hpp"

#include <poll.h>

#include <numbers>
#include <stdexcept>

namespace foresight::sim {

struct CanSimulator::Bus final : FrameSink {
  std::unique_ptr<hw::CanBus> end;
  std::vector<SimNode*> nodes;
  std::mutex write_mu;
  CanSimulator* owner = nullptr;
  void send(const can_frame& f) override {
    std::lock_guard lock(write_mu);
    // A full queue on the master side drops the frame, like a CAN controller
    // whose receiver overflowed; bounded retries keep the sim from stalling.
    for (int i = 0; i < 50; ++i) {
      const hw::CanIo io = end->write(f);
      if (io == hw::CanIo::Ok) {
        ++owner->frames_out_;
        return;
      }
      if (io != hw::CanIo::WouldBlock) break;
      pollfd p{end->fd(), POLLOUT, 0};
      ::poll(&p, 1, 1);
    }
    ++owner->frames_dropped_;
  }
};

MockBuses make_mock_buses(const hw::RemoteConfig& config) {
  MockBuses m;
  for (const hw::BusConfig& b : config.buses) {
    if (!b.is_mock())
      throw hw::CanError(config.source + ": bus '" + b.name + "' has interface '" + b.interface +
                         "', not mock: the simulator needs every bus to be a mock bus");
    auto [master, far] = hw::MockCanBus::create_pair(b.name);
    m.master.push_back(std::move(master));
    m.far.push_back(std::move(far));
  }
  return m;
}

CanSimulator::CanSimulator() = default;

CanSimulator::~CanSimulator() { stop(); }

std::unique_ptr<CanSimulator> CanSimulator::from_config(const hw::RemoteConfig& config,
                                                        std::vector<std::unique_ptr<hw::CanBus>> far_ends) {
  auto sim = std::make_unique<CanSimulator>();
  for (auto& f : far_ends) sim->add_bus(std::move(f));
  for (const hw::DriveConfig& d : config.drives) {
    SimDriveParams p;
    p.node_id = d.node_id;
    p.name = d.joint;
    p.counts_per_rev = d.counts_per_rev;
    p.max_motor_speed_counts_s = 100.0 * d.counts_per_rev;  // 6000 rpm
    sim->add_drive(static_cast<std::size_t>(config.bus_index(d.bus)), p);
    sim->drives_.back().has_scaling = true;
    sim->drives_.back().scaling = d;
  }
  if (config.ft.present) {
    SimFtParams p;
    p.node_id = config.ft.node_id;
    p.force_counts_per_n = config.ft.force_counts_per_n;
    p.torque_counts_per_nm = config.ft.torque_counts_per_nm;
    sim->add_ft_sensor(static_cast<std::size_t>(config.bus_index(config.ft.bus)), p);
  }
  return sim;
}

std::size_t CanSimulator::add_bus(std::unique_ptr<hw::CanBus> far_end) {
  auto b = std::make_unique<Bus>();
  b->end = std::move(far_end);
  b->owner = this;
  buses_.push_back(std::move(b));
  return buses_.size() - 1;
}

SimDrive& CanSimulator::add_drive(std::size_t bus, const SimDriveParams& params) {
  auto node = std::make_unique<SimDrive>(params);
  buses_.at(bus)->nodes.push_back(node.get());
  drives_.push_back({bus, std::move(node), false, hw::DriveConfig{}});
  return *drives_.back().node;
}

SimFtSensor& CanSimulator::add_ft_sensor(std::size_t bus, const SimFtParams& params) {
  ft_ = std::make_unique<SimFtSensor>(params);
  ft_bus_ = bus;
  buses_.at(bus)->nodes.push_back(ft_.get());
  return *ft_;
}

void CanSimulator::joint_positions_rad(std::span<double> out) const {
  if (out.size() < drives_.size()) throw std::logic_error("joint_positions_rad: output span too short");
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    const DriveEntry& d = drives_[i];
    if (!d.has_scaling) throw std::logic_error("joint_positions_rad: drive added without a DriveConfig");
    const double counts = d.node->position_counts();
    out[i] = d.scaling.offset_rad + counts * 2.0 * std::numbers::pi /
                                        (d.scaling.direction * d.scaling.counts_per_rev * d.scaling.gear_ratio);
  }
}

void CanSimulator::joint_velocities_rad_s(std::span<double> out) const {
  if (out.size() < drives_.size()) throw std::logic_error("joint_velocities_rad_s: output span too short");
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    const DriveEntry& d = drives_[i];
    if (!d.has_scaling) throw std::logic_error("joint_velocities_rad_s: drive added without a DriveConfig");
    out[i] = d.node->velocity_counts_s() * 2.0 * std::numbers::pi /
             (d.scaling.direction * d.scaling.counts_per_rev * d.scaling.gear_ratio);
  }
}

void CanSimulator::power_on() {
  if (powered_) return;
  powered_ = true;
  for (auto& b : buses_)
    for (SimNode* n : b->nodes) n->power_on(*b);
}

void CanSimulator::inject(std::size_t bus, const can_frame& f) { buses_.at(bus)->send(f); }

void CanSimulator::dispatch(std::size_t bus, const can_frame& f, Clock::time_point now) {
  ++frames_in_;
  Bus& b = *buses_[bus];
  for (SimNode* n : b.nodes) n->handle(f, now, b);
}

void CanSimulator::process(int timeout_ms) {
  std::lock_guard lock(step_mu_);
  power_on();
  if (timeout_ms > 0) {
    std::vector<pollfd> fds;
    for (auto& b : buses_) fds.push_back({b->end->fd(), POLLIN, 0});
    ::poll(fds.data(), fds.size(), timeout_ms);
  }
  const auto now = Clock::now();
  for (std::size_t i = 0; i < buses_.size(); ++i) {
    can_frame f{};
    for (int k = 0; k < 4096; ++k) {
      const hw::CanIo io = buses_[i]->end->read(f);
      if (io == hw::CanIo::Ok)
        dispatch(i, f, now);
      else if (io != hw::CanIo::ErrorFrame)
        break;
    }
  }
  for (auto& b : buses_)
    for (SimNode* n : b->nodes) n->tick(now, *b);
}

void CanSimulator::start() {
  if (running_.exchange(true)) return;
  thread_ = std::thread([this] { run(); });
}

void CanSimulator::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
}

void CanSimulator::run() {
  while (running_.load()) process(1);
}

}  // namespace foresight::sim
