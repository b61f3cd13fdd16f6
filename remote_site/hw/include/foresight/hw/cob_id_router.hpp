#pragma once
// Which node handler a received frame belongs to, by its 11-bit COB-ID: one
// table per bus, filled at set-up (DriveSystem's constructor) and only read in
// the cycle. A fixed array indexed by COB-ID, so routing a frame is one load:
// no search, no allocation, no lock (the master's real-time path). As in Lely's
// master/driver split (lely::canopen::BasicMaster dispatching to a
// BasicDriver per node), the router knows which handler owns which COB-ID;
// the handlers (cia402_drive.hpp, ft_node.hpp) know what the frames mean.

#include <array>
#include <cstddef>
#include <cstdint>

namespace foresight::hw {

class CobIdRouter {
 public:
  /// What a COB-ID is to the master. A later add() of the same COB-ID wins.
  enum class Kind : std::uint8_t {
    None,           ///< nobody on this bus should send it (UnknownCobId)
    Own,            ///< the master's own frames (RPDO, SDO request, NMT, heartbeat) looped back
    DriveTpdo,      ///< TPDO1 of drive `slot`: statusword, position, torque
    DriveVelocity,  ///< TPDO2 of drive `slot`: velocity actual
    DriveEmcy,
    DriveHeartbeat,
    DriveSdo,       ///< an SDO response, outside an SDO transfer
    FtForce,        ///< F/T frame A
    FtTorque,       ///< F/T frame B
    FtEmcy,
    FtHeartbeat,
    FtSdo,
  };
  struct Route {
    Kind kind = Kind::None;
    std::uint8_t slot = 0;  ///< the drive's joint index (0 for the F/T sensor and the master)
  };
  static constexpr std::size_t kCobIds = 2048;

  // ---- set-up -------------------------------------------------------------------
  /// A CiA 402 drive's COB-IDs (TPDO1, TPDO2 when `velocity_tpdo`, EMCY,
  /// heartbeat, SDO response; its RPDO and SDO requests as the master's own).
  void add_drive(std::uint8_t node, std::uint8_t slot, bool velocity_tpdo) noexcept;
  /// The F/T sensor's COB-IDs (frames A and B, EMCY, heartbeat, SDO response).
  void add_ft(std::uint8_t node) noexcept;
  /// The master's own NMT and heartbeat, when the controller loops them back.
  void add_master(std::uint8_t master_node_id) noexcept;

  // ---- real-time ----------------------------------------------------------------
  /// `cob_id` is an 11-bit identifier (CAN_SFF_MASK applied).
  Route route(std::uint32_t cob_id) const noexcept { return routes_[cob_id % kCobIds]; }

 private:
  void add(std::uint32_t cob_id, Kind kind, std::uint8_t slot) noexcept { routes_[cob_id % kCobIds] = {kind, slot}; }
  std::array<Route, kCobIds> routes_{};
};

}  // namespace foresight::hw
