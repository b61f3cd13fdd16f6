// DDS Security on the link, two real processes on loopback: material from
// scripts/make_dds_security.sh in a scratch folder; link_test_remote runs
// with the "remote" identity. The ground identity commands it; a participant
// whose certificate comes from another CA never matches anything; the
// observer identity reads telemetry and measures delay but may not create a
// command or chunk writer. Skips (saying why) without openssl or Cyclone's
// security plugins.

#include <gtest/gtest.h>

#include "foresight/test/child_process.hpp"
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <thread>

#include "foresight/ground_link/ground_link.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/convert.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/security.hpp"


namespace gl = foresight::ground_link;
namespace protocol = foresight::protocol;
namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;
namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

constexpr auto kConnectTimeout = 30s;
/// How long a participant that must not match is given to (not) match: far
/// longer than a secure handshake on loopback takes (~50-300 ms).
constexpr auto kNoMatchWindow = 4s;

class SecureLink : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string plugins = fp::security_plugin_dir();
    if (plugins.empty() || !fs::exists(fs::path(plugins) / "libdds_security_auth.so")) {
      GTEST_SKIP() << "Cyclone's DDS Security plugins were not found at build time";
    }
    if (std::system("command -v openssl >/dev/null 2>&1") != 0) GTEST_SKIP() << "openssl is not installed";
    char tmpl[] = "/tmp/foresight_sec_XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    const std::string cmd = "bash " + std::string(FORESIGHT_SOURCE_DIR) + "/scripts/make_dds_security.sh " + dir_ +
                            " >/dev/null";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    fp::use_loopback_if_unconfigured();
    domain_ = fp::unique_test_domain();
    foresight::test::ChildProcess::Options o;
    o.stop_grace_s = 5.0;
    remote_ = std::make_unique<foresight::test::ChildProcess>(
        std::vector<std::string>{std::string(FORESIGHT_BIN_DIR) + "/link_test_remote", "--domain",
                                 std::to_string(domain_), "--security", dir_, "--lifetime-s", "110"},
        o);
  }
  void TearDown() override {
    if (remote_) {
      EXPECT_TRUE(remote_->running()) << "the remote exited early (see its stderr)";
    }
    remote_.reset();
    if (!dir_.empty()) fs::remove_all(dir_);
  }

  std::string dir_;
  dds_domainid_t domain_ = 0;
  std::unique_ptr<foresight::test::ChildProcess> remote_;
};

}  // namespace

TEST_F(SecureLink, TheGroundIdentityCommandsTheSecureRemote) {
  gl::Config config;
  config.domain = domain_;
  config.security_dir = dir_;
  config.security_identity = "ground";
  config.delay.rate_hz = 20.0;
  gl::GroundLink ground(config);
  ASSERT_TRUE(ground.wait_for_remote(kConnectTimeout));
  const auto r = ground.execute(protocol::CommandKind::GotoJoint, protocol::GotoJoint{{0.1, 0, 0, 0, 0, 0, 0}, 0.5});
  EXPECT_TRUE(r.succeeded()) << r.reason;
  EXPECT_EQ(r.final_q_rad.size(), 7u);
  const auto deadline = Clock::now() + 10s;
  while (!ground.joint_state() && Clock::now() < deadline) std::this_thread::sleep_for(10ms);
  EXPECT_TRUE(ground.joint_state().has_value());
}

TEST_F(SecureLink, AParticipantOfAnotherCaCannotJoin) {
  fp::Participant intruder(domain_, fp::security_qos(dir_ + "/foreign", "intruder"));
  fp::Writer<msg::Command> commands(intruder);
  fp::Reader<msg::JointState> joints(intruder);
  EXPECT_FALSE(commands.wait_for_readers(1, kNoMatchWindow)) << "the intruder's command writer matched the remote";
  EXPECT_EQ(joints.matched_writers(), 0u);
  fp::Sample<msg::JointState> s;
  EXPECT_FALSE(joints.take(s)) << "the intruder received telemetry";
}

TEST_F(SecureLink, AnObserverReadsTelemetryButCannotCommand) {
  fp::Participant observer(domain_, fp::security_qos(dir_, "observer"));
  fp::Reader<msg::JointState> joints(observer);
  fp::Sample<msg::JointState> s;
  ASSERT_TRUE(joints.wait_take(s, kConnectTimeout)) << "no telemetry for the observer";
  EXPECT_EQ(s->q_rad._length, 7u);
  gl::DelayMonitor delay(observer);  // pings are granted to the observer
  EXPECT_TRUE(delay.wait_samples(3, kConnectTimeout));
  // A read-only GroundLink with the observer's identity watches the robot.
  gl::Config config;
  config.domain = domain_;
  config.security_dir = dir_;
  config.security_identity = "observer";
  config.read_only = true;
  gl::GroundLink watcher(config);
  ASSERT_TRUE(watcher.wait_for_remote(kConnectTimeout));
  const auto deadline = Clock::now() + 10s;
  while (!watcher.joint_state() && Clock::now() < deadline) std::this_thread::sleep_for(10ms);
  EXPECT_TRUE(watcher.joint_state().has_value());
  EXPECT_THROW(watcher.send(protocol::CommandKind::Recover), std::logic_error);
  // The one command topic it may write carries ABORT only: anything else is REJECTED.
  {
    fp::Writer<msg::Command> aborts(observer, fp::topics::kAbort);
    fp::Reader<msg::CommandAck> acks(observer);
    ASSERT_TRUE(aborts.wait_for_readers(1, kConnectTimeout));
    ASSERT_TRUE(acks.wait_for_writers(1, kConnectTimeout));
    fp::CommandSequencer seq;
    auto c = seq.next(foresight_msg_CMD_GOTO_JOINT);
    fp::fill_payload(*c, protocol::CommandKind::GotoJoint, protocol::GotoJoint{std::vector<double>(7, 0.2), 0.5});
    aborts.write(c);
    fp::Sample<msg::CommandAck> a;
    std::string reason;
    const auto until = Clock::now() + 20s;
    while (reason.empty() && Clock::now() < until)
      if (acks.wait_take(a, 100ms) && a->command_id == c->command_id && a->state == foresight_msg_ACK_REJECTED)
        reason = fp::from_wire(*a).reason;
    EXPECT_EQ(reason, "command " + std::to_string(c->command_id) + ": foresight/abort carries only ABORT");
  }
  for (const char* topic : {fp::topics::kCommand, fp::topics::kTrajectoryChunk}) {
    try {
      if (std::string(topic) == fp::topics::kCommand) {
        fp::Writer<msg::Command> w(observer);
      } else {
        fp::Writer<msg::TrajectoryChunk> w(observer);
      }
      ADD_FAILURE() << "the observer may write " << topic;
    } catch (const fp::ProtocolError& e) {
      EXPECT_EQ(e.what(), "create writer on " + std::string(topic) + ": Not Allowed By Security") << e.what();
    }
  }
}

