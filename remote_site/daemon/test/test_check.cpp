// foresight-remote check: every missing piece fails with its reason, the
// simulated site passes; the deployment files (systemd unit, CAN bring-up
// script, the two .deb packages) hold what they should.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/un.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <linux/can.h>

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "foresight/protocol/loopback.hpp"
#include "foresight/daemon/check.hpp"
#include "foresight/test/cli.hpp"
#include "foresight/test/remote_process.hpp"

namespace fs = std::filesystem;
using foresight::daemon::CheckItem;
using foresight::daemon::CheckOptions;
using foresight::daemon::CheckReport;
using foresight::daemon::CheckResult;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;
const std::string kSource = FORESIGHT_SOURCE_DIR;
const std::string kBin = FORESIGHT_BIN_DIR;

std::string slurp(const std::string& path) { return foresight::test::read_file(path); }

/// A scratch folder holding a copy of config/ (remote.yaml edited by `edit`).
struct ConfigDir {
  fs::path dir;
  explicit ConfigDir(bool with_urdf = true) {
    dir = foresight::test::temp_path("_cfg");
    fs::create_directories(dir);
    for (const char* f : {"remote.yaml", "scene.yaml", "oru.yaml"}) fs::copy_file(kConfig + "/" + f, dir / f);
    fs::copy(kConfig + "/drives", dir / "drives", fs::copy_options::recursive);  // the drives' SDO lists (sdo_file:)
    if (with_urdf) fs::copy_file(kConfig + "/robot.urdf", dir / "robot.urdf");
  }
  ~ConfigDir() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::string yaml() const { return (dir / "remote.yaml").string(); }
  void replace(const std::string& from, const std::string& to) const {
    std::string text = slurp(yaml());
    text = std::regex_replace(text, std::regex(from), to);
    std::ofstream(yaml()) << text;
  }
  /// The cabinet's buses: can0 and can1 instead of the mock buses.
  void real_buses() const {
    replace("name: arm_a, interface: mock", "name: arm_a, interface: can0");
    replace("name: arm_b, interface: mock", "name: arm_b, interface: can1");
  }
};

const CheckItem& must_find(const CheckReport& r, const std::string& name) {
  const CheckItem* i = r.find(name);
  if (i == nullptr) {
    ADD_FAILURE() << "no item '" << name << "' in\n" << r.text();
    static const CheckItem none{};
    return none;
  }
  return *i;
}

/// Runs `cmd` through the shell; stderr joins stdout unless `cmd` redirects it.
foresight::test::CliRun run_shell(const std::string& cmd) {
  return foresight::test::run_shell(cmd.find("2>") == std::string::npos ? cmd + " 2>&1" : cmd);
}

bool kernel_has_can() {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) return errno != EAFNOSUPPORT;
  ::close(fd);
  return true;
}

}  // namespace

// ---- CAN ----------------------------------------------------------------------------------

TEST(CheckCan, AssessesTheLinkFromIpJson) {
  using foresight::daemon::assess_can_link;
  const auto link = [](const std::string& flags, const std::string& state, int bitrate, int restart_ms) {
    return R"([{"ifname":"can0","flags":[)" + flags + R"(],"txqlen":1000,"link_type":"can",)" +
           R"("linkinfo":{"info_kind":"can","info_data":{"state":")" + state + R"(","restart_ms":)" +
           std::to_string(restart_ms) + R"(,"bittiming":{"bitrate":)" + std::to_string(bitrate) + "}}}}]";
  };
  const std::string up = R"("NOARP","UP","LOWER_UP","ECHO")";
  CheckItem i = assess_can_link("CAN arm_a (can0)", "can0", 1000000, link(up, "ERROR-ACTIVE", 1000000, 100));
  EXPECT_EQ(i.result, CheckResult::Pass) << i.why;
  EXPECT_EQ(i.why, "can0 up, ERROR-ACTIVE, 1000 kbit/s, restart-ms 100, txqueuelen 1000");

  i = assess_can_link("c", "can0", 1000000, link(up, "ERROR-ACTIVE", 500000, 100));
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("the configuration says 1000 kbit/s"), std::string::npos) << i.why;

  i = assess_can_link("c", "can0", 1000000, link(up, "BUS-OFF", 1000000, 100));
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("BUS-OFF"), std::string::npos) << i.why;

  i = assess_can_link("c", "can0", 1000000, link(R"("NOARP","ECHO")", "STOPPED", 1000000, 100));
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("can0 is down"), std::string::npos) << i.why;

  i = assess_can_link("c", "can0", 1000000, link(up, "ERROR-ACTIVE", 1000000, 0));
  EXPECT_EQ(i.result, CheckResult::Warn);
  EXPECT_NE(i.why.find("no automatic bus-off recovery"), std::string::npos) << i.why;

  i = assess_can_link("c", "eth0", 1000000, R"([{"ifname":"eth0","flags":["UP"],"link_type":"ether"}])");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("eth0 is not a CAN interface"), std::string::npos) << i.why;

  i = assess_can_link("c", "can0", 1000000, "Device \"can0\" does not exist.");
  EXPECT_EQ(i.result, CheckResult::Fail);
}

