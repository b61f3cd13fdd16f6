#pragma once
// The `foresight` operator CLI: one subcommand per file in commands/, each
// registering itself here at static-initialisation time. main.cpp parses the
// command line, runs the chosen command and turns exceptions into a message on
// stderr and a non-zero exit.
//
// Conventions for every command: a readable summary on stdout; with --json
// exactly one JSON object on stdout; errors on stderr, exit status non-zero.

#include <CLI/CLI.hpp>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

namespace foresight::cli {

/// Configures the subcommand's options on `sub` and returns the action to run
/// once parsing succeeded; the action returns the exit status.
using CommandSetup = std::function<std::function<int()>(CLI::App& sub)>;

struct CommandSpec {
  std::string name;
  std::string description;
  CommandSetup setup;
};

std::vector<CommandSpec>& command_registry();

/// Use at namespace scope in a commands/*.cpp file:
///   static const bool registered = register_command({"calibrate", "...", setup});
bool register_command(CommandSpec spec);

/// Default path of a config file (robot.urdf, oru.yaml, scene.yaml, ...):
/// $FORESIGHT_CONFIG_DIR/<file> when that variable is set, else the
/// project's config/ folder this binary was built from. Use it for option
/// defaults so commands work from any directory.
inline std::string default_config(const std::string& file) {
  const char* dir = std::getenv("FORESIGHT_CONFIG_DIR");
  return std::string(dir != nullptr && *dir != '\0' ? dir : FORESIGHT_DEFAULT_CONFIG_DIR) + "/" + file;
}

/// --cameras, --camera, --image and --frame: the calibrated camera and the
/// video frame the commands that draw over a video frame (overlay, preview,
/// predictive) read. `image_help` describes --image.
inline void add_video_frame_options(CLI::App& sub, std::string& cameras, std::string& camera, std::string& image,
                                    int& frame, const std::string& image_help) {
  sub.add_option("--cameras", cameras, "cameras.yaml from `foresight calibrate`")->required();
  sub.add_option("--camera", camera, "camera name in cameras.yaml")->required();
  sub.add_option("--image", image, image_help)->required();
  sub.add_option("--frame", frame, "frame index when --image is a video (0-based)")->check(CLI::NonNegativeNumber);
}

/// --gl, --robot, --object and --json: the options every command that renders
/// the arm shares. Give `robot` and `object` their defaults first (default_config).
inline void add_render_options(CLI::App& sub, std::string& gl, std::string& robot, std::string& object, bool& json) {
  sub.add_option("--gl", gl, "GL back end: osmesa | egl")->capture_default_str();
  sub.add_option("--robot", robot, "robot URDF")->capture_default_str();
  sub.add_option("--object", object, "task object model")->capture_default_str();
  sub.add_flag("--json", json, "print one JSON object");
}

/// Exit statuses shared by all commands.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;   ///< the computation failed (e.g. IK did not converge)
constexpr int kExitBadInput = 2;  ///< bad arguments or input files

}  // namespace foresight::cli
