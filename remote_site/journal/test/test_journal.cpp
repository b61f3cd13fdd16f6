// The journal's writer: rows round-trip, commands durable before return
// (a child process SIGKILLs itself right after record_command), telemetry
// batching, drops and decimation, rotation at the size bound, crash recovery,
// bad rows and bad files, the sqlite3 shell reading a live journal.

#include "foresight/journal/journal.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <thread>

#include <sys/syscall.h>

#include "foresight/journal/reader.hpp"
#include "journal_test_util.hpp"

// Interposes fdatasync for this test binary (libsqlite3 is a shared library, so
// its calls resolve here first) to count the syncs a commit really does.
namespace {
std::atomic<std::uint64_t> g_fdatasyncs{0};
}
extern "C" int fdatasync(int fd) {
  g_fdatasyncs.fetch_add(1, std::memory_order_relaxed);
  return static_cast<int>(syscall(SYS_fdatasync, fd));
}

namespace foresight::journal {
namespace {

using test::command;
using test::ScratchDir;
using test::sqlite_int;
using test::telemetry;
using test::test_options;
namespace fs = std::filesystem;

TEST(Journal, RowsRoundTrip) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  CommandRow c;
  c.stamp_ns = 1'796'143'023'000'000'001;
  c.session_id = 42;
  c.command_id = std::numeric_limits<std::uint64_t>::max() - 5;  // above 2^63: stored as signed, read back intact
  c.sequence_number = 9;
  c.kind = "TRAJECTORY";
  c.state = "REJECTED";
  c.code = "VALIDATION_FAILED";
  c.reason = "row 17 joint 3: velocity 2.1 rad/s above the limit 1.9 rad/s";
  c.detail = R"({"trajectory_id":5,"hash":"ab12"})";
  FaultRow f{1'796'143'023'000'000'002, 123456, 1, "following_error", "joint 4 lagged 0.05 rad",
             R"({"joint":4,"last":[[0.1,0.2],[0.1,0.25]]})"};
  UploadRow u{1'796'143'023'000'000'003, 5, "COMMITTED", "NONE", "", std::string(64, 'e'), 2000, 7};
  EventRow e{1'796'143'023'000'000'004, "start", "foresight-remote 0.1.0 --sim", R"({"config":"remote.yaml"})"};
  TelemetryRow t = telemetry(1'796'143'023'000'000'005, 77);
  t.q_rad[0] = 0.1 + 0.2;  // shortest round-trip text must give the same double back
  t.wrench[5] = std::numeric_limits<double>::quiet_NaN();  // stored as JSON null
  {
    Journal j(o);
    EXPECT_TRUE(j.previous_shutdown_clean());
    j.record_command(c);
    j.record_fault(f);
    j.record_upload(u);
    j.record_event(e);
    EXPECT_EQ(j.push_telemetry(t), PushResult::Accepted);
    ASSERT_TRUE(j.flush());
    const JournalStats s = j.stats();
    EXPECT_EQ(s.commands, 1u);
    EXPECT_EQ(s.faults, 1u);
    EXPECT_EQ(s.uploads, 1u);
    EXPECT_EQ(s.events, 1u);
    EXPECT_EQ(s.telemetry_written, 1u);
    EXPECT_EQ(s.telemetry_batches, 1u);
  }
  const JournalContents r = read_journal(o.path);
  ASSERT_EQ(r.commands.size(), 1u);
  const CommandRow& rc = r.commands[0];
  EXPECT_EQ(rc.stamp_ns, c.stamp_ns);
  EXPECT_EQ(rc.session_id, c.session_id);
  EXPECT_EQ(rc.command_id, c.command_id);
  EXPECT_EQ(rc.sequence_number, c.sequence_number);
  EXPECT_EQ(rc.kind, c.kind);
  EXPECT_EQ(rc.state, c.state);
  EXPECT_EQ(rc.code, c.code);
  EXPECT_EQ(rc.reason, c.reason);
  EXPECT_EQ(rc.detail, c.detail);
  ASSERT_EQ(r.faults.size(), 1u);
  EXPECT_EQ(r.faults[0].stamp_ns, f.stamp_ns);
  EXPECT_EQ(r.faults[0].cycle, f.cycle);
  EXPECT_EQ(r.faults[0].category, f.category);
  EXPECT_EQ(r.faults[0].cause, f.cause);
  EXPECT_EQ(r.faults[0].text, f.text);
  EXPECT_EQ(r.faults[0].evidence, f.evidence);
  ASSERT_EQ(r.uploads.size(), 1u);
  EXPECT_EQ(r.uploads[0].stamp_ns, u.stamp_ns);
  EXPECT_EQ(r.uploads[0].trajectory_id, u.trajectory_id);
  EXPECT_EQ(r.uploads[0].state, u.state);
  EXPECT_EQ(r.uploads[0].code, u.code);
  EXPECT_EQ(r.uploads[0].reason, u.reason);
  EXPECT_EQ(r.uploads[0].hash_hex, u.hash_hex);
  EXPECT_EQ(r.uploads[0].samples, u.samples);
  EXPECT_EQ(r.uploads[0].joints, u.joints);
  ASSERT_EQ(r.events.size(), 1u);
  EXPECT_EQ(r.events[0].stamp_ns, e.stamp_ns);
  EXPECT_EQ(r.events[0].kind, e.kind);
  EXPECT_EQ(r.events[0].text, e.text);
  EXPECT_EQ(r.events[0].detail, e.detail);
  EXPECT_EQ(r.telemetry_count, 1u);
  ASSERT_TRUE(r.telemetry_last.has_value());
  const TelemetryRow& rt = *r.telemetry_last;
  EXPECT_EQ(rt.stamp_ns, t.stamp_ns);
  EXPECT_EQ(rt.cycle, t.cycle);
  EXPECT_EQ(rt.mode, t.mode);
  EXPECT_EQ(rt.joint_count, t.joint_count);
  for (int i = 0; i < t.joint_count; ++i) {
    EXPECT_EQ(rt.q_rad[i], t.q_rad[i]) << i;  // bit-exact
    EXPECT_EQ(rt.q_cmd_rad[i], t.q_cmd_rad[i]) << i;
  }
  for (int i = 0; i < 5; ++i) EXPECT_EQ(rt.wrench[i], t.wrench[i]) << i;
  EXPECT_TRUE(std::isnan(rt.wrench[5]));
}

TEST(Journal, ZeroStampIsStampedWithWallClock) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  const std::int64_t before = Journal::now_ns();
  {
    Journal j(o);
    j.record_command(command(1));
  }
  const std::int64_t after = Journal::now_ns();
  const JournalContents r = read_journal(o.path);
  ASSERT_EQ(r.commands.size(), 1u);
  EXPECT_GE(r.commands[0].stamp_ns, before);
  EXPECT_LE(r.commands[0].stamp_ns, after);
}

