// foresight demo: the project's main job end to end (foresight/session/demo.hpp):
// the daemon on the embedded simulated robot, the ground chain, the ORU
// changeout over DDS with a preview of every motion, a report. Ctrl-C aborts
// the running command, then stops the daemon.
#include <atomic>
#include <csignal>

#include "command.hpp"
#include "foresight/session/demo.hpp"

namespace foresight::cli {
namespace {

std::atomic<bool> g_interrupt{false};
extern "C" void on_demo_interrupt(int) { g_interrupt.store(true); }

const bool registered = register_command(
    {"demo",
     "the main job: the daemon on the simulated robot, the ground chain, the ORU changeout over DDS, a report",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<session::DemoOptions>();
       sub.add_option("--out", o->out, "folder for report.json, report.md and everything the run makes")
           ->capture_default_str();
       sub.add_option("--rtt", o->rtt_s, "round trip of the emulated link, seconds (loopback where namespaces "
                                         "cannot be made)")
           ->capture_default_str();
       sub.add_flag("--fast", o->fast, "loopback, no emulated delay, faster previews (tests)");
       sub.add_flag("--chain", o->chain,
                    "send the changeout's motions ahead as chains (foresight run --chain): the work plus about "
                    "one round trip per WAIT, not one per step");
       sub.add_option("--domain", o->domain, "DDS domain id (default: one in 100-219 that no other process on this host holds)")
           ->check(check::Range(0, 232));
       sub.add_option("--script", o->script, "the task script")->capture_default_str();
       sub.add_option("--ready-timeout", o->ready_timeout_s, "seconds to wait for the daemon's ready line")
           ->check(check::WaitSeconds)
           ->capture_default_str();
       sub.add_option("--compare", o->compare,
                      "another run's report.json (e.g. without --chain): its timing beside this run's in report.md");
       sub.add_option("--stage", o->stage)->group("");  // internal: the ground half in the emulator's namespace
       return [o] {
         std::signal(SIGINT, on_demo_interrupt);
         std::signal(SIGTERM, on_demo_interrupt);
         return session::run_demo(*o, [] { return g_interrupt.load(); });
       };
     }});

}  // namespace
}  // namespace foresight::cli
