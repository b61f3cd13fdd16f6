// The operator's link commands and `foresight run` through the executable,
// with no remote: every bad input exits 2 with its exact message before
// anything connects; a missing remote exits 1 naming the domain; a dry run of
// the changeout script plans every motion of the paper's steps 3-17.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <sys/wait.h>

#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/test/cli.hpp"

using namespace foresight;
using foresight::test::run_foresight;
using foresight::test::temp_path;
using foresight::test::write_temp_file;

namespace {

const std::string kChangeout = std::string(FORESIGHT_CONFIG_DIR) + "/scripts/oru_changeout.task";

void expect_bad_input(const std::string& args, const std::string& message) {
  const auto r = run_foresight(args + " </dev/null");
  EXPECT_EQ(r.status, 2) << args << "\n" << r.err;
  EXPECT_EQ(r.err, message) << args;
  EXPECT_EQ(r.out, "") << args;
}

}  // namespace

TEST(LinkCli, BadArgumentsExit2BeforeConnecting) {
  expect_bad_input("invoke screw", "foresight invoke: error: unknown algorithm 'screw' (algorithms: guarded_move, "
                                   "insert, latch, unlatch, loosen, tighten, pull_out, tare, identify_payload)\n");
  expect_bad_input("invoke insert depth_m=6cm",
                   "foresight invoke: error: parameter depth_m: '6cm' is not a finite number\n");
  expect_bad_input("invoke insert depth", "foresight invoke: error: parameter 'depth' is not NAME=VALUE\n");
  expect_bad_input("goto", "foresight goto: error: give exactly one of --joints, --joints-deg or --tag\n");
  expect_bad_input("goto --joints 0,0 --tag stow",
                   "foresight goto: error: give exactly one of --joints, --joints-deg or --tag\n");
  expect_bad_input("goto --joints 0,0.1", "foresight goto: error: --joints has 2 values but the arm has 7 joints\n");
  expect_bad_input("goto --tag nowhere",
                   "foresight goto: error: --tag: unknown tag 'nowhere' (tags of oru: approach_20cm, hole_entrance, "
                   "insert_start, pulled_out_5cm, stow, tool_inserted, withdrawn_15cm)\n");
  expect_bad_input("send /nonexistent/traj.csv --run", "foresight send: error: /nonexistent/traj.csv: cannot open trajectory file\n");
}

TEST(LinkCli, OptionChecksExit2) {
  for (const std::string args : {"abort --category 3", "request everything", "status --domain 300",
                                 "watch --period 0", "send x.csv --upload-timeout -1"}) {
    const auto r = run_foresight(args);
    EXPECT_EQ(r.status, 2) << args << "\n" << r.err;
    EXPECT_FALSE(r.err.empty()) << args;
  }
  const std::string traj = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,-0.5,0,0,0\n1,0,0,0,-0.5,0,0,0\n");
  expect_bad_input("send " + traj + " --compliant", "foresight send: error: --compliant needs --run\n");
}

// One parser of FORESIGHT_DDS_DOMAIN on both sides: the ground and the
// daemon refuse the same values with the same words, exit 2 (the daemon used
// to take 'abc' as 0, '201x' as 201 and '-3' as 4294967293).
TEST(LinkCli, DomainFromTheEnvironmentIsChecked) {
  const std::string bin = std::string(FORESIGHT_BIN_DIR) + "/foresight";
  const std::string remote = std::string(FORESIGHT_BIN_DIR) + "/foresight-remote";
  const std::string err = temp_path(".err");
  for (const std::string bad : {"abc", "201x", "-3", "233", " 5", "+5"}) {
    // Set the variable for the child only.
    int st = std::system(("FORESIGHT_DDS_DOMAIN='" + bad + "' " + bin + " status 2>" + err + " >/dev/null").c_str());
    EXPECT_EQ(WEXITSTATUS(st), 2) << bad;
    EXPECT_EQ(foresight::test::read_file(err),
              "foresight status: error: FORESIGHT_DDS_DOMAIN: '" + bad + "' is not a DDS domain id (0-232)\n");
    st = std::system(("FORESIGHT_DDS_DOMAIN='" + bad + "' " + remote + " --sim 2>" + err + " >/dev/null").c_str());
    EXPECT_EQ(WEXITSTATUS(st), 2) << bad;
    EXPECT_EQ(foresight::test::read_file(err),
              "foresight-remote: error: FORESIGHT_DDS_DOMAIN: '" + bad + "' is not a DDS domain id (0-232)\n");
  }
}

