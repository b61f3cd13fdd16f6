#include "foresight/protocol/loopback.hpp"

#include <unistd.h>

#include <cstdlib>
#include <string>

#include "foresight/protocol/error.hpp"

namespace foresight::protocol {

std::string loopback_config_xml() {
  // MaxAutoParticipantIndex bounds the unicast discovery sweep (one port per
  // index); 20 participants per domain on one host is plenty for tests.
  return "<CycloneDDS><Domain id=\"any\">"
         "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces>"
         "<AllowMulticast>false</AllowMulticast></General>"
         "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
         "<MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>"
         "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>"
         "<Tracing><Verbosity>severe</Verbosity></Tracing>"
         "</Domain></CycloneDDS>";
}

bool use_loopback_if_unconfigured() {
  const char* existing = std::getenv("CYCLONEDDS_URI");
  if (existing != nullptr && *existing != '\0') return false;
  if (setenv("CYCLONEDDS_URI", loopback_config_xml().c_str(), 1) != 0) {
    throw ProtocolError("setenv CYCLONEDDS_URI failed");
  }
  return true;
}

dds_domainid_t unique_test_domain() {
  if (const char* forced = std::getenv("FORESIGHT_DDS_DOMAIN"); forced != nullptr && *forced != '\0') {
    char* end = nullptr;
    const long id = std::strtol(forced, &end, 10);
    if (*end != '\0' || id < 0 || id > 232) {
      throw ProtocolError(std::string("FORESIGHT_DDS_DOMAIN: '") + forced + "' is not a domain id in 0..232");
    }
    return static_cast<dds_domainid_t>(id);
  }
  return static_cast<dds_domainid_t>(1 + getpid() % 230);
}

}  // namespace foresight::protocol
