// foresight watch: one line a second with the link's round trip, the remote's
// mode and active command, the joints and their velocities, the wrist force,
// the tool and the remote's queue (a chain: what runs, what is queued), until
// Ctrl-C (or --count lines). Any station may watch; it commands nothing.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <thread>

#include "command.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_sigint(int) { g_stop.store(true); }

struct Options {
  LinkOptions link;
  int count = 0;
  double period_s = 1.0;
};

int run(const Options& o) {
  auto link = connect_remote(o.link);
  std::signal(SIGINT, on_sigint);
  std::signal(SIGTERM, on_sigint);
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.period_s));
  auto next = Clock::now() + period;
  for (int line = 0; (o.count == 0 || line < o.count) && !g_stop.load(); ++line) {
    // Sleep to the next tick in small slices so Ctrl-C ends it promptly.
    while (Clock::now() < next && !g_stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (g_stop.load()) break;
    next += period;
    const nlohmann::json j = status_json(*link);
    if (o.link.json) {
      std::cout << j.dump() << "\n" << std::flush;  // one JSON object a line
      continue;
    }
    std::printf("rtt %7.1f ms | %-10s", 1e3 * j["rtt_s"]["median"].get<double>(), j["state"].get<std::string>().c_str());
    if (j.contains("active_command_id") && j["active_command_id"].get<std::uint64_t>() != 0)
      std::printf(" cmd %llu", static_cast<unsigned long long>(j["active_command_id"].get<std::uint64_t>()));
    std::printf(" | q deg");
    for (const auto& q : j["joints_rad"]) std::printf(" %7.2f", q.get<double>() * 180.0 / M_PI);
    if (!j["joint_velocities_rad_s"].empty()) {
      std::printf(" | dq deg/s");
      for (const auto& v : j["joint_velocities_rad_s"]) std::printf(" %6.2f", v.get<double>() * 180.0 / M_PI);
    }
    if (j.contains("wrench")) {
      const auto& f = j["wrench"]["force_tool_n"];
      std::printf(" | |F| %6.1f N",
                  std::sqrt(std::pow(f[0].get<double>(), 2) + std::pow(f[1].get<double>(), 2) +
                            std::pow(f[2].get<double>(), 2)));
    }
    if (j.contains("tool"))
      std::printf(" | tool %s %.2f turns", j["tool"]["latched"].get<bool>() ? "latched" : "free",
                  j["tool"]["turns"].get<double>());
    if (const auto st = link->status()) {  // a chain on the remote: what runs, what waits
      const std::string queue = queue_text(st->value);
      if (!queue.empty()) std::printf(" | %s", queue.c_str());
    }
    if (!j["faults"].empty()) std::printf(" | FAULT %s", j["faults"][0].get<std::string>().c_str());
    std::printf("\n");
    std::fflush(stdout);
  }
  return kExitOk;
}

const bool registered = register_command(
    {"watch", "a live one-line-a-second view of the link and the remote until Ctrl-C",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("--count", o->count, "stop after this many lines (0: until Ctrl-C)")
           ->check(check::NonNegativeNumber);
       sub.add_option("--period", o->period_s, "seconds between lines")
           ->check(check::Range(0.05, 3600.0))
           ->capture_default_str();
       add_link_options(sub, o->link, false);
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
