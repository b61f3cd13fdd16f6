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
//   BM_PingPongVsDdsperf       alternating rounds in one run: our ping/pong
//                              against the protocol peer and against the remote
//                              link (link_test_remote: RemoteLink, pings served
//                              first), and Cyclone's own `ddsperf ping`/`pong`
//                              in two processes, reliable + listener and best
//                              effort + waitset. ddsperf prints HALF the round
//                              trip: doubled here. Counters: medians and p99s
//                              in us, and our/ddsperf ratios. ddsperf comes
//                              from cyclonedds-tools ($FORESIGHT_DDSPERF or PATH).
//   BM_TelemetryRate/plain, /secure   joint states the remote link publishes
//                              flat out (link_test_remote --telemetry-hz 0),
//                              received per second by a ground reader
//                              (best effort: what arrives, not what was sent)
//   BM_LinkSecurity/plain, /secure   the remote link (link_test_remote) with and
//                              without DDS Security (scripts/make_dds_security.sh
//                              material in a scratch folder; identities
//                              "remote" and "ground"): time to match, ping/pong
//                              round trip (listener ends) median/p99, and a
//                              1,800 x 7 upload -> COMMITTED (RemoteLink
//                              assembles, SHA-256, URDF limits) median.

#include <benchmark/benchmark.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fcntl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/security.hpp"
#include "foresight/protocol/trajectory_upload.hpp"

extern char** environ;

namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

std::string bin_path(const char* name) {
  return (std::filesystem::read_symlink("/proc/self/exe").parent_path() / ".." / "bin" / name)
      .lexically_normal()
      .string();
}

std::string peer_path() {
  if (const char* p = std::getenv("FORESIGHT_PROTOCOL_PEER"); p != nullptr && *p != '\0') return p;
  return bin_path("foresight_protocol_peer");
}

/// A child process (`argv[0]` is the path), killed (SIGTERM, then SIGKILL) on destruction.
struct Peer {
  explicit Peer(dds_domainid_t domain) {
    const std::string path = peer_path();
    const std::string d = std::to_string(domain);
    spawn({path, "--domain", d, "--lifetime-s", "600"});
  }
  /// `quiet`: stdout to /dev/null (ddsperf pong's chatter).
  Peer(const std::vector<std::string>& argv, bool quiet) { spawn(argv, quiet); }
  void spawn(const std::vector<std::string>& args, bool quiet = false) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    if (quiet) posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    const int rc = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) throw std::runtime_error("cannot start " + args[0]);
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

/// Ping/pong round trips (us, wall clock at this end) for `duration`, one
/// ping in flight at a time, as ddsperf's ping does.
std::vector<double> ping_pong_for(fp::Writer<msg::Ping>& ping, fp::Reader<msg::Pong>& pong,
                                  std::chrono::nanoseconds duration, std::uint64_t& id) {
  std::vector<double> rtt_us;
  fp::Sample<msg::Pong> got;
  const auto end = Clock::now() + duration;
  while (Clock::now() < end) {
    msg::Ping p{};
    p.ping_id = ++id;
    p.ground_send_ns = fp::now_ns();
    const auto t0 = Clock::now();
    ping.write(p);
    while (pong.wait_take(got, 200ms)) {
      if (got->ping_id == id) {
        rtt_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
        break;
      }
    }
  }
  return rtt_us;
}

/// As ddsperf's "ping listener": the pong listener (Cyclone's receive
/// thread) stamps the round trip and writes the next ping itself, so no
/// application thread wakes up in the loop. Runs for `duration`.
struct ListenerPinger {
  fp::Writer<msg::Ping>* ping = nullptr;
  std::uint64_t id = 0;
  Clock::time_point sent{}, end{};
  std::vector<double> rtt_us;
  fp::Sample<msg::Pong> got;
  std::atomic<bool> done{false};

