// linkemu_ddsping: the ground end of a DDS round-trip measurement across the
// link emulator. Sends protocol Pings (common/protocol) every --interval-ms,
// pipelined (it does not wait for each pong), matches Pongs by id and prints
// one JSON object: {"sent","received","rtt_ms":{"median","mean","min","max",
// "p95"},"offset_ms_median","discovery_s"}. The far end is
// foresight_protocol_peer (its Pong responder).
//
// With --upload-samples S it then uploads a smooth S x 7 trajectory in chunks
// (common/protocol make_chunks, reliable) and waits for the peer's
// TrajectoryStatus COMMITTED, adding "upload":{"samples","chunks","bytes",
// "seconds","state","hash_match"} (seconds: first chunk written -> COMMITTED
// seen, so it includes one round trip).
//
// Usage: linkemu_ddsping --domain N [--count 20] [--interval-ms 100]
//                        [--discovery-timeout-s 30] [--pong-timeout-s 10]
//                        [--upload-samples S] [--upload-timeout-s 120]
// Exit status: 0 when at least one pong came back, 1 otherwise, 2 bad usage.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/topics.hpp"
#include "foresight/protocol/trajectory_upload.hpp"

namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
using Clock = std::chrono::steady_clock;

namespace {

int usage(const std::string& why) {
  std::fprintf(stderr,
               "linkemu_ddsping: %s\nusage: linkemu_ddsping --domain N [--count 20] [--interval-ms 100] "
               "[--discovery-timeout-s 30] [--pong-timeout-s 10] [--upload-samples S] [--upload-timeout-s 120]\n",
               why.c_str());
  return 2;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const auto hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (v[hi] - v[lo]) * (pos - static_cast<double>(lo));
}

/// A smooth S x 7 trajectory at 100 Hz, well inside any joint limits.
foresight::Trajectory make_trajectory(long samples) {
  foresight::Trajectory t;
  t.time_s.resize(static_cast<std::size_t>(samples));
  t.positions_rad.resize(samples, 7);
  for (long s = 0; s < samples; ++s) {
    const double time = 0.01 * static_cast<double>(s);
    t.time_s[static_cast<std::size_t>(s)] = time;
    for (int j = 0; j < 7; ++j) t.positions_rad(s, j) = 0.3 * std::sin(0.2 * time + j);
  }
  return t;
}

nlohmann::json run_upload(const fp::Participant& participant, long samples, double timeout_s) {
  fp::Writer<msg::TrajectoryChunk> chunk(participant, fp::topics::kTrajectoryChunk, fp::qos::trajectory_chunk());
  fp::Reader<msg::TrajectoryStatus> status(participant, fp::topics::kTrajectoryStatus, fp::qos::trajectory_status());
  const auto timeout = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(timeout_s));
  // Chunks are volatile: write only once the peer's chunk readers (its
  // assembler and its echo) have matched, or they would miss the first ones.
  if (!chunk.wait_for_readers(2, timeout) || !status.wait_for_writers(1, timeout)) {
    return {{"state", "NOT_MATCHED"}};
  }
  const foresight::Trajectory t = make_trajectory(samples);
  const foresight::TrajectoryHash hash = foresight::trajectory_hash(t);
  const std::uint64_t id = 0x11e7;
  const auto chunks = fp::make_chunks(t, id, 0x5e55, hash, 250);
  std::size_t bytes = 0;
  for (const auto& c : chunks) bytes += c->samples._length * sizeof(double);
  const auto t0 = Clock::now();
  for (const auto& c : chunks) chunk.write(c);
  fp::Sample<msg::TrajectoryStatus> got;
  std::string state = "TIMEOUT";
  bool hash_match = false;
  const auto deadline = t0 + timeout;
  while (Clock::now() < deadline && status.wait_take(got, deadline - Clock::now())) {
    if (got->trajectory_id != id || got->state == foresight_msg_UPLOAD_ASSEMBLING) continue;
    state = got->state == foresight_msg_UPLOAD_COMMITTED ? "COMMITTED" : "REJECTED: " + std::string(fp::text(got->reason));
    hash_match = fp::get_hash(got->content_hash) == hash;
    break;
  }
  return {{"samples", samples},
          {"chunks", chunks.size()},
          {"bytes", bytes},
          {"seconds", std::chrono::duration<double>(Clock::now() - t0).count()},
          {"state", state},
          {"hash_match", hash_match}};
}

}  // namespace