TEST(CheckCan, NoCanInterfaceSaysSo) {
  ConfigDir cfg;
  cfg.real_buses();
  CheckOptions o;
  o.remote_yaml = cfg.yaml();
  o.tool_timeout_s = 0.1;
  const CheckReport r = foresight::daemon::run_check(o);
  EXPECT_FALSE(r.fit());
  for (const char* name : {"CAN arm_a (can0)", "CAN arm_b (can1)"}) {
    const CheckItem& i = must_find(r, name);
    EXPECT_EQ(i.result, CheckResult::Fail) << i.why;
    if (!kernel_has_can()) {
      EXPECT_NE(i.why.find("this kernel has no SocketCAN support (socket(PF_CAN) failed: EAFNOSUPPORT"),
                std::string::npos)
          << i.why;
    } else if (!fs::exists(std::string("/sys/class/net/") + (name[8] == 'a' ? "can0" : "can1"))) {
      EXPECT_NE(i.why.find("no interface can"), std::string::npos) << i.why;
    }
  }
  // The configuration itself is fine.
  EXPECT_EQ(must_find(r, "config").result, CheckResult::Pass) << must_find(r, "config").why;
  EXPECT_EQ(must_find(r, "robot model").result, CheckResult::Pass);
  EXPECT_EQ(must_find(r, "bus budget").result, CheckResult::Pass);
}

TEST(CheckCan, MockBusesAreNotACabinet) {
  CheckOptions o;
  o.remote_yaml = kConfig + "/remote.yaml";  // the repository's config: mock buses
  o.tool_timeout_s = 0.1;
  const CheckReport r = foresight::daemon::run_check(o);
  const CheckItem& i = must_find(r, "CAN arm_a (mock)");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("has interface 'mock': a real cabinet needs a SocketCAN interface"), std::string::npos) << i.why;
}

// ---- configuration and model --------------------------------------------------------------

TEST(CheckConfig, MissingUrdfIsNamed) {
  ConfigDir cfg(/*with_urdf=*/false);
  CheckOptions o;
  o.remote_yaml = cfg.yaml();
  o.sim = true;
  const CheckReport r = foresight::daemon::run_check(o);
  EXPECT_FALSE(r.fit());
  const CheckItem& i = must_find(r, "robot model");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_EQ(i.why, "missing URDF: " + (cfg.dir / "robot.urdf").string() + " does not exist");
  EXPECT_EQ(must_find(r, "CAN (simulated)").result, CheckResult::Skip);
}

TEST(CheckConfig, BadKeyNamesFileAndLine) {
  ConfigDir cfg;
  cfg.replace("control_lease_s: 10", "control_leas_s: 10");
  CheckOptions o;
  o.remote_yaml = cfg.yaml();
  o.sim = true;
  const CheckReport r = foresight::daemon::run_check(o);
  EXPECT_FALSE(r.fit());
  const CheckItem& i = must_find(r, "config");
  EXPECT_EQ(i.result, CheckResult::Fail);
  int line = 0;  // the key's line in the file
  {
    std::istringstream in(slurp(cfg.yaml()));
    std::string l;
    for (int n = 1; line == 0 && std::getline(in, l); ++n)
      if (l.find("control_leas_s") != std::string::npos) line = n;
  }
  ASSERT_GT(line, 0);
  EXPECT_EQ(i.why.rfind(cfg.yaml() + ":" + std::to_string(line) + ": controller.control_leas_s: unknown key", 0), 0u)
      << i.why;
}

