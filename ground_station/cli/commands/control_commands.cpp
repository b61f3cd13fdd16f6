// The remote's payload-less control commands, each waiting for its final
// acknowledgement:
//   foresight take-control     this ground session becomes the remote's commander
//                              (one station holds control at a time; any may abort or watch)
//   foresight release-control  give up command (another station may then take it)
//   foresight recover          leave STOPPED or FAULT (fault reset, drives enabled,
//                              holding) after the cause of a stop was fixed; takes
//                              control for its duration
#include <iostream>

#include "command.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

bool register_control_command(const char* name, const char* help, protocol::CommandKind kind, bool hold_control) {
  return register_command({name, help, [kind, hold_control](Command& sub) -> std::function<int()> {
                             auto o = std::make_shared<LinkOptions>();
                             add_link_options(sub, *o);
                             return [o, kind, hold_control] {
                               auto link = connect_remote(*o);
                               std::optional<ControlGuard> guard;
                               if (hold_control) guard.emplace(*link);
                               const auto r = send_and_wait(*link, kind, protocol::NoPayload{},
                                                            final_ack_timeout(*link, 0.0, o->timeout_s));
                               if (o->json) std::cout << result_json(kind, r).dump(2) << "\n";
                               else std::cout << result_line(kind, r) << "\n";
                               return exit_status(r);
                             };
                           }});
}

const bool registered =
    register_control_command("take-control",
                             "make this ground session the remote's commander; waits for the final acknowledgement",
                             protocol::CommandKind::TakeControl, false) &&
    register_control_command("release-control",
                             "give up command of the remote; waits for the final acknowledgement",
                             protocol::CommandKind::ReleaseControl, false) &&
    register_control_command(
        "recover", "leave STOPPED/FAULT: fault reset, enable the drives, hold; waits for the final acknowledgement",
        protocol::CommandKind::Recover, true);

}  // namespace
}  // namespace foresight::cli
