// Issue 26, "the remote refuses nonsense": the journal refuses files it must
// not write to, with what is wrong in the message, and leaves them exactly as
// they were (bytes and the folder's listing compared before and after):
// a newer schema, a read-only file or folder, a database locked by another
// connection, garbage, a foreign database, a directory, a FIFO. Rotation
// leaves files that are not journals alone. probe_journal (for
// `foresight-remote check`) says the same and writes nothing.

#include <gmock/gmock.h>
#include <grp.h>
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>

#include "../src/sqlite.hpp"  // detail::cause_of, kSchemaVersion (internal, header-only)
#include "foresight/journal/journal.hpp"
#include "foresight/journal/reader.hpp"
#include "journal_test_util.hpp"

namespace foresight::journal {
namespace {

using test::command;
using test::ScratchDir;
using test::sqlite_int;
using test::test_options;
using ::testing::HasSubstr;
namespace fs = std::filesystem;

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Every file in `dir` with its bytes: equal before and after = nothing changed.
std::map<std::string, std::string> snapshot(const std::string& dir) {
  std::map<std::string, std::string> m;
  for (const auto& e : fs::directory_iterator(dir))
    m[e.path().filename().string()] = e.is_regular_file() ? slurp(e.path().string()) : std::string("<not a file>");
  return m;
}

/// One SQL script on a plain connection; the error text or "".
std::string sql(const std::string& path, const std::string& script) {
  sqlite3* db = nullptr;
  std::string err;
  if (sqlite3_open(path.c_str(), &db) != SQLITE_OK) err = "open failed";
  char* msg = nullptr;
  if (err.empty() && sqlite3_exec(db, script.c_str(), nullptr, nullptr, &msg) != SQLITE_OK)
    err = msg != nullptr ? msg : "exec failed";
  sqlite3_free(msg);
  sqlite3_close(db);
  return err;
}

/// A closed journal with 3 command rows and 1 fault.
void make_journal(const JournalOptions& o) {
  Journal j(o);
  for (int i = 1; i <= 3; ++i) j.record_command(command(static_cast<std::uint64_t>(i)));
  j.record_fault({0, 1, 2, "estop", "E-stop input", "{}"});
}

/// The JournalError a Journal on `o` throws, or "no throw".
std::string journal_error(const JournalOptions& o) {
  try {
    Journal j(o);
    return "no throw";
  } catch (const JournalError& e) {
    return e.what();
  }
}

std::string probe_error(const std::string& path, std::chrono::milliseconds wait = std::chrono::milliseconds(1000)) {
  try {
    return "no throw: " + probe_journal(path, wait).describe;
  } catch (const JournalError& e) {
    return e.what();
  }
}

/// `work` where chmod binds: in this process when it is not root, else in a
/// forked child that drops to uid/gid 65534 (nobody). Its result, or nullopt
/// (with `why`) when root cannot drop its privileges here.
std::optional<std::string> unprivileged(const std::function<std::string()>& work, std::string& why) {
  if (::geteuid() != 0) return work();
  int fds[2];
  if (::pipe(fds) != 0) {
    why = "pipe failed";
    return std::nullopt;
  }
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    std::string out;
    if (::setgroups(0, nullptr) != 0 || ::setgid(65534) != 0 || ::setuid(65534) != 0) {
      out = std::string("\x01") + "running as root and cannot drop to uid 65534: " + std::strerror(errno);
    } else {
      try {
        out = work();
      } catch (const std::exception& e) {
        out = std::string("exception: ") + e.what();
      }
    }
    std::size_t off = 0;
    while (off < out.size()) {
      const ssize_t n = ::write(fds[1], out.data() + off, out.size() - off);
      if (n <= 0) break;
      off += static_cast<std::size_t>(n);
    }
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string out;
  char buf[512];
  ssize_t n;
  while ((n = ::read(fds[0], buf, sizeof buf)) > 0) out.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  if (!out.empty() && out[0] == '\x01') {
    why = out.substr(1);
    return std::nullopt;
  }
  return out;
}

// --- 1. a newer schema ------------------------------------------------------

TEST(JournalRefuses, ANewerSchemaAndLeavesItByteIdentical) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  ASSERT_EQ(sql(o.path, "PRAGMA user_version = 7"), "");
  const auto before = snapshot(dir.path());
  ASSERT_EQ(before.size(), 1u) << "no -wal or -shm left: the file is all there is";
  const std::string expected = o.path +
                               ": journal schema version 7 is newer than this controller's 1 (written by a newer "
                               "foresight-remote): refusing to write to it; move it aside or upgrade";
  EXPECT_EQ(journal_error(o), expected);
  EXPECT_EQ(snapshot(dir.path()), before);
  EXPECT_EQ(probe_error(o.path), expected);
  EXPECT_EQ(snapshot(dir.path()), before);
  EXPECT_EQ(sqlite_int(o.path, "PRAGMA user_version"), 7);
}

// The reader opens a newer schema read-only, says so, and reads what it knows.
TEST(JournalRefuses, ReaderReadsANewerSchemaReadOnlyWithAWarning) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  ASSERT_EQ(sql(o.path, "PRAGMA user_version = 7; CREATE TABLE later(x)"), "");
  const auto before = snapshot(dir.path());
  std::ostringstream out, err;
  ASSERT_EQ(run_journal_command({o.path, "", true}, out, err), 0) << err.str();
  const std::string warning = o.path +
                              ": journal schema version 7 is newer than this reader's 1 (written by a newer "
                              "foresight-remote): read read-only, only the columns this version knows";
  EXPECT_EQ(err.str(), "foresight-remote journal: warning: " + warning + "\n");
  const auto j = nlohmann::json::parse(out.str());
  EXPECT_EQ(j["commands"].size(), 3u);
  EXPECT_EQ(j["faults"].size(), 1u);
  ASSERT_EQ(j["warnings"].size(), 1u);
  EXPECT_EQ(j["warnings"][0], warning);
  EXPECT_EQ(snapshot(dir.path()), before);
}