TEST(LinkCli, NoRemoteExits1NamingTheDomain) {
  protocol::use_loopback_if_unconfigured();  // the child inherits CYCLONEDDS_URI
  const int domain = static_cast<int>(protocol::unique_test_domain());
  for (const std::string cmd : {"status", "abort", "request joints", "take-control", "watch --count 1"}) {
    const auto r = run_foresight(cmd + " --domain " + std::to_string(domain) + " --connect-timeout 0.5");
    EXPECT_EQ(r.status, 1) << cmd << "\n" << r.err;
    const std::string name = cmd.substr(0, cmd.find(' '));
    EXPECT_EQ(r.err, "foresight " + name + ": error: no remote answered on DDS domain " + std::to_string(domain) +
                         " within 0.5 s (is foresight-remote running? --domain / FORESIGHT_DDS_DOMAIN)\n")
        << cmd;
  }
}

// Issue 28, item 5: the daemon and the CLI in two terminals of one machine,
// with no CYCLONEDDS_URI (nor any other variable): both take the network of
// their configuration (loopback, unicast discovery), so they find each other
// on a host whose multicast does not loop back.
TEST(LinkCli, DaemonAndCliFindEachOtherWithoutAnyEnvironment) {
  const int domain = static_cast<int>(protocol::unique_test_domain());
  const std::string d = std::to_string(domain);
  const std::string journal = temp_path(".db"), log = temp_path(".log");
  const std::string bin = std::string(FORESIGHT_BIN_DIR);
  const std::string clean = "env -u CYCLONEDDS_URI -u FORESIGHT_DDS_DOMAIN -u FORESIGHT_DDS_SECURITY ";
  // The daemon in the background, ended by the test (at most 120 s by itself).
  ASSERT_EQ(std::system((clean + "timeout 120 " + bin + "/foresight-remote --sim --domain " + d + " --journal " +
                         journal + " >/dev/null 2>" + log + " & echo $! > " + log + ".pid")
                            .c_str()),
            0);
  const std::string err = temp_path(".err");
  const std::string out = temp_path(".out");
  const int st = std::system((clean + "timeout 120 " + bin + "/foresight status --domain " + d +
                              " --connect-timeout 60 --json >" + out + " 2>" + err)
                                 .c_str());
  std::system(("kill $(cat " + log + ".pid) 2>/dev/null").c_str());
  EXPECT_EQ(WEXITSTATUS(st), 0) << foresight::test::read_file(err) << "\ndaemon:\n" << foresight::test::read_file(log);
  const auto status = nlohmann::json::parse(foresight::test::read_file(out), nullptr, false);
  ASSERT_FALSE(status.is_discarded()) << foresight::test::read_file(out);
  EXPECT_TRUE(status["remote_alive"].get<bool>());
  EXPECT_EQ(status["link_security"], (nlohmann::json{{"dds_security", false}, {"identity", ""}}));
  EXPECT_NE(foresight::test::read_file(log).find("DDS network: interface lo, peers 127.0.0.1, multicast off"),
            std::string::npos)
      << foresight::test::read_file(log);
}

// A network the configuration names but this machine lacks: the CLI names
// the file and the problem, exit 2, before any DDS.
TEST(LinkCli, AMissingInterfaceInGroundYamlIsNamed) {
  const std::string dir = temp_path("_cfg");
  std::filesystem::create_directories(dir);
  std::ofstream(dir + "/ground.yaml") << "link:\n  network:\n    interface: nosuch0\n";
  const std::string err = temp_path(".err");
  const int st = std::system(("env -u CYCLONEDDS_URI FORESIGHT_CONFIG_DIR=" + dir + " " +
                              std::string(FORESIGHT_BIN_DIR) + "/foresight status --connect-timeout 0.5 2>" + err)
                                 .c_str());
  EXPECT_EQ(WEXITSTATUS(st), 2);
  const std::string text = foresight::test::read_file(err);
  EXPECT_EQ(text.rfind("foresight status: error: " + dir +
                           "/ground.yaml: link.network: interface 'nosuch0' does not exist (this machine has: lo",
                       0),
            0u)
      << text;
  std::filesystem::remove_all(dir);
}

