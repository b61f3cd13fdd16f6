// `foresight run SCRIPT` against the live daemon (`foresight-remote --sim` in
// its own process, DDS on loopback): step from the keyboard (the run on a
// pseudo-terminal, keys typed into it) and from flags (--keys); cancel of the
// current command (the remote reports CANCELED, the arm holds, the script goes
// on from that step); abort of the whole script (ABORT sent, the arm stops,
// nothing further is sent); bad input mid-script (an unreachable tag, a remote
// rejection) stops at that command with its message and the arm holding, and
// the script goes on after the fix with --from-line; an unknown algorithm is
// refused before anything is sent.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <map>
#include <sstream>
#include <thread>

#include "foresight/ground_link/ground_link.hpp"
#include "foresight/test/cli.hpp"
#include "hil_support.hpp"

using namespace foresight;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

/// `foresight <args>` on a pseudo-terminal: its stdin is a keyboard.
class PtyRun {
 public:
  explicit PtyRun(const std::vector<std::string>& args) {
    std::vector<std::string> argv = {std::string(FORESIGHT_BIN_DIR) + "/foresight"};
    argv.insert(argv.end(), args.begin(), args.end());
    pid_ = forkpty(&master_, nullptr, nullptr, nullptr);
    if (pid_ == 0) {
      std::vector<char*> a;
      for (auto& s : argv) a.push_back(s.data());
      a.push_back(nullptr);
      execv(a[0], a.data());
      _exit(127);
    }
  }
  ~PtyRun() {
    if (pid_ > 0 && !reaped_) {
      kill(pid_, SIGTERM);
      if (wait_exit(20.0) == -2) {
        kill(pid_, SIGKILL);
        wait_exit(5.0);
      }
    }
    if (master_ >= 0) close(master_);
  }
  bool started() const { return pid_ > 0 && master_ >= 0; }
  void press(char c) {
    mark_ = out_.size();
    ASSERT_EQ(write(master_, &c, 1), 1);
  }
  /// Waits for `needle` in what the run printed since the last key press.
  bool wait_for(const std::string& needle, double timeout_s) {
    const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
    while (Clock::now() < deadline) {
      if (out_.find(needle, mark_) != std::string::npos) return true;
      if (!read_some(100)) return out_.find(needle, mark_) != std::string::npos;
    }
    return false;
  }
  /// The exit status (-2: still running at the deadline).
  int wait_exit(double timeout_s) {
    const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
    while (Clock::now() < deadline) {
      read_some(20);
      int st = 0;
      if (waitpid(pid_, &st, WNOHANG) == pid_) {
        reaped_ = true;
        while (read_some(20)) {
        }
        return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
      }
    }
    return -2;
  }
  const std::string& output() const { return out_; }
  /// For a failure message: the runner's own lines (indented) and the last
  /// screen, without the redraws in between (the whole output of a long run
  /// is cut in the middle by CI's log, where the cause is).
  std::string brief() const {
    std::string said, line;
    std::istringstream in(out_);
    while (std::getline(in, line))
      if (line.rfind("    ", 0) == 0) said += line + "\n";
    const auto last = out_.rfind("\x1b[H\x1b[J");
    return "the runner said:\n" + said + "the last screen:\n" + (last == std::string::npos ? out_ : out_.substr(last + 6));
  }

 private:
  /// False once the terminal closed (the run exited).
  bool read_some(int ms) {
    pollfd p{master_, POLLIN, 0};
    if (poll(&p, 1, ms) <= 0) return true;
    char buf[4096];
    const ssize_t n = read(master_, buf, sizeof buf);
    if (n <= 0) return false;
    out_.append(buf, static_cast<std::size_t>(n));
    return true;
  }
  pid_t pid_ = -1;
  int master_ = -1;
  bool reaped_ = false;
  std::string out_;
  std::size_t mark_ = 0;
};

