// config/oru.yaml: the ORU object model (box, model points, hole, tag frames,
// visuals), as localization, the script checker and the plant load it.
#include "foresight/common/object_model.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static foresight::fuzz::ScratchFile file(".yaml");
  foresight::fuzz::expect_input_errors([&] {
    const auto model = foresight::ObjectModel::from_file(file.write(data, size));
    for (const auto& p : model.points) (void)model.point_index(p.name);
  });
  return 0;
}
