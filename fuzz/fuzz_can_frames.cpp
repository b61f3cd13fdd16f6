// CAN frames into the master's real-time cycle (DriveSystem::cycle_read):
// CiA 402 TPDOs (statusword, position, torque), heartbeats and boot-ups,
// EMCY, stray SDO traffic, the F/T sensor's frame pairs, RTR and extended
// frames, error frames, and datagrams that are not a can_frame at all.
//
// Input: records of [ctl][payload]. ctl bit 0 = bus; bit 7 set: a raw
// datagram of (ctl >> 1 & 31) bytes; otherwise one 16-byte struct can_frame.
// Every 24 records (and at the end) one cycle runs, the clock advancing by
// a period, or by a second when ctl bit 6 asks (heartbeat timeouts).
#include <chrono>
#include <cmath>
#include <cstring>

#include "can_fuzz_support.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace hw = foresight::hw;
  foresight::fuzz::MasterOnMockBuses rig(foresight::fuzz::remote_config());
  hw::JointFeedback joints;
  hw::FtReading ft;
  auto now = hw::DriveSystem::Clock::time_point{} + std::chrono::hours(1);
  const auto period = std::chrono::duration_cast<hw::DriveSystem::Clock::duration>(
      std::chrono::duration<double>(foresight::fuzz::remote_config().cycle_period_s()));
  int pending = 0;
  bool jump = false;
  auto cycle = [&] {
    now += jump ? std::chrono::seconds(1) : period;
    jump = false;
    const hw::CycleStatus s = rig.master->cycle_read(joints, ft, now);
    if (s.event_count > hw::CycleStatus::kMaxEvents) std::abort();
    for (std::size_t i = 0; i < s.event_count; ++i) (void)rig.master->describe(s.events[i]);
    for (std::size_t j = 0; j < joints.count; ++j)
      if (joints.joints[j].fresh && !std::isfinite(joints.joints[j].position_rad)) std::abort();
    pending = 0;
  };
  std::size_t off = 0;
  while (off < size) {
    const std::uint8_t ctl = data[off++];
    jump = jump || (ctl & 0x40);
    std::size_t n = (ctl & 0x80) ? ((ctl >> 1) & 31) : sizeof(can_frame);
    if (off + n > size) n = size - off;
    rig.put(ctl & 1, data + off, n);
    off += n;
    if (++pending == 24) cycle();
  }
  cycle();
  return 0;
}
