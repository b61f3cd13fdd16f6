// cameras.yaml: calibrated cameras (viewport, f_px, base_T_camera,
// covariance), as calibrate --out merges into it and every ground command
// reads it.
#include "foresight/camera/camera.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static foresight::fuzz::ScratchFile file(".yaml");
  foresight::fuzz::expect_input_errors([&] { (void)foresight::camera::load_cameras(file.write(data, size)); });
  return 0;
}
