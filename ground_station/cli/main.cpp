// foresight: the ground operator's command-line client.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <algorithm>
#include <exception>
#include <iostream>

#include "command.hpp"
#include "foresight/common/error.hpp"

namespace foresight::cli {

std::vector<CommandSpec>& command_registry() {
  static std::vector<CommandSpec> registry;
  return registry;
}

bool register_command(CommandSpec spec) {
  command_registry().push_back(std::move(spec));
  return true;
}

}  // namespace foresight::cli

int main(int argc, char** argv) {
  using namespace foresight::cli;
  spdlog::set_pattern("[%^%l%$] %v");
  CLI::App app{"foresight: ground operator client for the Foresight telerobotic servicing system"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "foresight 0.1.0");

  std::vector<std::pair<CLI::App*, std::function<int()>>> actions;
  auto& registry = command_registry();
  std::sort(registry.begin(), registry.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  for (auto& spec : registry) {
    CLI::App* sub = app.add_subcommand(spec.name, spec.description);
    actions.emplace_back(sub, spec.setup(*sub));
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : kExitBadInput;
  }
  for (auto& [sub, action] : actions) {
    if (!sub->parsed()) continue;
    try {
      return action();
    } catch (const foresight::InputError& e) {  // bad input: a file, option or data set
      std::cerr << "foresight " << sub->get_name() << ": error: " << e.what() << "\n";
      return kExitBadInput;
    } catch (const foresight::Error& e) {  // ComputationError and the rest of the tree: the computation failed
      std::cerr << "foresight " << sub->get_name() << ": error: " << e.what() << "\n";
      return kExitFailure;
    } catch (const std::invalid_argument& e) {  // the commands' own option checks (std::invalid_argument)
      std::cerr << "foresight " << sub->get_name() << ": error: " << e.what() << "\n";
      return kExitBadInput;
    } catch (const std::exception& e) {
      std::cerr << "foresight " << sub->get_name() << ": error: " << e.what() << "\n";
      return kExitFailure;
    }
  }
  return kExitBadInput;
}
