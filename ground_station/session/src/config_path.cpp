#include "foresight/session/config_path.hpp"

#include <cstdlib>

namespace foresight::session {

std::string default_config(const std::string& file) {
  const char* dir = std::getenv("FORESIGHT_CONFIG_DIR");
  return std::string(dir != nullptr && *dir != '\0' ? dir : FORESIGHT_DEFAULT_CONFIG_DIR) + "/" + file;
}

}  // namespace foresight::session
