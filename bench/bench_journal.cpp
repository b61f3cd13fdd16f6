// bench_journal: the controller journal (remote_site/journal) on this
// machine's disk (a scratch directory under $TMPDIR or /tmp; ext4 here, so
// fsync is real).
//
//   BM_RecordCommandDurable  record_command: one transaction, WAL fsync'ed
//                            (synchronous=FULL) before it returns; counters
//                            median_us / p99_us / max_us over the run
//   BM_SqliteInsertWalNormal peer: the same INSERT on a plain WAL connection
//                            with synchronous=NORMAL (no fsync at commit):
//                            what the durability costs
//   BM_TelemetrySustained    blocks of 10,000 rows pushed through the SPSC
//                            queue as fast as the writer thread commits them
//                            (retry when full), then flush: rows/s sustained
//                            end to end; counter full_retries_per_row
//   BM_PushTelemetry         push_telemetry itself into a ring with room (the
//                            supervisor's cost); the ring is drained untimed

#include <benchmark/benchmark.h>
#include <sqlite3.h>
#include <stdlib.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "foresight/journal/journal.hpp"

using namespace foresight::journal;
namespace fs = std::filesystem;

namespace {

struct Scratch {
  std::string dir;
  Scratch() {
    const char* base = std::getenv("TMPDIR");
    std::string tmpl = std::string(base != nullptr ? base : "/tmp") + "/bench_journal_XXXXXX";
    dir = mkdtemp(tmpl.data()) != nullptr ? tmpl : "/tmp";
  }
  ~Scratch() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

CommandRow sample_command(std::uint64_t id) {
  CommandRow r;
  r.session_id = 1;
  r.command_id = id;
  r.sequence_number = id;
  r.kind = "INVOKE_ALGORITHM";
  r.state = "RECEIVED";
  r.code = "NONE";
  r.detail = R"({"name":"insert","params":{"depth_m":0.05,"max_force_n":40},"timeout_s":30})";
  return r;
}

TelemetryRow sample_telemetry(std::uint64_t cycle) {
  TelemetryRow t;
  t.stamp_ns = 1'796'143'023'000'000'000 + static_cast<std::int64_t>(cycle) * 2'000'000;
  t.cycle = cycle;
  t.mode = 2;
  t.joint_count = 7;
  for (int j = 0; j < 7; ++j) {
    t.q_rad[j] = 0.1234567 * j + 1e-7 * static_cast<double>(cycle);
    t.q_cmd_rad[j] = t.q_rad[j] + 1e-5;
  }
  t.wrench = {1.25, -3.5, 12.75, 0.05, -0.125, 0.0};
  return t;
}

void add_percentiles(benchmark::State& state, std::vector<double>& us) {
  if (us.empty()) return;
  std::sort(us.begin(), us.end());
  state.counters["median_us"] = us[us.size() / 2];
  state.counters["p99_us"] = us[std::min(us.size() - 1, us.size() * 99 / 100)];
  state.counters["max_us"] = us.back();
}

void BM_RecordCommandDurable(benchmark::State& state) {
  Scratch s;
  JournalOptions o;
  o.path = s.dir + "/journal.sqlite3";
  Journal j(o);
  std::vector<double> us;
  us.reserve(100'000);
  std::uint64_t id = 0;
  const CommandRow base = sample_command(0);
  for (auto _ : state) {
    CommandRow r = base;
    r.command_id = ++id;
    const auto t0 = std::chrono::steady_clock::now();
    j.record_command(r);
    const auto t1 = std::chrono::steady_clock::now();
    if (us.size() < us.capacity()) us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  add_percentiles(state, us);
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RecordCommandDurable)->Unit(benchmark::kMicrosecond)->MinTime(2.0);

void BM_SqliteInsertWalNormal(benchmark::State& state) {
  Scratch s;
  const std::string path = s.dir + "/peer.sqlite3";
  sqlite3* db = nullptr;
  sqlite3_open(path.c_str(), &db);
  sqlite3_exec(db,
               "PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;"
               "CREATE TABLE commands(id INTEGER PRIMARY KEY, stamp_ns INTEGER, session_id INTEGER,"
               " command_id INTEGER, sequence_number INTEGER, kind TEXT, state TEXT, code TEXT, reason TEXT,"
               " detail TEXT);",
               nullptr, nullptr, nullptr);
  sqlite3_stmt* st = nullptr;
  sqlite3_prepare_v2(db,
                     "INSERT INTO commands(stamp_ns, session_id, command_id, sequence_number, kind, state, code,"
                     " reason, detail) VALUES(?1, 1, ?2, ?2, 'INVOKE_ALGORITHM', 'RECEIVED', 'NONE', '', ?3)",
                     -1, &st, nullptr);
  const CommandRow base = sample_command(0);
  std::vector<double> us;
  us.reserve(100'000);
  std::int64_t id = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    sqlite3_bind_int64(st, 1, Journal::now_ns());
    sqlite3_bind_int64(st, 2, ++id);
    sqlite3_bind_text(st, 3, base.detail.c_str(), -1, SQLITE_STATIC);
    if (sqlite3_step(st) != SQLITE_DONE) state.SkipWithError("insert failed");
    sqlite3_reset(st);
    const auto t1 = std::chrono::steady_clock::now();
    if (us.size() < us.capacity()) us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  sqlite3_finalize(st);
  sqlite3_close(db);
  add_percentiles(state, us);
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_SqliteInsertWalNormal)->Unit(benchmark::kMicrosecond);

void BM_TelemetrySustained(benchmark::State& state) {
  constexpr int kBlock = 10'000;
  Scratch s;
  JournalOptions o;
  o.path = s.dir + "/journal.sqlite3";
  o.telemetry_rate_hz = 0.0;  // keep every row
  o.telemetry_queue = 4096;
  o.telemetry_batch = static_cast<std::size_t>(state.range(0));
  o.flush_interval = std::chrono::milliseconds(5);
  o.max_bytes = 1ull << 30;
  Journal j(o);
  std::uint64_t cycle = 0, retries = 0;
  for (auto _ : state) {
    for (int i = 0; i < kBlock; ++i) {
      const TelemetryRow t = sample_telemetry(cycle++);
      // Bounded retry: the writer drains every 5 ms; 10 s is far beyond that.
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
      while (j.push_telemetry(t) == PushResult::Dropped && std::chrono::steady_clock::now() < deadline) {
        ++retries;
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    }
    if (!j.flush()) state.SkipWithError("flush timed out");
  }
  const JournalStats st = j.stats();
  state.SetItemsProcessed(static_cast<std::int64_t>(st.telemetry_written));
  state.counters["rows_written"] = static_cast<double>(st.telemetry_written);
  state.counters["batches"] = static_cast<double>(st.telemetry_batches);
  state.counters["full_retries_per_row"] =
      static_cast<double>(retries) / static_cast<double>(std::max<std::uint64_t>(1, st.telemetry_written));
  state.counters["write_errors"] = static_cast<double>(st.write_errors);
}
BENCHMARK(BM_TelemetrySustained)->Arg(64)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PushTelemetry(benchmark::State& state) {
  Scratch s;
  JournalOptions o;
  o.path = s.dir + "/journal.sqlite3";
  o.telemetry_rate_hz = 0.0;
  o.telemetry_queue = 1 << 16;
  o.flush_interval = std::chrono::hours(1);  // drained only by the flush below
  o.max_bytes = 1ull << 30;
  Journal j(o);
  const TelemetryRow t = sample_telemetry(1);
  std::uint64_t accepted = 0;
  for (auto _ : state) {
    if (j.push_telemetry(t) == PushResult::Accepted) {
      ++accepted;
    } else {  // full: drain outside the timed region, then the push is retried next iteration
      state.PauseTiming();
      j.flush();
      state.ResumeTiming();
    }
  }
  state.counters["accepted_fraction"] = static_cast<double>(accepted) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_PushTelemetry);

}  // namespace

BENCHMARK_MAIN();
