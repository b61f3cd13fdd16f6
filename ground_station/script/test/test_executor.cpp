// The executor model: step / auto / cancel / abort, retry and skip after a
// stop, and going on from a stopped command after the script was fixed; driven
// through drive() with scripted keys and a fake runner.
#include <gtest/gtest.h>

#include <algorithm>

#include "foresight/script/executor.hpp"

namespace foresight::script {
namespace {

const char* kScript =
    "VIDEO side\n"                                 // 0, line 1
    "TRAJECTORY to=approach_20cm   # approach\n"  // 1, line 2
    "INVOKE_ALGORITHM latch\n"                     // 2, line 3
    "\n"
    "REQUEST status\n";                            // 3, line 5

/// Completes every command, except those named in `fail_at` (by index, once
/// each) and those interrupted by the operator (it then "stops the robot").
class FakeRunner : public CommandRunner {
 public:
  std::vector<std::size_t> fail_at;
  std::size_t polls_before_done = 3;  ///< how long a command takes, in polls
  std::vector<std::string> ran;       ///< the command words, in order

  Outcome run(const Command& c, const std::function<bool()>& interrupted) override {
    ran.push_back(c.text);
    const std::size_t index = ran.size() - 1;
    for (std::size_t i = 0; i < polls_before_done; ++i)
      if (interrupted()) return {CommandState::Canceled, "stopped by ABORT", 0.1};
    for (auto it = fail_at.begin(); it != fail_at.end(); ++it)
      if (*it == index) {
        fail_at.erase(it);
        return {CommandState::Failed, "REJECTED: Unreachable", 0.2};
      }
    return {CommandState::Completed, "", 0.3};
  }
};

Executor fresh(std::size_t first = 0) { return Executor(parse_script(kScript, "t.task"), first); }

TEST(Executor, StepModeRunsOneCommandPerStepKey) {
  Executor ex = fresh();
  FakeRunner runner;
  ScriptedControls keys({Key::Step, Key::Step});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Quit);  // keys ran out while Ready
  EXPECT_EQ(runner.ran, (std::vector<std::string>{"VIDEO side", "TRAJECTORY to=approach_20cm"}));
  EXPECT_EQ(ex.current(), 2u);
  EXPECT_EQ(ex.state(), RunState::Ready);
  EXPECT_EQ(ex.command_state(0), CommandState::Completed);
  EXPECT_EQ(ex.command_state(2), CommandState::Pending);
  EXPECT_EQ(ex.listing(),
            "  [x]    1  VIDEO side\n"
            "  [x]    2  TRAJECTORY to=approach_20cm   # approach\n"
            "> [ ]    3  INVOKE_ALGORITHM latch\n"
            "  [ ]    5  REQUEST status\n");
}

TEST(Executor, AutoRunsToTheEnd) {
  Executor ex = fresh();
  FakeRunner runner;
  ScriptedControls keys({Key::Auto});
  std::vector<std::string> states;
  EXPECT_EQ(drive(ex, runner, keys, [&](const Executor& e) { states.push_back(to_string(e.state())); }),
            DriveEnd::Finished);
  EXPECT_EQ(runner.ran.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(ex.command_state(i), CommandState::Completed);
  EXPECT_EQ(ex.state(), RunState::Finished);
  EXPECT_EQ(states.front(), "ready");
  EXPECT_EQ(states.back(), "finished");
  EXPECT_EQ(std::count(states.begin(), states.end(), "running"), 4);
  EXPECT_EQ(ex.listing().find('>'), std::string::npos);  // nothing current once finished
}

TEST(Executor, StepDuringAutoSwitchesBackToStepMode) {
  Executor ex = fresh();
  FakeRunner runner;
  // Auto starts the first command; Step is pressed while it runs: the run pauses after it.
  class Keyboard : public Controls {
   public:
    int polls = 0;
    Key poll(double timeout_s) override {
      ++polls;
      if (polls == 1) return Key::Auto;
      if (polls == 2) return Key::Step;   // during VIDEO
      return timeout_s > 0 ? Key::Quit : Key::None;
    }
  } keys;
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Quit);
  EXPECT_EQ(runner.ran.size(), 1u);
  EXPECT_FALSE(ex.auto_mode());
  EXPECT_EQ(ex.current(), 1u);
}

TEST(Executor, FailureStopsAtTheCommandAndRetryGoesOn) {
  Executor ex = fresh();
  FakeRunner runner;
  runner.fail_at = {1};
  ScriptedControls keys({Key::Auto});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Stopped);
  EXPECT_EQ(ex.state(), RunState::Stopped);
  EXPECT_EQ(ex.current(), 1u);
  EXPECT_EQ(ex.command_state(1), CommandState::Failed);
  EXPECT_EQ(ex.stop_reason(), "line 2 TRAJECTORY failed: REJECTED: Unreachable");
  EXPECT_NE(ex.listing().find("> [!]    2  TRAJECTORY"), std::string::npos);
  // The operator fixes the cause and retries; auto is still on: it runs to the end.
  ScriptedControls again({Key::Retry});
  EXPECT_EQ(drive(ex, runner, again), DriveEnd::Finished);
  EXPECT_EQ(runner.ran.size(), 5u);  // VIDEO, TRAJECTORY (failed), TRAJECTORY, INVOKE, REQUEST
  EXPECT_EQ(ex.command_state(1), CommandState::Completed);
}