// Issue 28's bad input: an expired certificate and an identity whose
// permissions do not grant what the daemon needs are named by check, by the
// daemon's start-up and by the CLI, with a non-zero exit.
TEST(LinkCli, ExpiredAndUngrantedIdentitiesAreNamedEverywhere) {
  if (std::system("command -v openssl >/dev/null 2>&1") != 0) GTEST_SKIP() << "openssl is not installed";
  const std::string dir = temp_path("_sec");
  ASSERT_EQ(std::system(("bash " FORESIGHT_SOURCE_DIR "/scripts/make_dds_security.sh " + dir + " >/dev/null 2>&1").c_str()), 0);
  // An identity signed by the CA whose certificate expired yesterday.
  const std::string old = dir + "/identities/old";
  std::filesystem::create_directories(old);
  ASSERT_EQ(std::system(("openssl ecparam -name prime256v1 -genkey -noout -out " + old + "/key.pem 2>/dev/null && "
                         "openssl req -new -key " + old + "/key.pem -subj /C=NL/O=Foresight/CN=old -out " + old +
                         "/req.csr 2>/dev/null && openssl x509 -req -in " + old + "/req.csr -CA " + dir + "/ca.pem -CAkey " +
                         dir + "/ca_key.pem -CAcreateserial -sha256 -days -1 -out " + old + "/cert.pem >/dev/null 2>&1")
                            .c_str()),
            0);
  const std::string expired = "DDS Security: " + old + "/cert.pem: does not verify against " + dir +
                              "/ca.pem: certificate has expired";
  const std::string j = temp_path(".db");
  auto check = foresight::test::run_program("foresight-remote", "check --sim --journal " + j + " --security " + dir + " --identity old");
  EXPECT_EQ(check.status, 1);
  EXPECT_NE(check.out.find("FAIL  DDS security     " + expired), std::string::npos) << check.out;
  auto daemon = foresight::test::run_program("foresight-remote", "--sim --journal " + j + " --security " + dir + " --identity old");
  EXPECT_EQ(daemon.status, 2);
  EXPECT_NE(daemon.err.find("foresight-remote: error: --security: " + expired + "\n"), std::string::npos) << daemon.err;
  auto cli = run_foresight("status --security " + dir + " --identity old --connect-timeout 0.5");
  EXPECT_EQ(cli.status, 2);
  EXPECT_EQ(cli.err, "foresight status: error: --security: " + expired + "\n");

  // A valid identity whose grants are a commander's, not the remote's.
  check = foresight::test::run_program("foresight-remote", "check --sim --journal " + j + " --security " + dir + " --identity ground");
  EXPECT_EQ(check.status, 1);
  EXPECT_NE(check.out.find("FAIL  DDS security     identity 'ground' in " + dir +
                           ": its permissions (permissions.p7s) do not cover the daemon's link: create writer on "
                           "foresight/command/ack: Not Allowed By Security"),
            std::string::npos)
      << check.out;
  protocol::use_loopback_if_unconfigured();
  const std::string d = std::to_string(protocol::unique_test_domain());
  daemon = foresight::test::run_program("foresight-remote", "--sim --domain " + d + " --journal " + j + " --security " + dir +
                                               " --identity ground");
  EXPECT_EQ(daemon.status, 2);
  EXPECT_NE(daemon.err.find("foresight-remote: error: " + dir + "/permissions.p7s: identity 'ground' is not granted "
                            "what the daemon's link needs: create writer on foresight/command/ack: Not Allowed By "
                            "Security\n"),
            std::string::npos)
      << daemon.err;
  std::filesystem::remove_all(dir);
}

TEST(LinkCli, SendRefusesATrajectoryTheRemoteWouldReject) {
  // Joint 1 jumps 1 rad in 10 ms: far over its velocity limit.
  const std::string traj = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,-0.5,0,0,0\n0.01,1,0,0,-0.5,0,0,0\n");
  const auto r = run_foresight("send " + traj + " --connect-timeout 0.5");
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("violation(s); not sent (the remote would reject this trajectory)"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("no remote answered"), std::string::npos) << "it must refuse before connecting";
}