TEST(JournalRefuses, ReaderRefusesANewerSchemaItCannotRead) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  ASSERT_EQ(sql(o.path, "PRAGMA user_version = 8; ALTER TABLE commands RENAME COLUMN reason TO why"), "");
  const auto before = snapshot(dir.path());
  std::ostringstream out, err;
  EXPECT_EQ(run_journal_command({o.path, "", false}, out, err), 2);
  EXPECT_EQ(out.str(), "");
  EXPECT_THAT(err.str(), HasSubstr(o.path + ": journal schema version 8 is newer than this reader's 1 and not "
                                            "readable by it ("));
  EXPECT_THAT(err.str(), HasSubstr("no such column: reason"));
  EXPECT_THAT(err.str(), HasSubstr("); use a newer foresight-remote\n"));
  EXPECT_EQ(snapshot(dir.path()), before);
}

// --- 2. read-only, locked, not a database -----------------------------------

TEST(JournalRefuses, AReadOnlyFile) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  fs::permissions(dir.path(), fs::perms::all);  // the folder writable (and open to nobody): only the file is not
  fs::permissions(o.path, fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
  const auto before = snapshot(dir.path());
  std::string why;
  const auto got = unprivileged([&] { return journal_error(o) + "\n" + probe_error(o.path); }, why);
  if (!got) GTEST_SKIP() << why << ": a read-only file cannot be made here";
  const std::string expected = o.path + ": read-only: the file is not writable (Permission denied)";
  EXPECT_EQ(*got, expected + "\n" + expected);
  EXPECT_EQ(snapshot(dir.path()), before);
}

TEST(JournalRefuses, AReadOnlyFolder) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  fs::permissions(o.path, fs::perms::all);  // the file writable: only the folder is not
  fs::permissions(dir.path(), fs::perms::owner_read | fs::perms::owner_exec | fs::perms::group_read |
                                  fs::perms::group_exec | fs::perms::others_read | fs::perms::others_exec);
  const auto before = snapshot(dir.path());
  const std::string absent = dir.file("new.sqlite3");
  std::string why;
  const auto got = unprivileged(
      [&] {
        JournalOptions n = o;
        n.path = absent;
        return journal_error(o) + "\n" + probe_error(o.path) + "\n" + journal_error(n) + "\n" + probe_error(absent);
      },
      why);
  fs::permissions(dir.path(), fs::perms::all);  // ScratchDir can clean up
  if (!got) GTEST_SKIP() << why << ": a read-only folder cannot be made here";
  const std::string existing = o.path + ": read-only: its folder " + dir.path() + " is not writable (Permission denied)";
  const std::string create = absent + ": read-only: cannot create the journal: its folder " + dir.path() +
                             " is not writable (Permission denied)";
  EXPECT_EQ(*got, existing + "\n" + existing + "\n" + create + "\n" + create);
  EXPECT_EQ(snapshot(dir.path()), before);
}

