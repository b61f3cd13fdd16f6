// config/remote.yaml as the daemon reads it (hw's loaders of build_site):
// buses, CiA 402 drives, F/T sensor, the video switch section (the tool: fuzz_lst_yaml), then
// the validation (ranges, bus load, the start-up estimate) the daemon refuses
// start-up on. (The controller section's reader, daemon_config.cpp, lives in
// foresight_daemon, which would bring the whole remote into the fuzz build.)
#include "foresight/hw/remote_config.hpp"
#include "foresight/hw/video_switch.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = foresight::fuzz::text_of(data, size);
  foresight::fuzz::expect_input_errors([&] {
    foresight::hw::RemoteConfig config = foresight::hw::parse_remote_config(text, "fuzz.yaml");
    foresight::hw::validate(config);
    (void)foresight::hw::compute_bus_loads(config);
    (void)foresight::hw::estimate_startup(config).describe();
  });
  foresight::fuzz::expect_input_errors([&] { (void)foresight::hw::parse_video_switch_section(text, "fuzz.yaml"); });
  return 0;
}
