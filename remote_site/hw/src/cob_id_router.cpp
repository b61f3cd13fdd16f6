#include "foresight/hw/cob_id_router.hpp"

#include "foresight/hw/canopen.hpp"
#include "foresight/hw/ft_sensor.hpp"

namespace foresight::hw {

using namespace canopen;

void CobIdRouter::add_drive(std::uint8_t node, std::uint8_t slot, bool velocity_tpdo) noexcept {
  add(kTpdo1Base + node, Kind::DriveTpdo, slot);
  if (velocity_tpdo) add(kTpdo2Base + node, Kind::DriveVelocity, slot);
  add(kEmcyBase + node, Kind::DriveEmcy, slot);
  add(kHeartbeatBase + node, Kind::DriveHeartbeat, slot);
  add(kSdoTxBase + node, Kind::DriveSdo, slot);
  add(kRpdo1Base + node, Kind::Own, slot);  // our own frames, when the controller loops them back
  add(kSdoRxBase + node, Kind::Own, slot);
}

void CobIdRouter::add_ft(std::uint8_t node) noexcept {
  add(ft_frame::kForceBase + node, Kind::FtForce, 0);
  add(ft_frame::kTorqueBase + node, Kind::FtTorque, 0);
  add(kEmcyBase + node, Kind::FtEmcy, 0);
  add(kHeartbeatBase + node, Kind::FtHeartbeat, 0);
  add(kSdoTxBase + node, Kind::FtSdo, 0);
}

void CobIdRouter::add_master(std::uint8_t master_node_id) noexcept {
  add(kNmt, Kind::Own, 0);
  add(kHeartbeatBase + master_node_id, Kind::Own, 0);
}

}  // namespace foresight::hw
