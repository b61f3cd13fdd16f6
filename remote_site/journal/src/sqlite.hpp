#pragma once
// A thin RAII layer over the SQLite C API, shared by the journal's writer and
// reader (internal; not installed). Every failing call throws JournalError
// with the file name and SQLite's message.

#include <sqlite3.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>

#include "foresight/journal/journal.hpp"

namespace foresight::journal::detail {

/// 'FSJL': marks a database as a Foresight journal (PRAGMA application_id).
inline constexpr int kApplicationId = 0x46534A4C;
inline constexpr int kSchemaVersion = 1;

inline const char* const kSchema = R"sql(
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS commands(
  id INTEGER PRIMARY KEY, stamp_ns INTEGER NOT NULL, session_id INTEGER NOT NULL,
  command_id INTEGER NOT NULL, sequence_number INTEGER NOT NULL, kind TEXT NOT NULL,
  state TEXT NOT NULL, code TEXT NOT NULL, reason TEXT NOT NULL, detail TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS commands_stamp ON commands(stamp_ns);
CREATE INDEX IF NOT EXISTS commands_command ON commands(command_id);
CREATE TABLE IF NOT EXISTS faults(
  id INTEGER PRIMARY KEY, stamp_ns INTEGER NOT NULL, cycle INTEGER NOT NULL,
  category INTEGER NOT NULL CHECK(category IN (0, 1, 2)), cause TEXT NOT NULL,
  text TEXT NOT NULL, evidence TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS faults_stamp ON faults(stamp_ns);
CREATE TABLE IF NOT EXISTS uploads(
  id INTEGER PRIMARY KEY, stamp_ns INTEGER NOT NULL, trajectory_id INTEGER NOT NULL,
  state TEXT NOT NULL, code TEXT NOT NULL, reason TEXT NOT NULL, hash_hex TEXT NOT NULL,
  samples INTEGER NOT NULL, joints INTEGER NOT NULL);
CREATE INDEX IF NOT EXISTS uploads_stamp ON uploads(stamp_ns);
CREATE TABLE IF NOT EXISTS events(
  id INTEGER PRIMARY KEY, stamp_ns INTEGER NOT NULL, kind TEXT NOT NULL,
  text TEXT NOT NULL, detail TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS events_stamp ON events(stamp_ns);
CREATE TABLE IF NOT EXISTS telemetry(
  id INTEGER PRIMARY KEY, stamp_ns INTEGER NOT NULL, cycle INTEGER NOT NULL,
  mode INTEGER NOT NULL, joint_count INTEGER NOT NULL,
  q TEXT NOT NULL, q_cmd TEXT NOT NULL, wrench TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS telemetry_stamp ON telemetry(stamp_ns);
)sql";

/// errno in words ("Permission denied").
inline std::string errno_text(int e) { return std::error_code(e, std::generic_category()).message(); }

/// The folder `path` is in: "." for a bare file name.
inline std::string folder_of(const std::string& path) {
  const auto slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

/// Why a writer cannot write `path`, by access(2) (so also right for root,
/// whom chmod does not stop, and for a read-only file system): "the file is
/// not writable (Permission denied)" or "its folder D is not writable (...)";
/// empty when both are writable. The folder must be writable because SQLite
/// creates NAME-wal and NAME-shm beside NAME and rotation renames in it.
inline std::string unwritable_reason(const std::string& path) {
  if (::access(path.c_str(), F_OK) == 0 && ::access(path.c_str(), W_OK) != 0) {
    const int e = errno;
    return "the file is not writable (" + errno_text(e) + ")";
  }
  const std::string dir = folder_of(path);
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    const int e = errno;
    return "its folder " + dir + " is not writable (" + errno_text(e) + ")";
  }
  return {};
}

/// What an SQLite failure on `path` means for the operator, or empty:
/// SQLITE_NOTADB "not a journal database", SQLITE_BUSY / SQLITE_LOCKED
/// "locked by another process", SQLITE_READONLY "read-only: <why>",
/// SQLITE_CANTOPEN the folder or the permission that stopped it.
inline std::string cause_of(const std::string& path, int rc) {
  switch (rc & 0xff) {
    case SQLITE_NOTADB:
      return "not a journal database";
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      return "locked by another process";
    case SQLITE_READONLY: {
      const std::string why = unwritable_reason(path);
      return "read-only: " + (why.empty() ? std::string("SQLite could not write to the file or its folder") : why);
    }
    case SQLITE_CANTOPEN: {
      const std::string dir = folder_of(path);
      if (::access(dir.c_str(), F_OK) != 0) return "its folder " + dir + " does not exist";
      const std::string why = unwritable_reason(path);
      return why.empty() ? std::string() : "read-only: " + why;
    }
    default:
      return {};
  }
}

/// SQLite's message with cause_of() appended in parentheses when there is one.
inline std::string with_cause(const std::string& path, std::string msg, int rc) {
  const std::string cause = cause_of(path, rc);
  return cause.empty() ? msg : msg + " (" + cause + ")";
}

class Connection {
 public:
  Connection() = default;
  /// flags: SQLITE_OPEN_* (no SQLITE_OPEN_CREATE for readers). `uri`, when
  /// given, is what SQLite opens (a file: URI, with SQLITE_OPEN_URI); `path`
  /// names the file in messages.
  Connection(const std::string& path, int flags, const std::string& uri = {}) : path_(path) {
    const int rc = sqlite3_open_v2(uri.empty() ? path.c_str() : uri.c_str(), &db_, flags, nullptr);
    if (rc != SQLITE_OK) {
      const std::string msg = db_ != nullptr ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
      const int code = db_ != nullptr ? sqlite3_extended_errcode(db_) : rc;
      sqlite3_close(db_);
      db_ = nullptr;
      throw JournalError(path + ": cannot open journal: " + with_cause(path, msg, code));
    }
    sqlite3_extended_result_codes(db_, 1);
  }
  ~Connection() { sqlite3_close(db_); }
  Connection(Connection&& o) noexcept : db_(std::exchange(o.db_, nullptr)), path_(std::move(o.path_)) {}
  Connection& operator=(Connection&& o) noexcept {
    if (this != &o) {
      sqlite3_close(db_);
      db_ = std::exchange(o.db_, nullptr);
      path_ = std::move(o.path_);
    }
    return *this;
  }

  sqlite3* get() const noexcept { return db_; }
  const std::string& path() const noexcept { return path_; }

  /// The last failure's extended result code (SQLITE_BUSY, SQLITE_NOTADB ...).
  int errcode() const noexcept { return sqlite3_extended_errcode(db_); }

  [[noreturn]] void fail(std::string_view what) const {
    throw JournalError(path_ + ": " + std::string(what) + ": " + with_cause(path_, sqlite3_errmsg(db_), errcode()));
  }
  void exec(const char* sql) const {
    char* err = nullptr;
    const int rc = sqlite3_exec(db_, sql, nullptr, nullptr, &err);
    if (rc != SQLITE_OK) {
      const std::string msg = err != nullptr ? err : sqlite3_errmsg(db_);
      sqlite3_free(err);
      throw JournalError(path_ + ": " + with_cause(path_, msg, sqlite3_extended_errcode(db_)));
    }
  }

 private:
  sqlite3* db_ = nullptr;
  std::string path_;
};

class Statement {
 public:
  Statement() = default;
  Statement(const Connection& c, const char* sql) : conn_(&c) {
    if (sqlite3_prepare_v2(c.get(), sql, -1, &stmt_, nullptr) != SQLITE_OK) c.fail("cannot prepare statement");
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(Statement&& o) noexcept : conn_(o.conn_), stmt_(std::exchange(o.stmt_, nullptr)) {}
  Statement& operator=(Statement&& o) noexcept {
    if (this != &o) {
      sqlite3_finalize(stmt_);
      conn_ = o.conn_;
      stmt_ = std::exchange(o.stmt_, nullptr);
    }
    return *this;
  }

  Statement& bind(int i, std::int64_t v) {
    check(sqlite3_bind_int64(stmt_, i, v));
    return *this;
  }
  Statement& bind_u64(int i, std::uint64_t v) { return bind(i, static_cast<std::int64_t>(v)); }
  Statement& bind(int i, double v) {
    check(sqlite3_bind_double(stmt_, i, v));
    return *this;
  }
  /// The text must outlive step() (bound without a copy).
  Statement& bind(int i, std::string_view v) {
    check(sqlite3_bind_text(stmt_, i, v.data(), static_cast<int>(v.size()), SQLITE_STATIC));
    return *this;
  }
  /// True when a row is available, false when done; throws on error.
  bool step() {
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    conn_->fail("statement failed");
  }
  /// step() to completion, then reset for reuse.
  void run() {
    try {
      while (step()) {
      }
    } catch (...) {
      reset();
      throw;
    }
    reset();
  }
  void reset() noexcept {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }

  std::int64_t int64(int col) const noexcept { return sqlite3_column_int64(stmt_, col); }
  std::uint64_t u64(int col) const noexcept { return static_cast<std::uint64_t>(int64(col)); }
  std::string text(int col) const {
    const auto* p = sqlite3_column_text(stmt_, col);
    return p != nullptr ? std::string(reinterpret_cast<const char*>(p),
                                      static_cast<std::size_t>(sqlite3_column_bytes(stmt_, col)))
                        : std::string();
  }

 private:
  void check(int rc) const {
    if (rc != SQLITE_OK) conn_->fail("cannot bind parameter");
  }
  const Connection* conn_ = nullptr;
  sqlite3_stmt* stmt_ = nullptr;
};

/// One integer from a one-row query (e.g. a PRAGMA).
inline std::int64_t query_int(const Connection& c, const char* sql) {
  Statement s(c, sql);
  return s.step() ? s.int64(0) : 0;
}

/// "file:" URI of `path` (percent-encoding all but [A-Za-z0-9/._~-]).
inline std::string file_uri(const std::string& path) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string uri = "file:";
  for (const char ch : path) {
    const auto u = static_cast<unsigned char>(ch);
    if ((u >= 'A' && u <= 'Z') || (u >= 'a' && u <= 'z') || (u >= '0' && u <= '9') || u == '/' || u == '.' ||
        u == '_' || u == '~' || u == '-') {
      uri += ch;
    } else {
      uri += '%';
      uri += kHex[u >> 4];
      uri += kHex[u & 15];
    }
  }
  return uri;
}

/// Opens an existing `path` for reading without writing or creating anything
/// beside it. Without a NAME-wal (or a rollback NAME-journal) no writer has it
/// open and nothing committed is outside the main file: opened immutable (no
/// -wal, no -shm, no locks). With one, read-only (SQLITE_OPEN_READONLY) so
/// the WAL's rows are seen and locks respected; SQLite may then create a
/// missing NAME-shm, its scratch index.
inline Connection open_readonly(const std::string& path, int busy_ms) {
  const bool wal = ::access((path + "-wal").c_str(), F_OK) == 0 || ::access((path + "-journal").c_str(), F_OK) == 0;
  Connection c = wal ? Connection(path, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX)
                     : Connection(path, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX | SQLITE_OPEN_URI,
                                  file_uri(path) + "?immutable=1");
  sqlite3_busy_timeout(c.get(), busy_ms);
  return c;
}

}  // namespace foresight::journal::detail
