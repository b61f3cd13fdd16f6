#pragma once
// The remote controller's journal: an SQLite database in WAL mode that
// survives kill -9, so an engineer can query it with the sqlite3 shell
// (docs/journal.md has the schema and example queries).
//
// Writers:
//   record_command / record_fault / record_upload / record_event
//     durable: each is one transaction committed with synchronous=FULL (the
//     WAL is fsync'ed at commit) and returns only once the row is on disk.
//     Call record_command(RECEIVED ...) before acknowledging a command.
//     Thread-safe (one internal mutex). Not real-time: they block on disk I/O
//     and may throw JournalError (disk full, I/O error, bad row).
//   push_telemetry
//     noexcept, allocation-free, never blocks: one producer thread (the
//     daemon's supervisor, never the control cycle) pushes into a bounded SPSC
//     ring; the journal's own thread drains it in batches, one transaction per
//     batch, with synchronous=NORMAL (a committed batch survives a process
//     crash; the last batches may roll back on power loss). A full ring drops
//     the row and counts it.
//
// Rotation: after every committed transaction, when the database passes
// max_bytes, the journal checkpoints and closes it, renames NAME.(k) to
// NAME.(k+1) (dropping NAME.keep_files), NAME to NAME.1, and opens a new NAME.
// NAME is always the newest file.
//
// Reopening an existing journal (also after kill -9) runs SQLite's WAL
// recovery and appends; previous_shutdown_clean() says whether the last
// writer closed it (false after a crash).
//
// Refusals (docs/journal.md "What the journal refuses"): the writer checks an
// existing file before it writes a byte and throws JournalError naming it when
// it is not a regular file, not an SQLite database, not a Foresight journal,
// of a newer schema (user_version), read-only (the file or its folder), or
// locked by another process; the file is left exactly as it was. Rotation
// never removes or renames a NAME.k that is not a journal: it skips, keeps
// writing into NAME and says why in stats().last_error. probe_journal() runs
// the same checks for `foresight-remote check` and writes nothing.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/journal/rows.hpp"
#include "foresight/common/spsc_ring.hpp"

namespace foresight::journal {

/// A journal file could not be opened, written or read; what() names the file.
class JournalError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

struct JournalOptions {
  static constexpr std::uint64_t kMinMaxBytes = 128 * 1024;
  std::string path = "foresight-journal.db";
  std::uint64_t max_bytes = 64ull << 20;  ///< rotate when the database passes this (>= kMinMaxBytes)
  int keep_files = 4;                     ///< rotated files kept: NAME.1 .. NAME.keep_files
  std::size_t telemetry_queue = 4096;     ///< SPSC ring capacity (rows)
  std::size_t telemetry_batch = 512;      ///< rows per transaction at most
  std::chrono::milliseconds flush_interval{100};  ///< the writer thread's period
  /// Telemetry rows accepted per second of *stamp* time (decimation in
  /// push_telemetry); 0 keeps every pushed row.
  double telemetry_rate_hz = 50.0;
  /// How long opening and each transaction wait for another connection's
  /// lock (an engineer's sqlite3 shell) before failing with "locked by
  /// another process" (SQLite's busy timeout; > 0).
  std::chrono::milliseconds busy_timeout{5000};
};

/// What probe_journal found: a journal the writer can use.
struct JournalProbe {
  bool exists = false;     ///< false: the file does not exist yet (the writer will create it)
  int schema_version = 0;  ///< PRAGMA user_version; 0 when absent or an empty database
  std::string describe;    ///< one line, e.g. "F: journal schema 1, 12 command rows, 3 faults, clean shutdown"
};

/// The pre-flight check of `foresight-remote check`: would Journal accept
/// `path`? Writes nothing and creates nothing: opens the file read-only
/// (immutable when no writer has it open) and never opens a FIFO or device.
/// Throws JournalError naming the file for everything the writer refuses:
/// a folder that does not exist or is not writable (when the file is absent),
/// not a regular file, not an SQLite database, not a Foresight journal
/// (application_id), a newer schema, read-only (the file, its folder, its
/// -wal or -shm; access(2)), or locked by another process for `lock_wait`
/// (checked, when the journal is open elsewhere, by taking and at once
/// releasing SQLite's write lock: no row, no page is written).
JournalProbe probe_journal(const std::string& path,
                           std::chrono::milliseconds lock_wait = std::chrono::milliseconds(1000));

enum class PushResult : std::uint8_t {
  Accepted,   ///< queued for the writer thread
  Decimated,  ///< within 1/telemetry_rate_hz of the last accepted row: skipped
  Dropped,    ///< the ring was full: lost, counted
};

struct JournalStats {
  std::uint64_t commands = 0, faults = 0, uploads = 0, events = 0;  ///< rows written by this instance
  std::uint64_t telemetry_accepted = 0;   ///< pushed into the ring
  std::uint64_t telemetry_decimated = 0;  ///< skipped by the rate
  std::uint64_t telemetry_dropped = 0;    ///< lost: ring full
  std::uint64_t telemetry_written = 0;    ///< rows committed
  std::uint64_t telemetry_batches = 0;    ///< transactions committed
  std::uint64_t write_errors = 0;         ///< telemetry batches that failed (rows lost)
  std::uint64_t rotations = 0;
  /// The last failure, if any: a telemetry batch of the writer thread, or a
  /// rotation skipped or failed (a file that is not a journal in the way).
  std::string last_error;
};

class Journal {
 public:
  /// Set-up: opens or creates options.path (WAL, synchronous=FULL), creates
  /// the schema, rotates first if the file is already past max_bytes, starts
  /// the writer thread. Throws JournalError naming the file, or
  /// std::invalid_argument for bad options.
  explicit Journal(JournalOptions options);
  /// Stops the writer (drains the ring), marks the shutdown clean, checkpoints.
  ~Journal();
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  /// Durable: returns once committed and fsync'ed. Throws JournalError
  /// (invalid state, I/O). Not real-time.
  void record_command(const CommandRow& row);
  /// Durable. Throws JournalError when category is not 0, 1 or 2, or on I/O.
  void record_fault(const FaultRow& row);
  void record_upload(const UploadRow& row);
  void record_event(const EventRow& row);