TEST(Journal, BadRowsRejectedWithTheirReason) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  Journal j(o);
  try {
    j.record_command(command(1, "DONE"));
    FAIL() << "no throw";
  } catch (const JournalError& e) {
    EXPECT_EQ(std::string(e.what()), o.path +
                                         ": unknown command state 'DONE' (expected RECEIVED, REJECTED, QUEUED, "
                                         "EXECUTING, COMPLETED, FAILED or CANCELED)");
  }
  FaultRow f;
  f.category = 3;
  try {
    j.record_fault(f);
    FAIL() << "no throw";
  } catch (const JournalError& e) {
    EXPECT_EQ(std::string(e.what()), o.path + ": fault category must be 0, 1 or 2, got 3");
  }
  j.close();
  try {
    j.record_command(command(2));
    FAIL() << "no throw";
  } catch (const JournalError& e) {
    EXPECT_EQ(std::string(e.what()), o.path + ": journal is closed");
  }
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 0);
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from faults"), 0);
}

TEST(Journal, BadOptionsRejected) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.max_bytes = 100;
  EXPECT_THROW(Journal{o}, std::invalid_argument);
  o = test_options(dir);
  o.telemetry_queue = 0;
  EXPECT_THROW(Journal{o}, std::invalid_argument);
  o = test_options(dir);
  o.telemetry_rate_hz = -1;
  EXPECT_THROW(Journal{o}, std::invalid_argument);
}

