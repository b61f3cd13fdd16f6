// SDO responses to the master's set-up transfers (expedited upload of a
// 32-bit object, segmented upload of the device name 0x1008, download
// confirmations, aborts with any code), interleaved with other traffic, as
// DriveSystem::configure() meets them from a drive.
//
// Input: [op][frames...]: op picks the transfer; the rest is cut into
// 16-byte struct can_frame datagrams queued on the drive's bus before the
// transfer starts. A transfer that gets no answer times out (2 ms here).
#include <cstring>

#include "can_fuzz_support.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace hw = foresight::hw;
  if (size < 1) return 0;
  static const hw::RemoteConfig config = [] {
    hw::RemoteConfig c = foresight::fuzz::remote_config();
    c.sdo_timeout_s = 0.002;
    return c;
  }();
  foresight::fuzz::MasterOnMockBuses rig(config);
  const auto& drive = config.drives.at(0);
  const std::size_t bus = static_cast<std::size_t>(drive.bus_index);
  const std::uint8_t op = data[0];
  for (std::size_t off = 1; off < size; off += sizeof(can_frame)) {
    can_frame f{};
    std::memcpy(&f, data + off, std::min(sizeof f, size - off));
    rig.put(bus, &f, sizeof f);
  }
  foresight::fuzz::expect_input_errors([&] {
    switch (op % 3) {
      case 0: (void)rig.master->sdo_read(bus, drive.node_id, 0x1000, 0); break;
      case 1: (void)rig.master->sdo_read_string(bus, drive.node_id, 0x1008, 0); break;
      default: rig.master->sdo_write(bus, drive.node_id, 0x6060, 0, 8, 1); break;
    }
  });
  rig.drain();
  return 0;
}