TEST(Executor, CancelStopsOnlyTheCurrentCommand) {
  Executor ex = fresh();
  FakeRunner runner;
  // Step runs VIDEO; Step starts TRAJECTORY and Cancel arrives while it runs.
  ScriptedControls keys({Key::Step, Key::Step, Key::Cancel, Key::Skip, Key::Step});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Quit);
  EXPECT_EQ(ex.command_state(1), CommandState::Skipped);  // canceled, then skipped by the operator
  EXPECT_EQ(ex.command_state(2), CommandState::Completed);
  EXPECT_EQ(runner.ran, (std::vector<std::string>{"VIDEO side", "TRAJECTORY to=approach_20cm",
                                                  "INVOKE_ALGORITHM latch"}));
  EXPECT_EQ(ex.current(), 3u);
  EXPECT_EQ(keys.remaining(), 0u);
}

TEST(Executor, CancelLeavesTheRunStoppedAtThatCommand) {
  Executor ex = fresh();
  FakeRunner runner;
  ScriptedControls keys({Key::Step, Key::Cancel});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Stopped);
  EXPECT_EQ(ex.command_state(0), CommandState::Canceled);
  EXPECT_EQ(ex.stop_reason(), "line 1 VIDEO canceled: stopped by ABORT");
  EXPECT_EQ(ex.current(), 0u);
}

TEST(Executor, AbortWhileRunningEndsTheWholeScript) {
  Executor ex = fresh();
  FakeRunner runner;
  ScriptedControls keys({Key::Auto, Key::None, Key::None, Key::None, Key::Abort});
  // VIDEO polls 3 times (None, None, None) and completes; TRAJECTORY's first poll reads Abort.
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Aborted);
  EXPECT_EQ(ex.state(), RunState::Aborted);
  EXPECT_EQ(ex.command_state(1), CommandState::Canceled);  // the runner stopped the robot
  EXPECT_EQ(ex.command_state(2), CommandState::Pending);
  EXPECT_EQ(ex.stop_reason(), "aborted by the operator at line 2");
  EXPECT_EQ(runner.ran.size(), 2u);
  EXPECT_THROW(ex.start(), std::logic_error);
  EXPECT_THROW(ex.retry(), std::logic_error);
}