// Another connection holds the write lock (BEGIN EXCLUSIVE): "locked", not
// "not a journal database"; the writer waits busy_timeout (short here).
TEST(JournalRefuses, ADatabaseLockedByAnotherConnection) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  make_journal(o);
  o.busy_timeout = std::chrono::milliseconds(50);
  sqlite3* holder = nullptr;
  ASSERT_EQ(sqlite3_open(o.path.c_str(), &holder), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(holder, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK);
  const auto before = snapshot(dir.path());
  EXPECT_EQ(journal_error(o), o.path +
                                  ": locked by another process: no write lock within 50 ms (database is locked); is "
                                  "another foresight-remote or an sqlite3 shell writing to it?");
  EXPECT_EQ(probe_error(o.path, std::chrono::milliseconds(20)),
            o.path +
                ": locked by another process: no write lock within 20 ms (database is locked); is another "
                "foresight-remote or an sqlite3 shell writing to it?");
  EXPECT_EQ(snapshot(dir.path()), before);
  // The holder goes on (the probe used SQLite's own locking only) and lets go.
  EXPECT_EQ(sqlite3_exec(holder, "INSERT INTO events(stamp_ns, kind, text, detail) VALUES(1, 'shell', '', '')",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(holder, "COMMIT", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(holder);
  EXPECT_THAT(probe_error(o.path), HasSubstr("no throw: "));
  Journal j(o);
  j.record_command(command(4));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 4);
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from events"), 1);
}

// The same on a journal someone switched to rollback mode (no -wal, no -shm:
// the lock is on the main file).
TEST(JournalRefuses, ARollbackModeDatabaseLockedByAnotherConnection) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  make_journal(o);
  ASSERT_EQ(sql(o.path, "PRAGMA journal_mode = DELETE"), "");
  o.busy_timeout = std::chrono::milliseconds(50);
  sqlite3* holder = nullptr;
  ASSERT_EQ(sqlite3_open(o.path.c_str(), &holder), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(holder, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK);
  const auto before = snapshot(dir.path());
  EXPECT_EQ(journal_error(o), o.path +
                                  ": locked by another process: no write lock within 50 ms (database is locked); is "
                                  "another foresight-remote or an sqlite3 shell writing to it?");
  EXPECT_EQ(probe_error(o.path, std::chrono::milliseconds(20)),
            o.path +
                ": locked by another process: no write lock within 20 ms (database is locked); is another "
                "foresight-remote or an sqlite3 shell writing to it?");
  EXPECT_EQ(snapshot(dir.path()), before);
  ASSERT_EQ(sqlite3_exec(holder, "ROLLBACK", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(holder);
  EXPECT_THAT(probe_error(o.path), HasSubstr("no throw: "));
  EXPECT_EQ(snapshot(dir.path()), before) << "the probe's lock test wrote nothing";
}

TEST(JournalRefuses, GarbageAsNotAJournalDatabase) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  std::ofstream(o.path) << std::string(8192, 'z');
  const auto before = snapshot(dir.path());
  const std::string expected = o.path + ": statement failed: file is not a database (not a journal database)";
  EXPECT_EQ(journal_error(o), expected);
  EXPECT_EQ(probe_error(o.path), expected);
  EXPECT_EQ(snapshot(dir.path()), before);
}

TEST(JournalRefuses, AForeignDatabase) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  ASSERT_EQ(sql(o.path, "PRAGMA application_id = 1234; CREATE TABLE t(x); INSERT INTO t VALUES(1)"), "");
  const auto before = snapshot(dir.path());
  const std::string expected = o.path + ": not a Foresight journal (application_id 1234)";
  EXPECT_EQ(journal_error(o), expected);
  EXPECT_EQ(probe_error(o.path), expected);
  EXPECT_EQ(snapshot(dir.path()), before);
}

TEST(JournalRefuses, ADirectoryAndAFifo) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  fs::create_directory(o.path);
  EXPECT_EQ(journal_error(o), o.path + ": not a regular file (a directory)");
  EXPECT_EQ(probe_error(o.path), o.path + ": not a regular file (a directory)");
  o.path = dir.file("fifo");
  ASSERT_EQ(::mkfifo(o.path.c_str(), 0600), 0);
  // Opened, a FIFO would block until a writer came: stat first, never open.
  EXPECT_EQ(journal_error(o), o.path + ": not a regular file (a FIFO)");
  EXPECT_EQ(probe_error(o.path), o.path + ": not a regular file (a FIFO)");
  EXPECT_TRUE(fs::is_fifo(o.path));
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir.path())) ++n;
  EXPECT_EQ(n, 2u) << "nothing created beside them";
}

