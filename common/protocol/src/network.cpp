#include "foresight/protocol/network.hpp"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <netdb.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <memory>

#include "foresight/common/error.hpp"
#include "foresight/protocol/error.hpp"

namespace foresight::protocol {

namespace {

/// XML-safe: names and addresses are checked to hold nothing to escape.
bool plain(const std::string& s) {
  if (s.empty() || s.size() > 253) return false;
  for (const char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_' || c == ':')) return false;
  return true;
}

}  // namespace

std::string NetworkSettings::describe() const {
  std::string p;
  for (const auto& h : peers) p += (p.empty() ? "" : ", ") + h;
  return "interface " + interface + ", peers " + (p.empty() ? "none" : p) + ", multicast " + (multicast ? "on" : "off");
}

LinkSecuritySettings read_link_security(const yaml::MapReader& link, const std::string& fallback_identity) {
  LinkSecuritySettings out;
  out.dir = link.get_or<std::string>("security", "");
  if (!out.dir.empty() && std::filesystem::path(out.dir).is_relative())
    out.dir = (std::filesystem::path(link.file()).parent_path() / out.dir).lexically_normal().string();
  out.identity = link.get_or<std::string>("identity", fallback_identity);
  if (out.identity.empty() || out.identity.find('/') != std::string::npos || out.identity.find("..") != std::string::npos)
    link.fail_key("identity", "'" + out.identity + "' is not an identity name (a folder under identities/)");
  return out;
}

NetworkSettings read_network(const yaml::MapReader& m) {
  m.check_keys({"interface", "peers", "multicast"});
  NetworkSettings n;
  n.source = m.file() + ": " + m.label();
  n.interface = m.get_or<std::string>("interface", n.interface);
  if (!plain(n.interface))
    m.fail_key("interface", "'" + n.interface + "' is not an interface name or address (letters, digits, '.', '-', '_', ':')");
  if (m["peers"]) {
    const YAML::Node list = m["peers"];
    if (!list.IsSequence()) m.fail_key("peers", "expected a list of host names or addresses, e.g. [127.0.0.1]");
    n.peers.clear();
    for (const auto& p : list) {
      if (!p.IsScalar() || !plain(p.as<std::string>()))
        m.fail(p, m.name("peers") + ": '" + (p.IsScalar() ? p.as<std::string>() : std::string("(not a name)")) +
                      "' is not a host name or address");
      n.peers.push_back(p.as<std::string>());
    }
  }
  n.multicast = m.get_or<bool>("multicast", n.multicast);
  if (n.peers.empty() && !n.multicast)
    m.fail_key("peers", "is empty and multicast is off: nothing could be discovered");
  return n;
}

std::string cyclone_config_xml(const NetworkSettings& n) {
  // MaxAutoParticipantIndex bounds the unicast discovery sweep (one port per
  // index and peer); 20 participants per domain and host is plenty.
  in_addr parsed{};
  const bool address = inet_pton(AF_INET, n.interface.c_str(), &parsed) == 1;
  std::string xml = "<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface " +
                    std::string(address ? "address" : "name") + "=\"" + n.interface + "\"/></Interfaces>";
  xml += std::string("<AllowMulticast>") + (n.multicast ? "true" : "false") + "</AllowMulticast></General>";
  xml += "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>";
  if (!n.peers.empty()) {
    xml += "<Peers>";
    for (const auto& p : n.peers) xml += "<Peer address=\"" + p + "\"/>";
    xml += "</Peers>";
  }
  xml += "</Discovery><Tracing><Verbosity>severe</Verbosity></Tracing></Domain></CycloneDDS>";
  return xml;
}

std::vector<std::string> network_problems(const NetworkSettings& n) {
  std::vector<std::string> out;
  ifaddrs* list = nullptr;
  if (getifaddrs(&list) != 0) {
    out.push_back("the network interfaces cannot be listed (getifaddrs failed)");
  } else {
    std::unique_ptr<ifaddrs, decltype(&freeifaddrs)> guard(list, &freeifaddrs);
    std::vector<std::string> names;
    bool found = false, up = false;
    for (const ifaddrs* a = list; a != nullptr; a = a->ifa_next) {
      const std::string name = a->ifa_name != nullptr ? a->ifa_name : "";
      if (std::find(names.begin(), names.end(), name) == names.end()) names.push_back(name);
      bool match = name == n.interface;
      if (!match && a->ifa_addr != nullptr && a->ifa_addr->sa_family == AF_INET) {
        char text[INET_ADDRSTRLEN] = "";
        inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(a->ifa_addr)->sin_addr, text, sizeof text);
        match = n.interface == text;
      }
      if (match) {
        found = true;
        up = up || (a->ifa_flags & IFF_UP) != 0;
      }
    }
    if (!found) {
      std::string have;
      for (const auto& x : names) have += (have.empty() ? "" : ", ") + x;
      out.push_back("interface '" + n.interface + "' does not exist (this machine has: " + have + ")");
    } else if (!up) {
      out.push_back("interface '" + n.interface + "' is down");
    }
  }
  for (const auto& p : n.peers) {
    addrinfo hints{};
    hints.ai_family = AF_INET;
    addrinfo* res = nullptr;
    const int rc = getaddrinfo(p.c_str(), nullptr, &hints, &res);
    if (rc != 0) {
      out.push_back("peer '" + p + "' does not resolve (" + gai_strerror(rc) + ")");
      continue;
    }
    freeaddrinfo(res);
  }
  return out;
}

bool use_network(const NetworkSettings& n) {
  const char* existing = std::getenv("CYCLONEDDS_URI");
  if (existing != nullptr && *existing != '\0') return false;
  if (const auto problems = network_problems(n); !problems.empty()) throw InputError(n.source, problems.front());
  return apply_network(n);
}

bool apply_network(const NetworkSettings& n) {
  const char* existing = std::getenv("CYCLONEDDS_URI");
  if (existing != nullptr && *existing != '\0') return false;
  if (setenv("CYCLONEDDS_URI", cyclone_config_xml(n).c_str(), 1) != 0) throw ProtocolError("setenv CYCLONEDDS_URI failed");
  return true;
}

}  // namespace foresight::protocol