TEST(Executor, AbortWhileStoppedAndQuitWhileReady) {
  Executor ex = fresh();
  FakeRunner runner;
  runner.fail_at = {0};
  // None x3: VIDEO's three polls pass; it fails; Abort is read while stopped.
  ScriptedControls keys({Key::Step, Key::None, Key::None, Key::None, Key::Abort});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Aborted);
  EXPECT_EQ(ex.stop_reason(), "aborted by the operator after: line 1 VIDEO failed: REJECTED: Unreachable");

  Executor ex2 = fresh();
  ScriptedControls quit({Key::Quit});
  EXPECT_EQ(drive(ex2, runner, quit), DriveEnd::Quit);
  EXPECT_EQ(ex2.state(), RunState::Ready);
}

TEST(Executor, ResumeFromAStoppedCommandAfterTheScriptWasFixed) {
  Executor ex = fresh();
  FakeRunner runner;
  runner.fail_at = {1};
  ScriptedControls keys({Key::Auto});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Stopped);
  // The operator fixes line 2 (another goal) and adds a line before it.
  ex.replace_script(parse_script("VIDEO side\nGRAPHICS ghost\nTRAJECTORY to=hole_entrance\n"
                                 "INVOKE_ALGORITHM latch\n\nREQUEST status\n",
                                 "t.task"));
  EXPECT_EQ(ex.state(), RunState::Ready);
  EXPECT_EQ(ex.current(), 1u);  // the first command at or after the stopped line (2)
  EXPECT_EQ(ex.command_state(0), CommandState::Completed);  // VIDEO kept its outcome
  ScriptedControls go({Key::Auto});
  EXPECT_EQ(drive(ex, runner, go), DriveEnd::Finished);
  EXPECT_EQ(runner.ran.back(), "REQUEST status");
  EXPECT_EQ(runner.ran[2], "GRAPHICS ghost");
  EXPECT_EQ(runner.ran[3], "TRAJECTORY to=hole_entrance");
}

TEST(Executor, StartAtALineInANewSession) {
  const Script s = parse_script(kScript, "t.task");
  EXPECT_EQ(Executor::index_at_line(s, 3), 2u);
  EXPECT_EQ(Executor::index_at_line(s, 4), 3u);  // the blank line 4: the next command
  EXPECT_EQ(Executor::index_at_line(s, 99), 4u);
  Executor ex(s, Executor::index_at_line(s, 3));
  FakeRunner runner;
  ScriptedControls keys({Key::Auto});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Finished);
  EXPECT_EQ(runner.ran, (std::vector<std::string>{"INVOKE_ALGORITHM latch", "REQUEST status"}));
  EXPECT_EQ(ex.command_state(0), CommandState::Skipped);
  EXPECT_EQ(ex.command_state(1), CommandState::Skipped);
}

TEST(Executor, MisuseIsALogicError) {
  Executor ex = fresh();
  EXPECT_THROW(ex.finish({}), std::logic_error);
  EXPECT_THROW(ex.retry(), std::logic_error);
  ex.start();
  EXPECT_THROW(ex.start(), std::logic_error);
  EXPECT_THROW(ex.replace_script(parse_script("GRAB\n", "t")), std::logic_error);
  EXPECT_THROW(ex.finish({CommandState::Skipped, "", 0}), std::logic_error);
  ex.finish({CommandState::Completed, "", 0});
  EXPECT_EQ(ex.current(), 1u);
}

/// Chained mode (`run --chain`): TRAJECTORY and INVOKE_ALGORITHM are sent
/// ahead (Sent) and end when settled; REQUEST needs the arm where it is, so
/// drive() settles first. `break_at` (by line): that command ends Failed and
/// every later one sent ahead Canceled, as the remote's broken chain does.
class ChainRunner : public CommandRunner {
 public:
  int break_at = 0;
  std::vector<std::string> calls;  ///< "run LINE" and "settle LINE outcome", in order
  std::vector<int> outstanding;
  bool interrupted_settle = false;
  bool broke_once = false;

