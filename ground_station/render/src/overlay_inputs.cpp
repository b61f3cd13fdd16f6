#include "foresight/render/overlay_inputs.hpp"

#include <stdexcept>

#include "foresight/common/error.hpp"

namespace foresight::render {

camera::Camera load_camera(const std::string& path, const std::string& name) {
  const auto cams = camera::load_cameras(path);
  const auto it = cams.find(name);
  if (it == cams.end()) {
    std::string known;
    for (const auto& [n, r] : cams) known += (known.empty() ? "" : ", ") + n;
    throw InputError(path, "no camera '" + name + "' (known: " + known + ")");
  }
  return it->second.camera;
}

}  // namespace foresight::render
