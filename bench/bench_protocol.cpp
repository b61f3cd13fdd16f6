// Protocol benchmarks between TWO PROCESSES on loopback: this benchmark and
// foresight_protocol_peer (the test peer: echoes, answers pings with pongs,
// assembles and verifies uploads). The peer is found beside this binary
// (../bin/foresight_protocol_peer) or at $FORESIGHT_PROTOCOL_PEER.
//
//   BM_PingPongRoundTrip       one ping -> pong round trip (best-effort QoS);
//                              counters: rtt median / p99 in microseconds
//   BM_TrajectoryUpload2000x7  2000 samples x 7 joints (112 KiB, 2 chunks):
//     /acked                   write all chunks -> Writer::wait_for_acks (paced
//                              by Cyclone's heartbeat/ack cycle)
//     /delivered               write all chunks -> the peer has them all
//                              (its "n/n chunks, validating" status is back)
//     /committed               write all chunks -> the peer assembled them,
//                              checked the SHA-256 and limits (validate()),
//                              and published UPLOAD_COMMITTED
//   BM_EndpointDiscovery       new participant + writer in a domain this process
//                              already joined -> matched with the peer's reader
//   BM_ColdDiscovery           first participant of a domain (domain start-up,
//                              participant and endpoint discovery) -> matched

#include <benchmark/benchmark.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/trajectory_upload.hpp"

extern char** environ;

namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

std::string peer_path() {
  if (const char* p = std::getenv("FORESIGHT_PROTOCOL_PEER"); p != nullptr && *p != '\0') return p;
  return (std::filesystem::read_symlink("/proc/self/exe").parent_path() / ".." / "bin" / "foresight_protocol_peer")
      .lexically_normal()
      .string();
}

/// A peer process in `domain`, killed (SIGTERM, then SIGKILL) on destruction.
struct Peer {
  explicit Peer(dds_domainid_t domain) {
    const std::string path = peer_path();
    const std::string d = std::to_string(domain);
    const char* argv[] = {path.c_str(), "--domain", d.c_str(), "--lifetime-s", "600", nullptr};
    if (posix_spawn(&pid, path.c_str(), nullptr, nullptr, const_cast<char* const*>(argv), environ) != 0) {
      throw std::runtime_error("cannot start " + path);
    }
  }
  ~Peer() {
    kill(pid, SIGTERM);
    int status = 0;
    for (int i = 0; i < 300 && waitpid(pid, &status, WNOHANG) != pid; ++i) std::this_thread::sleep_for(10ms);
    if (waitpid(pid, &status, WNOHANG) == 0) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
    }
  }
  Peer(const Peer&) = delete;
  Peer& operator=(const Peer&) = delete;
  pid_t pid = -1;
};

/// One peer process and one participant for the whole run.
struct Setup {
  Setup() {
    fp::use_loopback_if_unconfigured();
    domain = fp::unique_test_domain();
    peer = std::make_unique<Peer>(domain);
    participant = std::make_unique<fp::Participant>(domain);
  }
  ~Setup() {
    participant.reset();
    peer.reset();
  }
  dds_domainid_t domain = 0;
  std::unique_ptr<Peer> peer;
  std::unique_ptr<fp::Participant> participant;
};

Setup& setup() {
  static Setup s;
  return s;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
}