/// The ground link (ground_) only watches the joints; `foresight run` commands.
class RunScript : public test::DaemonTest {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(DaemonTest::SetUp());
    work_ = test::temp_path("_run");
    std::filesystem::create_directories(work_);
  }
  void TearDown() override {
    DaemonTest::TearDown();
    std::filesystem::remove_all(work_);
  }

  std::string script(const std::string& name, const std::string& text) {
    const std::string p = work_ + "/" + name;
    std::ofstream(p) << text;
    return p;
  }
  /// The options every run here shares: this daemon, the ORU at its true pose,
  /// no preview rendering (the previews have their own tests; they take minutes).
  std::vector<std::string> common_args() const {
    return {"--domain", std::to_string(domain_), "--work", work_, "--object-pose", "scene", "--no-preview", "--recover"};
  }
  std::string args_text(const std::string& script_path, const std::string& extra) const {
    std::string s = "run " + script_path;
    for (const auto& a : common_args()) s += " " + a;
    return s + " " + extra;
  }

  Eigen::VectorXd joints() {
    for (int i = 0; i < 500; ++i) {
      if (auto js = ground_->joint_state(); js && js->value.q_rad.size() == 7)
        return Eigen::Map<const Eigen::VectorXd>(js->value.q_rad.data(), 7);
      std::this_thread::sleep_for(20ms);
    }
    ADD_FAILURE() << "no joint report";
    return Eigen::VectorXd::Zero(7);
  }
  /// True once the arm has not moved more than 1e-4 rad over 0.5 s (within 15 s).
  bool arm_holds(Eigen::VectorXd* q_held = nullptr) {
    const auto deadline = Clock::now() + 15s;
    Eigen::VectorXd ref = joints();
    auto since = Clock::now();
    while (Clock::now() < deadline) {
      std::this_thread::sleep_for(50ms);
      const Eigen::VectorXd q = joints();
      if ((q - ref).cwiseAbs().maxCoeff() > 1e-4) {
        ref = q;
        since = Clock::now();
      } else if (Clock::now() - since >= 500ms) {
        if (q_held) *q_held = q;
        return true;
      }
    }
    return false;
  }

  /// The daemon's journal: every command it received, in order.
  nlohmann::json remote_commands() {
    const auto j = journal_json();
    if (!j.contains("commands")) {
      ADD_FAILURE() << "journal without commands: " << j.dump();
      return nlohmann::json::array();
    }
    return j["commands"];
  }
  /// Every command the remote received, once each in order of arrival (the
  /// journal has a row per state): its kind and its last state.
  std::vector<std::pair<std::string, std::string>> received() {
    std::vector<std::pair<std::string, std::string>> out;
    std::map<std::pair<std::string, std::uint64_t>, std::size_t> index;  // (session, id) -> position
    for (const auto& c : remote_commands()) {
      const auto key = std::make_pair(c["session_id"].dump(), c["command_id"].get<std::uint64_t>());
      const auto [it, fresh] = index.emplace(key, out.size());
      if (fresh) out.emplace_back(c["kind"].get<std::string>(), "");
      out[it->second].second = c["state"].get<std::string>();
    }
    return out;
  }
  std::vector<std::string> received_kinds() {
    std::vector<std::string> kinds;
    for (const auto& [k, st] : received()) kinds.push_back(k);
    return kinds;
  }
  /// The final states of the commands of one kind, in order.
  std::vector<std::string> states_of(const std::string& kind) {
    std::vector<std::string> s;
    for (const auto& [k, st] : received())
      if (k == kind) s.push_back(st);
    return s;
  }

  std::string work_;
};

// Two motions and a request; the first motion is long enough to cancel.
const char* kMotions =
    "REQUEST status                 # line 1\n"
    "TRAJECTORY to=approach_20cm    # line 2: a few seconds' motion\n"
    "TRAJECTORY to=start            # line 3: back where the run began\n";