// check runs every loader the daemon runs: the video switch section (not
// parsed by check before) and the start-up estimate; the daemon refuses the
// same file with the same words, also under --sim.
TEST(CheckConfig, TheVideoSwitchSectionIsCheckedAsTheDaemonChecksIt) {
  ConfigDir cfg;
  cfg.replace("  port: 1503\n", "  port: 70000\n");
  CheckOptions o;
  o.remote_yaml = cfg.yaml();
  o.sim = true;
  const CheckReport r = foresight::daemon::run_check(o);
  EXPECT_FALSE(r.fit());
  const CheckItem& i = must_find(r, "config");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find(cfg.yaml() + ":"), std::string::npos) << i.why;
  EXPECT_NE(i.why.find("video_switch.port"), std::string::npos) << i.why;
  const foresight::test::CliRun daemon = run_shell("timeout 60 " + kBin + "/foresight-remote --sim --journal " + (cfg.dir / "j.db").string() +
                                    " --config " + cfg.yaml() + " 2>&1");
  EXPECT_EQ(daemon.status, 2) << daemon.out;
  EXPECT_NE(daemon.out.find(i.why), std::string::npos) << daemon.out << "\n" << i.why;

  ConfigDir good;
  o.remote_yaml = good.yaml();
  const CheckReport good_report = foresight::daemon::run_check(o);
  const CheckItem& ok = must_find(good_report, "config");
  EXPECT_EQ(ok.result, CheckResult::Pass) << ok.why;
  EXPECT_NE(ok.why.find("video switch 127.0.0.1:1503 (4 cameras); start-up up to "), std::string::npos) << ok.why;
}

TEST(CheckConfig, DriveJointMismatch) {
  ConfigDir cfg;
  cfg.replace("joint: joint2, bus: arm_a", "joint: joint9, bus: arm_a");
  CheckOptions o;
  o.remote_yaml = cfg.yaml();
  o.sim = true;
  const CheckReport r = foresight::daemon::run_check(o);
  const CheckItem& i = must_find(r, "robot model");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("drive 2 is for joint 'joint9', the robot's joint 2 is 'joint2'"), std::string::npos) << i.why;
}

// The journal item runs the writer's own checks (journal::probe_journal),
// writing nothing: a folder that is not there, a file that is not a journal, a
// newer schema fail as the daemon would fail on them.
TEST(CheckConfig, JournalFolderMustExist) {
  using foresight::daemon::check_journal_dir;
  CheckItem i = check_journal_dir("/nonexistent_foresight_dir/j.db");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_EQ(i.why, "/nonexistent_foresight_dir/j.db: cannot create the journal: its folder /nonexistent_foresight_dir "
                   "does not exist");
  const std::string dir = foresight::test::temp_path("_jcheck");
  fs::create_directories(dir);
  i = check_journal_dir(dir + "/j.db");
  EXPECT_EQ(i.result, CheckResult::Pass) << i.why;
  EXPECT_EQ(i.why, dir + "/j.db: does not exist yet: will be created");
  EXPECT_FALSE(fs::exists(dir + "/j.db"));

  { std::ofstream(dir + "/notes.db") << "not a database, but somebody's notes\n"; }
  i = check_journal_dir(dir + "/notes.db");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("not a journal database"), std::string::npos) << i.why;
  EXPECT_EQ(slurp(dir + "/notes.db"), "not a database, but somebody's notes\n");

  i = check_journal_dir(dir);
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("not a regular file (a directory)"), std::string::npos) << i.why;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// ---- tool -----------------------------------------------------------------------------------

TEST(CheckTool, UnreachableEndpointFails) {
  // A port that was just free: bind, read the port, close (nothing listens).
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  socklen_t len = sizeof a;
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len), 0);
  const int port = ntohs(a.sin_port);
  ::close(fd);

  foresight::hw::LstToolConfig c;
  c.host = "127.0.0.1";
  c.port = port;
  const CheckItem i = foresight::daemon::check_tool(c, 0.2);
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_EQ(i.why.rfind("the LST at tcp 127.0.0.1:" + std::to_string(port) + " unit 1 does not answer: ", 0), 0u)
      << i.why;
}

// ---- the simulated site passes ----------------------------------------------------------------

TEST(CheckSim, SimulatedSitePasses) {
  CheckOptions o;
  o.remote_yaml = kConfig + "/remote.yaml";
  o.sim = true;
  o.journal_path = "/tmp/foresight-check-journal.db";
  const CheckReport r = foresight::daemon::run_check(o);
  EXPECT_TRUE(r.fit()) << r.text();
  EXPECT_EQ(r.count(CheckResult::Fail), 0);
  const CheckItem& can = must_find(r, "CAN (simulated)");
  EXPECT_EQ(can.result, CheckResult::Pass) << can.why;
  EXPECT_NE(can.why.find("7 simulated drives and the F/T sensor answered on mock buses arm_a, arm_b"),
            std::string::npos)
      << can.why;
  const CheckItem& tool = must_find(r, "tool");
  EXPECT_EQ(tool.result, CheckResult::Pass) << tool.why;
  EXPECT_EQ(tool.why.rfind("tcp 127.0.0.1:", 0), 0u) << tool.why;
  EXPECT_EQ(must_find(r, "bus budget").why, "arm_a 57.7%, arm_b 57.8% worst case at 500 Hz (limit 70%)");
  EXPECT_EQ(must_find(r, "DDS security").result, CheckResult::Skip);
  // --sim never fails for missing real-time permissions.
  EXPECT_NE(must_find(r, "rt priority").result, CheckResult::Fail);
  EXPECT_NE(must_find(r, "memory lock").result, CheckResult::Fail);
}

