#include "foresight/sim/can_simulator.hpp"

#include <linux/can/error.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <chrono>
#include <numbers>
#include <stdexcept>

namespace foresight::sim {

struct CanSimulator::Bus final : FrameSink {
  std::unique_ptr<hw::CanBus> end;
  std::vector<SimNode*> nodes;
  std::mutex write_mu;
  CanSimulator* owner = nullptr;
  // impairment (guarded by write_mu)
  BusImpairment imp;
  std::mt19937_64 rng{1};
  bool bus_off = false;
  struct Timed {
    Clock::time_point due;
    can_frame f;
  };
  std::deque<Timed> queue;
  Clock::time_point now{};  // of the process()/process_at() step running (delays count from it)

  std::mt19937_64 hb_rng{2};
  bool lose(double p) { return p > 0.0 && std::uniform_real_distribution<double>(0.0, 1.0)(rng) < p; }
  /// Heartbeats draw from their own stream: their phase against the SYNCs
  /// comes from wall time at power-on, and must not shift which PDOs a seeded
  /// run loses.
  bool lose(const can_frame& f, double p) {
    const bool hb = (f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) == 0 &&
                    (f.can_id & CAN_SFF_MASK) >= hw::canopen::kHeartbeatBase &&
                    (f.can_id & CAN_SFF_MASK) < hw::canopen::kHeartbeatBase + 0x80;
    return p > 0.0 && std::uniform_real_distribution<double>(0.0, 1.0)(hb ? hb_rng : rng) < p;
  }
  /// A node's frame onto the bus: lost, delayed, or written now.
  void send(const can_frame& f) override {
    std::lock_guard lock(write_mu);
    if (bus_off) return;
    if (!(f.can_id & CAN_ERR_FLAG) && lose(f, imp.loss)) {
      ++owner->frames_lost_;
      return;
    }
    if (imp.delay_s > 0.0 || imp.jitter_s > 0.0) {
      const double d = imp.delay_s + (imp.jitter_s > 0.0 ? std::uniform_real_distribution<double>(0.0, imp.jitter_s)(rng) : 0.0);
      Clock::time_point due = now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(d));
      if (!queue.empty() && due < queue.back().due) due = queue.back().due;  // FIFO
      queue.push_back({due, f});
      return;
    }
    write_now(f);
  }
  /// Loopback of the master's own frame (never on the wire: not impaired).
  void echo(const can_frame& f) {
    std::lock_guard lock(write_mu);
    if (queue.empty()) write_now(f);
    else queue.push_back({queue.back().due, f});  // stays in bus order behind delayed frames
  }
  void flush(Clock::time_point now) {
    std::lock_guard lock(write_mu);
    for (std::size_t k = 0; k < 4096 && !queue.empty() && queue.front().due <= now; ++k) {
      write_now(queue.front().f);
      queue.pop_front();
    }
  }
  void write_now(const can_frame& f) {
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
    p.sto_status_bit = config.sto_status_bit;
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

void CanSimulator::inject(std::size_t bus, const can_frame& f) {
  Bus& b = *buses_.at(bus);
  std::lock_guard lock(b.write_mu);
  b.write_now(f);  // injected frames bypass loss, delay and bus-off
}

void CanSimulator::set_impairment(std::size_t bus, const BusImpairment& imp) {
  Bus& b = *buses_.at(bus);
  std::lock_guard lock(b.write_mu);
  b.imp = imp;
  b.rng.seed(imp.seed);
  b.hb_rng.seed(imp.seed ^ 0x9E3779B97F4A7C15ull);
}

void CanSimulator::inject_bus_off(std::size_t bus) {
  Bus& b = *buses_.at(bus);
  std::lock_guard lock(b.write_mu);
  b.write_now(hw::make_frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF, {0, 0, 0, 0, 0, 0, 0, 0}));
  b.bus_off = true;
  b.queue.clear();
}

void CanSimulator::inject_error_passive(std::size_t bus) {
  Bus& b = *buses_.at(bus);
  std::lock_guard lock(b.write_mu);
  b.write_now(hw::make_frame(CAN_ERR_FLAG | CAN_ERR_CRTL,
                             {0, CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE, 0, 0, 0, 0, 0, 0}));
}

void CanSimulator::recover_bus(std::size_t bus) {
  Bus& b = *buses_.at(bus);
  std::lock_guard lock(b.write_mu);
  b.bus_off = false;
  b.write_now(hw::make_frame(CAN_ERR_FLAG | CAN_ERR_RESTARTED, {0, 0, 0, 0, 0, 0, 0, 0}));
}

namespace {
bool is_sync(const can_frame& f) noexcept {
  return (f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) == 0 && (f.can_id & CAN_SFF_MASK) == hw::canopen::kSync;
}
}  // namespace

void CanSimulator::dispatch(std::size_t bus, const can_frame& f, Clock::time_point now) {
  ++frames_in_;
  Bus& b = *buses_[bus];
  // A CAN controller with own-message reception loops the master's SYNC back
  // in bus order, before the TPDOs that answer it (SocketCAN
  // CAN_RAW_RECV_OWN_MSGS); DriveSystem uses it to spot late TPDOs.
  const bool sync = is_sync(f);
  {
    std::lock_guard lock(b.write_mu);
    if (b.bus_off) return;  // nothing reaches the nodes
    if (b.lose(f, b.imp.loss) || (sync && b.lose(b.imp.sync_loss))) {
      ++frames_lost_;
      return;
    }
  }
  if (sync) b.echo(f);
  for (SimNode* n : b.nodes) n->handle(f, now, b);
}

void CanSimulator::process(int timeout_ms) {
  if (timeout_ms > 0) {
    std::vector<pollfd> fds;
    for (auto& b : buses_) fds.push_back({b->end->fd(), POLLIN, 0});
    ::poll(fds.data(), fds.size(), timeout_ms);
  }
  step(Clock::now(), true);
}

void CanSimulator::process_at(Clock::time_point now) { step(now, false); }

void CanSimulator::step(Clock::time_point now, bool stamped) {
  std::lock_guard lock(step_mu_);
  power_on();
  for (auto& b : buses_) {
    {
      std::lock_guard bl(b->write_mu);
      b->now = now;
    }
    b->flush(now);
  }
  // The buses one cycle at a time, in turn: each bus's frames up to its next
  // SYNC, then the next bus's. A late simulator thread finds several cycles
  // waiting; draining one bus before the next moved the drives of the first
  // through all of them while the F/T sensor on the second still sampled its
  // first SYNC with those joints already at the last: a reading of an arm
  // pose that never was (the likely cause of a CI run's F/T saturation, a
  // phantom shaft-in-wall contact of 2-3 mm during an insertion). One frame
  // of lookahead per bus.
  struct Next {
    can_frame f{};
    std::int64_t stamp_ns = 0;
    bool have = false;
    bool done = false;
    Clock::time_point last{};
    int read = 0;
  };
  std::vector<Next> next(buses_.size());
  auto pull = [&](std::size_t i) {
    Next& n = next[i];
    n.have = false;
    while (!n.done && n.read < 4096) {
      ++n.read;
      const hw::CanIo io = buses_[i]->end->read(n.f, n.stamp_ns);
      if (io == hw::CanIo::Ok) {
        n.have = true;
        return;
      }
      if (io != hw::CanIo::ErrorFrame) n.done = true;
    }
  };
  for (std::size_t i = 0; i < buses_.size(); ++i) pull(i);
  for (bool any = true; any;) {
    any = false;
    for (std::size_t i = 0; i < buses_.size(); ++i) {
      Next& n = next[i];
      for (bool first = true; n.have && (first || !is_sync(n.f)); first = false) {
        // When the master wrote it (bounded by now, and in bus order); the
        // read time where the kernel gave no stamp.
        Clock::time_point at = now;
        if (stamped && n.stamp_ns > 0)
          at = std::clamp(Clock::time_point(std::chrono::nanoseconds(n.stamp_ns)), n.last, now);
        n.last = at;
        dispatch(i, n.f, at);
        pull(i);
        any = true;
      }
    }
  }
  for (auto& b : buses_)
    for (SimNode* n : b->nodes) n->tick(now, *b);
}

void CanSimulator::start(int rt_priority) {
  if (running_.exchange(true)) return;
  thread_ = std::thread([this, rt_priority] {
    sched_param sp{};
    sp.sched_priority = rt_priority;
    realtime_.store(rt_priority > 0 && pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0 ? 1 : 0);
    run();
  });
}

void CanSimulator::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
}

void CanSimulator::run() {
  while (running_.load()) {
    const std::uint64_t before = frames_in_.load();
    const auto t0 = Clock::now();
    process(1);
    // poll() returns at once on a closed master end (POLLHUP): never spin,
    // this thread may be SCHED_FIFO.
    if (frames_in_.load() == before && Clock::now() - t0 < std::chrono::microseconds(500))
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

}  // namespace foresight::sim