TEST_F(RunScript, StepCancelAndGoOnFromTheKeyboard) {
  const std::string s = script("motions.task", kMotions);
  std::vector<std::string> args = {"run", s};
  for (const auto& a : common_args()) args.push_back(a);
  PtyRun run(args);
  ASSERT_TRUE(run.started());
  ASSERT_TRUE(run.wait_for("keys: s step", 60.0)) << run.brief();
  const Eigen::VectorXd q_start = joints();

  run.press('s');  // line 1 only: step mode stops before line 2
  ASSERT_TRUE(run.wait_for("[x]    1  REQUEST", 30.0)) << run.brief();
  ASSERT_TRUE(run.wait_for("> [ ]    2  TRAJECTORY", 5.0)) << run.brief();
  ASSERT_TRUE(run.wait_for("step | ready", 5.0)) << run.brief();

  run.press('s');  // line 2 starts ...
  ASSERT_TRUE(run.wait_for("> [~]    2  TRAJECTORY", 60.0)) << run.brief();
  // ... and moves the arm, then the operator cancels it.
  const auto deadline = Clock::now() + 30s;
  while ((joints() - q_start).cwiseAbs().maxCoeff() < 0.01 && Clock::now() < deadline) std::this_thread::sleep_for(20ms);
  ASSERT_GT((joints() - q_start).cwiseAbs().maxCoeff(), 0.01) << "the arm did not start moving\n" << run.brief();
  run.press('c');
  ASSERT_TRUE(run.wait_for("> [c]    2  TRAJECTORY", 30.0)) << run.brief();
  EXPECT_TRUE(run.wait_for("stopped", 5.0)) << run.brief();
  // The update step says the motion ended short, not that the joints "differ".
  EXPECT_NE(run.output().find("update: the motion ended short of its planned end: the arm stopped "),
            std::string::npos)
      << run.brief();
  Eigen::VectorXd q_held;
  ASSERT_TRUE(arm_holds(&q_held)) << "the arm did not come to rest after the cancel";
  EXPECT_EQ(states_of("TRAJECTORY").back(), "CANCELED");

  run.press('r');  // retry the same step: still in step mode, so it waits for s
  ASSERT_TRUE(run.wait_for("> [ ]    2  TRAJECTORY", 10.0)) << run.brief();
  run.press('s');
  ASSERT_TRUE(run.wait_for("[x]    2  TRAJECTORY", 120.0)) << run.brief();
  run.press('s');
  ASSERT_TRUE(run.wait_for("[x]    3  TRAJECTORY", 120.0)) << run.brief();
  EXPECT_EQ(run.wait_exit(30.0), 0) << run.brief();
  EXPECT_NE(run.output().find(": finished"), std::string::npos) << run.brief();
  // Back at the start (TRAJECTORY to=start), within the remote's tracking.
  ASSERT_TRUE(arm_holds());
  EXPECT_LT((joints() - q_start).cwiseAbs().maxCoeff(), 0.01);
  const auto t = states_of("TRAJECTORY");
  ASSERT_EQ(t.size(), 3u) << "cancelled, retried, back to start";
  EXPECT_EQ(t[0], "CANCELED");
  EXPECT_EQ(t[1], "COMPLETED");
  EXPECT_EQ(t[2], "COMPLETED");
}

TEST_F(RunScript, CancelFromFlagsThenRetryAndAuto) {
  const std::string s = script("motions.task", kMotions);
  const auto r = test::run_foresight(args_text(s, "--keys step,step,wait:10,cancel,retry,auto --json"));
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["end"], "finished");
  for (const auto& step : j["steps"]) EXPECT_EQ(step["outcome"], "completed") << step.dump();
  // The run's own journal: line 2 canceled, then completed on the retry.
  std::vector<std::string> line2;
  std::ifstream in(work_ + "/run.jsonl");
  for (std::string l; std::getline(in, l);) {
    const auto e = nlohmann::json::parse(l);
    if (e["line"] == 2) line2.push_back(e["outcome"].get<std::string>());
  }
  EXPECT_EQ(line2, (std::vector<std::string>{"canceled", "completed"}));
  const auto t = states_of("TRAJECTORY");
  ASSERT_EQ(t.size(), 3u);
  EXPECT_EQ(t[0], "CANCELED");
  EXPECT_EQ(t[1], "COMPLETED");
}

TEST_F(RunScript, AbortStopsTheArmAndSendsNothingFurther) {
  const std::string s = script("motions.task", kMotions);
  const Eigen::VectorXd q_start = joints();
  const auto r = test::run_foresight(args_text(s, "--keys step,step,wait:10,abort --json"));
  EXPECT_EQ(r.status, 1) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["end"], "aborted");
  EXPECT_EQ(j["stop_reason"], "aborted by the operator at line 2");
  EXPECT_EQ(j["steps"][0]["outcome"], "completed");
  EXPECT_EQ(j["steps"][1]["outcome"], "canceled");
  EXPECT_EQ(j["steps"][2]["outcome"], "pending");
  Eigen::VectorXd q_held;
  ASSERT_TRUE(arm_holds(&q_held));
  EXPECT_GT((q_held - q_start).cwiseAbs().maxCoeff(), 0.005) << "the motion had started";
  // The remote saw the motion canceled by an ABORT, and after it nothing but
  // the control being given back.
  EXPECT_EQ(states_of("TRAJECTORY"), (std::vector<std::string>{"CANCELED"}));
  const auto kinds = received_kinds();
  const auto it = std::find(kinds.begin(), kinds.end(), "TRAJECTORY");
  ASSERT_NE(it, kinds.end());
  const std::vector<std::string> after(it + 1, kinds.end());
  EXPECT_EQ(after, (std::vector<std::string>{"ABORT", "RELEASE_CONTROL"})) << r.out;
  // Still holding a while later: nothing else was sent.
  ASSERT_TRUE(arm_holds());
  EXPECT_LT((joints() - q_held).cwiseAbs().maxCoeff(), 1e-4);
}