TEST(CheckCli, SimPassesAndRealConfigFailsWithReasons) {
  foresight::test::CliRun ok = run_shell("timeout 120 " + kBin + "/foresight-remote check --config " + kConfig +
                     "/remote.yaml --sim --json --journal /tmp/foresight-check-journal.db 2>/dev/null");
  ASSERT_EQ(ok.status, 0) << ok.out;
  const auto j = nlohmann::json::parse(ok.out);
  EXPECT_TRUE(j.at("fit").get<bool>());
  EXPECT_EQ(j.at("counts").at("fail").get<int>(), 0);
  EXPECT_GE(j.at("items").size(), 11u);

  ConfigDir cfg;
  cfg.real_buses();
  foresight::test::CliRun bad = run_shell("timeout 120 " + kBin + "/foresight-remote check --config " + cfg.yaml() + " 2>/dev/null");
  EXPECT_EQ(bad.status, 1) << bad.out;
  EXPECT_NE(bad.out.find("FAIL  CAN arm_a (can0)"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("FAIL  tool"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("NOT fit to run"), std::string::npos) << bad.out;
}

// A name that is not UTF-8 (a byte 0xff in the configuration's path) is
// printed as U+FFFD in the JSON, not an abort in the JSON writer (exit 134).
TEST(CheckCli, BytesThatAreNotUtf8StillGiveJson) {
  foresight::test::CliRun r = run_shell("timeout 120 " + kBin + "/foresight-remote check --sim --json --config \"$(printf '/nonexistent/r\\377x.yaml')\" 2>/dev/null");
  EXPECT_EQ(r.status, 1) << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_FALSE(j.at("fit").get<bool>());
  EXPECT_NE(r.out.find("/nonexistent/r\xef\xbf\xbdx.yaml"), std::string::npos) << r.out;
}

// ---- DDS security ---------------------------------------------------------------------------------

TEST(CheckSecurity, SkippedMissingValidForeign) {
  using foresight::daemon::check_security;
  EXPECT_EQ(check_security("", "remote").result, CheckResult::Skip);

  const std::string none = foresight::test::temp_path("_nosec");
  CheckItem i = check_security(none, "remote");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find(none + "/ca.pem is missing"), std::string::npos) << i.why;

  if (run_shell("command -v openssl").status != 0) GTEST_SKIP() << "openssl is not installed";
  const std::string dir = foresight::test::temp_path("_sec");
  const foresight::test::CliRun made = run_shell("bash " + kSource + "/scripts/make_dds_security.sh " + dir);
  ASSERT_EQ(made.status, 0) << made.out;
  i = check_security(dir, "remote");
  EXPECT_EQ(i.result, CheckResult::Pass) << i.why;
  EXPECT_NE(i.why.find("identity 'remote' in " + dir + ": certificate signed by the CA, matches its key"),
            std::string::npos)
      << i.why;

  // The foreign CA's identity put in place of ours: it does not verify against our CA.
  fs::copy(dir + "/foreign/identities/intruder", dir + "/identities/intruder", fs::copy_options::recursive);
  i = check_security(dir, "intruder");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("does not verify against " + dir + "/ca.pem"), std::string::npos) << i.why;

  // A key that is not the certificate's.
  fs::copy_file(dir + "/identities/ground/key.pem", dir + "/identities/remote/key.pem",
                fs::copy_options::overwrite_existing);
  i = check_security(dir, "remote");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("does not match its key.pem"), std::string::npos) << i.why;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// The signed documents are checked as Cyclone's access control will check