  Outcome run(const Command& c, const std::function<bool()>& interrupted) override {
    calls.push_back("run " + std::to_string(c.line));
    if (interrupted()) return {CommandState::Canceled, "interrupted", 0.0};
    if (chains(c) && is_remote(c.op)) {
      outstanding.push_back(c.line);
      return {CommandState::Sent, "sent", 0.0};
    }
    return {CommandState::Completed, "", 0.0};
  }
  bool chains(const Command& c) const override { return c.op != Op::Request && c.op != Op::Wait; }
  void settle(const std::function<bool()>& interrupted,
              const std::function<void(int, const Outcome&)>& on_settled) override {
    bool broken = false;
    for (const int line : outstanding) {
      if (interrupted()) interrupted_settle = true;
      Outcome o{CommandState::Completed, "done", 1.0};
      if (broken || interrupted_settle) o = {CommandState::Canceled, "chain broken at command " + std::to_string(break_at), 0.0};
      else if (line == break_at && !broke_once) {
        o = {CommandState::Failed, "tool jam", 2.0};
        broken = broke_once = true;  // the fault cleared: a retry goes through
      }
      calls.push_back("settle " + std::to_string(line) + " " + to_string(o.state));
      on_settled(line, o);
    }
    outstanding.clear();
  }
};

const char* kChained =
    "TRAJECTORY to=approach_20cm\n"                // line 1
    "INVOKE_ALGORITHM insert depth_m=0.06\n"       // line 2
    "GRAB\n"                                       // line 3
    "INVOKE_ALGORITHM loosen\n"                    // line 4
    "WAIT\n"                                       // line 5
    "INVOKE_ALGORITHM unlatch\n"                   // line 6
    "REQUEST status\n";                            // line 7

TEST(Executor, AChainIsSentAheadAndSettledBeforeACommandThatNeedsTheArm) {
  Executor ex(parse_script(kChained, "c.task"));
  ChainRunner runner;
  ScriptedControls keys({Key::Auto});
  std::vector<std::string> marks;  // the listing's mark of line 2 as the run goes
  EXPECT_EQ(drive(ex, runner, keys, [&](const Executor& e) { marks.push_back(to_string(e.command_state(1))); }),
            DriveEnd::Finished);
  EXPECT_EQ(runner.calls, (std::vector<std::string>{"run 1", "run 2", "run 3", "run 4", "settle 1 completed",
                                                    "settle 2 completed", "settle 4 completed", "run 5", "run 6",
                                                    "settle 6 completed", "run 7"}));
  for (std::size_t i = 0; i < 7; ++i) EXPECT_EQ(ex.command_state(i), CommandState::Completed) << i;
  EXPECT_NE(std::find(marks.begin(), marks.end(), "sent"), marks.end()) << "line 2 was shown sent before it ended";
  EXPECT_FALSE(ex.has_sent());
}

TEST(Executor, ABrokenChainStopsTheRunAtItsFirstFailedCommandAndRetryGoesOnFromThere) {
  Executor ex(parse_script(kChained, "c.task"));
  ChainRunner runner;
  runner.break_at = 2;
  ScriptedControls keys({Key::Auto, Key::Retry, Key::Auto});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Finished);
  // The chain 1, 2, 4 settled at WAIT: 2 failed, 4 canceled; the run stopped at
  // line 2 (not at WAIT), and the retry ran 2, 3, 4 again (the runner replans
  // from where the arm is).
  EXPECT_EQ(runner.calls, (std::vector<std::string>{"run 1", "run 2", "run 3", "run 4", "settle 1 completed",
                                                    "settle 2 failed", "settle 4 canceled", "run 2", "run 3", "run 4",
                                                    "settle 2 completed", "settle 4 completed", "run 5", "run 6",
                                                    "settle 6 completed", "run 7"}));
  for (std::size_t i = 0; i < 7; ++i) EXPECT_EQ(ex.command_state(i), CommandState::Completed) << i;
}

