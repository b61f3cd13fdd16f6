#include "foresight/ground_link/delay_monitor.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>

#include "foresight/protocol/commands.hpp"

namespace foresight::ground_link {

namespace msg = protocol::msg;
using Clock = std::chrono::steady_clock;

namespace {
/// Nearest-rank percentile of sorted values, p in [0, 1].
double percentile(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return 0.0;
  const auto n = sorted.size();
  auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(n)));
  rank = std::clamp<std::size_t>(rank, 1, n);
  return sorted[rank - 1];
}
}  // namespace

DelayStats compute_delay_stats(std::span<const protocol::DelaySample> samples) {
  DelayStats s;
  s.count = samples.size();
  if (samples.empty()) return s;
  std::vector<double> rtt;
  rtt.reserve(samples.size());
  double sum = 0.0;
  std::size_t over_half = 0, over_four = 0;
  std::int64_t best_rtt = std::numeric_limits<std::int64_t>::max();
  for (const auto& d : samples) {
    const double r = static_cast<double>(d.rtt_ns) * 1e-9;
    rtt.push_back(r);
    sum += r;
    if (r > 0.5) ++over_half;
    if (r > 4.0) ++over_four;
    if (d.rtt_ns < best_rtt) {
      best_rtt = d.rtt_ns;
      s.clock_offset_s = static_cast<double>(d.offset_ns) * 1e-9;
    }
  }
  s.last_rtt_s = rtt.back();
  std::sort(rtt.begin(), rtt.end());
  const double n = static_cast<double>(rtt.size());
  s.median_s = percentile(rtt, 0.5);
  s.p95_s = percentile(rtt, 0.95);
  s.p99_s = percentile(rtt, 0.99);
  s.min_s = rtt.front();
  s.max_s = rtt.back();
  s.mean_s = sum / n;
  s.share_over_0_5s = static_cast<double>(over_half) / n;
  s.share_over_4s = static_cast<double>(over_four) / n;
  return s;
}

struct DelayMonitor::Impl {
  Impl(const protocol::Participant& p, Config c)
      : config(c), pings(p), pongs(p), stop_guard(p), waitset(p) {
    if (!(config.rate_hz > 0.0)) throw std::invalid_argument("DelayMonitor: rate_hz must be positive");
    if (config.window == 0) throw std::invalid_argument("DelayMonitor: window must be at least 1");
    waitset.attach(stop_guard, 1);
    if (config.pong_in_listener) {
      dds_listener_t* listener = dds_create_listener(this);
      dds_lset_data_available(listener, &Impl::on_pong_data);
      const dds_return_t rc = dds_set_listener(pongs.get(), listener);
      dds_delete_listener(listener);
      protocol::check(rc, "set the pong listener");
    } else {
      waitset.attach(pongs, 2);
    }
    thread = std::thread([this] { run(); });
  }

  /// Stamps t4 on Cyclone's receive thread, as the pong arrives: the round
  /// trip then excludes this process's thread wake-up. A take, a short lock
  /// and a notify; nothing there throws (bad_alloc in the deque aside).
  static void on_pong_data(dds_entity_t reader, void* arg) noexcept {
    auto* self = static_cast<Impl*>(arg);
    for (int i = 0; i < 64; ++i) {
      void* buffers[1] = {self->listener_pong.get()};
      dds_sample_info_t info;
      if (dds_take(reader, buffers, &info, 1, 1) <= 0) break;
      if (info.valid_data && self->from_remote(reader, info)) self->record(*self->listener_pong, protocol::now_ns());
    }
  }

  /// The writer check (set_writer_check); a writer's participant looked up once.
  bool from_remote(dds_entity_t reader, const dds_sample_info_t& info) noexcept {
    std::lock_guard lock(writer_mutex);
    if (!accept_writer) return true;
    auto it = writers.find(info.publication_handle);
    if (it == writers.end()) {
      if (writers.size() > 256) writers.clear();  // bounded: writers come and go
      try {
        it = writers.emplace(info.publication_handle, protocol::writer_participant(reader, info.publication_handle)).first;
      } catch (...) {
        return false;
      }
    }
    if (accept_writer(it->second)) return true;
    if (ignored.fetch_add(1) == 0)
      spdlog::warn("delay monitor: pongs of participant {} ignored: not the remote (another process answering our pings)",
                   it->second.hex());
    return false;
  }

  void record(const msg::Pong& pong, std::int64_t t4) noexcept {
    {
      std::lock_guard lock(mutex);
      // Only our own pings count (other ground stations ping too; ids
      // start at a random base and t1 must match), each once.
      const auto it = outstanding.find(pong.ping_id);
      if (it == outstanding.end() || it->second.second != pong.ground_send_ns) return;
      outstanding.erase(it);
      // The remote's stamps: a pong whose numbers overflow or give a negative
      // round trip (remote processing longer than the round trip) is dropped.
      const auto d = protocol::delay_from_pong(pong, t4);
      if (!d.valid || d.rtt_ns < 0) return;
      samples.push_back(d);
      if (samples.size() > config.window) samples.pop_front();
      latest = d;
      ++received;
    }
    changed.notify_all();
  }