void BM_PingPongRoundTrip(benchmark::State& state) {
  fp::Writer<msg::Ping> ping(*setup().participant);
  fp::Reader<msg::Pong> pong(*setup().participant);
  if (!ping.wait_for_readers(2, 10s) || !pong.wait_for_writers(1, 10s)) {
    state.SkipWithError("peer not discovered");
    return;
  }
  std::this_thread::sleep_for(100ms);  // let the peer's side of the match settle
  fp::Sample<msg::Pong> got;
  std::vector<double> rtt_us;
  rtt_us.reserve(100000);
  std::uint64_t id = 0, lost = 0;
  for (auto _ : state) {
    msg::Ping p{};
    p.ping_id = ++id;
    p.ground_send_ns = fp::now_ns();
    const auto t0 = Clock::now();
    ping.write(p);
    bool ok = false;
    while (pong.wait_take(got, 200ms)) {
      if (got->ping_id == id) {
        ok = true;
        break;
      }
    }
    if (!ok) {
      ++lost;
      continue;
    }
    rtt_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  state.counters["rtt_median_us"] = percentile(rtt_us, 0.5);
  state.counters["rtt_p99_us"] = percentile(rtt_us, 0.99);
  state.counters["lost"] = static_cast<double>(lost);
}
BENCHMARK(BM_PingPongRoundTrip)->Unit(benchmark::kMicrosecond)->MinTime(2.0)->UseRealTime();

foresight::Trajectory make_trajectory(int samples, int joints) {
  foresight::Trajectory t;
  t.time_s.resize(static_cast<std::size_t>(samples));
  t.positions_rad.resize(samples, joints);
  for (int s = 0; s < samples; ++s) {
    t.time_s[static_cast<std::size_t>(s)] = 0.01 * s;
    for (int j = 0; j < joints; ++j) t.positions_rad(s, j) = 0.4 * std::sin(0.005 * s + 0.7 * j);
  }
  return t;
}

enum class UploadEnd { Acked, Delivered, Committed };

void BM_TrajectoryUpload2000x7(benchmark::State& state, UploadEnd end) {
  fp::Writer<msg::TrajectoryChunk> writer(*setup().participant);
  fp::Reader<msg::TrajectoryStatus> status(*setup().participant);
  if (!writer.wait_for_readers(2, 10s) || !status.wait_for_writers(1, 10s)) {
    state.SkipWithError("peer not discovered");
    return;
  }
  const foresight::Trajectory t = make_trajectory(2000, 7);
  const foresight::TrajectoryHash hash = foresight::trajectory_hash(t);
  std::uint64_t id = (static_cast<std::uint64_t>(end) + 1) << 40;
  fp::Sample<msg::TrajectoryStatus> s;
  // Waits for the status of `id` that ends this mode's measurement.
  auto wait_status = [&](UploadEnd until) {
    while (status.wait_take(s, 5s)) {
      if (s->trajectory_id != id) continue;
      if (s->state == foresight_msg_UPLOAD_REJECTED) return false;
      if (until == UploadEnd::Delivered && s->chunks_received == s->chunk_count) return true;
      if (s->state == foresight_msg_UPLOAD_COMMITTED) return true;
    }
    return false;
  };
  // Warm-up upload: proves the path both ways before timing.
  for (const auto& c : fp::make_chunks(t, ++id, 1, hash)) writer.write(c);
  if (!wait_status(UploadEnd::Committed)) {
    state.SkipWithError("warm-up upload not committed");
    return;
  }
  for (auto _ : state) {
    state.PauseTiming();
    const auto chunks = fp::make_chunks(t, ++id, 1, hash);
    state.ResumeTiming();
    for (const auto& c : chunks) writer.write(c);
    const bool ok = end == UploadEnd::Acked ? writer.wait_for_acks(5s) : wait_status(end);
    if (!ok) {
      state.SkipWithError("upload not acknowledged / delivered / committed within 5 s");
      return;
    }
    // Do not let the verdict leak into the next iteration. The status topic
    // keeps the last state per upload, so the status that showed every chunk
    // received may already be the COMMITTED one: then there is no other to
    // wait for (waiting would cost the 5 s timeout every iteration).
    if (end == UploadEnd::Delivered && s->state != foresight_msg_UPLOAD_COMMITTED) {
      state.PauseTiming();
      wait_status(UploadEnd::Committed);
      state.ResumeTiming();
    }
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * 2000 * 8 * 8);
}
BENCHMARK_CAPTURE(BM_TrajectoryUpload2000x7, acked, UploadEnd::Acked)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_TrajectoryUpload2000x7, delivered, UploadEnd::Delivered)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_TrajectoryUpload2000x7, committed, UploadEnd::Committed)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// A new participant in a domain this process already has (the peer's
// participant is known): endpoint discovery only.
void BM_EndpointDiscovery(benchmark::State& state) {
  setup();
  for (auto _ : state) {
    fp::Participant p(setup().domain);
    fp::Writer<msg::Command> w(p);
    if (!w.wait_for_readers(2, 10s)) {
      state.SkipWithError("peer not discovered within 10 s");
      return;
    }
  }
}
BENCHMARK(BM_EndpointDiscovery)->Unit(benchmark::kMillisecond)->Iterations(20)->UseRealTime();

// A ground starting while the remote runs: the first participant of a domain
// in this process (Cyclone creates the domain: sockets, threads), then
// participant (SPDP) and endpoint (SEDP) discovery of the running peer.
void BM_ColdDiscovery(benchmark::State& state) {
  setup();
  const dds_domainid_t domain = 1 + (setup().domain - 1 + 115) % 230;
  Peer peer(domain);
  std::this_thread::sleep_for(500ms);  // the peer is up before timing starts
  for (auto _ : state) {
    fp::Participant p(domain);
    fp::Writer<msg::Command> w(p);
    if (!w.wait_for_readers(2, 10s)) {
      state.SkipWithError("peer not discovered within 10 s");
      return;
    }
  }
}
BENCHMARK(BM_ColdDiscovery)->Unit(benchmark::kMillisecond)->Iterations(10)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
