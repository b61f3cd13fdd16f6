// The `tool:` section of config/remote.yaml: the LST tool over Modbus
// (address, registers, scales, limits).
#include "foresight/hw/lst_tool.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  foresight::fuzz::expect_input_errors([&] {
    const foresight::hw::LstToolConfig config =
        foresight::hw::parse_lst_tool_config(foresight::fuzz::text_of(data, size), "fuzz.yaml");
    foresight::hw::validate(config);
  });
  return 0;
}
