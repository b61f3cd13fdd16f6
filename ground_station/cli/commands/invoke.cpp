// foresight invoke ALGORITHM [k=v ...]: run one of the remote's guarded
// algorithms (guarded_move, insert, latch, unlatch, loosen, tighten, pull_out)
// with its parameters, and wait for its final ack.
#include <cmath>
#include <cstdlib>
#include <iostream>

#include "command.hpp"
#include "foresight/script/script.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct Options {
  LinkOptions link;
  std::string algorithm;
  std::vector<std::string> params;
  double algorithm_timeout_s = 0.0;
};

protocol::InvokeAlgorithm parse(const Options& o) {
  const auto& names = script::algorithm_names();
  if (std::find(names.begin(), names.end(), o.algorithm) == names.end()) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown algorithm '" + o.algorithm + "' (algorithms: " + list + ")");
  }
  protocol::InvokeAlgorithm inv;
  inv.name = o.algorithm;
  inv.timeout_s = o.algorithm_timeout_s;
  for (const auto& p : o.params) {
    const std::size_t eq = p.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == p.size())
      throw std::invalid_argument("parameter '" + p + "' is not NAME=VALUE");
    const std::string value = p.substr(eq + 1);
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    if (end != value.c_str() + value.size() || !std::isfinite(v))
      throw std::invalid_argument("parameter " + p.substr(0, eq) + ": '" + value + "' is not a finite number");
    inv.params.push_back({p.substr(0, eq), v});
  }
  return inv;
}

int run(const Options& o) {
  const protocol::InvokeAlgorithm inv = parse(o);  // bad input before connecting
  auto link = connect_remote(o.link);
  const auto kind = protocol::CommandKind::InvokeAlgorithm;
  // The algorithm's own timeout bounds it; 60 s when it uses its default.
  const double expected = o.algorithm_timeout_s > 0 ? o.algorithm_timeout_s : 60.0;
  const ControlGuard control_guard(*link);
  const auto r = send_and_wait(*link, kind, inv, final_ack_timeout(*link, expected, o.link.timeout_s));
  if (o.link.json) {
    auto j = result_json(kind, r);
    j["algorithm"] = inv.name;
    for (const auto& p : inv.params) j["params"][p.name] = p.value;
    std::cout << j.dump(2) << "\n";
  } else {
    std::cout << result_line(kind, r) << "\n";
  }
  return exit_status(r);
}

const bool registered = register_command(
    {"invoke", "run a remote algorithm (guarded_move, insert, latch, unlatch, loosen, tighten, pull_out) NAME=VALUE...",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("algorithm", o->algorithm, "the algorithm's name")->required();
       sub.add_option("params", o->params, "its parameters, NAME=VALUE (SI units, e.g. depth_m=0.06)");
       sub.add_option("--algorithm-timeout", o->algorithm_timeout_s, "the algorithm's own timeout, s (0: its default)")
           ->check(check::NonNegativeNumber);
       add_link_options(sub, o->link);
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
