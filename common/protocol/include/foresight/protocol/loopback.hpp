#pragma once
// DDS on the loopback interface, for tests and benchmarks on one machine
// (Cyclone's default interface may not be loopback). Call before the first Participant
// of the process: Cyclone reads CYCLONEDDS_URI once, when the domain is
// created; child processes inherit the variable.

#include <dds/dds.h>

#include <optional>
#include <string>

namespace foresight::protocol {

/// Cyclone configuration: only `lo`, no multicast, unicast discovery of
/// 127.0.0.1 with automatic participant indices (so several processes on one
/// host find each other), and quiet logs.
std::string loopback_config_xml();

/// Sets CYCLONEDDS_URI to loopback_config_xml() unless the user already set
/// it (a user's own configuration wins). Returns true when it set it.
bool use_loopback_if_unconfigured();

/// Claims a DDS domain id in [first, last] that no other process on this host
/// holds: an exclusive flock on /tmp/foresight-dds-domain-<id>.lock, kept until
/// the process exits (child processes it starts on that domain need no lock of
/// their own). The search starts at a pid-derived id so that concurrent
/// claimers rarely contend. ProtocolError when every id in the range is held
/// ("no free DDS domain in 1..230: every one is held by another process").
dds_domainid_t claim_free_domain(dds_domainid_t first, dds_domainid_t last);

/// $FORESIGHT_DDS_DOMAIN as a domain id, nullopt when unset or empty: the one
/// parser of it (the daemon, the ground, the tests). InputError
/// "FORESIGHT_DDS_DOMAIN: 'abc' is not a DDS domain id (0-232)" for anything
/// but a whole decimal number in 0..232 ("201x", "-3", " 5" included).
std::optional<int> domain_from_environment();

/// The domain id of this process's tests: claimed once with
/// claim_free_domain(1, 230) and the same on every later call, so tests that
/// ctest runs in parallel never share a domain (a pid modulo the range did:
/// threads use up pids, so a long test met a short one's domain now and then).
/// Cyclone's default port mapping allows ids up to 232. FORESIGHT_DDS_DOMAIN
/// overrides (no claim is made then).
dds_domainid_t unique_test_domain();

}  // namespace foresight::protocol