  void send() noexcept {
    msg::Ping p{};
    p.ping_id = ++id;
    p.ground_send_ns = fp::now_ns();
    sent = Clock::now();
    (void)ping->try_write(p);
  }
  static void on_pong(dds_entity_t reader, void* arg) noexcept {
    auto* self = static_cast<ListenerPinger*>(arg);
    for (;;) {
      void* buffers[1] = {self->got.get()};
      dds_sample_info_t info;
      if (dds_take(reader, buffers, &info, 1, 1) <= 0) return;
      if (!info.valid_data || self->got->ping_id != self->id || self->done.load()) continue;
      const auto now = Clock::now();
      if (self->rtt_us.size() < self->rtt_us.capacity()) {
        self->rtt_us.push_back(std::chrono::duration<double, std::micro>(now - self->sent).count());
      }
      if (now >= self->end) {
        self->done.store(true);
        return;
      }
      self->send();
    }
  }
};

std::vector<double> ping_pong_listener_for(fp::Writer<msg::Ping>& ping, fp::Reader<msg::Pong>& pong,
                                           std::chrono::nanoseconds duration, std::uint64_t& id) {
  ListenerPinger pinger;
  pinger.ping = &ping;
  pinger.id = id;
  pinger.rtt_us.reserve(1'000'000);
  pinger.end = Clock::now() + duration;
  dds_listener_t* listener = dds_create_listener(&pinger);
  dds_lset_data_available(listener, &ListenerPinger::on_pong);
  fp::check(dds_set_listener(pong.get(), listener), "set pong listener");
  dds_delete_listener(listener);
  pinger.send();
  // A lost ping (best effort) stalls the chain: re-send after 200 ms of silence.
  const auto hard_end = pinger.end + 2s;
  std::size_t seen = 0;
  auto last_progress = Clock::now();
  while (!pinger.done.load() && Clock::now() < hard_end) {
    std::this_thread::sleep_for(20ms);
    const std::size_t n = pinger.rtt_us.size();
    if (n != seen) {
      seen = n;
      last_progress = Clock::now();
    } else if (Clock::now() - last_progress > 200ms) {
      pinger.send();
      last_progress = Clock::now();
    }
  }
  fp::check(dds_set_listener(pong.get(), nullptr), "clear pong listener");  // waits for a running callback
  id = pinger.id;
  return std::move(pinger.rtt_us);
}

std::string ddsperf_path() {
  if (const char* p = std::getenv("FORESIGHT_DDSPERF"); p != nullptr && *p != '\0') return p;
  return "ddsperf";
}

/// One ddsperf ping/pong pair in `domain` for `seconds`: the per-second
/// lines' 50% and 99% values, doubled (ddsperf prints (t_now - t_sent) / 2).
/// The first line (discovery, warm-up) is dropped. Empty when ddsperf is
/// missing or printed nothing.
struct DdsperfRun {
  std::vector<double> median_rtt_us, p99_rtt_us;
};
DdsperfRun run_ddsperf(dds_domainid_t domain, int seconds, bool reliable, bool listener) {
  DdsperfRun out;
  const std::string d = std::to_string(domain);
  const std::string mode = listener ? "listener" : "waitset";
  std::vector<std::string> pong_args = {ddsperf_path(), "-i", d, "-D", std::to_string(seconds + 3)};
  if (!reliable) pong_args.push_back("-u");
  pong_args.insert(pong_args.end(), {"pong", mode});
  std::unique_ptr<Peer> pong;
  try {
    pong = std::make_unique<Peer>(pong_args, true);
  } catch (const std::exception&) {
    return out;
  }
  std::string cmd = ddsperf_path() + " -i " + d + " -D " + std::to_string(seconds + 1) + (reliable ? "" : " -u") +
                    " ping " + mode + " 2>&1";
  FILE* f = popen(cmd.c_str(), "r");
  if (f == nullptr) return out;
  char line[1024];
  int n = 0;
  while (std::fgets(line, sizeof line, f) != nullptr) {
    const char* m = std::strstr(line, " 50% ");
    const char* q = std::strstr(line, " 99% ");
    if (m == nullptr || q == nullptr) continue;
    if (n++ == 0) continue;  // warm-up second
    out.median_rtt_us.push_back(2.0 * std::strtod(m + 5, nullptr));
    out.p99_rtt_us.push_back(2.0 * std::strtod(q + 5, nullptr));
  }
  pclose(f);
  return out;
}

