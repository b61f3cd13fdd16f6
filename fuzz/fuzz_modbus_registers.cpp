// Modbus input registers as the tool and the video switch return them: the
// LST status block (lst_tool_registers.hpp) and the video switch's, decoded
// to SI units. Any 16 bits may come back from a device; the decoded numbers
// must stay finite (they feed the controller's tool sequence and the status
// the ground sees).
#include <cmath>
#include <cstring>

#include "foresight/hw/lst_tool.hpp"
#include "foresight/hw/video_switch.hpp"
#include "fuzz_support.hpp"

namespace {
void require_finite(double v, const char* what) {
  if (!std::isfinite(v)) {
    std::fprintf(stderr, "fuzz: %s decoded to a non-finite value\n", what);
    std::abort();
  }
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace hw = foresight::hw;
  // Each block of 16 bytes is one register read (8 registers); the first
  // byte of the input picks the device.
  if (size < 1) return 0;
  const bool video = (data[0] & 1) != 0;
  ++data;
  --size;
  constexpr std::size_t kBlock = 8 * sizeof(std::uint16_t);
  for (std::size_t off = 0; off + kBlock <= size; off += kBlock) {
    std::uint16_t regs[8];
    std::memcpy(regs, data + off, kBlock);
    if (video) {
      const hw::VideoSwitchStatus s = hw::decode_video_status(regs);
      require_finite(s.pan_rad, "video pan_rad");
      require_finite(s.tilt_rad, "video tilt_rad");
      require_finite(s.focal_px, "video focal_px");
    } else {
      const hw::LstStatus s = hw::decode_status(regs);
      require_finite(s.turns, "lst turns");
      require_finite(s.torque_nm, "lst torque_nm");
      require_finite(s.speed_rad_s, "lst speed_rad_s");
      require_finite(s.peak_torque_nm, "lst peak_torque_nm");
      (void)s.describe();
    }
  }
  return 0;
}
