#include "foresight/linkemu/dds_config.hpp"

#include <cstdio>

namespace foresight::linkemu {

std::string cyclone_config_xml(const std::string& interface, const std::string& peer_address,
                               double spdp_interval_s) {
  char interval[32];
  std::snprintf(interval, sizeof interval, "%gs", spdp_interval_s);
  return "<CycloneDDS><Domain id=\"any\">"
         "<General><Interfaces><NetworkInterface name=\"" +
         interface +
         "\"/></Interfaces>"
         "<AllowMulticast>false</AllowMulticast></General>"
         "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
         "<MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>"
         "<SPDPInterval>" +
         interval +
         "</SPDPInterval>"
         "<Peers><Peer address=\"" +
         peer_address +
         "\"/></Peers></Discovery>"
         // A long link holds a lot of unacknowledged data: start a reliable
         // writer's high watermark at its maximum instead of 30 kB, or an
         // upload stalls a round trip per 30 kB and blocks the writer.
         "<Internal><Watermarks><WhcHighInit>500kB</WhcHighInit></Watermarks></Internal>"
         "</Domain></CycloneDDS>";
}

}  // namespace foresight::linkemu