double median_of(std::vector<double> v) { return percentile(std::move(v), 0.5); }

void BM_PingPongVsDdsperf(benchmark::State& state) {
  const int rounds = 3;
  const int seconds = 2;
  // Our pings against the protocol peer (the shared set-up).
  fp::Writer<msg::Ping> ping(*setup().participant);
  fp::Reader<msg::Pong> pong(*setup().participant);
  // Our pings against the remote link, in a domain of its own.
  const dds_domainid_t link_domain = 1 + (setup().domain - 1 + 57) % 230;
  const dds_domainid_t perf_domain = 1 + (setup().domain - 1 + 173) % 230;
  const std::string link_remote = bin_path("link_test_remote");
  std::unique_ptr<Peer> remote;
  std::unique_ptr<fp::Participant> link_participant;
  std::unique_ptr<fp::Writer<msg::Ping>> link_ping;
  std::unique_ptr<fp::Reader<msg::Pong>> link_pong;
  if (std::filesystem::exists(link_remote)) {
    remote = std::make_unique<Peer>(std::vector<std::string>{link_remote, "--domain", std::to_string(link_domain),
                                                             "--lifetime-s", "600"},
                                    true);
    link_participant = std::make_unique<fp::Participant>(link_domain);
    link_ping = std::make_unique<fp::Writer<msg::Ping>>(*link_participant);
    link_pong = std::make_unique<fp::Reader<msg::Pong>>(*link_participant);
  }
  if (!ping.wait_for_readers(2, 10s) || !pong.wait_for_writers(1, 10s) ||
      (link_ping && (!link_ping->wait_for_readers(1, 10s) || !link_pong->wait_for_writers(1, 10s)))) {
    state.SkipWithError("peer or link remote not discovered");
    return;
  }
  std::uint64_t id = 0;
  std::vector<double> peer_rtt, link_rtt, link_listener_rtt, rel_listener_med, rel_listener_p99, be_waitset_med, be_waitset_p99;
  for (auto _ : state) {
    for (int round = 0; round < rounds; ++round) {
      auto a = ping_pong_for(ping, pong, std::chrono::seconds(seconds), id);
      peer_rtt.insert(peer_rtt.end(), a.begin(), a.end());
      if (link_ping) {
        auto b = ping_pong_for(*link_ping, *link_pong, std::chrono::seconds(seconds), id);
        link_rtt.insert(link_rtt.end(), b.begin(), b.end());
        auto c = ping_pong_listener_for(*link_ping, *link_pong, std::chrono::seconds(seconds), id);
        link_listener_rtt.insert(link_listener_rtt.end(), c.begin(), c.end());
      }
      auto rl = run_ddsperf(perf_domain, seconds, true, true);
      rel_listener_med.insert(rel_listener_med.end(), rl.median_rtt_us.begin(), rl.median_rtt_us.end());
      rel_listener_p99.insert(rel_listener_p99.end(), rl.p99_rtt_us.begin(), rl.p99_rtt_us.end());
      auto bw = run_ddsperf(perf_domain, seconds, false, false);
      be_waitset_med.insert(be_waitset_med.end(), bw.median_rtt_us.begin(), bw.median_rtt_us.end());
      be_waitset_p99.insert(be_waitset_p99.end(), bw.p99_rtt_us.begin(), bw.p99_rtt_us.end());
    }
  }
  const double ours = percentile(peer_rtt, 0.5);
  state.counters["peer_median_us"] = ours;
  state.counters["peer_p99_us"] = percentile(peer_rtt, 0.99);
  state.counters["peer_roundtrips"] = static_cast<double>(peer_rtt.size());
  if (!link_rtt.empty()) {
    state.counters["link_median_us"] = percentile(link_rtt, 0.5);
    state.counters["link_p99_us"] = percentile(link_rtt, 0.99);
    state.counters["link_listener_median_us"] = percentile(link_listener_rtt, 0.5);
    state.counters["link_listener_p99_us"] = percentile(link_listener_rtt, 0.99);
  }
  if (rel_listener_med.empty()) {
    state.SetLabel("ddsperf not found or printed nothing: our numbers only");
    return;
  }
  const double rel = median_of(rel_listener_med);
  state.counters["ddsperf_rel_listener_median_us"] = rel;
  state.counters["ddsperf_rel_listener_p99_us"] = median_of(rel_listener_p99);
  state.counters["peer_over_rel_listener"] = ours / rel;
  if (!link_rtt.empty()) {
    state.counters["link_over_rel_listener"] = percentile(link_rtt, 0.5) / rel;
    state.counters["link_listener_over_rel_listener"] = percentile(link_listener_rtt, 0.5) / rel;
  }
  if (!be_waitset_med.empty()) {
    const double be = median_of(be_waitset_med);
    state.counters["ddsperf_be_waitset_median_us"] = be;
    state.counters["ddsperf_be_waitset_p99_us"] = median_of(be_waitset_p99);
    state.counters["peer_over_be_waitset"] = ours / be;
  }
}
void BM_LinkSecurity(benchmark::State& state, bool secure) {
  const std::string link_remote = bin_path("link_test_remote");
  if (!std::filesystem::exists(link_remote)) {
    state.SkipWithError("link_test_remote not built");
    return;
  }
  setup();  // loopback configuration
  std::string dir;
  if (secure) {
    if (foresight::protocol::security_plugin_dir().empty()) {
      state.SkipWithError("Cyclone's DDS Security plugins not found at build time");
      return;
    }
    char tmpl[] = "/tmp/foresight_bench_sec_XXXXXX";
    if (mkdtemp(tmpl) == nullptr) {
      state.SkipWithError("mkdtemp failed");
      return;
    }
    dir = tmpl;
    const std::string cmd = "bash " + std::string(FORESIGHT_CONFIG_DIR) + "/../scripts/make_dds_security.sh " + dir +
                            " >/dev/null";
    if (std::system(cmd.c_str()) != 0) {
      state.SkipWithError("make_dds_security.sh failed (openssl?)");
      return;
    }
  }
  const dds_domainid_t domain = 1 + (setup().domain - 1 + (secure ? 91 : 37)) % 230;
  std::vector<std::string> args{link_remote, "--domain", std::to_string(domain), "--lifetime-s", "600"};
  if (secure) args.insert(args.end(), {"--security", dir});
  double match_ms = 0.0;
  std::vector<double> rtt_us, upload_ms;
  {
    Peer remote(args, true);
    const auto t0 = Clock::now();
    auto participant = secure ? std::make_unique<fp::Participant>(domain, fp::security_qos(dir, "ground"))
                              : std::make_unique<fp::Participant>(domain);
    fp::Writer<msg::Ping> ping(*participant);
    fp::Reader<msg::Pong> pong(*participant);
    fp::Writer<msg::TrajectoryChunk> chunks(*participant);
    fp::Reader<msg::TrajectoryStatus> status(*participant);
    if (!ping.wait_for_readers(1, 30s) || !pong.wait_for_writers(1, 30s) || !chunks.wait_for_readers(1, 30s) ||
        !status.wait_for_writers(1, 30s)) {
      state.SkipWithError("link remote not matched within 30 s");
      return;
    }
    match_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    const foresight::Trajectory t = make_trajectory(1800, 7);
    const foresight::TrajectoryHash hash = foresight::trajectory_hash(t);
    std::uint64_t id = 0, upload_id = secure ? (9ull << 40) : (8ull << 40);
    fp::Sample<msg::TrajectoryStatus> s;
    for (auto _ : state) {
      auto r = ping_pong_listener_for(ping, pong, 3s, id);
      rtt_us.insert(rtt_us.end(), r.begin(), r.end());
      for (int k = 0; k < 10; ++k) {
        const auto parts = fp::make_chunks(t, ++upload_id, 1, hash);
        const auto u0 = Clock::now();
        for (const auto& c : parts) chunks.write(c);
        bool committed = false;
        while (!committed && status.wait_take(s, 10s)) {
          committed = s->trajectory_id == upload_id && s->state == foresight_msg_UPLOAD_COMMITTED;
          if (s->trajectory_id == upload_id && s->state == foresight_msg_UPLOAD_REJECTED) break;
        }
        if (!committed) {
          state.SkipWithError("upload not committed within 10 s");
          return;
        }
        upload_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - u0).count());
      }
    }
  }
  if (!dir.empty()) std::filesystem::remove_all(dir);
  state.counters["match_ms"] = match_ms;
  state.counters["rtt_median_us"] = percentile(rtt_us, 0.5);
  state.counters["rtt_p99_us"] = percentile(rtt_us, 0.99);
  state.counters["roundtrips"] = static_cast<double>(rtt_us.size());
  state.counters["upload1800x7_committed_median_ms"] = percentile(upload_ms, 0.5);
  state.counters["upload1800x7_committed_max_ms"] = percentile(upload_ms, 1.0);
}
void BM_TelemetryRate(benchmark::State& state, bool secure) {
  const std::string link_remote = bin_path("link_test_remote");
  if (!std::filesystem::exists(link_remote)) {
    state.SkipWithError("link_test_remote not built");
    return;
  }
  setup();
  std::string dir;
  if (secure) {
    char tmpl[] = "/tmp/foresight_bench_sec_XXXXXX";
    if (foresight::protocol::security_plugin_dir().empty() || mkdtemp(tmpl) == nullptr) {
      state.SkipWithError("no DDS Security plugins or no scratch folder");
      return;
    }
    dir = tmpl;
    const std::string cmd = "bash " + std::string(FORESIGHT_CONFIG_DIR) + "/../scripts/make_dds_security.sh " + dir +
                            " >/dev/null";
    if (std::system(cmd.c_str()) != 0) {
      state.SkipWithError("make_dds_security.sh failed (openssl?)");
      return;
    }
  }
  const dds_domainid_t domain = 1 + (setup().domain - 1 + (secure ? 143 : 199)) % 230;
  std::vector<std::string> args{link_remote, "--domain", std::to_string(domain), "--lifetime-s", "600",
                                "--telemetry-hz", "0"};
  if (secure) args.insert(args.end(), {"--security", dir});
  double per_s = 0.0;
  {
    Peer remote(args, true);
    auto participant = secure ? std::make_unique<fp::Participant>(domain, fp::security_qos(dir, "ground"))
                              : std::make_unique<fp::Participant>(domain);
    fp::Reader<msg::JointState> joints(*participant);
    fp::Sample<msg::JointState> s;
    if (!joints.wait_take(s, 30s)) {
      state.SkipWithError("no joint state within 30 s");
      return;
    }
    for (auto _ : state) {
      std::uint64_t n = 0;
      const auto t0 = Clock::now();
      const auto end = t0 + 3s;
      while (Clock::now() < end) {
        if (joints.wait_take(s, 100ms)) ++n;
      }
      per_s = static_cast<double>(n) / std::chrono::duration<double>(Clock::now() - t0).count();
    }
  }
  if (!dir.empty()) std::filesystem::remove_all(dir);
  state.counters["joint_states_per_s"] = per_s;
}
BENCHMARK_CAPTURE(BM_TelemetryRate, plain, false)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(BM_TelemetryRate, secure, true)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

BENCHMARK_CAPTURE(BM_LinkSecurity, plain, false)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(BM_LinkSecurity, secure, true)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

BENCHMARK(BM_PingPongVsDdsperf)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
