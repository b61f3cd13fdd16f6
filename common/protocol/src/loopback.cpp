#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/network.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <charconv>
#include <cstdlib>
#include <cstring>
#include <string>

#include "foresight/common/error.hpp"
#include "foresight/protocol/error.hpp"

namespace foresight::protocol {

std::string loopback_config_xml() { return cyclone_config_xml(NetworkSettings{}); }

bool use_loopback_if_unconfigured() { return apply_network(NetworkSettings{}); }

std::optional<int> domain_from_environment() {
  const char* env = std::getenv("FORESIGHT_DDS_DOMAIN");
  if (env == nullptr || *env == '\0') return std::nullopt;
  int id = -1;
  const char* end = env + std::strlen(env);
  const auto [at, ec] = std::from_chars(env, end, id);  // no sign, no space, whole string
  if (ec != std::errc() || at != end || id < 0 || id > 232)
    throw InputError("FORESIGHT_DDS_DOMAIN", std::string("'") + env + "' is not a DDS domain id (0-232)");
  return id;
}

dds_domainid_t unique_test_domain() {
  if (const auto forced = domain_from_environment()) return static_cast<dds_domainid_t>(*forced);
  static const dds_domainid_t claimed = claim_free_domain(1, 230);
  return claimed;
}

dds_domainid_t claim_free_domain(dds_domainid_t first, dds_domainid_t last) {
  if (last < first) throw ProtocolError("claim_free_domain: empty range");
  const dds_domainid_t span = last - first + 1;
  const auto start = static_cast<dds_domainid_t>(getpid()) % span;
  for (dds_domainid_t k = 0; k < span; ++k) {
    const dds_domainid_t id = first + (start + k) % span;
    const std::string path = "/tmp/foresight-dds-domain-" + std::to_string(id) + ".lock";
    const int fd = ::open(path.c_str(), O_RDONLY | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) continue;  // another user's lock file we may not open: taken as held
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) return id;  // fd deliberately kept open: the claim lasts the process
    ::close(fd);
  }
  throw ProtocolError("no free DDS domain in " + std::to_string(first) + ".." + std::to_string(last) +
                      ": every one is held by another process (/tmp/foresight-dds-domain-*.lock)");
}

}  // namespace foresight::protocol
