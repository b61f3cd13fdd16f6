#pragma once
// DDS on the loopback interface, for tests and benchmarks on one machine
// (../shared/STACK.md, "DDS on loopback"). Call before the first Participant
// of the process: Cyclone reads CYCLONEDDS_URI once, when the domain is
// created; child processes inherit the variable.

#include <dds/dds.h>

#include <string>

namespace foresight::protocol {

/// Cyclone configuration: only `lo`, no multicast, unicast discovery of
/// 127.0.0.1 with automatic participant indices (so several processes on one
/// host find each other), and quiet logs.
std::string loopback_config_xml();

/// Sets CYCLONEDDS_URI to loopback_config_xml() unless the user already set
/// it (a user's own configuration wins). Returns true when it set it.
bool use_loopback_if_unconfigured();

/// A domain id for this process: derived from the pid so tests that ctest
/// runs in parallel do not see each other's traffic. In 1..230 (Cyclone's
/// default port mapping allows ids up to 232); FORESIGHT_DDS_DOMAIN overrides.
dds_domainid_t unique_test_domain();

}  // namespace foresight::protocol