TEST(Journal, WalModeAndSchemaVisibleToAPlainConnection) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  Journal j(o);
  j.record_command(command(1));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 1);  // visible while the writer is open
  // journal_mode is persistent in the file: a fresh connection sees WAL.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(o.path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "PRAGMA journal_mode", -1, &st, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(st, 0)), "wal");
  sqlite3_finalize(st);
  sqlite3_close(db);
  EXPECT_EQ(j.synchronous_level(), 2);  // FULL: every durable commit fsyncs the WAL
  j.push_telemetry(telemetry(1'000, 0));
  ASSERT_TRUE(j.flush());
  EXPECT_EQ(j.stats().telemetry_batches, 1u);
  EXPECT_EQ(j.synchronous_level(), 2);  // back to FULL after a NORMAL telemetry batch
  EXPECT_EQ(sqlite_int(o.path, "PRAGMA application_id"), 0x46534A4C);
  EXPECT_EQ(sqlite_int(o.path, "PRAGMA user_version"), 1);
}

// synchronous=FULL really reaches the disk: each durable row costs at least
// one fdatasync of the WAL before record_* returns (a prepared "PRAGMA
// synchronous=NORMAL" would silently have made it zero).
TEST(Journal, EveryDurableRecordSyncsTheWal) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  Journal j(o);
  const std::uint64_t before = g_fdatasyncs.load();
  for (int i = 0; i < 20; ++i) j.record_command(command(static_cast<std::uint64_t>(i)));
  j.record_fault({0, 1, 2, "test", "test", "{}"});
  j.record_upload({0, 1, "COMMITTED", "NONE", "", "00", 1, 7});
  j.record_event({0, "start", "test", ""});
  EXPECT_GE(g_fdatasyncs.load() - before, 23u);
}

// The child records N commands and SIGKILLs itself right after the last
// record_command returns: no destructor, no close, no checkpoint. Every one
// of the N rows must be there when the parent reopens the file.
TEST(Journal, CommandsDurableBeforeReturnAcrossSigkill) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  constexpr int kCommands = 50;
  constexpr int kFlushedTelemetry = 100;
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    try {
      Journal j(o);
      for (int i = 0; i < kFlushedTelemetry; ++i) j.push_telemetry(telemetry(1'000'000'000 + i, i));
      if (!j.flush()) _exit(3);
      for (int i = 0; i < 10; ++i) j.push_telemetry(telemetry(2'000'000'000 + i, 1000 + i));  // never flushed
      for (int i = 1; i <= kCommands; ++i) {
        j.record_command(command(static_cast<std::uint64_t>(i)));
        if (i == kCommands) raise(SIGKILL);
      }
    } catch (...) {
      _exit(4);
    }
    _exit(5);  // not reached
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);
  EXPECT_EQ(WTERMSIG(status), SIGKILL);
  EXPECT_TRUE(fs::exists(o.path + "-wal")) << "the killed writer left its WAL (nothing checkpointed)";

  {
    Journal j(o);  // WAL recovery, then append
    EXPECT_FALSE(j.previous_shutdown_clean());
    j.record_command(command(kCommands + 1));
  }
  const JournalContents r = read_journal(o.path);
  ASSERT_EQ(r.commands.size(), static_cast<std::size_t>(kCommands + 1));
  for (int i = 0; i <= kCommands; ++i) EXPECT_EQ(r.commands[i].command_id, static_cast<std::uint64_t>(i + 1));
  EXPECT_GE(r.telemetry_count, static_cast<std::uint64_t>(kFlushedTelemetry));
  EXPECT_LE(r.telemetry_count, static_cast<std::uint64_t>(kFlushedTelemetry + 10));

  Journal again(o);
  EXPECT_TRUE(again.previous_shutdown_clean());
}

// Killed while its writer thread is busy: telemetry pushed between the
// commands, drained every 2 ms. All commands are there, the file passes
// integrity_check, and the telemetry is a gap-free prefix (a batch is one
// transaction: all of it or none).
TEST(Journal, SigkillWhileTheWriterThreadIsBusy) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.flush_interval = std::chrono::milliseconds(2);
  o.telemetry_batch = 16;
  constexpr int kCommands = 40;
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    try {
      Journal j(o);
      std::uint64_t cycle = 0;
      for (int i = 1; i <= kCommands; ++i) {
        for (int k = 0; k < 50; ++k, ++cycle) j.push_telemetry(telemetry(1'000 + static_cast<std::int64_t>(cycle), cycle));
        j.record_command(command(static_cast<std::uint64_t>(i)));
        if (i == kCommands / 2) {  // the writer has committed at least one batch (bounded wait)
          const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
          while (j.stats().telemetry_batches == 0 && std::chrono::steady_clock::now() < deadline)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        if (i == kCommands) raise(SIGKILL);
      }
    } catch (...) {
      _exit(4);
    }
    _exit(5);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), kCommands);
  EXPECT_EQ(sqlite_int(o.path, "select count(distinct command_id) from commands"), kCommands);
  const long long rows = sqlite_int(o.path, "select count(*) from telemetry");
  EXPECT_GT(rows, 0);
  EXPECT_LE(rows, 50LL * kCommands);
  EXPECT_EQ(sqlite_int(o.path, "select coalesce(max(cycle) + 1, 0) from telemetry"), rows);  // no holes
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from pragma_integrity_check where integrity_check = 'ok'"), 1);
}

TEST(Journal, MissingDirectoryNamed) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.path = dir.file("no/such/dir/journal.sqlite3");
  try {
    Journal j(o);
    FAIL() << "no throw";
  } catch (const JournalError& e) {
    EXPECT_EQ(std::string(e.what()),
              o.path + ": cannot create the journal: its folder " + dir.file("no/such/dir") + " does not exist");
  }
}

TEST(Journal, PushAfterCloseIsDropped) {
  ScratchDir dir;
  Journal j(test_options(dir));
  j.close();
  EXPECT_EQ(j.push_telemetry(telemetry(1, 1)), PushResult::Dropped);
  EXPECT_EQ(j.stats().telemetry_dropped, 1u);
  EXPECT_TRUE(j.flush());  // nothing to wait for
}

TEST(Journal, ReopenAppends) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  for (int session = 0; session < 3; ++session) {
    Journal j(o);
    EXPECT_TRUE(j.previous_shutdown_clean());
    for (int i = 0; i < 4; ++i) j.record_command(command(static_cast<std::uint64_t>(session * 4 + i)));
  }
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 12);
  EXPECT_EQ(sqlite_int(o.path, "select max(command_id) from commands"), 11);
}

