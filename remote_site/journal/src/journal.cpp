#include "foresight/journal/journal.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <system_error>

#include <spdlog/spdlog.h>

#include "sqlite.hpp"

namespace foresight::journal {

using detail::Connection;
using detail::Statement;
namespace fs = std::filesystem;

struct Journal::Db {
  Connection conn;
  Statement insert_command, insert_fault, insert_upload, insert_event, insert_telemetry;
  Statement begin, commit, page_count;
  std::int64_t page_size = 4096;
};

namespace {

bool valid_state(const std::string& s) {
  return std::any_of(kCommandStates.begin(), kCommandStates.end(), [&](const char* k) { return s == k; });
}

/// "[a,b,c]" with the shortest round-trip form of each double; writes into
/// `buf` (large enough for 16 doubles), returns the text.
std::string_view json_array(const double* v, std::size_t n, char* buf, std::size_t cap) {
  char* p = buf;
  char* const end = buf + cap;
  *p++ = '[';
  for (std::size_t i = 0; i < n; ++i) {
    if (i > 0) *p++ = ',';
    if (std::isfinite(v[i])) {
      p = std::to_chars(p, end - 1, v[i]).ptr;
    } else {
      // JSON has no NaN/inf: null keeps the array's length and index meaning.
      for (const char c : std::string_view("null")) *p++ = c;
    }
  }
  *p++ = ']';
  return {buf, static_cast<std::size_t>(p - buf)};
}

std::string rotated_name(const std::string& path, int i) { return path + "." + std::to_string(i); }

void remove_db_files(const std::string& path) {
  std::error_code ec;
  fs::remove(path, ec);
  fs::remove(path + "-wal", ec);
  fs::remove(path + "-shm", ec);
}

int millis(std::chrono::milliseconds t) {
  return static_cast<int>(std::clamp<std::int64_t>(t.count(), 0, INT_MAX));
}

/// "a directory", "a FIFO" ...: what a file that is not a regular file is.
std::string file_kind(mode_t m) {
  if (S_ISDIR(m)) return "a directory";
  if (S_ISFIFO(m)) return "a FIFO";
  if (S_ISSOCK(m)) return "a socket";
  if (S_ISCHR(m)) return "a character device";
  if (S_ISBLK(m)) return "a block device";
  if (S_ISLNK(m)) return "a symbolic link";
  return "not a regular file";
}

bool busy(int code) { return (code & 0xff) == SQLITE_BUSY || (code & 0xff) == SQLITE_LOCKED; }

std::string locked_message(const std::string& path, int waited_ms, const std::string& sqlite_msg) {
  return path + ": locked by another process: no write lock within " + std::to_string(waited_ms) + " ms (" +
         sqlite_msg + "); is another foresight-remote or an sqlite3 shell writing to it?";
}

std::string newer_schema_message(const std::string& path, std::int64_t version) {
  return path + ": journal schema version " + std::to_string(version) + " is newer than this controller's " +
         std::to_string(detail::kSchemaVersion) +
         " (written by a newer foresight-remote): refusing to write to it; move it aside or upgrade";
}

/// What an existing file holds, read without writing anything.
struct Inspection {
  bool exists = false;
  std::int64_t app_id = 0;
  std::int64_t schema = 0;  ///< PRAGMA user_version
  std::int64_t tables = 0;
  bool wal_mode = false;  ///< the header's read version is 2 (journal_mode=WAL)
  bool blank() const { return app_id == 0 && tables == 0; }  ///< an empty database: the writer initialises it
};

/// Everything the writer refuses, checked before it opens the file for
/// writing (so a refused file is left exactly as it was). Throws
/// JournalError naming `path`. Never opens a FIFO or a device (stat first);
/// reads an existing file through detail::open_readonly. Does not look for
/// locks: the writer learns those from its first write transaction, the
/// probe separately.
Inspection inspect(const std::string& path, int busy_ms) {
  Inspection in;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int e = errno;
    if (e != ENOENT) throw JournalError(path + ": cannot open journal: " + detail::errno_text(e));
    const std::string dir = detail::folder_of(path);
    struct stat ds {};
    if (::stat(dir.c_str(), &ds) != 0)
      throw JournalError(path + ": cannot create the journal: its folder " + dir + " does not exist");
    if (!S_ISDIR(ds.st_mode))
      throw JournalError(path + ": cannot create the journal: " + dir + " is not a folder");
    if (::access(dir.c_str(), W_OK | X_OK) != 0) {
      const int e = errno;
      throw JournalError(path + ": read-only: cannot create the journal: its folder " + dir + " is not writable (" +
                         detail::errno_text(e) + ")");
    }
    return in;
  }
  in.exists = true;
  if (!S_ISREG(st.st_mode)) throw JournalError(path + ": not a regular file (" + file_kind(st.st_mode) + ")");
  if (::access(path.c_str(), R_OK) != 0) {
    const int e = errno;
    throw JournalError(path + ": cannot read the journal: " + detail::errno_text(e));
  }
  {
    const detail::Connection c = detail::open_readonly(path, busy_ms);
    try {
      in.app_id = detail::query_int(c, "PRAGMA application_id");  // garbage fails here: "(not a journal database)"
      in.schema = detail::query_int(c, "PRAGMA user_version");
      in.tables = detail::query_int(c, "SELECT count(*) FROM sqlite_master");
    } catch (const JournalError&) {
      // A rollback-mode writer's exclusive lock keeps even readers out.
      if (busy(c.errcode())) throw JournalError(locked_message(path, busy_ms, sqlite3_errmsg(c.get())));
      throw;
    }
  }
  {
    std::ifstream f(path, std::ios::binary);
    char header[20] = {};
    f.read(header, sizeof header);
    in.wal_mode = f.gcount() == sizeof header && header[18] == 2;
  }
  if (in.app_id != detail::kApplicationId && !in.blank())
    throw JournalError(path + ": not a Foresight journal (application_id " + std::to_string(in.app_id) + ")");
  if (in.schema > detail::kSchemaVersion) throw JournalError(newer_schema_message(path, in.schema));
  if (const std::string why = detail::unwritable_reason(path); !why.empty())
    throw JournalError(path + ": read-only: " + why);
  for (const char* suffix : {"-wal", "-shm"}) {
    const std::string f = path + suffix;
    if (::access(f.c_str(), F_OK) == 0 && ::access(f.c_str(), W_OK) != 0) {
      const int e = errno;
      throw JournalError(path + ": read-only: " + f + " is not writable (" + detail::errno_text(e) + ")");
    }
  }
  return in;
}

/// Empty when `path` is absent or a Foresight journal: a regular file with
/// SQLite's header and our application_id (read from the header, bytes 68..71,
/// big-endian; a rotated file is checkpointed, so its header is complete).
/// Else what it is, for the message. `companion`: a NAME-wal or NAME-shm,
/// SQLite's own when empty or starting with its magic.
std::string not_ours(const std::string& path, char companion = 0) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    const int e = errno;
    return e == ENOENT ? std::string() : detail::errno_text(e);
  }
  if (!S_ISREG(st.st_mode)) return file_kind(st.st_mode);
  std::array<unsigned char, 100> h{};
  std::ifstream in(path, std::ios::binary);
  if (!in) return "unreadable";
  in.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()));
  const auto n = static_cast<std::size_t>(in.gcount());
  const auto be32 = [&](std::size_t at) {
    return (std::uint32_t{h[at]} << 24) | (std::uint32_t{h[at + 1]} << 16) | (std::uint32_t{h[at + 2]} << 8) | h[at + 3];
  };
  if (companion == 'w') {  // WAL header magic 0x377f0682 / 0x377f0683
    if (n == 0 || (n >= 4 && (be32(0) & 0xFFFFFFFEu) == 0x377F0682u)) return {};
    return "not an SQLite WAL file";
  }
  if (companion == 's') {  // the wal-index: iVersion 3007000, native order; SQLite truncates it to 3 bytes at times
    std::uint32_t version = 0;
    if (n >= 4) std::memcpy(&version, h.data(), 4);
    if (n < 4 || version == 3007000u) return {};
    return "not an SQLite shared-memory file";
  }
  if (n < h.size() || std::memcmp(h.data(), "SQLite format 3", 16) != 0) return "not an SQLite database";
  const std::uint32_t app_id = be32(68);
  if (app_id != static_cast<std::uint32_t>(detail::kApplicationId))
    return "an SQLite database with application_id " + std::to_string(static_cast<std::int32_t>(app_id));
  return {};
}

}  // namespace