  void run() noexcept {
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / config.rate_hz));
    auto next_ping = Clock::now();
    protocol::Sample<msg::Ping> ping;
    protocol::Sample<msg::Pong> pong;
    while (!stopping.load()) {
      try {
        const auto now = Clock::now();
        if (now >= next_ping) {
          ping->ping_id = ++next_id;
          ping->ground_send_ns = protocol::now_ns();
          {
            std::lock_guard lock(mutex);
            outstanding[ping->ping_id] = {now, ping->ground_send_ns};
            // Pings never answered (lost) are dropped after pong_timeout_s.
            const auto limit = std::chrono::duration_cast<Clock::duration>(
                std::chrono::duration<double>(config.pong_timeout_s));
            while (!outstanding.empty() && now - outstanding.begin()->second.first > limit) {
              outstanding.erase(outstanding.begin());
            }
          }
          (void)pings.try_write(*ping);
          sent.fetch_add(1);
          next_ping += period;
          if (next_ping < now) next_ping = now + period;  // fell behind (descheduled): do not burst
        }
        waitset.wait(std::max(Clock::duration::zero(), next_ping - Clock::now()));
        if (!config.pong_in_listener) {
          dds_sample_info_t info{};
          for (int i = 0; i < 64 && pongs.take(pong, &info); ++i)
            if (from_remote(pongs.get(), info)) record(*pong, protocol::now_ns());
        }
      } catch (const std::exception& e) {
        spdlog::error("delay monitor: {}", e.what());
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    }
  }

  Config config;
  protocol::Writer<msg::Ping> pings;
  protocol::Reader<msg::Pong> pongs;
  protocol::GuardCondition stop_guard;
  protocol::WaitSet waitset;
  std::atomic<bool> stopping{false};
  std::atomic<std::uint64_t> sent{0};
  std::uint64_t next_id = protocol::random_id() & 0xffffffff00000000ULL;

  mutable std::mutex mutex;
  mutable std::condition_variable changed;
  std::map<std::uint64_t, std::pair<Clock::time_point, std::int64_t>> outstanding;  // id -> sent, t1
  std::deque<protocol::DelaySample> samples;
  std::optional<protocol::DelaySample> latest;
  std::uint64_t received = 0;
  protocol::Sample<msg::Pong> listener_pong;  // Cyclone's receive thread only
  std::mutex writer_mutex;  // accept_writer, writers
  std::function<bool(const protocol::ParticipantGuid&)> accept_writer;
  std::map<dds_instance_handle_t, protocol::ParticipantGuid> writers;
  std::atomic<std::uint64_t> ignored{0};
  std::thread thread;
};

DelayMonitor::DelayMonitor(const protocol::Participant& participant, Config config)
    : impl_(std::make_unique<Impl>(participant, config)) {}

DelayMonitor::~DelayMonitor() { stop(); }

void DelayMonitor::stop() noexcept {
  if (!impl_) return;
  impl_->stopping.store(true);
  // Cyclone waits for a running listener callback before this returns.
  if (impl_->config.pong_in_listener) (void)dds_set_listener(impl_->pongs.get(), nullptr);
  try {
    impl_->stop_guard.trigger();
  } catch (...) {
    // the loop sees `stopping` at its next ping
  }
  if (impl_->thread.joinable()) impl_->thread.join();
}

DelayStats DelayMonitor::stats() const {
  std::vector<protocol::DelaySample> copy;
  std::uint64_t received = 0;
  {
    std::lock_guard lock(impl_->mutex);
    copy.assign(impl_->samples.begin(), impl_->samples.end());
    received = impl_->received;
  }
  DelayStats s = compute_delay_stats(copy);
  s.sent = impl_->sent.load();
  s.received = received;
  return s;
}

std::optional<protocol::DelaySample> DelayMonitor::last() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->latest;
}

std::int64_t DelayMonitor::clock_offset_ns() const noexcept {
  std::lock_guard lock(impl_->mutex);
  std::int64_t best = std::numeric_limits<std::int64_t>::max(), offset = 0;
  for (const auto& d : impl_->samples) {
    if (d.rtt_ns < best) {
      best = d.rtt_ns;
      offset = d.offset_ns;
    }
  }
  if (impl_->samples.empty() && impl_->latest) offset = impl_->latest->offset_ns;
  return offset;
}

std::vector<protocol::DelaySample> DelayMonitor::window() const {
  std::lock_guard lock(impl_->mutex);
  return {impl_->samples.begin(), impl_->samples.end()};
}

bool DelayMonitor::wait_samples(std::size_t count, std::chrono::nanoseconds timeout) const {
  std::unique_lock lock(impl_->mutex);
  return impl_->changed.wait_for(lock, timeout, [&] { return impl_->received >= count; });
}

void DelayMonitor::set_writer_check(std::function<bool(const protocol::ParticipantGuid&)> accept) {
  std::lock_guard lock(impl_->writer_mutex);
  impl_->accept_writer = std::move(accept);
}

std::uint64_t DelayMonitor::ignored_pongs() const noexcept { return impl_->ignored.load(); }

void DelayMonitor::clear() {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->samples.empty()) impl_->latest = impl_->samples.back();
  impl_->samples.clear();
}

}  // namespace foresight::ground_link