// them (issue 26: check passed a damaged governance), and the daemon names the
// damaged file before it touches the drives instead of "create participant: Error".
TEST(CheckSecurity, SignedDocumentsAndDamagedFilesAreNamedByCheckAndTheDaemon) {
  using foresight::daemon::check_security;
  if (run_shell("command -v openssl").status != 0) GTEST_SKIP() << "openssl is not installed";
  const std::string dir = foresight::test::temp_path("_secdocs");
  const foresight::test::CliRun made = run_shell("bash " + kSource + "/scripts/make_dds_security.sh " + dir);
  ASSERT_EQ(made.status, 0) << made.out;
  ASSERT_EQ(check_security(dir, "remote").result, CheckResult::Pass);
  EXPECT_NE(check_security(dir, "remote").why.find("governance and permissions signed by the CA"), std::string::npos);
  const std::string governance = slurp(dir + "/governance.p7s");

  // Another CA's governance: well-formed, signed, but not by ours.
  fs::copy_file(dir + "/foreign/governance.p7s", dir + "/governance.p7s", fs::copy_options::overwrite_existing);
  CheckItem i = check_security(dir, "remote");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("DDS Security: " + dir + "/governance.p7s: the governance document's signature does not verify "
                       "against the CA"), std::string::npos) << i.why;

  // A signed document whose content was edited after signing.
  std::string edited = governance;
  const auto at = edited.find("<allow_unauthenticated_participants>false");
  ASSERT_NE(at, std::string::npos);
  edited.replace(at, 41, "<allow_unauthenticated_participants>true ");
  { std::ofstream(dir + "/governance.p7s", std::ios::trunc) << edited; }
  i = check_security(dir, "remote");
  EXPECT_EQ(i.result, CheckResult::Fail);
  EXPECT_NE(i.why.find("governance.p7s: the governance document's signature does not verify"), std::string::npos) << i.why;

  // Not S/MIME at all; a truncated certificate.
  { std::ofstream(dir + "/governance.p7s", std::ios::trunc) << governance; }
  { std::ofstream(dir + "/permissions.p7s", std::ios::trunc) << "<dds>unsigned</dds>\n"; }
  i = check_security(dir, "remote");
  EXPECT_NE(i.why.find("DDS Security: " + dir + "/permissions.p7s: is not an S/MIME signed permissions document"),
            std::string::npos) << i.why;
  fs::copy_file(dir + "/foreign/permissions.p7s", dir + "/permissions.p7s", fs::copy_options::overwrite_existing);
  const std::string cert = slurp(dir + "/identities/remote/cert.pem");
  { std::ofstream(dir + "/identities/remote/cert.pem", std::ios::trunc) << cert.substr(0, cert.size() / 2); }
  i = check_security(dir, "remote");
  EXPECT_NE(i.why.find("DDS Security: " + dir + "/identities/remote/cert.pem: is not a PEM certificate"),
            std::string::npos) << i.why;

  // The daemon: exit 2 at start-up naming the file; nothing was configured.
  const foresight::test::CliRun daemon = run_shell("timeout 60 " + kBin + "/foresight-remote --sim --journal " + dir +
                                    "/j.db --security " + dir + " 2>&1");
  EXPECT_EQ(daemon.status, 2) << daemon.out;
  EXPECT_NE(daemon.out.find("foresight-remote: error: --security: DDS Security: " + dir +
                            "/identities/remote/cert.pem: is not a PEM certificate"), std::string::npos) << daemon.out;
  EXPECT_EQ(daemon.out.find("configuring"), std::string::npos) << daemon.out;
  EXPECT_FALSE(fs::exists(dir + "/j.db"));
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// Security by default (issue 28): off the simulator the daemon does not run
// an open link unless the configuration says `insecure: true` in so many
// words; check says the same; a relative folder is the configuration's.
TEST(CheckSecurity, OffTheSimulatorAnOpenLinkIsRefusedUnlessSaidInsecure) {
  ConfigDir cfg;
  cfg.real_buses();
  const std::string journal = (cfg.dir / "j.db").string();
  const foresight::test::CliRun open = run_shell("timeout 60 " + kBin + "/foresight-remote --config " + cfg.yaml() + " --journal " +
                                  journal + " --domain 7 2>&1");
  EXPECT_EQ(open.status, 2) << open.out;
  EXPECT_NE(open.out.find("foresight-remote: error: " + cfg.yaml() +
                          ": controller.link.security is not set: the DDS link would be open to every participant of "
                          "domain 7. Make the identities (make_dds_security.sh DIR, docs/deploy.md) and set "
                          "controller.link.security: DIR (or --security DIR), or say controller.link.insecure: true "
                          "to run it open\n"),
            std::string::npos)
      << open.out;
  EXPECT_EQ(open.out.find("configuring"), std::string::npos) << "the hardware was touched:\n" << open.out;
  EXPECT_FALSE(fs::exists(journal));

  auto security_item = [&](const std::string& yaml) {
    const foresight::test::CliRun r = run_shell("timeout 120 " + kBin + "/foresight-remote check --json --config " + yaml +
                                 " 2>/dev/null");
    const auto report = nlohmann::json::parse(r.out);
    for (const auto& i : report.at("items"))
      if (i.at("name") == "DDS security") return std::make_pair(i.at("result").get<std::string>(), i.at("why").get<std::string>());
    ADD_FAILURE() << "no DDS security item:\n" << r.out;
    return std::make_pair(std::string(), std::string());
  };
  auto [result, why] = security_item(cfg.yaml());
  EXPECT_EQ(result, "FAIL");
  EXPECT_EQ(why, "not configured: the daemon refuses to start off --sim without controller.link.security (or "
                 "--security DIR), unless controller.link.insecure: true");

  // Said in so many words: the daemon goes on (to the missing CAN interface here) with a warning; check warns.
  cfg.replace("    identity: remote\n", "    identity: remote\n    insecure: true\n");
  const foresight::test::CliRun insecure = run_shell("timeout 60 " + kBin + "/foresight-remote --config " + cfg.yaml() +
                                      " --journal " + journal + " --domain 7 2>&1");
  EXPECT_NE(insecure.status, 0);
  EXPECT_EQ(insecure.out.find("controller.link.security is not set"), std::string::npos) << insecure.out;
  EXPECT_NE(insecure.out.find("controller.link.insecure: true: the DDS link runs without DDS Security (any participant "
                              "of domain 7 can reach it)"),
            std::string::npos)
      << insecure.out;
  std::tie(result, why) = security_item(cfg.yaml());
  EXPECT_EQ(result, "WARN");
  EXPECT_EQ(why, "controller.link.insecure: true: the link runs without DDS Security; any participant of the DDS domain "
                 "can command the arm (make_dds_security.sh, docs/deploy.md)");

  // Both at once contradict each other: check and the daemon refuse the configuration.
  cfg.replace("security: \"\"", "security: sec");
  const foresight::test::CliRun both = run_shell("timeout 60 " + kBin + "/foresight-remote check --config " + cfg.yaml() + " 2>&1");
  EXPECT_EQ(both.status, 1) << both.out;
  EXPECT_NE(both.out.find(": controller.link.insecure: contradicts link.security 'sec': say one or the other"),
            std::string::npos)
      << both.out;

  // The folder relative to the configuration file.
  cfg.replace("    insecure: true\n", "");
  if (run_shell("command -v openssl").status != 0) GTEST_SKIP() << "openssl is not installed";
  ASSERT_EQ(run_shell("bash " + kSource + "/scripts/make_dds_security.sh " + (cfg.dir / "sec").string()).status, 0);
  std::tie(result, why) = security_item(cfg.yaml());
  EXPECT_EQ(result, "PASS") << why;
  EXPECT_NE(why.find("identity 'remote' in " + (cfg.dir / "sec").string() + ":"), std::string::npos) << why;
}

