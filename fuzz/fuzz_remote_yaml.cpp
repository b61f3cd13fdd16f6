// config/remote.yaml: buses, CiA 402 drives, F/T sensor, controller
// settings, then the bus-load arithmetic the DriveSystem refuses start-up on.
#include "foresight/hw/remote_config.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  foresight::fuzz::expect_input_errors([&] {
    foresight::hw::RemoteConfig config =
        foresight::hw::parse_remote_config(foresight::fuzz::text_of(data, size), "fuzz.yaml");
    foresight::hw::validate(config);
    (void)foresight::hw::compute_bus_loads(config);
  });
  return 0;
}
