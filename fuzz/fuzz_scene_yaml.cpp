// config/scene.yaml: the work site (object pose, panel, cameras, contact and
// plant parameters), as every ground command and the simulator load it.
#include "foresight/common/scene.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static foresight::fuzz::ScratchFile file(".yaml");
  foresight::fuzz::expect_input_errors([&] { (void)foresight::Scene::from_file(file.write(data, size)); });
  return 0;
}
