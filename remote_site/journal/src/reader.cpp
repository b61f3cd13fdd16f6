#include "foresight/journal/reader.hpp"
#include "foresight/common/json_text.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <filesystem>
#include <iomanip>
#include <ostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "sqlite.hpp"

namespace foresight::journal {

using detail::Connection;
using detail::Statement;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

constexpr int kMaxRotatedScan = 10000;  // bound on NAME.1, NAME.2 ... probing

constexpr int kBusyMs = 5000;

/// The schema version of a file open_for_reading() accepted.
struct Opened {
  Connection conn;
  std::int64_t schema = 0;
};

/// A journal of this schema: opened without create, read-write when it can
/// (so SQLite recovers a crashed writer's WAL, as the sqlite3 shell does),
/// else read-only. A newer schema (a newer foresight-remote wrote it): opened
/// read-only, never written (detail::open_readonly), read as far as its
/// tables still have the columns this reader knows, with a warning.
Opened open_for_reading(const std::string& path, std::vector<std::string>& warnings) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw JournalError(path + ": no such journal file");
  if (!fs::is_regular_file(path, ec)) throw JournalError(path + ": not a regular file");
  Opened o;
  {
    Connection ro = detail::open_readonly(path, kBusyMs);
    const std::int64_t app_id = detail::query_int(ro, "PRAGMA application_id");  // garbage: "(not a journal database)"
    if (app_id != detail::kApplicationId)
      throw JournalError(path + ": not a Foresight journal (application_id " + std::to_string(app_id) + ")");
    o.schema = detail::query_int(ro, "PRAGMA user_version");
    if (o.schema > detail::kSchemaVersion) {
      warnings.push_back(path + ": journal schema version " + std::to_string(o.schema) + " is newer than this reader's " +
                         std::to_string(detail::kSchemaVersion) +
                         " (written by a newer foresight-remote): read read-only, only the columns this version knows");
      o.conn = std::move(ro);
      return o;
    }
  }
  try {
    o.conn = Connection(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX);
  } catch (const JournalError&) {
    o.conn = Connection(path, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX);
  }
  sqlite3_busy_timeout(o.conn.get(), kBusyMs);
  return o;
}

std::vector<double> parse_array(const std::string& text) {
  std::vector<double> v;
  const json j = json::parse(text, nullptr, false);
  if (!j.is_array()) return v;
  for (const auto& x : j) v.push_back(x.is_number() ? x.get<double>() : std::numeric_limits<double>::quiet_NaN());
  return v;
}

void read_rows(const Connection& c, const ReadOptions& o, JournalContents& out);

void read_file_into(const std::string& path, const ReadOptions& o, JournalContents& out) {
  const Opened opened = open_for_reading(path, out.warnings);
  try {
    read_rows(opened.conn, o, out);
  } catch (const JournalError& e) {
    if (opened.schema <= detail::kSchemaVersion) throw;
    throw JournalError(path + ": journal schema version " + std::to_string(opened.schema) +
                       " is newer than this reader's " + std::to_string(detail::kSchemaVersion) +
                       " and not readable by it (" + e.what() + "); use a newer foresight-remote");
  }
  out.files.push_back(path);
}