TEST(Journal, TelemetryWrittenInBatchesOneTransactionEach) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.telemetry_queue = 1024;
  o.telemetry_batch = 256;
  Journal j(o);
  for (int i = 0; i < 1000; ++i) ASSERT_EQ(j.push_telemetry(telemetry(1'000 + i, i)), PushResult::Accepted);
  ASSERT_TRUE(j.flush());
  const JournalStats s = j.stats();
  EXPECT_EQ(s.telemetry_accepted, 1000u);
  EXPECT_EQ(s.telemetry_dropped, 0u);
  EXPECT_EQ(s.telemetry_written, 1000u);
  EXPECT_EQ(s.telemetry_batches, 4u);  // 256 + 256 + 256 + 232
  EXPECT_EQ(s.write_errors, 0u);
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from telemetry"), 1000);
  EXPECT_EQ(sqlite_int(o.path, "select max(cycle) - min(cycle) from telemetry"), 999);
  // The JSON arrays are queryable from the shell with SQLite's JSON functions.
  EXPECT_EQ(sqlite_int(o.path, "select json_array_length(q) from telemetry limit 1"), 7);
}

TEST(Journal, WriterThreadDrainsOnItsOwnAtTheFlushInterval) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.flush_interval = std::chrono::milliseconds(20);
  Journal j(o);
  for (int i = 0; i < 30; ++i) j.push_telemetry(telemetry(1'000 + i, i));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (j.stats().telemetry_written < 30 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(j.stats().telemetry_written, 30u);
}

TEST(Journal, FullQueueDropsAndCounts) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.telemetry_queue = 8;
  Journal j(o);
  int accepted = 0, dropped = 0;
  for (int i = 0; i < 100; ++i) {
    const PushResult r = j.push_telemetry(telemetry(1'000 + i, i));
    accepted += r == PushResult::Accepted;
    dropped += r == PushResult::Dropped;
  }
  EXPECT_EQ(accepted, 8);
  EXPECT_EQ(dropped, 92);
  ASSERT_TRUE(j.flush());
  JournalStats s = j.stats();
  EXPECT_EQ(s.telemetry_dropped, 92u);
  EXPECT_EQ(s.telemetry_written, 8u);
  EXPECT_EQ(sqlite_int(o.path, "select max(cycle) from telemetry"), 7);  // the first 8 kept, the rest dropped
  // Drained: room again.
  EXPECT_EQ(j.push_telemetry(telemetry(5'000, 500)), PushResult::Accepted);
}

TEST(Journal, TelemetryDecimatedToTheConfiguredRate) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.telemetry_rate_hz = 10.0;  // one row per 100 ms of stamp time
  Journal j(o);
  const std::int64_t t0 = 1'796'143'023'000'000'000;
  for (int i = 0; i < 1000; ++i) j.push_telemetry(telemetry(t0 + i * 1'000'000, i));  // 1 kHz for 1 s
  ASSERT_TRUE(j.flush());
  const JournalStats s = j.stats();
  EXPECT_EQ(s.telemetry_accepted, 10u);
  EXPECT_EQ(s.telemetry_decimated, 990u);
  EXPECT_EQ(s.telemetry_written, 10u);
  EXPECT_EQ(sqlite_int(o.path, "select group_concat(cycle) = '0,100,200,300,400,500,600,700,800,900' from telemetry"),
            1);
}

TEST(Journal, PushTelemetryDoesNotAllocate) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.telemetry_queue = 64;
  Journal j(o);
  const TelemetryRow t = telemetry(1, 1);
  EXPECT_EQ(test::allocations_in([&] {
              for (int i = 0; i < 1000; ++i) (void)j.push_telemetry(t);  // 64 accepted, then drops
            }),
            0);
  EXPECT_EQ(j.stats().telemetry_dropped, 1000u - 64u);
}

// Every file stays near max_bytes; NAME is the newest, NAME.1 the one before;
// NAME.keep_files+1 never exists; the rows read back are one contiguous tail.
TEST(Journal, RotatesAtTheSizeBoundKeepingKeepFiles) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.max_bytes = 256 * 1024;
  o.keep_files = 2;
  constexpr int kRows = 300;
  {
    Journal j(o);
    for (int i = 1; i <= kRows; ++i) {
      CommandRow c = command(static_cast<std::uint64_t>(i));
      c.detail = "{\"pad\":\"" + std::string(4000, 'x') + "\"}";  // ~1 page a row: 1.2 MB in all
      j.record_command(c);
    }
    EXPECT_GE(j.stats().rotations, 4u);
  }
  ASSERT_TRUE(fs::exists(o.path));
  ASSERT_TRUE(fs::exists(o.path + ".1"));
  ASSERT_TRUE(fs::exists(o.path + ".2"));
  EXPECT_FALSE(fs::exists(o.path + ".3"));
  EXPECT_FALSE(fs::exists(o.path + ".1-wal"));  // rotated files stand alone
  // One transaction past the bound at most (a row, its overflow and index pages).
  for (const std::string& f : {o.path, o.path + ".1", o.path + ".2"})
    EXPECT_LE(fs::file_size(f), o.max_bytes + 16 * 1024) << f;
  EXPECT_GE(fs::file_size(o.path + ".1"), o.max_bytes) << "rotated only once past the bound";

  const JournalContents r = read_journal(o.path);
  ASSERT_EQ(r.files.size(), 3u);
  EXPECT_EQ(r.files[0], o.path + ".2");
  EXPECT_EQ(r.files[2], o.path);
  ASSERT_GT(r.commands.size(), 80u);
  EXPECT_LT(r.commands.size(), static_cast<std::size_t>(kRows));
  EXPECT_EQ(r.commands.back().command_id, static_cast<std::uint64_t>(kRows));
  for (std::size_t i = 1; i < r.commands.size(); ++i)
    ASSERT_EQ(r.commands[i].command_id, r.commands[i - 1].command_id + 1) << i;

  // Only the newest file without the rotated ones.
  ReadOptions newest;
  newest.include_rotated = false;
  const JournalContents n = read_journal(o.path, newest);
  EXPECT_EQ(n.files.size(), 1u);
  EXPECT_LT(n.commands.size(), r.commands.size());
  if (!n.commands.empty()) {
    EXPECT_EQ(n.commands.back().command_id, static_cast<std::uint64_t>(kRows));
  }
}

TEST(Journal, TelemetryBatchesRotateToo) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.max_bytes = JournalOptions::kMinMaxBytes;
  o.keep_files = 1;
  o.telemetry_batch = 64;
  o.telemetry_queue = 4096;
  Journal j(o);
  for (int i = 0; i < 3000; ++i) ASSERT_EQ(j.push_telemetry(telemetry(1'000 + i, i)), PushResult::Accepted);
  ASSERT_TRUE(j.flush());
  EXPECT_GE(j.stats().rotations, 2u);
  EXPECT_EQ(j.stats().write_errors, 0u) << j.stats().last_error;
  EXPECT_EQ(j.stats().telemetry_written, 3000u);
  EXPECT_TRUE(fs::exists(o.path + ".1"));
  EXPECT_FALSE(fs::exists(o.path + ".2"));
  const JournalContents r = read_journal(o.path);
  ASSERT_TRUE(r.telemetry_last.has_value());
  EXPECT_EQ(r.telemetry_last->cycle, 2999u);
  EXPECT_LT(r.telemetry_count, 3000u);  // the oldest files are gone
}

TEST(Journal, OpensAnOversizedJournalIntoANewFile) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  {
    Journal j(o);
    for (int i = 0; i < 50; ++i) {
      CommandRow c = command(static_cast<std::uint64_t>(i));
      c.detail = "{\"pad\":\"" + std::string(4000, 'x') + "\"}";
      j.record_command(c);
    }
  }
  o.max_bytes = JournalOptions::kMinMaxBytes;
  Journal j(o);
  EXPECT_EQ(j.stats().rotations, 1u);
  EXPECT_TRUE(fs::exists(o.path + ".1"));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 0);
  EXPECT_EQ(sqlite_int(o.path + ".1", "select count(*) from commands"), 50);
}

// A rotation that must not rename (NAME.1 is a non-empty directory here, not
// a journal) keeps the journal writing into NAME, says why in
// stats().last_error, and retries.
TEST(Journal, FailedRotationKeepsJournaling) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.max_bytes = JournalOptions::kMinMaxBytes;
  o.keep_files = 1;
  fs::create_directories(o.path + ".1/occupied");
  Journal j(o);
  for (int i = 0; i < 60; ++i) {
    CommandRow c = command(static_cast<std::uint64_t>(i));
    c.detail = "{\"pad\":\"" + std::string(4000, 'x') + "\"}";
    j.record_command(c);
  }
  EXPECT_EQ(j.stats().rotations, 0u);
  EXPECT_EQ(j.stats().last_error, o.path + ": not rotating: " + o.path +
                                      ".1 is not a Foresight journal (a directory); left untouched, journaling goes "
                                      "on in " + o.path + " past max_bytes until it is moved aside");
  EXPECT_TRUE(fs::exists(o.path + ".1/occupied"));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 60);
  fs::remove_all(o.path + ".1");  // the obstacle gone: the next transaction rotates
  j.record_command(command(60));
  EXPECT_EQ(j.stats().rotations, 1u);
  EXPECT_EQ(sqlite_int(o.path + ".1", "select count(*) from commands"), 61);
}

TEST(Journal, CorruptFileNamed) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  std::ofstream(o.path) << std::string(8192, 'z');
  try {
    Journal j(o);
    FAIL() << "no throw";
  } catch (const JournalError& e) {
    EXPECT_EQ(std::string(e.what()), o.path + ": statement failed: file is not a database (not a journal database)");
  }
}

TEST(Journal, ForeignDatabaseRefused) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(o.path.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "create table t(x)", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  try {
    Journal j(o);
    FAIL() << "no throw";
  } catch (const JournalError& e) {
    EXPECT_EQ(std::string(e.what()), o.path + ": not a Foresight journal (application_id 0)");
  }
}

TEST(Journal, Sqlite3ShellReadsALiveJournal) {
  if (std::system("command -v sqlite3 >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "the sqlite3 shell is not installed (Debian package sqlite3)";
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  Journal j(o);
  for (int i = 0; i < 5; ++i) j.record_command(command(static_cast<std::uint64_t>(i)));
  j.push_telemetry(telemetry(1'000, 0));
  ASSERT_TRUE(j.flush());
  const auto shell = [&](const std::string& sql) {
    const std::string cmd = "timeout 60 sqlite3 '" + o.path + "' '" + sql + "' 2>&1";
    std::string out;
    FILE* p = popen(cmd.c_str(), "r");
    if (p == nullptr) return out;
    char buf[256];
    std::size_t n;
    while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    pclose(p);
    return out;
  };
  EXPECT_EQ(shell("select count(*) from commands"), "5\n");
  EXPECT_EQ(shell("select state from commands where command_id = 3"), "RECEIVED\n");
  EXPECT_EQ(shell("select json_extract(q, \"$[1]\") from telemetry"), "0.1\n");
  EXPECT_EQ(shell("pragma journal_mode"), "wal\n");
  j.record_command(command(5));  // the writer goes on beside the shell
  EXPECT_EQ(shell("select count(*) from commands"), "6\n");
}

}  // namespace
}  // namespace foresight::journal