// What the writer and reader append to SQLite's message, by its result code.
TEST(JournalRefuses, SqliteFailuresExplainedByTheirCode) {
  ScratchDir dir;
  const std::string f = dir.file("j.sqlite3");
  EXPECT_EQ(detail::cause_of(f, SQLITE_NOTADB), "not a journal database");
  EXPECT_EQ(detail::cause_of(f, SQLITE_BUSY), "locked by another process");
  EXPECT_EQ(detail::cause_of(f, SQLITE_BUSY_SNAPSHOT), "locked by another process");
  EXPECT_EQ(detail::cause_of(f, SQLITE_LOCKED), "locked by another process");
  EXPECT_THAT(detail::cause_of(f, SQLITE_READONLY), HasSubstr("read-only: "));
  EXPECT_EQ(detail::cause_of(dir.file("gone/j.sqlite3"), SQLITE_CANTOPEN),
            "its folder " + dir.file("gone") + " does not exist");
  EXPECT_EQ(detail::cause_of(f, SQLITE_FULL), "");  // no guess for the rest: SQLite's own message
  EXPECT_EQ(detail::with_cause(f, "database is locked", SQLITE_BUSY), "database is locked (locked by another process)");
}

// --- 3. rotation never removes or renames what is not a journal ---------------

TEST(JournalRefuses, ToRotateOverFilesThatAreNotJournals) {
  ScratchDir dir;
  JournalOptions o = test_options(dir);
  o.max_bytes = JournalOptions::kMinMaxBytes;
  o.keep_files = 3;
  const std::string notes = "shift notes: do not delete\n";
  std::ofstream(o.path + ".1") << notes;
  std::ofstream(o.path + ".3") << "another text file\n";
  Journal j(o);
  for (int i = 0; i < 60; ++i) {  // ~240 KB: past max_bytes
    CommandRow c = command(static_cast<std::uint64_t>(i));
    c.detail = "{\"pad\":\"" + std::string(4000, 'x') + "\"}";
    j.record_command(c);
  }
  EXPECT_EQ(j.stats().rotations, 0u);
  EXPECT_EQ(j.stats().last_error, o.path + ": not rotating: " + o.path +
                                      ".1 is not a Foresight journal (not an SQLite database); left untouched, "
                                      "journaling goes on in " + o.path + " past max_bytes until it is moved aside");
  EXPECT_EQ(slurp(o.path + ".1"), notes);
  EXPECT_EQ(slurp(o.path + ".3"), "another text file\n");
  EXPECT_FALSE(fs::exists(o.path + ".2"));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 60);

  // NAME.1 moved aside: NAME.3 (the one rotation would delete) still blocks.
  fs::rename(o.path + ".1", dir.file("notes.txt"));
  j.record_command(command(60));
  EXPECT_EQ(j.stats().rotations, 0u);
  EXPECT_THAT(j.stats().last_error,
              HasSubstr(": not rotating: " + o.path + ".3 is not a Foresight journal (not an SQLite database)"));
  EXPECT_EQ(slurp(o.path + ".3"), "another text file\n");
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 61);

  // A foreign database at NAME.2 (and NAME.3 gone): still not ours.
  fs::remove(o.path + ".3");
  ASSERT_EQ(sql(o.path + ".2", "PRAGMA application_id = 99; CREATE TABLE t(x)"), "");
  const std::string foreign = slurp(o.path + ".2");
  j.record_command(command(61));
  EXPECT_EQ(j.stats().rotations, 0u);
  EXPECT_THAT(j.stats().last_error,
              HasSubstr(o.path + ".2 is not a Foresight journal (an SQLite database with application_id 99)"));
  EXPECT_EQ(slurp(o.path + ".2"), foreign);

  // A stray NAME.2-wal that is not SQLite's blocks too.
  fs::remove(o.path + ".2");
  std::ofstream(o.path + ".2-wal") << "not a wal";
  j.record_command(command(62));
  EXPECT_EQ(j.stats().rotations, 0u);
  EXPECT_THAT(j.stats().last_error, HasSubstr(o.path + ".2-wal is not SQLite's (not an SQLite WAL file)"));
  EXPECT_EQ(slurp(o.path + ".2-wal"), "not a wal");

  // Nothing in the way: the next transaction rotates, every row kept.
  fs::remove(o.path + ".2-wal");
  j.record_command(command(63));
  EXPECT_EQ(j.stats().rotations, 1u);
  EXPECT_EQ(sqlite_int(o.path + ".1", "select count(*) from commands"), 64);
  j.record_command(command(64));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 1);
  EXPECT_EQ(slurp(dir.file("notes.txt")), notes);
}