void read_rows(const Connection& c, const ReadOptions& o, JournalContents& out) {
  {
    Statement s(c,
                "SELECT stamp_ns, session_id, command_id, sequence_number, kind, state, code, reason, detail"
                " FROM commands WHERE stamp_ns >= ?1 ORDER BY id");
    s.bind(1, o.since_ns);
    while (s.step())
      out.commands.push_back(
          {s.int64(0), s.u64(1), s.u64(2), s.u64(3), s.text(4), s.text(5), s.text(6), s.text(7), s.text(8)});
  }
  {
    Statement s(c, "SELECT stamp_ns, cycle, category, cause, text, evidence FROM faults WHERE stamp_ns >= ?1 ORDER BY id");
    s.bind(1, o.since_ns);
    while (s.step())
      out.faults.push_back({s.int64(0), s.u64(1), static_cast<int>(s.int64(2)), s.text(3), s.text(4), s.text(5)});
  }
  {
    Statement s(c,
                "SELECT stamp_ns, trajectory_id, state, code, reason, hash_hex, samples, joints"
                " FROM uploads WHERE stamp_ns >= ?1 ORDER BY id");
    s.bind(1, o.since_ns);
    while (s.step())
      out.uploads.push_back({s.int64(0), s.u64(1), s.text(2), s.text(3), s.text(4), s.text(5),
                             static_cast<std::uint32_t>(s.int64(6)), static_cast<std::uint32_t>(s.int64(7))});
  }
  {
    Statement s(c, "SELECT stamp_ns, kind, text, detail FROM events WHERE stamp_ns >= ?1 ORDER BY id");
    s.bind(1, o.since_ns);
    while (s.step()) out.events.push_back({s.int64(0), s.text(1), s.text(2), s.text(3)});
  }
  {
    Statement s(c, "SELECT count(*) FROM telemetry WHERE stamp_ns >= ?1");
    s.bind(1, o.since_ns);
    if (s.step()) out.telemetry_count += s.u64(0);
  }
  {
    Statement s(c,
                "SELECT stamp_ns, cycle, mode, joint_count, q, q_cmd, wrench FROM telemetry"
                " WHERE stamp_ns >= ?1 ORDER BY id DESC LIMIT 1");
    s.bind(1, o.since_ns);
    if (s.step()) {
      TelemetryRow t;
      t.stamp_ns = s.int64(0);
      t.cycle = s.u64(1);
      t.mode = static_cast<std::uint8_t>(s.int64(2));
      // A damaged or hostile row may hold any count (-1 became 255 and wrote past q_rad).
      t.joint_count = static_cast<std::uint8_t>(std::clamp<std::int64_t>(s.int64(3), 0, TelemetryRow::kMaxJoints));
      const auto q = parse_array(s.text(4)), qc = parse_array(s.text(5)), w = parse_array(s.text(6));
      std::copy_n(q.begin(), std::min<std::size_t>(q.size(), t.joint_count), t.q_rad.begin());
      std::copy_n(qc.begin(), std::min<std::size_t>(qc.size(), t.joint_count), t.q_cmd_rad.begin());
      std::copy_n(w.begin(), std::min<std::size_t>(w.size(), 6), t.wrench.begin());
      out.telemetry_last = t;
    }
  }
}

/// Digits only, e.g. "2026" -> 2026; false when empty, not digits, or too large.
bool parse_uint(std::string_view s, int& v) {
  if (s.empty() || !std::all_of(s.begin(), s.end(), [](char ch) { return std::isdigit(static_cast<unsigned char>(ch)); }))
    return false;
  return std::from_chars(s.data(), s.data() + s.size(), v).ec == std::errc{};
}

json json_or_string(const std::string& text) {
  if (text.empty()) return json::object();
  json j = json::parse(text, nullptr, false);
  return j.is_discarded() ? json(text) : j;
}

json to_json(const TelemetryRow& t) {
  const auto arr = [](const double* v, std::size_t n) {
    json a = json::array();
    for (std::size_t i = 0; i < n; ++i) a.push_back(v[i]);
    return a;
  };
  return {{"stamp_ns", t.stamp_ns},
          {"cycle", t.cycle},
          {"mode", t.mode},
          {"joint_count", t.joint_count},
          {"q_rad", arr(t.q_rad.data(), t.joint_count)},
          {"q_cmd_rad", arr(t.q_cmd_rad.data(), t.joint_count)},
          {"wrench", arr(t.wrench.data(), 6)}};
}

json to_json(const JournalContents& c, const std::string& db, std::optional<std::int64_t> since) {
  json j;
  j["db"] = db;
  j["files"] = c.files;
  j["since_ns"] = since ? json(*since) : json(nullptr);
  j["commands"] = json::array();
  for (const auto& r : c.commands)
    j["commands"].push_back({{"stamp_ns", r.stamp_ns},
                             {"session_id", r.session_id},
                             {"command_id", r.command_id},
                             {"sequence_number", r.sequence_number},
                             {"kind", r.kind},
                             {"state", r.state},
                             {"code", r.code},
                             {"reason", r.reason},
                             {"detail", json_or_string(r.detail)}});
  j["faults"] = json::array();
  for (const auto& r : c.faults)
    j["faults"].push_back({{"stamp_ns", r.stamp_ns},
                           {"cycle", r.cycle},
                           {"category", r.category},
                           {"cause", r.cause},
                           {"text", r.text},
                           {"evidence", json_or_string(r.evidence)}});
  j["uploads"] = json::array();
  for (const auto& r : c.uploads)
    j["uploads"].push_back({{"stamp_ns", r.stamp_ns},
                            {"trajectory_id", r.trajectory_id},
                            {"state", r.state},
                            {"code", r.code},
                            {"reason", r.reason},
                            {"hash_hex", r.hash_hex},
                            {"samples", r.samples},
                            {"joints", r.joints}});
  j["events"] = json::array();
  for (const auto& r : c.events)
    j["events"].push_back(
        {{"stamp_ns", r.stamp_ns}, {"kind", r.kind}, {"text", r.text}, {"detail", json_or_string(r.detail)}});
  j["telemetry_count"] = c.telemetry_count;
  j["telemetry_last"] = c.telemetry_last ? to_json(*c.telemetry_last) : json(nullptr);
  j["warnings"] = c.warnings;
  return j;
}