int main(int argc, char** argv) {
  long domain = -1;
  long count = 20;
  double interval_ms = 100.0;
  double discovery_timeout_s = 30.0;
  double pong_timeout_s = 10.0;
  long upload_samples = 0;
  double upload_timeout_s = 120.0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (i + 1 >= argc) return usage("missing value after " + arg);
    const std::string value = argv[++i];
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    if (*end != '\0' || !std::isfinite(v) || v < 0) return usage(arg + " wants a non-negative number");
    if (arg == "--domain") domain = static_cast<long>(v);
    else if (arg == "--count") count = static_cast<long>(v);
    else if (arg == "--interval-ms") interval_ms = v;
    else if (arg == "--discovery-timeout-s") discovery_timeout_s = v;
    else if (arg == "--pong-timeout-s") pong_timeout_s = v;
    else if (arg == "--upload-samples") upload_samples = static_cast<long>(v);
    else if (arg == "--upload-timeout-s") upload_timeout_s = v;
    else return usage("unknown argument " + arg);
  }
  if (domain < 0 || domain > 232) return usage("--domain N (0..232) is required");
  if (count < 1 || count > 100000) return usage("--count wants 1..100000");

  try {
    fp::Participant participant(static_cast<dds_domainid_t>(domain));
    fp::Writer<msg::Ping> ping(participant);
    fp::Reader<msg::Pong> pong(participant);
    const auto t0 = Clock::now();
    const auto discovery = std::chrono::duration<double>(discovery_timeout_s);
    if (!ping.wait_for_readers(1, std::chrono::duration_cast<std::chrono::nanoseconds>(discovery)) ||
        !pong.wait_for_writers(1, std::chrono::duration_cast<std::chrono::nanoseconds>(discovery))) {
      std::fprintf(stderr, "linkemu_ddsping: no peer discovered within %g s\n", discovery_timeout_s);
      return 1;
    }
    fp::Sample<msg::Pong> got;
    // Warm-up: repeat a ping until one pong returns, so every reader of the
    // peer has matched before measuring (best-effort: no retransmission).
    std::uint64_t id = 0;
    bool warm = false;
    const auto warm_deadline = t0 + discovery;
    while (!warm && Clock::now() < warm_deadline) {
      msg::Ping p{};
      p.ping_id = ++id;
      p.ground_send_ns = fp::now_ns();
      ping.write(p);
      const auto wait_end = Clock::now() + std::chrono::milliseconds(500);
      while (Clock::now() < wait_end && pong.wait_take(got, wait_end - Clock::now())) {
        if (got->ping_id >= 1) warm = true;
      }
    }
    if (!warm) {
      std::fprintf(stderr, "linkemu_ddsping: no pong within %g s of discovery\n", discovery_timeout_s);
      return 1;
    }
    const double discovery_s = std::chrono::duration<double>(Clock::now() - t0).count();
    while (pong.take(got)) {
    }

    const std::uint64_t first_id = id + 1;
    const std::uint64_t last_id = id + static_cast<std::uint64_t>(count);
    std::vector<double> rtt_ms, offset_ms;
    const auto interval = std::chrono::duration<double, std::milli>(interval_ms);
    auto next_send = Clock::now();
    Clock::time_point end = Clock::time_point::max();
    while (Clock::now() < end) {
      if (id < last_id && Clock::now() >= next_send) {
        msg::Ping p{};
        p.ping_id = ++id;
        p.ground_send_ns = fp::now_ns();
        ping.write(p);
        next_send += std::chrono::duration_cast<Clock::duration>(interval);
        if (id == last_id) end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                                     std::chrono::duration<double>(pong_timeout_s));
      }
      const auto wait_until = id < last_id ? std::min(next_send, end) : end;
      const auto left = wait_until - Clock::now();
      if (left > Clock::duration::zero() && pong.wait_take(got, left)) {
        if (got->ping_id < first_id || got->ping_id > last_id) continue;
        const fp::DelaySample d = fp::delay_from_pong(*got, fp::now_ns());
        rtt_ms.push_back(static_cast<double>(d.rtt_ns) * 1e-6);
        offset_ms.push_back(static_cast<double>(d.offset_ns) * 1e-6);
        if (rtt_ms.size() == static_cast<std::size_t>(count)) break;
      }
    }
    nlohmann::json upload = nullptr;
    if (upload_samples > 0) upload = run_upload(participant, upload_samples, upload_timeout_s);
    double mean = 0.0;
    for (double r : rtt_ms) mean += r;
    if (!rtt_ms.empty()) mean /= static_cast<double>(rtt_ms.size());
    const nlohmann::json out = {
        {"sent", count},
        {"received", rtt_ms.size()},
        {"rtt_ms",
         {{"median", percentile(rtt_ms, 0.5)},
          {"mean", mean},
          {"min", rtt_ms.empty() ? 0.0 : *std::min_element(rtt_ms.begin(), rtt_ms.end())},
          {"max", rtt_ms.empty() ? 0.0 : *std::max_element(rtt_ms.begin(), rtt_ms.end())},
          {"p95", percentile(rtt_ms, 0.95)}}},
        {"offset_ms_median", percentile(offset_ms, 0.5)},
        {"discovery_s", discovery_s},
        {"upload", upload}};
    std::printf("%s\n", out.dump().c_str());
    if (upload_samples > 0 && !(upload.value("state", "") == "COMMITTED" && upload.value("hash_match", false))) {
      return 1;
    }
    return rtt_ms.empty() ? 1 : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "linkemu_ddsping: %s\n", e.what());
    return 1;
  }
}