TEST(Executor, ABrokenChainReportsItsCauseAndCancelsTheRest) {
  Executor ex(parse_script(kChained, "c.task"));
  ChainRunner runner;
  runner.break_at = 2;
  ScriptedControls keys({Key::Auto});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Stopped);  // the keys ran out while stopped
  EXPECT_EQ(ex.current(), 1u);
  EXPECT_EQ(ex.stop_reason(), "line 2 INVOKE_ALGORITHM failed: tool jam");
  EXPECT_EQ(ex.command_state(0), CommandState::Completed);
  EXPECT_EQ(ex.command_state(1), CommandState::Failed);
  EXPECT_EQ(ex.command_state(2), CommandState::Completed);  // GRAB: the ground's display only
  EXPECT_EQ(ex.command_state(3), CommandState::Canceled);
  EXPECT_EQ(ex.outcome(3).message, "chain broken at command 2");
  EXPECT_EQ(ex.command_state(4), CommandState::Pending);  // WAIT never ran
  EXPECT_EQ(ex.listing(),
            "  [x]    1  TRAJECTORY to=approach_20cm\n"
            "> [!]    2  INVOKE_ALGORITHM insert depth_m=0.06\n"
            "  [x]    3  GRAB\n"
            "  [c]    4  INVOKE_ALGORITHM loosen\n"
            "  [ ]    5  WAIT\n"
            "  [ ]    6  INVOKE_ALGORITHM unlatch\n"
            "  [ ]    7  REQUEST status\n");
}

TEST(Executor, AbortWhileAChainRunsStopsItAll) {
  Executor ex(parse_script(kChained, "c.task"));
  ChainRunner runner;
  // Lines 1 and 2 are sent; GRAB reads Abort: the runner is told to stop the chain.
  ScriptedControls keys({Key::Auto, Key::None, Key::None, Key::Abort});
  EXPECT_EQ(drive(ex, runner, keys), DriveEnd::Aborted);
  EXPECT_TRUE(runner.interrupted_settle);
  EXPECT_EQ(ex.command_state(0), CommandState::Canceled);
  EXPECT_EQ(ex.command_state(1), CommandState::Canceled);
  EXPECT_EQ(ex.command_state(2), CommandState::Canceled);
  EXPECT_FALSE(ex.has_sent());
  EXPECT_EQ(ex.stop_reason(), "aborted by the operator at line 3");
}

TEST(Executor, SettleMisuseIsALogicError) {
  Executor ex(parse_script(kChained, "c.task"));
  EXPECT_THROW(ex.settle(1, {CommandState::Completed, "", 0.0}), std::logic_error);  // nothing sent
  ex.start();
  ex.finish({CommandState::Sent, "sent", 0.0});
  EXPECT_TRUE(ex.has_sent());
  EXPECT_THROW(ex.settle(1, {CommandState::Sent, "", 0.0}), std::logic_error);
  ex.start();
  EXPECT_THROW(ex.settle(1, {CommandState::Completed, "", 0.0}), std::logic_error);  // while a command runs
}

TEST(Executor, KeysFromCharactersAndNames) {
  EXPECT_EQ(key_from_char('s'), Key::Step);
  EXPECT_EQ(key_from_char('g'), Key::Auto);
  EXPECT_EQ(key_from_char('c'), Key::Cancel);
  EXPECT_EQ(key_from_char('a'), Key::Abort);
  EXPECT_EQ(key_from_char('r'), Key::Retry);
  EXPECT_EQ(key_from_char('k'), Key::Skip);
  EXPECT_EQ(key_from_char('q'), Key::Quit);
  EXPECT_EQ(key_from_char('x'), Key::None);
  EXPECT_EQ(key_from_name("cancel"), Key::Cancel);
  EXPECT_FALSE(key_from_name("halt").has_value());
}

}  // namespace
}  // namespace foresight::script