// Issue 28, item 5: the DDS network is configuration; a missing interface or
// a peer that does not resolve is named by check and by the daemon's start-up.
TEST(CheckNetwork, AMissingInterfaceOrPeerIsNamedByCheckAndTheDaemon) {
  ConfigDir cfg;
  const foresight::test::CliRun good = run_shell("env -u CYCLONEDDS_URI timeout 120 " + kBin + "/foresight-remote check --sim --json --config " +
                                  cfg.yaml() + " --journal " + (cfg.dir / "j.db").string() + " 2>/dev/null");
  const auto report = nlohmann::json::parse(good.out, nullptr, false);
  ASSERT_FALSE(report.is_discarded()) << good.out;
  bool seen = false;
  for (const auto& i : report.at("items"))
    if (i.at("name") == "DDS network") {
      seen = true;
      EXPECT_EQ(i.at("result"), "PASS") << i.dump();
      EXPECT_EQ(i.at("why"), "interface lo, peers 127.0.0.1, multicast off (" + cfg.yaml() + ": controller.link.network)");
    }
  EXPECT_TRUE(seen) << good.out;

  cfg.replace("interface: lo ", "interface: nosuch0 ");
  cfg.replace("peers: \\[127.0.0.1\\]", "peers: [127.0.0.1, no-such-host.invalid]");
  const foresight::test::CliRun bad = run_shell("env -u CYCLONEDDS_URI timeout 120 " + kBin + "/foresight-remote check --sim --config " +
                                 cfg.yaml() + " 2>/dev/null");
  EXPECT_EQ(bad.status, 1) << bad.out;
  EXPECT_NE(bad.out.find("FAIL  DDS network      " + cfg.yaml() +
                         ": controller.link.network: interface 'nosuch0' does not exist (this machine has: lo"),
            std::string::npos)
      << bad.out;
  EXPECT_NE(bad.out.find("; peer 'no-such-host.invalid' does not resolve ("), std::string::npos) << bad.out;

  const std::string journal = (cfg.dir / "d.db").string();
  const foresight::test::CliRun daemon = run_shell("env -u CYCLONEDDS_URI timeout 60 " + kBin + "/foresight-remote --sim --config " +
                                    cfg.yaml() + " --journal " + journal + " 2>&1");
  EXPECT_EQ(daemon.status, 2) << daemon.out;
  EXPECT_NE(daemon.out.find("foresight-remote: error: " + cfg.yaml() +
                            ": controller.link.network: interface 'nosuch0' does not exist (this machine has: lo"),
            std::string::npos)
      << daemon.out;
  EXPECT_EQ(daemon.out.find("configuring"), std::string::npos) << daemon.out;
  EXPECT_FALSE(fs::exists(journal));
}