// The reader goes on past a rotated NAME.k that is not a journal (the files
// rotation now leaves alone), with a warning, and reads the rest.
TEST(JournalRefuses, ReaderSkipsARotatedFileThatIsNotAJournal) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  std::ofstream(o.path + ".1") << "shift notes\n";
  std::ostringstream out, err;
  ASSERT_EQ(run_journal_command({o.path, "", true}, out, err), 0) << err.str();
  EXPECT_EQ(err.str(), "foresight-remote journal: warning: " + o.path +
                           ".1: statement failed: file is not a database (not a journal database): skipped\n");
  const auto j = nlohmann::json::parse(out.str());
  EXPECT_EQ(j["files"], nlohmann::json::array({o.path}));
  EXPECT_EQ(j["commands"].size(), 3u);
  EXPECT_EQ(slurp(o.path + ".1"), "shift notes\n");
}

// --- 4. probe_journal -------------------------------------------------------

TEST(JournalProbe, AnAbsentFileWillBeCreatedAndIsNot) {
  ScratchDir dir;
  const std::string f = dir.file("journal.sqlite3");
  const JournalProbe p = probe_journal(f);
  EXPECT_FALSE(p.exists);
  EXPECT_EQ(p.schema_version, 0);
  EXPECT_EQ(p.describe, f + ": does not exist yet: will be created");
  EXPECT_TRUE(fs::is_empty(dir.path()));
  EXPECT_EQ(probe_error(dir.file("no/such/journal.sqlite3")),
            dir.file("no/such/journal.sqlite3") + ": cannot create the journal: its folder " + dir.file("no/such") +
                " does not exist");
}

TEST(JournalProbe, AJournalDescribedAndLeftAsItWas) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  make_journal(o);
  const auto before = snapshot(dir.path());
  const JournalProbe p = probe_journal(o.path);
  EXPECT_TRUE(p.exists);
  EXPECT_EQ(p.schema_version, detail::kSchemaVersion);
  EXPECT_EQ(p.describe, o.path + ": journal schema 1, 3 command rows, 1 fault, clean shutdown");
  EXPECT_EQ(snapshot(dir.path()), before) << "no -wal, no -shm, no byte changed";
}

// A journal open in this very process: the probe passes (no write lock is held
// between transactions) and the writer goes on unharmed.
TEST(JournalProbe, ALiveJournalInThisProcess) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  Journal j(o);
  j.record_command(command(1));
  const JournalProbe p = probe_journal(o.path, std::chrono::milliseconds(20));
  EXPECT_EQ(p.describe, o.path + ": journal schema 1, 1 command row, 0 faults, not shut down cleanly (still running, "
                                 "or it crashed)");
  j.record_command(command(2));
  EXPECT_EQ(sqlite_int(o.path, "select count(*) from commands"), 2);
}

TEST(JournalProbe, AnEmptyFileWillBeInitialised) {
  ScratchDir dir;
  const std::string f = dir.file("journal.sqlite3");
  std::ofstream{f};
  const JournalProbe p = probe_journal(f);
  EXPECT_TRUE(p.exists);
  EXPECT_EQ(p.describe, f + ": an empty SQLite database: will be initialised as a journal (schema 1)");
  EXPECT_EQ(fs::file_size(f), 0u);
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir.path())) ++n;
  EXPECT_EQ(n, 1u);
}

}  // namespace
}  // namespace foresight::journal