JournalProbe probe_journal(const std::string& path, std::chrono::milliseconds lock_wait) {
  if (path.empty()) throw JournalError("journal: path is empty");
  const int wait_ms = millis(lock_wait);
  const Inspection in = inspect(path, wait_ms);
  JournalProbe p;
  p.exists = in.exists;
  if (!in.exists) {
    p.describe = path + ": does not exist yet: will be created";
    return p;
  }
  if (in.blank()) {
    p.describe = path + ": an empty SQLite database: will be initialised as a journal (schema " +
                 std::to_string(detail::kSchemaVersion) + ")";
    return p;
  }
  p.schema_version = static_cast<int>(in.schema);
  // Locked: only a connection that has the journal open in WAL mode can hold
  // its write lock, and such a connection has NAME-wal and NAME-shm. Then take
  // SQLite's write lock and give it back at once (BEGIN IMMEDIATE; ROLLBACK:
  // nothing written), on a connection that neither creates files nor
  // checkpoints on close. (fcntl(F_GETLK) on our own descriptor would be
  // lighter, but closing it drops every POSIX lock this process holds on the
  // file: SQLite's own, if this process has the journal open.)
  // A database in rollback mode (journal_mode=DELETE: not ours, but someone
  // may have switched it) is locked on the main file: check it the same way
  // unless a NAME-journal exists (a read-write connection would roll it back).
  std::error_code ec;
  const bool wal_open = fs::exists(path + "-wal", ec) && fs::exists(path + "-shm", ec);
  const bool rollback_mode = !in.wal_mode && !fs::exists(path + "-journal", ec);
  if (wal_open || rollback_mode) {
    const Connection c(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX);
    sqlite3_db_config(c.get(), SQLITE_DBCONFIG_NO_CKPT_ON_CLOSE, 1, static_cast<int*>(nullptr));
    sqlite3_busy_timeout(c.get(), wait_ms);
    const int rc = sqlite3_exec(c.get(), "BEGIN IMMEDIATE", nullptr, nullptr, nullptr);
    if (rc != SQLITE_OK) {
      const int code = c.errcode();
      const std::string msg = sqlite3_errmsg(c.get());
      if (busy(code)) throw JournalError(locked_message(path, wait_ms, msg));
      throw JournalError(path + ": cannot lock the journal: " + detail::with_cause(path, msg, code));
    }
    sqlite3_exec(c.get(), "ROLLBACK", nullptr, nullptr, nullptr);
  }
  const Connection c = detail::open_readonly(path, wait_ms);
  const std::int64_t commands = detail::query_int(c, "SELECT count(*) FROM commands");
  const std::int64_t faults = detail::query_int(c, "SELECT count(*) FROM faults");
  std::string clean = "no shutdown recorded";
  {
    Statement q(c, "SELECT value FROM meta WHERE key='clean_shutdown'");
    if (q.step()) clean = q.text(0) == "1" ? "clean shutdown" : "not shut down cleanly (still running, or it crashed)";
  }
  p.describe = path + ": journal schema " + std::to_string(in.schema) + ", " + std::to_string(commands) +
               (commands == 1 ? " command row, " : " command rows, ") + std::to_string(faults) +
               (faults == 1 ? " fault, " : " faults, ") + clean;
  return p;
}