TEST_F(RunScript, AnUnreachableTagStopsThereAndTheScriptGoesOnAfterTheFix) {
  // The object "localized" 5 m away: its tags are out of the arm's reach.
  const std::string far = work_ + "/far.json";
  std::ofstream(far) << R"({"base_T_object": [[1,0,0,5],[0,1,0,0],[0,0,1,0.5],[0,0,0,1]]})";
  const std::string s = script("far.task",
                               "REQUEST status\n"
                               "OBJECT oru pose=" + far + "\n"
                               "TRAJECTORY to=approach_20cm\n"
                               "REQUEST joints\n");
  const Eigen::VectorXd q_start = joints();
  auto r = test::run_foresight(args_text(s, "--auto"));
  EXPECT_EQ(r.status, 1) << r.err << r.out;
  EXPECT_NE(r.out.find("line 3 failed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("not sent: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("go on after a fix: foresight run " + s + " --from-line 3"), std::string::npos) << r.out;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n') > 0, true);
  ASSERT_TRUE(arm_holds());
  EXPECT_LT((joints() - q_start).cwiseAbs().maxCoeff(), 1e-4) << "nothing moved";
  auto kinds = received_kinds();
  EXPECT_EQ(std::count(kinds.begin(), kinds.end(), "TRAJECTORY"), 0);
  EXPECT_EQ(std::count(kinds.begin(), kinds.end(), "REQUEST"), 1) << "line 4 was not sent";

  // The fix: the object's true pose (--object-pose scene), from the stopped line.
  r = test::run_foresight(args_text(s, "--auto --from-line 3 --json"));
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["steps"][0]["outcome"], "skipped");
  EXPECT_EQ(j["steps"][1]["outcome"], "skipped");
  EXPECT_EQ(j["steps"][2]["outcome"], "completed");
  EXPECT_EQ(j["steps"][3]["outcome"], "completed");
  kinds = received_kinds();
  EXPECT_EQ(std::count(kinds.begin(), kinds.end(), "TRAJECTORY"), 1);
}

TEST_F(RunScript, ARemoteRejectionStopsThereAndTheScriptGoesOnAfterTheFix) {
  const std::string s = script("tare.task",
                               "REQUEST status\n"
                               "INVOKE_ALGORITHM tare samples=0   # the remote allows 1..10000\n"
                               "REQUEST joints\n");
  auto r = test::run_foresight(args_text(s, "--auto --json"));
  EXPECT_EQ(r.status, 1) << r.err << r.out;
  auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["end"], "stopped");
  EXPECT_EQ(j["resume_line"], 2);
  EXPECT_EQ(j["steps"][1]["outcome"], "failed");
  EXPECT_NE(j["steps"][1]["message"].get<std::string>().find("tare: samples 0 must be an integer in 1..10000"),
            std::string::npos)
      << j["steps"][1].dump();
  EXPECT_EQ(j["steps"][2]["outcome"], "pending");
  EXPECT_EQ(states_of("INVOKE_ALGORITHM"), (std::vector<std::string>{"REJECTED"}));
  ASSERT_TRUE(arm_holds());

  std::ofstream(s) << "REQUEST status\nINVOKE_ALGORITHM tare samples=20\nREQUEST joints\n";  // the fix
  r = test::run_foresight(args_text(s, "--auto --from-line 2 --json"));
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["end"], "finished");
  EXPECT_EQ(j["steps"][1]["outcome"], "completed");
  EXPECT_EQ(j["steps"][2]["outcome"], "completed");
  EXPECT_EQ(states_of("INVOKE_ALGORITHM"), (std::vector<std::string>{"REJECTED", "COMPLETED"}));
}

TEST_F(RunScript, AnUnknownAlgorithmIsRefusedBeforeAnythingIsSent) {
  const std::string s = script("unknown.task", "REQUEST status\nINVOKE_ALGORITHM unscrew timeout_s=5\n");
  const std::size_t before = remote_commands().size();
  const auto r = test::run_foresight(args_text(s, "--auto"));
  EXPECT_EQ(r.status, 2) << r.err << r.out;
  EXPECT_EQ(r.err, "foresight run: error: " + s +
                       ":2:18: INVOKE_ALGORITHM algorithm: 'unscrew' is not one of guarded_move, insert, latch, "
                       "unlatch, loosen, tighten, pull_out, tare, identify_payload\n");
  EXPECT_EQ(remote_commands().size(), before) << "nothing reached the remote";
}

}  // namespace
