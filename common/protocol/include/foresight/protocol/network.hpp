#pragma once
// The link's settings both sides read from their YAML (`link:`): its DDS
// Security folder and identity, and the DDS network as configuration: which interface the link uses, which
// hosts it discovers by unicast, and whether it may use multicast. The
// daemon reads it from remote.yaml (`controller.link.network`), the CLI from
// ground.yaml (`link.network`); both turn it into Cyclone's configuration
// (CYCLONEDDS_URI) before their first participant. A user's own
// CYCLONEDDS_URI wins. Set-up only (allocates, may throw).
//
// The two cases shipped (docs/deploy.md, "The DDS network"):
//   one machine             interface: lo, peers: [127.0.0.1], multicast: false (the default)
//   two machines over a     interface: eth1, peers: [10.42.0.1, 10.42.0.2], multicast: false
//   point-to-point link     (both ends listed: the same file serves both sides)

#include <string>
#include <vector>

#include "foresight/common/yaml_util.hpp"

namespace foresight::protocol {

struct NetworkSettings {
  std::string interface = "lo";                  ///< a network interface's name (ip link) or its IPv4 address
  std::vector<std::string> peers{"127.0.0.1"};   ///< hosts found by unicast discovery: names or addresses
  bool multicast = false;                        ///< SPDP and data by multicast too (never across a space link)
  std::string source;                            ///< "FILE: KEY", for messages ("" = the default)
  /// "interface lo, peers 127.0.0.1, multicast off".
  std::string describe() const;
};

/// The DDS Security part of a `link:` map, the same on both sides:
/// `security` (a folder, relative to the file; "" = none) and `identity`
/// (a folder name under identities/, `fallback` when absent). InputError
/// "<file>:<line>: <path>.identity: '../x' is not an identity name ...".
struct LinkSecuritySettings {
  std::string dir;
  std::string identity;
};
LinkSecuritySettings read_link_security(const yaml::MapReader& link, const std::string& fallback_identity);

/// Reads a `network:` map (keys interface, peers, multicast; each optional,
/// the defaults above): InputError "<file>:<line>: <path>.<key>: ..." for an
/// unknown key, a wrong type, an empty name or an empty peer list.
NetworkSettings read_network(const yaml::MapReader& network);

/// The Cyclone configuration for `n` (the interface, the peers, multicast,
/// automatic participant indices so several processes of one host find each
/// other, quiet logs).
std::string cyclone_config_xml(const NetworkSettings& n);

/// What stands in the way on this machine, one sentence each, empty when
/// nothing: "interface 'eth7' does not exist (this machine has: lo, eth0)",
/// "interface 'eth1' is down", "peer 'cabinet' does not resolve (Name or
/// service not known)".
std::vector<std::string> network_problems(const NetworkSettings& n);

/// Sets CYCLONEDDS_URI to cyclone_config_xml(n) unless the environment
/// already has one (the user's own configuration wins: returns false and
/// changes nothing). Call before the process's first participant.
bool apply_network(const NetworkSettings& n);

/// The daemon's and the CLI's start: as apply_network(), but first refuses
/// settings this machine cannot use (InputError "<n.source>: <the first of
/// network_problems>"). Returns false, checking nothing, when the user's own
/// CYCLONEDDS_URI wins.
bool use_network(const NetworkSettings& n);

}  // namespace foresight::protocol