std::int64_t Journal::now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

Journal::Journal(JournalOptions options) : options_(std::move(options)), ring_(options_.telemetry_queue) {
  if (options_.path.empty()) throw std::invalid_argument("journal: path is empty");
  // An empty journal (schema, indexes) is ~13 pages (53 KB): a smaller bound
  // would rotate after every transaction.
  if (options_.max_bytes < JournalOptions::kMinMaxBytes) throw std::invalid_argument("journal: max_bytes must be at least 131072");
  if (options_.keep_files < 0) throw std::invalid_argument("journal: keep_files must be >= 0");
  if (options_.telemetry_batch == 0) throw std::invalid_argument("journal: telemetry_batch must be positive");
  if (options_.flush_interval.count() <= 0) throw std::invalid_argument("journal: flush_interval must be positive");
  if (!(options_.telemetry_rate_hz >= 0.0) || !std::isfinite(options_.telemetry_rate_hz))
    throw std::invalid_argument("journal: telemetry_rate_hz must be finite and >= 0");
  if (options_.busy_timeout.count() <= 0) throw std::invalid_argument("journal: busy_timeout must be positive");
  period_ns_ = options_.telemetry_rate_hz > 0.0 ? static_cast<std::int64_t>(1e9 / options_.telemetry_rate_hz) : 0;
  batch_.resize(options_.telemetry_batch);

  {
    std::lock_guard lk(db_mu_);
    open_db();
    maybe_rotate();
  }
  writer_ = std::thread([this] { writer_loop(); });
}