// Columns wide enough for 64-bit ids (session and trajectory ids are random
// 64-bit numbers, up to 20 digits), so every field stays its own column.
void print_table(std::ostream& out, const JournalContents& c, const std::string& db, std::optional<std::int64_t> since) {
  out << "journal " << db << " (" << c.files.size() << (c.files.size() == 1 ? " file" : " files") << ")";
  if (since) out << ", since " << format_utc(*since);
  out << "\n\ncommands: " << c.commands.size() << "\n";
  if (!c.commands.empty()) {
    out << std::left << "  " << std::setw(26) << "time" << std::setw(22) << "session" << std::setw(9) << "command"
        << std::setw(7) << "seq" << std::setw(18) << "kind" << std::setw(11) << "state" << std::setw(20) << "code"
        << "reason\n";
    for (const auto& r : c.commands)
      out << "  " << std::setw(26) << format_utc(r.stamp_ns) << std::setw(22) << r.session_id << std::setw(9)
          << r.command_id << std::setw(7) << r.sequence_number << std::setw(18) << r.kind << std::setw(11) << r.state
          << std::setw(20) << r.code << r.reason << "\n";
  }
  out << "\nfaults: " << c.faults.size() << "\n";
  if (!c.faults.empty()) {
    out << "  " << std::setw(26) << "time" << std::setw(10) << "cycle" << std::setw(5) << "cat" << std::setw(22)
        << "cause" << "text\n";
    for (const auto& r : c.faults)
      out << "  " << std::setw(26) << format_utc(r.stamp_ns) << std::setw(10) << r.cycle << std::setw(5)
          << r.category << std::setw(22) << r.cause << r.text << "\n";
  }
  out << "\nuploads: " << c.uploads.size() << "\n";
  if (!c.uploads.empty()) {
    out << "  " << std::setw(26) << "time" << std::setw(22) << "trajectory" << std::setw(11) << "state"
        << std::setw(20) << "code" << std::setw(9) << "samples" << std::setw(8) << "joints" << std::setw(18)
        << "hash" << "reason\n";
    for (const auto& r : c.uploads)
      out << "  " << std::setw(26) << format_utc(r.stamp_ns) << std::setw(22) << r.trajectory_id << std::setw(11)
          << r.state << std::setw(20) << r.code << std::setw(9) << r.samples << std::setw(8) << r.joints
          << std::setw(18) << r.hash_hex.substr(0, 16) << r.reason << "\n";
  }
  out << "\nevents: " << c.events.size() << "\n";
  if (!c.events.empty()) {
    out << "  " << std::setw(26) << "time" << std::setw(16) << "kind" << "text\n";
    for (const auto& r : c.events)
      out << "  " << std::setw(26) << format_utc(r.stamp_ns) << std::setw(16) << r.kind << r.text << "\n";
  }
  out << "\ntelemetry: " << c.telemetry_count << " rows";
  if (c.telemetry_last)
    out << ", last " << format_utc(c.telemetry_last->stamp_ns) << " (cycle " << c.telemetry_last->cycle << ", mode "
        << int(c.telemetry_last->mode) << ")";
  out << std::right << "\n";
}

}  // namespace

JournalContents read_journal(const std::string& path, const ReadOptions& options) {
  JournalContents c;
  if (options.include_rotated) {
    int n = 0;
    std::error_code ec;
    while (n < kMaxRotatedScan && fs::exists(path + "." + std::to_string(n + 1), ec)) ++n;
    // A rotated file that is not a journal (rotation leaves such files alone:
    // someone's notes at NAME.1) or is damaged is skipped with a warning: the
    // others are still read. NAME itself must be readable.
    for (int i = n; i >= 1; --i) {
      try {
        read_file_into(path + "." + std::to_string(i), options, c);
      } catch (const JournalError& e) {
        c.warnings.push_back(std::string(e.what()) + ": skipped");
      }
    }
  }
  read_file_into(path, options, c);
  return c;
}

