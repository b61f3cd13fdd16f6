#pragma once
// The `foresight` operator CLI: one subcommand per file in commands/, each
// registering itself here at static-initialisation time. main.cpp parses the
// command line, runs the chosen command and turns exceptions into a message on
// stderr and a non-zero exit.
//
// Conventions for every command: a readable summary on stdout; with --json
// exactly one JSON object on stdout; errors on stderr, exit status non-zero.
//
// Commands declare their options through Command and Option below: CLI11 does
// the parsing, but only main.cpp includes it (its inline code costs ~11 s of
// compile time in every file that includes it; scripts/build_report.sh).

#include <cstdint>
#include <cstdlib>
#include <deque>
#include <functional>
#include <initializer_list>
#include <string>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/session/config_path.hpp"

namespace CLI {
class App;
class Option;
}  // namespace CLI

namespace foresight::cli {

/// A check of an option's value, applied by the parser (named as CLI11's).
struct Check {
  enum class Kind { Positive, NonNegative, RangeInt, RangeReal, MemberInt, MemberText };
  Kind kind = Kind::Positive;
  double lo = 0.0, hi = 0.0;
  std::vector<long long> ints;
  std::vector<std::string> texts;
};
namespace check {
inline Check make(Check::Kind kind, double lo = 0.0, double hi = 0.0) {
  Check c;
  c.kind = kind;
  c.lo = lo;
  c.hi = hi;
  return c;
}
inline const Check PositiveNumber = make(Check::Kind::Positive);
inline const Check NonNegativeNumber = make(Check::Kind::NonNegative);
inline Check Range(int lo, int hi) { return make(Check::Kind::RangeInt, lo, hi); }
inline Check Range(double lo, double hi) { return make(Check::Kind::RangeReal, lo, hi); }
/// A wait in seconds: a millisecond to a day (1e300 s overflowed the clock
/// arithmetic into "timed out after 0.0 s" at once).
inline const Check WaitSeconds = make(Check::Kind::RangeReal, 0.001, 86400.0);
inline Check IsMember(std::initializer_list<int> v) {
  Check c = make(Check::Kind::MemberInt);
  c.ints.assign(v.begin(), v.end());
  return c;
}
inline Check IsMember(std::initializer_list<const char*> v) {
  Check c = make(Check::Kind::MemberText);
  c.texts.assign(v.begin(), v.end());
  return c;
}
}  // namespace check

/// One option of a command; the calls chain as CLI11's do.
class Option {
 public:
  explicit Option(CLI::Option* impl) : impl_(impl) {}
  Option* required();
  /// Show the value the variable holds now as the default in --help.
  Option* capture_default_str();
  Option* check(const Check& c);
  Option* excludes(Option* other);
  /// Split each value at `sep` (vector options).
  Option* delimiter(char sep);
  /// "" hides the option from --help.
  Option* group(const std::string& name);

 private:
  CLI::Option* impl_;
};

/// A command (or a subcommand of one): its options, flags and subcommands.
/// A name with dashes is an option (--name), without a positional argument.
class Command {
 public:
  explicit Command(CLI::App& impl) : impl_(&impl) {}
  Command(const Command&) = delete;
  Command& operator=(const Command&) = delete;

  Option* add_option(const std::string& name, std::string& value, const std::string& help = "");
  Option* add_option(const std::string& name, int& value, const std::string& help = "");
  Option* add_option(const std::string& name, unsigned& value, const std::string& help = "");
  Option* add_option(const std::string& name, std::int64_t& value, const std::string& help = "");
  Option* add_option(const std::string& name, std::uint64_t& value, const std::string& help = "");
  Option* add_option(const std::string& name, double& value, const std::string& help = "");
  Option* add_option(const std::string& name, std::vector<std::string>& value, const std::string& help = "");
  Option* add_option(const std::string& name, std::vector<double>& value, const std::string& help = "");
  Option* add_option(const std::string& name, std::vector<int>& value, const std::string& help = "");
  Option* add_flag(const std::string& name, bool& value, const std::string& help = "");
  Command* add_subcommand(const std::string& name, const std::string& help);
  void require_subcommand(int n);
  /// True once the command line named this command.
  bool parsed() const;

 private:
  Option* keep(CLI::Option* o);
  CLI::App* impl_;
  std::deque<Option> options_;  // stable addresses: callers keep Option*
  std::deque<Command> subcommands_;
};

/// Configures the subcommand's options on `sub` and returns the action to run
/// once parsing succeeded; the action returns the exit status.
using CommandSetup = std::function<std::function<int()>(Command& sub)>;

struct CommandSpec {
  std::string name;
  std::string description;
  CommandSetup setup;
};

std::vector<CommandSpec>& command_registry();

/// Use at namespace scope in a commands/*.cpp file:
///   static const bool registered = register_command({"calibrate", "...", setup});
bool register_command(CommandSpec spec);

/// Option defaults name config files through session::default_config.
using session::default_config;

/// --cameras, --camera, --image and --frame: the calibrated camera and the
/// video frame the commands that draw over a video frame (overlay, preview,
/// predictive) read. `image_help` describes --image.
inline void add_video_frame_options(Command& sub, std::string& cameras, std::string& camera, std::string& image,
                                    int& frame, const std::string& image_help) {
  sub.add_option("--cameras", cameras, "cameras.yaml from `foresight calibrate`")->required();
  sub.add_option("--camera", camera, "camera name in cameras.yaml")->required();
  sub.add_option("--image", image, image_help)->required();
  sub.add_option("--frame", frame, "frame index when --image is a video (0-based)")->check(check::NonNegativeNumber);
}

/// --gl, --robot, --object and --json: the options every command that renders
/// the arm shares. Give `robot` and `object` their defaults first (default_config).
inline void add_render_options(Command& sub, std::string& gl, std::string& robot, std::string& object, bool& json) {
  sub.add_option("--gl", gl, "GL back end: osmesa | egl")->capture_default_str();
  sub.add_option("--robot", robot, "robot URDF")->capture_default_str();
  sub.add_option("--object", object, "task object model")->capture_default_str();
  sub.add_flag("--json", json, "print one JSON object");
}

}  // namespace foresight::cli
