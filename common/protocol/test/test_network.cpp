// The DDS network as configuration (network.hpp): the YAML map, Cyclone's
// XML made of it, and what stands in its way on this machine.
#include <gtest/gtest.h>

#include <string>

#include "foresight/common/error.hpp"
#include "foresight/protocol/network.hpp"

namespace fp = foresight::protocol;
namespace yaml = foresight::yaml;

namespace {

fp::NetworkSettings read(const std::string& text) {
  const YAML::Node root = yaml::parse(text, "ground.yaml");
  const yaml::MapReader top(root, "ground.yaml", "");
  return fp::read_network(top.map("link").map("network"));
}

std::string refusal(const std::string& text) {
  try {
    read(text);
  } catch (const foresight::InputError& e) {
    return e.what();
  }
  return "(accepted)";
}

}  // namespace

TEST(Network, TheYamlMapAndItsDefaults) {
  const fp::NetworkSettings d = read("link:\n  network: {}\n");
  EXPECT_EQ(d.interface, "lo");
  EXPECT_EQ(d.peers, (std::vector<std::string>{"127.0.0.1"}));
  EXPECT_FALSE(d.multicast);
  EXPECT_EQ(d.source, "ground.yaml: link.network");
  EXPECT_EQ(d.describe(), "interface lo, peers 127.0.0.1, multicast off");

  const fp::NetworkSettings two =
      read("link:\n  network:\n    interface: eth1\n    peers: [10.42.0.1, cabinet.local]\n    multicast: false\n");
  EXPECT_EQ(two.interface, "eth1");
  EXPECT_EQ(two.peers, (std::vector<std::string>{"10.42.0.1", "cabinet.local"}));
  EXPECT_EQ(read("link:\n  network: {peers: [], multicast: true}\n").peers.size(), 0u);
}

TEST(Network, BadInputNamesTheFileLineAndKey) {
  EXPECT_EQ(refusal("link:\n  network:\n    interfce: lo\n"),
            "ground.yaml:3: link.network.interfce: unknown key (expected one of: interface, peers, multicast)");
  EXPECT_EQ(refusal("link:\n  network:\n    interface: \"eth 0\"\n"),
            "ground.yaml:3: link.network.interface: 'eth 0' is not an interface name or address (letters, digits, "
            "'.', '-', '_', ':')");
  EXPECT_EQ(refusal("link:\n  network:\n    peers: 127.0.0.1\n"),
            "ground.yaml:3: link.network.peers: expected a list of host names or addresses, e.g. [127.0.0.1]");
  EXPECT_EQ(refusal("link:\n  network:\n    peers: [\"a</Peer>\"]\n"),
            "ground.yaml:3: link.network.peers: 'a</Peer>' is not a host name or address");
  EXPECT_EQ(refusal("link:\n  network:\n    peers: []\n"),
            "ground.yaml:3: link.network.peers: is empty and multicast is off: nothing could be discovered");
  EXPECT_EQ(refusal("link:\n  network:\n    multicast: maybe\n"),
            "ground.yaml:3: link.network.multicast: not true or false: 'maybe'");
}

TEST(Network, CycloneConfigurationOfTheSettings) {
  const std::string lo = fp::cyclone_config_xml(fp::NetworkSettings{});
  EXPECT_NE(lo.find("<NetworkInterface name=\"lo\"/>"), std::string::npos) << lo;
  EXPECT_NE(lo.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos) << lo;
  EXPECT_NE(lo.find("<Peers><Peer address=\"127.0.0.1\"/></Peers>"), std::string::npos) << lo;
  fp::NetworkSettings p2p;
  p2p.interface = "10.42.0.1";
  p2p.peers = {"10.42.0.1", "10.42.0.2"};
  const std::string x = fp::cyclone_config_xml(p2p);
  EXPECT_NE(x.find("<NetworkInterface address=\"10.42.0.1\"/>"), std::string::npos) << x;
  EXPECT_NE(x.find("<Peer address=\"10.42.0.1\"/><Peer address=\"10.42.0.2\"/>"), std::string::npos) << x;
}

TEST(Network, WhatStandsInTheWayOnThisMachine) {
  EXPECT_TRUE(fp::network_problems(fp::NetworkSettings{}).empty());
  fp::NetworkSettings by_address;
  by_address.interface = "127.0.0.1";
  EXPECT_TRUE(fp::network_problems(by_address).empty());
  fp::NetworkSettings bad;
  bad.interface = "nosuch0";
  bad.peers = {"127.0.0.1", "no-such-host.invalid"};
  const auto problems = fp::network_problems(bad);
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_EQ(problems[0].rfind("interface 'nosuch0' does not exist (this machine has: lo", 0), 0u) << problems[0];
  EXPECT_EQ(problems[1].rfind("peer 'no-such-host.invalid' does not resolve (", 0), 0u) << problems[1];
}
