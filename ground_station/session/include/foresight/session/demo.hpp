#pragma once
// `foresight demo`, the project's main job end to end. Starts the controller
// daemon (`foresight-remote --sim`, the embedded simulated robot) on a fresh
// DDS domain -- through the link emulator (`foresight-linkemu`, rtt_s of
// round trip) where network namespaces can be made, else on loopback (said
// so) -- waits for its ready line, runs the ground chain in this process
// (simulated operator clicks -> calibration of every camera -> localization
// of the ORU -> overlay: the operations the commands call), takes control,
// then the ORU changeout task script over DDS with a preview of every motion
// (the same ScriptRunner as `foresight run --auto`), stops the daemon, and
// writes OUT/report.json and OUT/report.md. An interrupt aborts the running
// command, then stops the daemon. Set-up code, not real-time.
//
// With the link emulator the ground half runs as a child in the ground's
// namespace (`foresight demo --stage ground`), which writes OUT/ground.json;
// on loopback it runs in this process.

#include <functional>
#include <string>

#include "foresight/session/config_path.hpp"

namespace foresight::session {

struct DemoOptions {
  std::string out = "demo";
  double rtt_s = 4.0;  ///< the paper's round trip
  bool fast = false;   ///< loopback, no emulated delay, faster previews
  bool chain = false;  ///< the changeout's motions sent ahead as chains
  int domain = -1;     ///< < 0: one no other process on this host holds
  std::string stage;   ///< "" (everything), "ground" (the ground half only) or "plot" (OUT/delay.png again)
  std::string compare; ///< another run's report.json whose timing report.md shows beside this one's
  std::string script = default_config("scripts/oru_changeout.task");
  double ready_timeout_s = 60.0;
};

/// Runs the demo (or its stage); the exit status (0 completed, 1 failed).
/// `interrupted` is polled throughout (Ctrl-C). Bad options: InputError /
/// std::invalid_argument before anything starts.
int run_demo(DemoOptions& options, const std::function<bool()>& interrupted);

}  // namespace foresight::session