std::optional<std::int64_t> parse_since(const std::string& text) {
  const std::string_view s(text);
  if (s.empty()) return std::nullopt;
  if (std::all_of(s.begin(), s.end(), [](char ch) { return std::isdigit(static_cast<unsigned char>(ch)); })) {
    std::int64_t v = 0;
    if (std::from_chars(s.data(), s.data() + s.size(), v).ec != std::errc{}) return std::nullopt;
    return v;
  }
  // YYYY-MM-DD[(T| )HH:MM[:SS[.fraction]]][Z|+00:00|+0000]
  if (s.size() < 10 || s[4] != '-' || s[7] != '-') return std::nullopt;
  int y = 0, mo = 0, d = 0, h = 0, mi = 0, sec = 0;
  std::int64_t frac_ns = 0;
  if (!parse_uint(s.substr(0, 4), y) || !parse_uint(s.substr(5, 2), mo) || !parse_uint(s.substr(8, 2), d))
    return std::nullopt;
  std::string_view rest = s.substr(10);
  if (!rest.empty() && (rest[0] == 'T' || rest[0] == 't' || rest[0] == ' ')) {
    rest.remove_prefix(1);
    if (rest.size() < 5 || rest[2] != ':' || !parse_uint(rest.substr(0, 2), h) || !parse_uint(rest.substr(3, 2), mi))
      return std::nullopt;
    rest.remove_prefix(5);
    if (!rest.empty() && rest[0] == ':') {
      if (rest.size() < 3 || !parse_uint(rest.substr(1, 2), sec)) return std::nullopt;
      rest.remove_prefix(3);
      if (!rest.empty() && (rest[0] == '.' || rest[0] == ',')) {
        rest.remove_prefix(1);
        std::size_t n = 0;
        std::int64_t scale = 100'000'000;
        while (n < rest.size() && std::isdigit(static_cast<unsigned char>(rest[n]))) {
          frac_ns += (rest[n] - '0') * scale;
          scale /= 10;
          ++n;
        }
        if (n == 0) return std::nullopt;
        rest.remove_prefix(n);
      }
    }
  }
  if (!(rest.empty() || rest == "Z" || rest == "z" || rest == "+00:00" || rest == "+0000" || rest == "+00"))
    return std::nullopt;
  using namespace std::chrono;
  const year_month_day ymd{year{y}, month{static_cast<unsigned>(mo)}, day{static_cast<unsigned>(d)}};
  if (!ymd.ok() || h > 23 || mi > 59 || sec > 59) return std::nullopt;
  const auto t = sys_days{ymd} + hours{h} + minutes{mi} + seconds{sec};
  return duration_cast<nanoseconds>(t.time_since_epoch()).count() + frac_ns;
}

std::string format_utc(std::int64_t stamp_ns) {
  using namespace std::chrono;
  const sys_time<nanoseconds> t{nanoseconds{stamp_ns}};
  const auto day_point = floor<days>(t);
  const year_month_day ymd{day_point};
  const hh_mm_ss<milliseconds> hms{floor<milliseconds>(t - day_point)};
  char buf[40];
  std::snprintf(buf, sizeof buf, "%04d-%02u-%02uT%02d:%02d:%02d.%03dZ", int(ymd.year()), unsigned(ymd.month()),
                unsigned(ymd.day()), int(hms.hours().count()), int(hms.minutes().count()),
                int(hms.seconds().count()), int(hms.subseconds().count()));
  return buf;
}

int run_journal_command(const JournalQuery& q, std::ostream& out, std::ostream& err) {
  constexpr const char* kCmd = "foresight-remote journal: ";
  std::optional<std::int64_t> since;
  if (!q.since.empty()) {
    since = parse_since(q.since);
    if (!since) {
      err << kCmd << "--since '" << q.since
          << "': expected nanoseconds since the epoch or an ISO-8601 UTC time such as 2026-12-01T16:37:03Z\n";
      return 2;
    }
  }
  if (q.db.empty()) {
    err << kCmd << "--db: empty file name\n";
    return 2;
  }
  JournalContents c;
  try {
    ReadOptions o;
    if (since) o.since_ns = *since;
    c = read_journal(q.db, o);
  } catch (const JournalError& e) {
    err << kCmd << e.what() << "\n";
    return 2;
  }
  for (const std::string& w : c.warnings) err << kCmd << "warning: " << w << "\n";
  if (q.json) {
    out << json_text(to_json(c, q.db, since)) << "\n";
  } else {
    print_table(out, c, q.db, since);
  }
  return 0;
}

}  // namespace foresight::journal
