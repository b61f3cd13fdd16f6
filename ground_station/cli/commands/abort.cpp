// foresight abort: stop the remote's motion (any station may), category 2
// (controlled stop, power on) by default or 1 (controlled stop, then power
// off); --command aborts one command only. Waits for the abort's final ack.
#include <iostream>

#include "command.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct Options {
  LinkOptions link;
  int category = 2;
  std::uint64_t command_id = 0;
  std::string reason = "operator abort";
};

int run(const Options& o) {
  auto link = connect_remote(o.link);
  protocol::Abort a;
  a.target_command_id = o.command_id;
  a.category = o.category == 1 ? protocol::StopCategory::Cat1 : protocol::StopCategory::Cat2;
  a.reason = o.reason;
  const auto kind = protocol::CommandKind::Abort;
  const auto r = send_and_wait(*link, kind, a, final_ack_timeout(*link, 0.0, o.link.timeout_s));
  if (o.link.json) {
    auto j = result_json(kind, r);
    j["category"] = o.category;
    j["target_command_id"] = o.command_id;
    std::cout << j.dump(2) << "\n";
  } else {
    std::cout << result_line(kind, r) << "\n";
  }
  return exit_status(r);
}

const bool registered = register_command(
    {"abort", "stop the remote's motion (category 2 by default; 1: then power off)",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("--category", o->category, "IEC 60204-1 stop category: 1 or 2")
           ->check(check::IsMember({1, 2}))
           ->capture_default_str();
       sub.add_option("--command", o->command_id, "abort only this command id (default: whatever runs and all queued)");
       sub.add_option("--reason", o->reason, "why (journaled by the remote)")->capture_default_str();
       add_link_options(sub, o->link);
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
