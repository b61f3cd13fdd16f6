#pragma once
// What every node on the master's buses shares, whatever its profile: where
// it is (bus, node id, joint), its NMT state from its heartbeat, its last
// EMCY, and the supervision of its heartbeat and of its cyclic PDOs. The
// profile handlers derive from it (cia402_drive.hpp, ft_node.hpp), as Lely's
// drivers share lely::canopen::BasicDriver. Internal to foresight_hw: the
// public face is DriveSystem.
//
// Everything but the constructors runs in the real-time cycle: noexcept, no
// allocation, no lock. Events go to the master's EventQueue in the order they
// happen.

#include <linux/can.h>

#include <atomic>
#include <chrono>
#include <cstdint>

#include "foresight/hw/canopen.hpp"
#include "foresight/hw/cob_id_router.hpp"
#include "foresight/hw/drive_system.hpp"

namespace foresight::hw {

class CanNode {
 public:
  using Clock = std::chrono::steady_clock;
  using Kind = CobIdRouter::Kind;
  /// What a routed frame did: taken, refused as malformed (the master
  /// reports MalformedFrame), or a TPDO answering an earlier SYNC (the master
  /// counts it in stale_tpdos).
  enum class Rx : std::uint8_t { Taken, Malformed, Stale };
  /// The master's state a frame is read in.
  struct RxContext {
    Clock::time_point now{};
    std::uint64_t cycle = 0;    ///< the master's cycle counter
    bool configured = false;    ///< configure() has succeeded: NMT changes are faults
    bool stale = false;         ///< read before the echo of the bus's last SYNC
    const std::atomic<bool>* quick_stop = nullptr;  ///< request_quick_stop() pending
  };

  CanNode(std::size_t bus_index, std::uint8_t node_id, std::int8_t joint_index) noexcept
      : bus(bus_index), node(node_id), joint(joint_index) {}

  std::uint8_t bus8() const noexcept { return static_cast<std::uint8_t>(bus); }
  /// An event about this node.
  HwEvent event(HwFault f, std::uint32_t code, std::uint32_t detail) const noexcept {
    return {f, bus8(), node, joint, code, detail};
  }
  /// configure() sent NMT start: heartbeat monitoring starts now.
  void start_monitoring(Clock::time_point now) noexcept {
    last_hb = now;
    heartbeat_lost = false;
    nmt = canopen::NmtState::Operational;
  }
  /// enable(): a heartbeat lost while the cycle was not running stays lost
  /// (a stop on every cycle) until the node is heard again. False: still lost.
  bool heartbeat_heard(Clock::time_point now, std::chrono::nanoseconds timeout) noexcept {
    if (!heartbeat_lost) return true;
    if (now - last_hb > timeout) return false;
    heartbeat_lost = false;
    return true;
  }

  std::size_t bus = 0;
  std::uint8_t node = 0;
  std::int8_t joint = -1;  ///< joint index, -1 when not a drive
  canopen::NmtState nmt = canopen::NmtState::PreOperational;
  bool booted = false;  ///< boot-up message seen (configure() waits for it)
  /// Rebooted (boot-up) or left NMT operational since configure(): its
  /// configuration is lost or in doubt; no enable until it is configured again.
  bool unconfigured = false;
  bool heartbeat_lost = false;
  std::uint16_t last_emcy = 0;  ///< last EMCY error code (0: none / reset)
  Clock::time_point last_hb{};
  int missed = 0;  ///< cycles with a SYNC sent and no fresh sample
  bool miss_reported = false;

 protected:
  /// EMCY (CiA 301): error code, error register, manufacturer bytes.
  Rx on_emcy(const can_frame& f, EventQueue& events) noexcept;
  /// Heartbeat / boot-up: the node's NMT state.
  Rx on_heartbeat(const can_frame& f, const RxContext& ctx, EventQueue& events) noexcept;
  /// After a cycle with a SYNC sent: `fresh` is whether its sample arrived;
  /// `missing` (TpdoMissing, FtMissing) once tpdo_miss_limit in a row did not.
  void count_missed(bool fresh, int limit, HwFault missing, EventQueue& events) noexcept;
  /// HeartbeatLost once the node is silent longer than `timeout`.
  void check_heartbeat(Clock::time_point now, std::chrono::nanoseconds timeout, bool configured,
                       EventQueue& events) noexcept;
};

}  // namespace foresight::hw