// ---- deployment files -----------------------------------------------------------------------------

TEST(Deploy, UnitPassesSystemdAnalyzeVerify) {
  if (run_shell("command -v systemd-analyze").status != 0) GTEST_SKIP() << "systemd-analyze is not installed";
  const std::string unit = kSource + "/remote_site/deploy/systemd/foresight-remote.service";
  std::string text = slurp(unit);
  ASSERT_FALSE(text.empty());
  for (const char* key : {"Type=notify", "WatchdogSec=", "LimitRTPRIO=", "LimitMEMLOCK=infinity", "Restart=on-failure",
                          "NotifyAccess=main", "ExecStart=/usr/bin/foresight-remote"})
    EXPECT_NE(text.find(key), std::string::npos) << key;
  // verify checks that ExecStart exists: point it at the built daemon.
  const fs::path dir = foresight::test::temp_path("_unit");
  fs::create_directories(dir);
  text = std::regex_replace(text, std::regex("/usr/bin/foresight-remote"), kBin + "/foresight-remote");
  std::ofstream(dir / "foresight-remote.service") << text;
  const foresight::test::CliRun v = run_shell("systemd-analyze verify " + (dir / "foresight-remote.service").string());
  EXPECT_EQ(v.status, 0) << v.out;
  EXPECT_EQ(v.out.find("foresight-remote.service:"), std::string::npos) << v.out;  // no complaint about our unit

  // The CAN bring-up unit, its script at the source path.
  std::string can = slurp(kSource + "/remote_site/deploy/can/foresight-can.service");
  ASSERT_NE(can.find("ExecStart=/usr/lib/foresight/can-setup.sh"), std::string::npos);
  can = std::regex_replace(can, std::regex("/usr/lib/foresight/can-setup.sh"),
                           kSource + "/remote_site/deploy/can/can-setup.sh");
  std::ofstream(dir / "foresight-can.service") << can;
  const foresight::test::CliRun c = run_shell("systemd-analyze verify " + (dir / "foresight-can.service").string());
  EXPECT_EQ(c.status, 0) << c.out;
  EXPECT_EQ(c.out.find("foresight-can.service:"), std::string::npos) << c.out;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

TEST(Deploy, CanSetupDryRun) {
  const foresight::test::CliRun r = run_shell("bash " + kSource + "/remote_site/deploy/can/can-setup.sh --dry-run can0 can1");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("ip link set can0 down"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ip link set can0 type can bitrate 1000000 restart-ms 100"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ip link set can0 txqueuelen 1000"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ip link set can1 up"), std::string::npos) << r.out;
  const foresight::test::CliRun bad = run_shell("bash " + kSource + "/remote_site/deploy/can/can-setup.sh --dry-run --bitrate 7 can0");
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE(bad.out.find("bit rate 7 is not one of"), std::string::npos) << bad.out;
}

TEST(Deploy, PackagesHoldWhatTheyShould) {
  const std::string build = fs::path(kBin).parent_path().string();
  for (const char* b : {"foresight-remote", "foresight"})
    if (!fs::exists(kBin + "/" + b)) GTEST_SKIP() << kBin << "/" << b << " is not built (build every target first)";
  if (run_shell("command -v cpack && command -v dpkg-deb && command -v dpkg-shlibdeps").status != 0)
    GTEST_SKIP() << "cpack, dpkg-deb or dpkg-shlibdeps missing";
  const foresight::test::CliRun r = run_shell("timeout 170 bash " + kSource + "/remote_site/deploy/test_packages.sh " + build);
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("packages: ok"), std::string::npos) << r.out;
}

// The daemon speaks systemd's notify protocol: a fake NOTIFY_SOCKET (what
// systemd gives a Type=notify service) receives READY=1 after the ready line,
// WATCHDOG=1 every WatchdogSec/2 while the loop and the supervisor progress,
// and STOPPING=1 at SIGTERM.
TEST(Deploy, DaemonNotifiesReadyWatchdogStopping) {
  const std::string sock_path = foresight::test::temp_path(".notify");
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  std::snprintf(a.sun_path, sizeof a.sun_path, "%s", sock_path.c_str());
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);

  std::vector<std::string> messages;
  const auto wait_for = [&](const std::string& what, int count, double timeout_s) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    const auto seen = [&] {
      int n = 0;
      for (const auto& m : messages) n += m.find(what) != std::string::npos ? 1 : 0;
      return n;
    };
    while (seen() < count && std::chrono::steady_clock::now() < deadline) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 100) > 0) {
        char buf[1024];
        const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        if (n > 0) messages.emplace_back(buf, static_cast<std::size_t>(n));
      }
    }
    return seen() >= count;
  };

  ::setenv("NOTIFY_SOCKET", sock_path.c_str(), 1);
  ::setenv("WATCHDOG_USEC", "2000000", 1);  // 2 s: pinged every 1 s
  foresight::test::RemoteProcess::Options o;
  o.domain = static_cast<int>(foresight::protocol::unique_test_domain());
  {
    foresight::test::RemoteProcess daemon(o);
    ::unsetenv("NOTIFY_SOCKET");
    ::unsetenv("WATCHDOG_USEC");
    ASSERT_TRUE(daemon.ready()) << daemon.log();
    EXPECT_TRUE(wait_for("READY=1", 1, 10.0)) << daemon.log();
    EXPECT_TRUE(wait_for("WATCHDOG=1", 3, 15.0)) << daemon.log();
    EXPECT_EQ(daemon.stop(SIGTERM, 30.0), 0) << daemon.log();
    EXPECT_TRUE(wait_for("STOPPING=1", 1, 5.0)) << daemon.log();
    EXPECT_EQ(daemon.log().find("watchdog: no progress"), std::string::npos) << daemon.log();
  }
  ::close(fd);
  std::remove(sock_path.c_str());
  ASSERT_FALSE(messages.empty());
  EXPECT_NE(messages.front().find("READY=1"), std::string::npos) << messages.front();
  EXPECT_NE(messages.back().find("STOPPING=1"), std::string::npos) << messages.back();
}

