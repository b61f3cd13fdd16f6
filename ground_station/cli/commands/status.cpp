// foresight status: the link's measured delay (round trip statistics, clock
// offset) and the remote's latest state: controller mode, active command,
// stop and faults, joint angles and velocities, tool, wrist wrench, each with
// its age; joint states the link dropped as invalid, by reason.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct Options {
  LinkOptions link;
  int samples = 5;
  double sample_timeout_s = 5.0;
};

int run(const Options& o) {
  auto link = connect_remote(o.link);
  // A few round trips for the statistics, and the first telemetry (both bounded).
  link->delay().wait_samples(static_cast<std::size_t>(o.samples),
                             std::chrono::duration_cast<std::chrono::nanoseconds>(
                                 std::chrono::duration<double>(o.sample_timeout_s)));
  wait_joints(*link, o.sample_timeout_s);
  const nlohmann::json j = status_json(*link);
  if (o.link.json) {
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  const auto& r = j["rtt_s"];
  std::printf("link: round trip median %.1f ms, p99 %.1f ms, max %.1f ms over %zu; clock offset %+.3f ms; remote %s\n",
              1e3 * r["median"].get<double>(), 1e3 * r["p99"].get<double>(), 1e3 * r["max"].get<double>(),
              r["count"].get<std::size_t>(), 1e3 * j["clock_offset_s"].get<double>(),
              j["remote_alive"].get<bool>() ? "alive" : "SILENT");
  if (j["link_security"]["dds_security"].get<bool>())
    std::printf("link security: DDS Security as station '%s'\n", j["link_security"]["identity"].get<std::string>().c_str());
  else
    std::printf("link security: NONE: the link is open to every participant of the DDS domain (--sim, or "
                "controller.link.insecure: true)\n");
  std::printf("controller: %s", j["state"].get<std::string>().c_str());
  if (j.contains("active_command_id") && j["active_command_id"].get<std::uint64_t>() != 0)
    std::printf(", running command %llu", static_cast<unsigned long long>(j["active_command_id"].get<std::uint64_t>()));
  std::printf("\n");
  if (!j["drives"].empty()) {
    std::printf("drives:");
    for (const auto& d : j["drives"])
      std::printf(" %d:%s%s", d["joint"].get<int>(), d["state"].get<std::string>().c_str(),
                  d["powered"].get<bool>() ? "(powered)" : "");
    std::printf("\n");
  }
  if (j.contains("loop")) {
    const auto& l = j["loop"];
    const std::uint32_t limit = l["max_missed_cycles"].get<std::uint32_t>();
    std::printf("control loop: %s, memory %s%s; %llu cycles, %llu overruns, at most %u missed in a row (%s); wake-up "
                "latency p99 %.0f us, max %.0f us\n",
                l["realtime"].get<bool>() ? "SCHED_FIFO" : "NOT real time (no SCHED_FIFO)",
                l["memory_locked"].get<bool>() ? "locked" : "NOT locked",
                l["realtime_required"].get<bool>() ? ", required to enable the drives" : "",
                static_cast<unsigned long long>(l["cycles"].get<std::uint64_t>()),
                static_cast<unsigned long long>(l["overruns"].get<std::uint64_t>()),
                l["missed_streak_max"].get<std::uint32_t>(),
                limit > 0 ? ("stop at " + std::to_string(limit)).c_str() : "no overrun stop",
                l["wakeup_latency_us"]["p99"].get<double>(), l["wakeup_latency_us"]["max"].get<double>());
  }
  if (j.contains("rate_limit")) {
    const auto& rl = j["rate_limit"];
    const auto cycles = rl["cycles"].get<std::uint64_t>();
    if (cycles == 0) {
      std::printf("rate limiter: never acted\n");
    } else {
      std::string joints;
      for (const auto& jn : rl["last_joints"]) joints += (joints.empty() ? "" : ", ") + std::to_string(jn.get<int>());
      std::printf("rate limiter: %s; %llu cycles limited since start, last on joint(s) %s (command %llu), lag up to "
                  "%.4f rad\n",
                  rl["limiting"].get<bool>() ? "LIMITING now" : "idle", static_cast<unsigned long long>(cycles),
                  joints.c_str(), static_cast<unsigned long long>(rl["last_command_id"].get<std::uint64_t>()),
                  rl["last_max_lag_rad"].get<double>());
    }
  }
  if (j.contains("queue") && !j["queue"].empty()) {
    std::printf("queue:");
    for (const auto& q : j["queue"]) {
      std::printf(" %llu %s (%s", static_cast<unsigned long long>(q["command_id"].get<std::uint64_t>()),
                  q["kind"].get<std::string>().c_str(), q["state"].get<std::string>().c_str());
      if (const auto after = q["after_command_id"].get<std::uint64_t>(); after != 0)
        std::printf(", after %llu", static_cast<unsigned long long>(after));
      std::printf(")");
    }
    std::printf("\n");
  }
  if (!j["joints_rad"].empty()) {
    std::printf("joints (deg, %.2f s old):", j["joints_age_s"].get<double>());
    for (const auto& q : j["joints_rad"]) std::printf(" %.2f", q.get<double>() * 180.0 / M_PI);
    std::printf("\n");
    std::printf("joint velocities (deg/s):");
    for (const auto& v : j["joint_velocities_rad_s"]) std::printf(" %.2f", v.get<double>() * 180.0 / M_PI);
    std::printf("\n");
  } else {
    std::printf("joints: no report yet\n");
  }
  if (j.contains("tool"))
    std::printf("tool: %s, %s, %.2f turns, %.2f N m\n", j["tool"]["latched"].get<bool>() ? "latched" : "unlatched",
                j["tool"]["running"].get<bool>() ? "running" : "stopped", j["tool"]["turns"].get<double>(),
                j["tool"]["torque_nm"].get<double>());
  if (j.contains("wrench")) {
    const auto& f = j["wrench"]["force_tool_n"];
    const auto& t = j["wrench"]["torque_tool_nm"];
    std::printf("wrench (tool frame): F %.2f %.2f %.2f N, T %.3f %.3f %.3f N m\n", f[0].get<double>(),
                f[1].get<double>(), f[2].get<double>(), t[0].get<double>(), t[1].get<double>(), t[2].get<double>());
  }
  const auto& dropped = j["joint_states_dropped"];
  const auto n_dropped = dropped["joint_count"].get<std::uint64_t>() + dropped["length"].get<std::uint64_t>() +
                         dropped["not_finite"].get<std::uint64_t>();
  if (n_dropped != 0)
    std::printf("joint states dropped: %llu (wrong joint count %llu, sequence lengths %llu, not finite %llu)\n",
                static_cast<unsigned long long>(n_dropped),
                static_cast<unsigned long long>(dropped["joint_count"].get<std::uint64_t>()),
                static_cast<unsigned long long>(dropped["length"].get<std::uint64_t>()),
                static_cast<unsigned long long>(dropped["not_finite"].get<std::uint64_t>()));
  if (j["faults"].empty()) std::printf("faults: none\n");
  for (const auto& f : j["faults"]) std::printf("fault: %s\n", f.get<std::string>().c_str());
  return kExitOk;
}

const bool registered = register_command(
    {"status", "the link's delay statistics and the remote's state, joints, tool, wrench and faults",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       add_link_options(sub, o->link, false);
       sub.add_option("--samples", o->samples, "round trips to wait for before reporting")
           ->check(check::Range(1, 10000))
           ->capture_default_str();
       sub.add_option("--sample-timeout", o->sample_timeout_s, "at most this long, s")
           ->check(check::WaitSeconds)
           ->capture_default_str();
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
