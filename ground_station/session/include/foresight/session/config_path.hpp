#pragma once
// Where the ground finds its configuration files by default.

#include <string>

namespace foresight::session {

/// Default path of a config file (robot.urdf, oru.yaml, scene.yaml,
/// ground.yaml, ...): $FORESIGHT_CONFIG_DIR/<file> when that variable is set,
/// else the project's config/ folder this binary was built from. Option
/// defaults use it so commands work from any directory.
std::string default_config(const std::string& file);

}  // namespace foresight::session
