// Drive configuration lists (config/drives/*.sdo: the SDO writes a drive gets
// at configure(), read back after), and the text the master prints for a
// value it read.
#include "foresight/hw/sdo_list.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  foresight::fuzz::expect_input_errors([&] {
    const auto entries = foresight::hw::parse_sdo_list(foresight::fuzz::text_of(data, size), "fuzz.sdo");
    for (const auto& e : entries) (void)foresight::hw::sdo_value_text(e, 0xFFFFFFFFu);
  });
  return 0;
}
