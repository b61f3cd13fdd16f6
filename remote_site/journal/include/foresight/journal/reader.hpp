#pragma once
// Reading a journal back, and the `foresight-remote journal` command.
// Not real-time; everything here may allocate and throw.

#include <cstdint>
#include <iosfwd>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "foresight/journal/journal.hpp"
#include "foresight/journal/rows.hpp"

namespace foresight::journal {

/// The default journal file, relative to the working directory (the same as
/// JournalOptions::path and the daemon's controller.journal.path).
inline constexpr const char* kDefaultJournalPath = "foresight-journal.db";

struct ReadOptions {
  std::int64_t since_ns = std::numeric_limits<std::int64_t>::min();  ///< rows with stamp_ns >= since_ns
  bool include_rotated = true;  ///< also read NAME.N ... NAME.1 (oldest first) when they exist
};

struct JournalContents {
  std::vector<std::string> files;  ///< the files read, oldest first
  std::vector<CommandRow> commands;
  std::vector<FaultRow> faults;
  std::vector<UploadRow> uploads;
  std::vector<EventRow> events;
  std::uint64_t telemetry_count = 0;
  std::optional<TelemetryRow> telemetry_last;  ///< the newest telemetry row, if any
  /// Read, but with a caveat: a file of a newer schema (read read-only, only
  /// the columns this version knows), a rotated NAME.k skipped because it is
  /// not a readable journal. Printed on err by the command.
  std::vector<std::string> warnings;
};

/// Reads `path` (and its rotated predecessors). Throws JournalError naming the
/// file when it does not exist, is not an SQLite database or not a journal
/// (a rotated predecessor that is not is skipped, with a warning).
/// Opens read-write without create, so SQLite can recover a crashed writer's
/// WAL, as the sqlite3 shell does; falls back to read-only. A file of a newer
/// schema is opened read-only (never written) and read with a warning, or,
/// when its tables lack the columns this version reads, refused naming both
/// versions.
JournalContents read_journal(const std::string& path, const ReadOptions& options = {});

/// `--since`: nanoseconds since the epoch ("1764600000000000000") or an
/// ISO-8601 UTC time ("2026-12-01T16:37:03Z", "2026-12-01T16:37:03.250Z",
/// "2026-12-01 16:37:03", "2026-12-01"; a trailing Z or +00:00 is optional,
/// other offsets are refused). nullopt when it is neither.
std::optional<std::int64_t> parse_since(const std::string& text);

/// ns since the epoch -> "2026-12-01T16:37:03.250Z" (milliseconds).
std::string format_utc(std::int64_t stamp_ns);

/// What `foresight-remote journal` was asked (the lead's CLI11 main fills it).
struct JournalQuery {
  std::string db = kDefaultJournalPath;  ///< --db
  std::string since;                     ///< --since, empty = everything
  bool json = false;                     ///< --json
};

/// `foresight-remote journal [--db F] [--since T] [--json]`. Prints a readable
/// table (or with json exactly one JSON object) on `out`; errors on `err`.
/// Returns 0, or 2 for a bad --since or a missing / unreadable / corrupt db.
int run_journal_command(const JournalQuery& q, std::ostream& out, std::ostream& err);

}  // namespace foresight::journal
