// foresight recover: leave STOPPED or FAULT (fault reset, drives enabled, holding)
// after the cause of a stop was fixed.
#include <iostream>

#include "command.hpp"
#include "link_options.hpp"
#include "link_session.hpp"

namespace foresight::cli {
namespace {

const bool registered = register_command(
    {"recover", "leave STOPPED/FAULT: fault reset, enable the drives, hold; waits for the final acknowledgement",
     [](CLI::App& sub) -> std::function<int()> {
       auto o = std::make_shared<LinkOptions>();
       add_link_options(sub, *o);
       return [o] {
         auto link = connect_remote(resolve_domain(o->domain), o->connect_timeout_s);
         const auto kind = control::CommandKind::Recover;
         const ControlGuard control_guard(*link);
         const auto r = send_and_wait(*link, kind, control::NoPayload{}, final_ack_timeout(*link, 0.0, o->timeout_s));
         if (o->json) std::cout << result_json(kind, r).dump(2) << "\n";
         else std::cout << result_line(kind, r) << "\n";
         return exit_status(r);
       };
     }});

}  // namespace
}  // namespace foresight::cli
