// foresight request joints|wrench|tool|status|trajectories: ask the remote for
// a fresh report, wait for the final ack, and print the report.
#include <chrono>
#include <iostream>
#include <thread>

#include "command.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct Options {
  LinkOptions link;
  std::string what;
};

int run(const Options& o) {
  protocol::Request req;
  if (o.what == "joints") req.what = protocol::RequestWhat::JointState;
  else if (o.what == "wrench") req.what = protocol::RequestWhat::Wrench;
  else if (o.what == "tool") req.what = protocol::RequestWhat::ToolState;
  else if (o.what == "trajectories") req.what = protocol::RequestWhat::Trajectories;
  else req.what = protocol::RequestWhat::Status;
  auto link = connect_remote(o.link);
  const auto kind = protocol::CommandKind::Request;
  const auto r = send_and_wait(*link, kind, req, final_ack_timeout(*link, 0.0, o.link.timeout_s));
  // The report the request made travels beside the ack: give it a moment (bounded).
  if (r.succeeded()) wait_joints(*link, 1.0);
  const nlohmann::json s = status_json(*link);
  nlohmann::json report;
  if (o.what == "joints") report = {{"joints_rad", s["joints_rad"]},
                                                {"joint_velocities_rad_s", s["joint_velocities_rad_s"]},
                                                {"age_s", s["joints_age_s"]}};
  else if (o.what == "wrench") report = s.value("wrench", nlohmann::json(nullptr));
  else if (o.what == "tool") report = s.value("tool", nlohmann::json(nullptr));
  else report = s;
  if (o.link.json) {
    auto j = result_json(kind, r);
    j["what"] = o.what;
    j["report"] = report;
    std::cout << j.dump(2) << "\n";
  } else {
    std::cout << result_line(kind, r) << "\n" << o.what << ": " << report.dump() << "\n";
  }
  return exit_status(r);
}

const bool registered = register_command(
    {"request", "ask the remote for a report (joints, wrench, tool, status, trajectories) and print it",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("what", o->what, "joints | wrench | tool | status | trajectories")
           ->required()
           ->check(check::IsMember({"joints", "wrench", "tool", "status", "trajectories"}));
       add_link_options(sub, o->link);
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