// DDS Security 1.1, 9.3.3: an authenticated participant's GUID begins with 48
// bits of its certificate's subject. The remote binds control to them, so
// every process of one station is the same commander (issue 28, item 6).
TEST_F(SecureLink, AnAuthenticatedParticipantsGuidBeginsWithItsIdentity) {
  auto guid_of = [](const fp::Participant& p) {
    dds_guid_t g;
    EXPECT_EQ(dds_get_guid(p.get(), &g), DDS_RETCODE_OK);
    fp::ParticipantGuid out;
    std::memcpy(out.bytes.data(), g.v, 16);
    return out;
  };
  fp::Participant a(domain_, fp::security_qos(dir_, "ground"));
  fp::Participant b(domain_, fp::security_qos(dir_, "ground"));
  fp::Participant o(domain_, fp::security_qos(dir_, "observer"));
  const fp::ParticipantGuid ground = fp::identity_of_certificate(dir_ + "/identities/ground/cert.pem");
  EXPECT_NE(guid_of(a), guid_of(b));
  EXPECT_EQ(fp::identity_of(guid_of(a)), ground) << guid_of(a).hex();
  EXPECT_EQ(fp::identity_of(guid_of(b)), ground) << guid_of(b).hex();
  EXPECT_EQ(fp::identity_of(guid_of(o)), fp::identity_of_certificate(dir_ + "/identities/observer/cert.pem"));
  EXPECT_NE(fp::identity_of(guid_of(o)), ground);
  EXPECT_EQ(ground.bytes[0] & 0x80u, 0x80u);
  for (std::size_t i = 6; i < 16; ++i) EXPECT_EQ(ground.bytes[i], 0u);

  const auto known = fp::known_identities(dir_);
  std::vector<std::string> names;
  for (const auto& [id, name] : known) {
    names.push_back(name);
    if (name == "ground") {
      EXPECT_EQ(id, ground);
    }
  }
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"ground", "observer", "remote"}));
  try {
    fp::identity_of_certificate(dir_ + "/ca_key.pem");
    ADD_FAILURE() << "a key taken for a certificate";
  } catch (const fp::ProtocolError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("DDS Security: " + dir_ + "/ca_key.pem: is not a PEM certificate", 0), 0u)
        << e.what();
  }
}

// Each role publishes only its own side's topics: a ground station cannot
// speak as the remote (acks, status, telemetry, pongs), the remote cannot
// command. One participant at a time: Cyclone 0.10 gives participants that
// live at once in one domain of one process the first one's permissions.
TEST_F(SecureLink, EachRolePublishesOnlyItsOwnSidesTopics) {
  auto refused = [](const std::string& topic, auto make) {
    try {
      make();
      ADD_FAILURE() << "allowed to write " << topic;
    } catch (const fp::ProtocolError& e) {
      EXPECT_EQ(e.what(), "create writer on " + topic + ": Not Allowed By Security") << e.what();
    }
  };
  {
    fp::Participant ground(domain_, fp::security_qos(dir_, "ground"));
    refused(fp::topics::kCommandAck, [&] { fp::Writer<msg::CommandAck> w(ground); });
    refused(fp::topics::kControllerStatus, [&] { fp::Writer<msg::ControllerStatus> w(ground); });
    refused(fp::topics::kJointState, [&] { fp::Writer<msg::JointState> w(ground); });
    refused(fp::topics::kPong, [&] { fp::Writer<msg::Pong> w(ground); });
    refused(fp::topics::kTrajectoryStatus, [&] { fp::Writer<msg::TrajectoryStatus> w(ground); });
    EXPECT_NO_THROW(fp::Writer<msg::Command> w(ground));
    EXPECT_NO_THROW(fp::Writer<msg::TrajectoryChunk> w(ground));
  }
  {
    fp::Participant remote(domain_, fp::security_qos(dir_, "remote"));
    refused(fp::topics::kCommand, [&] { fp::Writer<msg::Command> w(remote); });
    refused(fp::topics::kTrajectoryChunk, [&] { fp::Writer<msg::TrajectoryChunk> w(remote); });
    EXPECT_NO_THROW(fp::Writer<msg::ControllerStatus> w(remote));
    EXPECT_NO_THROW(fp::Writer<msg::Pong> w(remote));
  }
}
