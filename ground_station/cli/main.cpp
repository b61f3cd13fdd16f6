// foresight: the ground operator's command-line client. The one translation
// unit that includes CLI11: Command and Option (command.hpp) are implemented
// here over it.
#include <CLI/CLI.hpp>
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

Option* Option::required() {
  impl_->required();
  return this;
}
Option* Option::capture_default_str() {
  impl_->capture_default_str();
  return this;
}
Option* Option::check(const Check& c) {
  switch (c.kind) {
    case Check::Kind::Positive: impl_->check(CLI::PositiveNumber); break;
    case Check::Kind::NonNegative: impl_->check(CLI::NonNegativeNumber); break;
    case Check::Kind::RangeInt: impl_->check(CLI::Range(static_cast<int>(c.lo), static_cast<int>(c.hi))); break;
    case Check::Kind::RangeReal: impl_->check(CLI::Range(c.lo, c.hi)); break;
    case Check::Kind::MemberInt: impl_->check(CLI::IsMember(c.ints)); break;
    case Check::Kind::MemberText: impl_->check(CLI::IsMember(c.texts)); break;
  }
  return this;
}
Option* Option::excludes(Option* other) {
  impl_->excludes(other->impl_);
  return this;
}
Option* Option::delimiter(char sep) {
  impl_->delimiter(sep);
  return this;
}
Option* Option::group(const std::string& name) {
  impl_->group(name);
  return this;
}

Option* Command::keep(CLI::Option* o) { return &options_.emplace_back(o); }
Option* Command::add_option(const std::string& name, std::string& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, int& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, unsigned& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, std::int64_t& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, std::uint64_t& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, double& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, std::vector<std::string>& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, std::vector<double>& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_option(const std::string& name, std::vector<int>& v, const std::string& help) {
  return keep(impl_->add_option(name, v, help));
}
Option* Command::add_flag(const std::string& name, bool& v, const std::string& help) {
  return keep(impl_->add_flag(name, v, help));
}
Command* Command::add_subcommand(const std::string& name, const std::string& help) {
  return &subcommands_.emplace_back(*impl_->add_subcommand(name, help));
}
void Command::require_subcommand(int n) { impl_->require_subcommand(n); }
bool Command::parsed() const { return impl_->parsed(); }

}  // namespace foresight::cli

int main(int argc, char** argv) {
  using namespace foresight::cli;
  using foresight::kExitBadInput;
  using foresight::kExitFailure;
  spdlog::set_pattern("[%^%l%$] %v");
  CLI::App app{"foresight: ground operator client for the Foresight telerobotic servicing system"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "foresight 0.1.0");

  std::vector<std::pair<CLI::App*, std::function<int()>>> actions;
  std::deque<Command> commands;  // the commands' options live as long as the parse
  auto& registry = command_registry();
  std::sort(registry.begin(), registry.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  for (auto& spec : registry) {
    CLI::App* sub = app.add_subcommand(spec.name, spec.description);
    actions.emplace_back(sub, spec.setup(commands.emplace_back(*sub)));
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
