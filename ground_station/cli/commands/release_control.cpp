// foresight release-control: this ground session gives up command of the remote
// (another station may then take it).
#include <iostream>

#include "command.hpp"
#include "link_options.hpp"
#include "link_session.hpp"

namespace foresight::cli {
namespace {

const bool registered = register_command(
    {"release-control", "give up command of the remote; waits for the final acknowledgement",
     [](CLI::App& sub) -> std::function<int()> {
       auto o = std::make_shared<LinkOptions>();
       add_link_options(sub, *o);
       return [o] {
         auto link = connect_remote(resolve_domain(o->domain), o->connect_timeout_s);
         const auto kind = control::CommandKind::ReleaseControl;
         const auto r = send_and_wait(*link, kind, control::NoPayload{}, final_ack_timeout(*link, 0.0, o->timeout_s));
         if (o->json) std::cout << result_json(kind, r).dump(2) << "\n";
         else std::cout << result_line(kind, r) << "\n";
         return exit_status(r);
       };
     }});

}  // namespace
}  // namespace foresight::cli