  /// One producer thread only. noexcept, allocation-free, never blocks.
  /// Throttled to telemetry_rate_hz by the row's stamp_ns (a row with
  /// stamp_ns == 0 is never decimated). After close() every push is Dropped.
  PushResult push_telemetry(const TelemetryRow& row) noexcept;

  /// Blocks until every telemetry row pushed before the call is committed
  /// (or failed), at most `timeout`. False on timeout. Not real-time.
  bool flush(std::chrono::milliseconds timeout = std::chrono::seconds(10));

  /// Stops the writer thread after draining, marks the shutdown clean and
  /// closes the database. Idempotent; the destructor calls it. Recording after
  /// close() throws JournalError.
  void close();

  JournalStats stats() const;
  /// Diagnostics: the connection's PRAGMA synchronous between transactions
  /// (2 = FULL, what record_* commit with). Throws JournalError when closed.
  int synchronous_level() const;
  /// False when the file existed and its last writer did not close it (crash).
  bool previous_shutdown_clean() const noexcept { return previous_clean_; }
  const std::string& path() const noexcept { return options_.path; }

  /// Wall-clock now, ns since the Unix epoch (CLOCK_REALTIME).
  static std::int64_t now_ns() noexcept;

 private:
  struct Db;
  void open_db();
  void close_db(bool clean);
  void maybe_rotate();
  void rotate();
  void writer_loop();
  bool drain();  ///< true when rows may remain (round limit reached)
  void write_batch(std::size_t n);
  void note_write_error(std::string what);  ///< writer thread, under db_mu_
  void require_open() const;
  /// Empty when NAME.1 .. NAME.keep_files (and their -wal, -shm) are
  /// journals or absent; else why rotation must not touch them.
  std::string rotation_obstacle() const;

  JournalOptions options_;
  bool previous_clean_ = true;
  std::string rotation_blocked_;  ///< the last obstacle warned about (warn once per obstacle)

  mutable std::mutex db_mu_;  ///< guards db_ and the counters below
  std::unique_ptr<Db> db_;
  JournalStats stats_;

  // Telemetry: producer side (push_telemetry).
  SpscRing<TelemetryRow> ring_;
  std::int64_t period_ns_ = 0;
  std::int64_t last_accepted_ns_ = 0;
  bool any_accepted_ = false;
  std::atomic<std::uint64_t> accepted_{0}, decimated_{0}, dropped_{0};
  std::atomic<bool> closing_{false};  ///< close() began: pushes are dropped

  // Telemetry: consumer side (writer thread).
  std::vector<TelemetryRow> batch_;
  std::mutex wake_mu_;
  std::condition_variable wake_cv_, done_cv_;
  bool stop_ = false;
  std::uint64_t flush_requested_ = 0, flush_done_ = 0;
  std::thread writer_;
  bool closed_ = false;
};

}  // namespace foresight::journal
