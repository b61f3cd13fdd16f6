// The reader and `foresight-remote journal`: --since parsing (ns and ISO-8601
// UTC against known epoch values), the table, the JSON object's keys, the
// since filter, and bad input with its exact message and exit status 2.

#include "foresight/journal/reader.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <sqlite3.h>

#include "journal_test_util.hpp"

namespace foresight::journal {
namespace {

using nlohmann::json;
using test::ScratchDir;
using test::test_options;

// date -u -d '2026-12-01T16:37:03Z' +%s
constexpr std::int64_t kT = 1'796'143'023LL * 1'000'000'000LL;

TEST(JournalSince, NanosecondsAndIsoUtc) {
  EXPECT_EQ(parse_since("0"), 0);
  EXPECT_EQ(parse_since("1796143023000000000"), kT);
  EXPECT_EQ(parse_since("2026-12-01T16:37:03Z"), kT);
  EXPECT_EQ(parse_since("2026-12-01T16:37:03"), kT);
  EXPECT_EQ(parse_since("2026-12-01 16:37:03+00:00"), kT);
  EXPECT_EQ(parse_since("2026-12-01T16:37:03.25Z"), kT + 250'000'000);
  EXPECT_EQ(parse_since("2026-12-01T16:37:03.000000001Z"), kT + 1);
  EXPECT_EQ(parse_since("2026-12-01T16:37Z"), kT - 3'000'000'000LL);
  EXPECT_EQ(parse_since("2026-12-01"), kT - (16 * 3600 + 37 * 60 + 3) * 1'000'000'000LL);
  EXPECT_EQ(parse_since("2000-02-29T00:00:00Z"), 951'782'400LL * 1'000'000'000LL);  // leap day
}

TEST(JournalSince, BadValuesRefused) {
  for (const char* bad : {"", "yesterday", "-5", "1.5", "99999999999999999999", "2026-13-01", "2026-02-30",
                          "2026-12-01T24:00:00Z", "2026-12-01T16:60Z", "2026-12-01T16:37:03+02:00",
                          "2026-12-01T16:37:03.Z", "2026-12-01T16", "2026/12/01", "2026-12-01Tfoo"})
    EXPECT_FALSE(parse_since(bad).has_value()) << bad;
}

TEST(JournalSince, FormatUtcRoundTrips) {
  EXPECT_EQ(format_utc(kT + 250'000'000), "2026-12-01T16:37:03.250Z");
  EXPECT_EQ(format_utc(0), "1970-01-01T00:00:00.000Z");
  EXPECT_EQ(parse_since(format_utc(kT + 123'000'000)), kT + 123'000'000);
}

/// A journal with two commands (three acks) before kT and one after, a fault
/// after, an upload, an event and telemetry.
std::string make_journal(const ScratchDir& dir) {
  JournalOptions o = test_options(dir);
  Journal j(o);
  auto c = test::command(1);
  c.stamp_ns = kT - 2'000'000'000;
  c.kind = "TRAJECTORY";
  j.record_command(c);
  c.state = "COMPLETED";
  c.stamp_ns = kT - 1'000'000'000;
  c.detail = R"({"final_q_rad":[0.5,0.25]})";
  j.record_command(c);
  auto d = test::command(2, "REJECTED");
  d.stamp_ns = kT;  // exactly at --since: included
  d.code = "HASH_MISMATCH";
  d.reason = "content hash differs from the announced one";
  d.detail = "not json";
  j.record_command(d);
  j.record_fault({kT + 1, 900, 0, "estop", "E-stop input", R"({"input":"file"})"});
  j.record_upload({kT - 5, 3, "COMMITTED", "NONE", "", "00ff", 200, 7});
  j.record_event({kT - 10, "start", "foresight-remote --sim", ""});
  for (int i = 0; i < 5; ++i) j.push_telemetry(test::telemetry(kT - 100 + i * 50, static_cast<std::uint64_t>(i)));
  EXPECT_TRUE(j.flush());
  return o.path;
}

TEST(JournalCommand, JsonHasTheDocumentedKeys) {
  ScratchDir dir;
  const std::string db = make_journal(dir);
  std::ostringstream out, err;
  ASSERT_EQ(run_journal_command({db, "", true}, out, err), 0) << err.str();
  EXPECT_EQ(err.str(), "");
  const json j = json::parse(out.str());  // exactly one object
  ASSERT_TRUE(j.is_object());
  EXPECT_EQ(j["db"], db);
  ASSERT_EQ(j["commands"].size(), 3u);
  const json& c0 = j["commands"][0];
  for (const char* k : {"command_id", "kind", "state", "code", "reason", "stamp_ns"})
    EXPECT_TRUE(c0.contains(k)) << k;
  EXPECT_EQ(c0["command_id"], 1);
  EXPECT_EQ(c0["kind"], "TRAJECTORY");
  EXPECT_EQ(c0["state"], "RECEIVED");
  EXPECT_EQ(c0["code"], "NONE");
  EXPECT_EQ(c0["stamp_ns"], kT - 2'000'000'000);
  EXPECT_EQ(j["commands"][1]["detail"]["final_q_rad"][1], 0.25);  // detail embedded as JSON
  EXPECT_EQ(j["commands"][2]["detail"], "not json");               // or as a string when it is not JSON
  EXPECT_EQ(j["commands"][2]["reason"], "content hash differs from the announced one");
  ASSERT_EQ(j["faults"].size(), 1u);
  EXPECT_EQ(j["faults"][0]["category"], 0);
  EXPECT_EQ(j["faults"][0]["cause"], "estop");
  EXPECT_EQ(j["faults"][0]["evidence"]["input"], "file");
  EXPECT_EQ(j["uploads"][0]["hash_hex"], "00ff");
  EXPECT_EQ(j["events"][0]["kind"], "start");
  EXPECT_EQ(j["telemetry_count"], 5);
  EXPECT_EQ(j["telemetry_last"]["cycle"], 4);
  EXPECT_EQ(j["telemetry_last"]["q_rad"].size(), 7u);
  EXPECT_TRUE(j["since_ns"].is_null());
}

// A damaged journal (issue 26): a telemetry row with joint_count -1 and 40
// angles (the reader wrote past its 16-joint array), a reason whose bytes are
// not UTF-8 (the JSON writer aborted). Read: at most 16 joints, U+FFFD.
TEST(JournalCommand, ADamagedRowIsReadWithinBoundsAndItsBytesAsText) {
  ScratchDir dir;
  const std::string db = make_journal(dir);
  sqlite3* h = nullptr;
  ASSERT_EQ(sqlite3_open(db.c_str(), &h), SQLITE_OK);
  std::string forty = "[";
  for (int i = 0; i < 40; ++i) forty += (i ? "," : "") + std::to_string(i);
  forty += "]";
  const std::string sql = "UPDATE telemetry SET joint_count = -1, q = '" + forty + "'; UPDATE commands SET reason = "
                          "CAST(X'41ff42' AS TEXT) WHERE command_id = 2;";
  ASSERT_EQ(sqlite3_exec(h, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(h);
  sqlite3_close(h);
  std::ostringstream out, err;
  ASSERT_EQ(run_journal_command({db, "", true}, out, err), 0) << err.str();
  const json j = json::parse(out.str());
  EXPECT_EQ(j["telemetry_last"]["joint_count"], 0);
  EXPECT_EQ(j["telemetry_last"]["q_rad"].size(), 0u);
  EXPECT_EQ(j["commands"][2]["reason"], "A\xef\xbf\xbd" "B");
}

TEST(JournalCommand, SinceFiltersEveryTable) {
  ScratchDir dir;
  const std::string db = make_journal(dir);
  for (const std::string since : {"2026-12-01T16:37:03Z", "1796143023000000000"}) {
    std::ostringstream out, err;
    ASSERT_EQ(run_journal_command({db, since, true}, out, err), 0) << err.str();
    const json j = json::parse(out.str());
    EXPECT_EQ(j["since_ns"], kT);
    ASSERT_EQ(j["commands"].size(), 1u) << since;
    EXPECT_EQ(j["commands"][0]["command_id"], 2);
    EXPECT_EQ(j["faults"].size(), 1u);
    EXPECT_EQ(j["uploads"].size(), 0u);
    EXPECT_EQ(j["events"].size(), 0u);
    EXPECT_EQ(j["telemetry_count"], 3);  // stamps kT-100 + {0,50,100,150,200}: three at or after kT
  }
}

TEST(JournalCommand, ReadableTable) {
  ScratchDir dir;
  const std::string db = make_journal(dir);
  std::ostringstream out, err;
  ASSERT_EQ(run_journal_command({db, "", false}, out, err), 0) << err.str();
  const std::string s = out.str();
  EXPECT_NE(s.find("journal " + db + " (1 file)"), std::string::npos) << s;
  EXPECT_NE(s.find("commands: 3"), std::string::npos) << s;
  EXPECT_NE(s.find("2026-12-01T16:37:03.000Z  7                     2        2      GOTO_JOINT        REJECTED   HASH_MISMATCH       "
                   "content hash differs from the announced one\n"),
            std::string::npos)
      << s;
  EXPECT_NE(s.find("faults: 1"), std::string::npos);
  EXPECT_NE(s.find("estop"), std::string::npos);
  EXPECT_NE(s.find("uploads: 1"), std::string::npos);
  EXPECT_NE(s.find("events: 1"), std::string::npos);
  EXPECT_NE(s.find("telemetry: 5 rows"), std::string::npos);
}

TEST(JournalCommand, BadSinceNamesTheFlag) {
  ScratchDir dir;
  const std::string db = make_journal(dir);
  std::ostringstream out, err;
  EXPECT_EQ(run_journal_command({db, "last tuesday", false}, out, err), 2);
  EXPECT_EQ(out.str(), "");
  EXPECT_EQ(err.str(),
            "foresight-remote journal: --since 'last tuesday': expected nanoseconds since the epoch or an ISO-8601 "
            "UTC time such as 2026-12-01T16:37:03Z\n");
}

TEST(JournalCommand, MissingDbNamesTheFile) {
  ScratchDir dir;
  const std::string db = dir.file("nope.sqlite3");
  std::ostringstream out, err;
  EXPECT_EQ(run_journal_command({db, "", true}, out, err), 2);
  EXPECT_EQ(out.str(), "");
  EXPECT_EQ(err.str(), "foresight-remote journal: " + db + ": no such journal file\n");
  EXPECT_FALSE(std::filesystem::exists(db));  // the reader never creates one
}

TEST(JournalCommand, CorruptDbNamesTheFile) {
  ScratchDir dir;
  const std::string db = dir.file("garbage.sqlite3");
  std::ofstream(db) << std::string(4096, 'g');
  std::ostringstream out, err;
  EXPECT_EQ(run_journal_command({db, "", false}, out, err), 2);
  EXPECT_EQ(out.str(), "");
  EXPECT_EQ(err.str(), "foresight-remote journal: " + db +
                           ": statement failed: file is not a database (not a journal database)\n");
}

TEST(JournalCommand, DefaultDbIsTheWritersDefault) {
  EXPECT_EQ(JournalQuery{}.db, JournalOptions{}.path);
  EXPECT_EQ(JournalQuery{}.db, "foresight-journal.db");
}

TEST(JournalCommand, EmptyJournal) {
  ScratchDir dir;
  const JournalOptions o = test_options(dir);
  { Journal j(o); }
  std::ostringstream out, err;
  ASSERT_EQ(run_journal_command({o.path, "", true}, out, err), 0);
  const json j = json::parse(out.str());
  EXPECT_EQ(j["commands"].size(), 0u);
  EXPECT_EQ(j["faults"].size(), 0u);
  EXPECT_EQ(j["telemetry_count"], 0);
  EXPECT_TRUE(j["telemetry_last"].is_null());
}

}  // namespace
}  // namespace foresight::journal