// Restart=on-failure after a crash: the daemon comes back holding. The second
// run says the first did not shut down cleanly, and its telemetry shows the
// controller Disabled (drives off) until the ground sends RECOVER.
TEST(Deploy, RestartAfterCrashComesUpHolding) {
  const std::string journal = foresight::test::temp_path(".db");
  const auto read_journal = [&] {
    const foresight::test::CliRun j = run_shell(kBin + "/foresight-remote journal --json --db " + journal + " 2>/dev/null");
    return j.status == 0 ? nlohmann::json::parse(j.out) : nlohmann::json::object();
  };
  foresight::test::RemoteProcess::Options o;
  o.domain = static_cast<int>(foresight::protocol::unique_test_domain());
  o.journal = journal;
  {
    foresight::test::RemoteProcess first(o);
    ASSERT_TRUE(first.ready()) << first.log();
    EXPECT_EQ(first.stop(SIGKILL, 10.0), 128 + SIGKILL);
  }
  const auto count_after_crash = read_journal().value("telemetry_count", 0);
  foresight::test::RemoteProcess second(o);
  ASSERT_TRUE(second.ready()) << second.log();
  EXPECT_NE(second.log().find("the previous run did not shut down cleanly; coming up holding, drives disabled"),
            std::string::npos)
      << second.log();
  // Telemetry of the second run reaches the journal (10 rows/s): poll with a deadline.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  int rows = 0;
  while (std::chrono::steady_clock::now() < deadline && (rows = read_journal().value("telemetry_count", 0)) <=
                                                            count_after_crash + 2)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_GT(rows, count_after_crash + 2);
  EXPECT_EQ(second.stop(SIGTERM, 30.0), 0) << second.log();
  const auto j = read_journal();
  ASSERT_TRUE(j.contains("telemetry_last")) << j.dump();
  EXPECT_EQ(j["telemetry_last"].value("mode", -1), 0) << j.dump();  // ControllerMode::Disabled
  int starts = 0;
  for (const auto& e : j["events"]) starts += e.value("kind", "") == "start" ? 1 : 0;
  EXPECT_EQ(starts, 2);
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((journal + suffix).c_str());
}
