#pragma once
// Scratch directories and small helpers for the journal tests.

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>

#include "foresight/journal/journal.hpp"

namespace foresight::journal::test {

/// Heap allocations (malloc and operator new) of this thread while `work`
/// runs (test_spsc_ring.cpp holds the binary's allocation counter).
long allocations_in(const std::function<void()>& work);

/// A fresh directory under /tmp, removed with everything in it at the end.
class ScratchDir {
 public:
  ScratchDir() {
    char tmpl[] = "/tmp/foresight_journal_XXXXXX";
    const char* d = mkdtemp(tmpl);
    EXPECT_NE(d, nullptr);
    path_ = d != nullptr ? d : "/tmp";
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  std::string file(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

/// Options for a test: a file in `dir`, a writer thread that never wakes by
/// itself (only flush() and close() drain the ring), every row kept.
inline JournalOptions test_options(const ScratchDir& dir, const std::string& name = "journal.sqlite3") {
  JournalOptions o;
  o.path = dir.file(name);
  o.flush_interval = std::chrono::hours(1);
  o.telemetry_rate_hz = 0.0;
  return o;
}

/// One integer from `sql` on a separate, plain SQLite connection (what an
/// engineer's tool sees); -1 on any error.
inline long long sqlite_int(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  long long v = -1;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &st, nullptr) == SQLITE_OK && sqlite3_step(st) == SQLITE_ROW)
      v = sqlite3_column_int64(st, 0);
    sqlite3_finalize(st);
  }
  sqlite3_close(db);
  return v;
}

inline CommandRow command(std::uint64_t id, const char* state = "RECEIVED") {
  CommandRow r;
  r.session_id = 7;
  r.command_id = id;
  r.sequence_number = id;
  r.kind = "GOTO_JOINT";
  r.state = state;
  r.code = "NONE";
  r.detail = R"({"q_rad":[0,0.1,0.2]})";
  return r;
}

inline TelemetryRow telemetry(std::int64_t stamp_ns, std::uint64_t cycle, int joints = 7) {
  TelemetryRow t;
  t.stamp_ns = stamp_ns;
  t.cycle = cycle;
  t.mode = 2;
  t.joint_count = static_cast<std::uint8_t>(joints);
  for (int j = 0; j < joints; ++j) {
    t.q_rad[j] = 0.1 * j + 1e-6 * static_cast<double>(cycle);
    t.q_cmd_rad[j] = 0.1 * j;
  }
  t.wrench = {1.5, -2.25, 3.0, 0.125, -0.5, 0.0};
  return t;
}

}  // namespace foresight::journal::test
