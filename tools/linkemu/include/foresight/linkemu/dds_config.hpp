#pragma once
// A Cyclone DDS configuration for one end of the emulated link. The TUN
// interface is point-to-point without multicast routing, so discovery is
// unicast to the far end's address; participant indices are automatic so
// several participants per namespace find each other's ports. Set-up code.

#include <string>

namespace foresight::linkemu {

/// The XML for CYCLONEDDS_URI: only `interface`, no multicast, unicast peer
/// `peer_address`, SPDP re-announced every `spdp_interval_s` (a lost
/// announcement on a lossy link is repeated soon, not after Cyclone's 30 s).
/// A reliable writer's unacknowledged-data watermark starts at 500 kB (not
/// 30 kB): on a 4 s link the default made a 115 kB upload block its writer
/// past the protocol's 5 s max blocking time. No <Tracing>: Cyclone then
/// writes no cyclonedds.log into the working directory; errors go to stderr.
std::string cyclone_config_xml(const std::string& interface, const std::string& peer_address,
                               double spdp_interval_s = 2.0);

}  // namespace foresight::linkemu