TEST(RunCli, ScriptErrorsNameLineAndColumn) {
  const std::string bad = write_temp_file("VIDEO side\n\nTRAJECTORY to=approach_20cm,hole_entance:linear\n", ".task");
  expect_bad_input("run " + bad + " --auto",
                   "foresight run: error: " + bad +
                       ":3:29: unknown tag 'hole_entance' (tags: approach_20cm, hole_entrance, insert_start, pulled_out_5cm, stow, "
                       "tool_inserted, withdrawn_15cm)\n");
  const std::string syntax = write_temp_file("GRAPHICS hidden\nINVOKE_ALGORITHM insert depth_m=6cm\n", ".task");
  expect_bad_input("run " + syntax + " --auto",
                   "foresight run: error: " + syntax + ":2:33: INVOKE_ALGORITHM depth_m: '6cm' is not a finite number\n");
  expect_bad_input("run /nonexistent/x.task --auto", "foresight run: error: /nonexistent/x.task: cannot open script\n");
  expect_bad_input("run " + kChangeout, "foresight run: error: stdin is not a terminal: give --auto or --keys\n");
  expect_bad_input("run " + kChangeout + " --keys step,halt",
                   "foresight run: error: --keys: 'halt' is not a key (step, auto, cancel, abort, retry, skip, quit, wait[:N])\n");
  expect_bad_input("run " + kChangeout + " --keys step,wait:0",
                   "foresight run: error: --keys: 'wait:0': wait:N needs N in 1..100000\n");
  expect_bad_input("run " + kChangeout + " --auto --dry-run",
                   "foresight run: error: --dry-run needs --joints or --joints-deg\n");
}

TEST(RunCli, DryRunPlansTheWholeChangeoutFromTheFirstMotion) {
  // The arm's start: the pose the simulated operator's clicks end at (as the demo).
  const std::string q_file = temp_path(".txt");
  const auto clicks = run_foresight("synth-clicks --joints-out " + q_file + " --calibration-out " +
                                    temp_path(".csv") + " --object-out " + temp_path(".csv"));
  ASSERT_EQ(clicks.status, 0) << clicks.err;
  std::string q = foresight::test::read_file(q_file);
  while (!q.empty() && (q.back() == '\n' || q.back() == ' ')) q.pop_back();
  const std::string work = temp_path("_run");
  // From the first TAG line (after CALIBRATE and LOCALIZE), the ORU at its true pose.
  const std::string script_text = foresight::test::read_file(kChangeout);
  const auto tag_at = script_text.find("\nTAG ");
  ASSERT_NE(tag_at, std::string::npos);
  const auto tag_line = 2 + std::count(script_text.begin(), script_text.begin() + static_cast<long>(tag_at), '\n');
  const auto r = run_foresight("run " + kChangeout + " --auto --dry-run --no-preview --object-pose scene --json" +
                               " --joints " + q + " --work " + work + " --from-line " + std::to_string(tag_line));
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["end"], "finished");
  int completed = 0, skipped = 0, trajectories = 0;
  for (const auto& s : j["steps"]) {
    if (s["outcome"] == "completed") ++completed;
    if (s["outcome"] == "skipped") ++skipped;
    if (s["command"].get<std::string>().rfind("TRAJECTORY", 0) == 0) ++trajectories;
  }
  EXPECT_EQ(skipped, 6);  // OBJECT VIDEO GRAPHICS FRAME CALIBRATE LOCALIZE
  EXPECT_EQ(completed, static_cast<int>(j["steps"].size()) - 6);
  EXPECT_GE(trajectories, 4);  // approach, hole entrance, stow, ..., start
  // `GOTO_JOINT start` brings the simulated arm back to where it began.
  const auto q_end = j["final_q_rad"].get<std::vector<double>>();
  ASSERT_EQ(q_end.size(), 7u);
  std::vector<double> q0;
  std::stringstream ss(q);
  std::string item;
  while (std::getline(ss, item, ',')) q0.push_back(std::stod(item));
  ASSERT_EQ(q0.size(), 7u);
  for (int i = 0; i < 7; ++i) EXPECT_NEAR(q_end[i], q0[i], 1e-9);
  // Every motion was written and journaled with its hash.
  const std::string journal = foresight::test::read_file(work + "/run.jsonl");
  EXPECT_NE(journal.find("\"sha256\""), std::string::npos);
}
