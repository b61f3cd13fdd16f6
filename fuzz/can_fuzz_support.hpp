#pragma once
// A DriveSystem (the CANopen master the daemon runs) on mock buses built from
// config/remote.yaml, with the far end of every bus in the fuzzer's hands:
// hostile frames go in exactly as a drive, the F/T sensor or a broken node
// would put them on the wire. Set-up code, not real-time.
#include <sys/socket.h>

#include <memory>
#include <vector>

#include "foresight/hw/can_bus.hpp"
#include "foresight/hw/drive_system.hpp"
#include "foresight/hw/remote_config.hpp"

namespace foresight::fuzz {

struct MasterOnMockBuses {
  std::vector<hw::CanBus*> far;  ///< the simulated side of each bus (owned below)
  std::vector<std::unique_ptr<hw::MockCanBus>> far_owned;
  std::unique_ptr<hw::DriveSystem> master;

  explicit MasterOnMockBuses(hw::RemoteConfig config) {
    std::vector<std::unique_ptr<hw::CanBus>> near;
    for (const auto& b : config.buses) {
      auto [a, z] = hw::MockCanBus::create_pair(b.name);
      near.push_back(std::move(a));
      far.push_back(z.get());
      far_owned.push_back(std::move(z));
    }
    master = std::make_unique<hw::DriveSystem>(std::move(config), std::move(near));
  }

  /// One datagram onto bus `bus` from its far end (any length: a short or
  /// long datagram is what a broken driver would deliver).
  bool put(std::size_t bus, const void* bytes, std::size_t n) {
    return ::send(far[bus % far.size()]->fd(), bytes, n, MSG_DONTWAIT) == static_cast<ssize_t>(n);
  }
  /// Drops what the master sent (requests, RPDOs, SYNC).
  void drain() {
    for (auto* b : far) {
      can_frame f{};
      for (int i = 0; i < 4096 && b->read(f) != hw::CanIo::WouldBlock; ++i) {
      }
    }
  }
};

inline const hw::RemoteConfig& remote_config() {
  static const hw::RemoteConfig c = hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  return c;
}

}  // namespace foresight::fuzz