Journal::~Journal() {
  try {
    close();
  } catch (...) {
    // A destructor must not throw; the rows already committed stay on disk.
  }
}

void Journal::open_db() {
  const std::string& path = options_.path;
  const int busy_ms = millis(options_.busy_timeout);
  // Everything we refuse, before the file is opened for writing.
  const bool existed = inspect(path, busy_ms).exists;
  auto db = std::make_unique<Db>();
  db->conn = Connection(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX);
  Connection& c = db->conn;
  sqlite3_busy_timeout(c.get(), busy_ms);  // an engineer's sqlite3 shell may hold a lock briefly
  if (sqlite3_db_readonly(c.get(), "main") == 1) {
    const std::string why = detail::unwritable_reason(path);
    throw JournalError(path + ": read-only: " + (why.empty() ? std::string("SQLite opened it read-only") : why));
  }

  try {
    Statement wal(c, "PRAGMA journal_mode=WAL");  // switching from rollback mode needs the file's lock
    if (!wal.step() || wal.text(0) != "wal") throw JournalError(options_.path + ": cannot switch to WAL mode");
  } catch (const JournalError&) {
    if (busy(c.errcode())) throw JournalError(locked_message(path, busy_ms, sqlite3_errmsg(c.get())));
    throw;
  }
  c.exec("PRAGMA synchronous=FULL");
  // Keep the -wal file from staying large after checkpoints (the size bound).
  c.exec("PRAGMA journal_size_limit=1048576");
  if (sqlite3_exec(c.get(), "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK) {
    const int code = c.errcode();
    const std::string msg = sqlite3_errmsg(c.get());
    if (busy(code)) throw JournalError(locked_message(path, busy_ms, msg));
    throw JournalError(path + ": cannot start a transaction: " + detail::with_cause(path, msg, code));
  }
  try {
    // Again under the write lock: another writer may have changed the file
    // since inspect(). Nothing is written yet; a refusal rolls back.
    const std::int64_t app_id = detail::query_int(c, "PRAGMA application_id");
    const std::int64_t tables = detail::query_int(c, "SELECT count(*) FROM sqlite_master");
    const std::int64_t schema = detail::query_int(c, "PRAGMA user_version");
    if (app_id != detail::kApplicationId && (app_id != 0 || tables != 0))
      throw JournalError(path + ": not a Foresight journal (application_id " + std::to_string(app_id) + ")");
    if (schema > detail::kSchemaVersion) throw JournalError(newer_schema_message(path, schema));
    c.exec(detail::kSchema);
    c.exec(("PRAGMA application_id=" + std::to_string(detail::kApplicationId)).c_str());
    c.exec(("PRAGMA user_version=" + std::to_string(detail::kSchemaVersion)).c_str());
    {
      Statement q(c, "SELECT value FROM meta WHERE key='clean_shutdown'");
      if (existed && q.step() && q.text(0) == "0") previous_clean_ = false;
    }
    Statement up(c, "INSERT INTO meta(key, value) VALUES(?1, ?2) ON CONFLICT(key) DO UPDATE SET value=excluded.value");
    up.bind(1, std::string_view("clean_shutdown")).bind(2, std::string_view("0")).run();
    const std::string now = std::to_string(now_ns());
    Statement ins(c, "INSERT OR IGNORE INTO meta(key, value) VALUES('created_ns', ?1)");
    ins.bind(1, std::string_view(now)).run();
    c.exec("COMMIT");
  } catch (...) {
    sqlite3_exec(c.get(), "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }

  db->page_size = detail::query_int(c, "PRAGMA page_size");
  db->insert_command = Statement(c,
      "INSERT INTO commands(stamp_ns, session_id, command_id, sequence_number, kind, state, code, reason, detail)"
      " VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)");
  db->insert_fault = Statement(c,
      "INSERT INTO faults(stamp_ns, cycle, category, cause, text, evidence) VALUES(?1, ?2, ?3, ?4, ?5, ?6)");
  db->insert_upload = Statement(c,
      "INSERT INTO uploads(stamp_ns, trajectory_id, state, code, reason, hash_hex, samples, joints)"
      " VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)");
  db->insert_event = Statement(c, "INSERT INTO events(stamp_ns, kind, text, detail) VALUES(?1, ?2, ?3, ?4)");
  db->insert_telemetry = Statement(c,
      "INSERT INTO telemetry(stamp_ns, cycle, mode, joint_count, q, q_cmd, wrench)"
      " VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7)");
  db->begin = Statement(c, "BEGIN");
  db->commit = Statement(c, "COMMIT");
  // Never prepare "PRAGMA synchronous=...": SQLite applies it when the
  // statement is *compiled*, so a prepared NORMAL would silently turn the
  // connection's durable commits into non-fsync'ed ones. write_batch execs them.
  db->page_count = Statement(c, "PRAGMA page_count");
  db_ = std::move(db);
}

void Journal::close_db(bool clean) {
  if (!db_) return;
  if (clean) {
    Statement up(db_->conn, "UPDATE meta SET value='1' WHERE key='clean_shutdown'");
    up.run();
  }
  db_.reset();  // the last connection closing checkpoints and removes the -wal file
}

void Journal::require_open() const {
  if (!db_) throw JournalError(options_.path + ": journal is closed");
}

void Journal::maybe_rotate() {
  Statement& pc = db_->page_count;
  const std::int64_t pages = pc.step() ? pc.int64(0) : 0;
  pc.reset();
  if (static_cast<std::uint64_t>(pages * db_->page_size) > options_.max_bytes) rotate();
}

std::string Journal::rotation_obstacle() const {
  for (int i = 1; i <= options_.keep_files; ++i) {
    const std::string f = rotated_name(options_.path, i);
    if (std::string why = not_ours(f); !why.empty()) return f + " is not a Foresight journal (" + why + ")";
    for (const char* suffix : {"-wal", "-shm"})
      if (std::string why = not_ours(f + suffix, suffix[1]); !why.empty())
        return f + suffix + " is not SQLite's (" + why + ")";
  }
  return {};
}

void Journal::rotate() {
  // Rotation removes NAME.keep_files and renames the others: never a file that
  // is not a journal (someone's notes named journal.db.1, a folder). Then keep
  // journaling into NAME past max_bytes, say why (warn once), retry next time.
  if (const std::string obstacle = rotation_obstacle(); !obstacle.empty()) {
    stats_.last_error = options_.path + ": not rotating: " + obstacle +
                        "; left untouched, journaling goes on in " + options_.path +
                        " past max_bytes until it is moved aside";
    if (obstacle != rotation_blocked_) {
      spdlog::warn("journal: {}", stats_.last_error);
      rotation_blocked_ = obstacle;
    }
    return;
  }
  rotation_blocked_.clear();
  // Everything into the main file first: a rotated file must stand alone
  // without its -wal. A reader holding an old snapshot can keep the
  // checkpoint from completing; then try again after the next transaction.
  int log_frames = 0, checkpointed = 0;
  const int rc = sqlite3_wal_checkpoint_v2(db_->conn.get(), nullptr, SQLITE_CHECKPOINT_TRUNCATE, &log_frames,
                                           &checkpointed);
  if (rc != SQLITE_OK || log_frames != checkpointed) return;
  close_db(true);

  const std::string& p = options_.path;
  std::error_code ec;
  if (options_.keep_files == 0) {
    remove_db_files(p);
  } else {
    remove_db_files(rotated_name(p, options_.keep_files));
    // A -wal or -shm left beside a rotated file (a read-only reader's) moves
    // with it: never attached to another file's data.
    for (int i = options_.keep_files - 1; i >= 1; --i)
      for (const char* suffix : {"", "-wal", "-shm"})
        if (fs::exists(rotated_name(p, i) + suffix, ec))
          fs::rename(rotated_name(p, i) + suffix, rotated_name(p, i + 1) + suffix, ec);
    ec.clear();
    fs::rename(p, rotated_name(p, 1), ec);
    if (ec) {
      // Keep journaling into the same (oversized) file; the next transaction
      // tries again. The row that triggered this is already committed.
      stats_.last_error = p + ": cannot rotate to " + rotated_name(p, 1) + ": " + ec.message();
      open_db();
      return;
    }
    fs::remove(p + "-wal", ec);
    fs::remove(p + "-shm", ec);
  }
  ++stats_.rotations;
  open_db();
}

void Journal::record_command(const CommandRow& r) {
  if (!valid_state(r.state))
    throw JournalError(options_.path + ": unknown command state '" + r.state +
                       "' (expected RECEIVED, REJECTED, QUEUED, EXECUTING, COMPLETED, FAILED or CANCELED)");
  std::lock_guard lk(db_mu_);
  require_open();
  db_->insert_command.bind(1, r.stamp_ns != 0 ? r.stamp_ns : now_ns())
      .bind_u64(2, r.session_id)
      .bind_u64(3, r.command_id)
      .bind_u64(4, r.sequence_number)
      .bind(5, std::string_view(r.kind))
      .bind(6, std::string_view(r.state))
      .bind(7, std::string_view(r.code))
      .bind(8, std::string_view(r.reason))
      .bind(9, std::string_view(r.detail))
      .run();  // autocommit: one transaction, WAL fsync'ed (synchronous=FULL)
  ++stats_.commands;
  maybe_rotate();
}

void Journal::record_fault(const FaultRow& r) {
  if (r.category < 0 || r.category > 2)
    throw JournalError(options_.path + ": fault category must be 0, 1 or 2, got " + std::to_string(r.category));
  std::lock_guard lk(db_mu_);
  require_open();
  db_->insert_fault.bind(1, r.stamp_ns != 0 ? r.stamp_ns : now_ns())
      .bind_u64(2, r.cycle)
      .bind(3, static_cast<std::int64_t>(r.category))
      .bind(4, std::string_view(r.cause))
      .bind(5, std::string_view(r.text))
      .bind(6, std::string_view(r.evidence))
      .run();
  ++stats_.faults;
  maybe_rotate();
}

void Journal::record_upload(const UploadRow& r) {
  std::lock_guard lk(db_mu_);
  require_open();
  db_->insert_upload.bind(1, r.stamp_ns != 0 ? r.stamp_ns : now_ns())
      .bind_u64(2, r.trajectory_id)
      .bind(3, std::string_view(r.state))
      .bind(4, std::string_view(r.code))
      .bind(5, std::string_view(r.reason))
      .bind(6, std::string_view(r.hash_hex))
      .bind(7, static_cast<std::int64_t>(r.samples))
      .bind(8, static_cast<std::int64_t>(r.joints))
      .run();
  ++stats_.uploads;
  maybe_rotate();
}

void Journal::record_event(const EventRow& r) {
  std::lock_guard lk(db_mu_);
  require_open();
  db_->insert_event.bind(1, r.stamp_ns != 0 ? r.stamp_ns : now_ns())
      .bind(2, std::string_view(r.kind))
      .bind(3, std::string_view(r.text))
      .bind(4, std::string_view(r.detail))
      .run();
  ++stats_.events;
  maybe_rotate();
}

PushResult Journal::push_telemetry(const TelemetryRow& row) noexcept {
  if (closing_.load(std::memory_order_relaxed)) {  // nobody would write it
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return PushResult::Dropped;
  }
  if (period_ns_ > 0 && row.stamp_ns != 0) {
    if (any_accepted_ && row.stamp_ns - last_accepted_ns_ < period_ns_) {
      decimated_.fetch_add(1, std::memory_order_relaxed);
      return PushResult::Decimated;
    }
  }
  if (!ring_.try_push(row)) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return PushResult::Dropped;
  }
  if (row.stamp_ns != 0) {
    last_accepted_ns_ = row.stamp_ns;
    any_accepted_ = true;
  }
  accepted_.fetch_add(1, std::memory_order_relaxed);
  return PushResult::Accepted;
}

bool Journal::flush(std::chrono::milliseconds timeout) {
  std::unique_lock lk(wake_mu_);
  if (!writer_.joinable() || stop_) return true;
  const std::uint64_t ticket = ++flush_requested_;
  wake_cv_.notify_one();
  return done_cv_.wait_for(lk, timeout, [&] { return flush_done_ >= ticket; });
}

void Journal::writer_loop() {
  bool backlog = false;
  for (;;) {
    bool stopping = false;
    std::uint64_t ticket = 0;
    {
      std::unique_lock lk(wake_mu_);
      // With a backlog (the producer outpaced one drain) go on at once.
      if (!backlog)
        wake_cv_.wait_for(lk, options_.flush_interval, [&] { return stop_ || flush_requested_ != flush_done_; });
      stopping = stop_;
      ticket = flush_requested_;
    }
    // Every row pushed before `ticket` was taken is in the ring now, and drain()
    // pops at least a ring's worth in FIFO order: those rows are all written.
    backlog = drain();
    {
      std::lock_guard lk(wake_mu_);
      flush_done_ = ticket;
    }
    done_cv_.notify_all();
    if (stopping) return;
  }
}

bool Journal::drain() {
  // Bounded: at least one ring's worth (so a flush is complete), at most a few
  // batches more, so a fast producer cannot hold the writer here for ever.
  const std::size_t max_rounds = ring_.capacity() / batch_.size() + 4;
  for (std::size_t round = 0; round < max_rounds; ++round) {
    std::size_t n = 0;
    while (n < batch_.size() && ring_.try_pop(batch_[n])) ++n;
    if (n > 0) write_batch(n);
    if (n < batch_.size()) return false;
  }
  return true;
}

void Journal::write_batch(std::size_t n) {
  std::lock_guard lk(db_mu_);
  if (!db_) {
    note_write_error(options_.path + ": journal is closed; " + std::to_string(n) + " telemetry rows lost");
    return;
  }
  Db& d = *db_;
  char q[16 * 32 + 4], qc[16 * 32 + 4], w[6 * 32 + 4];
  try {
    d.conn.exec("PRAGMA synchronous=NORMAL");  // a batch may roll back on power loss, never on a crash
    d.begin.run();
    try {
      for (std::size_t i = 0; i < n; ++i) {
        const TelemetryRow& r = batch_[i];
        const std::size_t nj = std::min<std::size_t>(r.joint_count, TelemetryRow::kMaxJoints);
        d.insert_telemetry.bind(1, r.stamp_ns != 0 ? r.stamp_ns : now_ns())
            .bind_u64(2, r.cycle)
            .bind(3, static_cast<std::int64_t>(r.mode))
            .bind(4, static_cast<std::int64_t>(nj))
            .bind(5, json_array(r.q_rad.data(), nj, q, sizeof q))
            .bind(6, json_array(r.q_cmd_rad.data(), nj, qc, sizeof qc))
            .bind(7, json_array(r.wrench.data(), 6, w, sizeof w))
            .run();
      }
      d.commit.run();
    } catch (...) {
      sqlite3_exec(d.conn.get(), "ROLLBACK", nullptr, nullptr, nullptr);
      d.conn.exec("PRAGMA synchronous=FULL");
      throw;
    }
    d.conn.exec("PRAGMA synchronous=FULL");
    stats_.telemetry_written += n;
    ++stats_.telemetry_batches;
    maybe_rotate();
  } catch (const std::exception& e) {
    note_write_error(std::string(e.what()) + " (" + std::to_string(n) + " telemetry rows lost)");
  }
}

void Journal::note_write_error(std::string what) {
  // The writer thread: counted in stats() and logged, the first and then every
  // 100th, so a full disk does not flood the log at the telemetry rate.
  stats_.write_errors += 1;
  stats_.last_error = std::move(what);
  if (stats_.write_errors == 1 || stats_.write_errors % 100 == 0)
    spdlog::error("journal: {} ({} telemetry batch failures so far)", stats_.last_error, stats_.write_errors);
}

void Journal::close() {
  {
    std::lock_guard lk(wake_mu_);
    if (closed_) return;
    closed_ = true;
    stop_ = true;
  }
  closing_.store(true, std::memory_order_relaxed);
  wake_cv_.notify_one();
  if (writer_.joinable()) writer_.join();
  std::lock_guard lk(db_mu_);
  close_db(true);
}

int Journal::synchronous_level() const {
  std::lock_guard lk(db_mu_);
  require_open();
  return static_cast<int>(detail::query_int(db_->conn, "PRAGMA synchronous"));
}

JournalStats Journal::stats() const {
  std::lock_guard lk(db_mu_);
  JournalStats s = stats_;
  s.telemetry_accepted = accepted_.load(std::memory_order_relaxed);
  s.telemetry_decimated = decimated_.load(std::memory_order_relaxed);
  s.telemetry_dropped = dropped_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace foresight::journal
