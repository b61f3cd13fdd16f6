#include <gtest/gtest.h>

#include <string>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"

using namespace foresight;

namespace {

template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(YamlUtil, LoadAndParseErrorsNameTheFile) {
  EXPECT_EQ(error_of([] { yaml::load_file("/nonexistent/x.yaml", "cannot open x file"); }),
            "/nonexistent/x.yaml: cannot open x file");
  EXPECT_EQ(error_of([] { yaml::parse("a: [1, 2\nb: 3\n", "F"); }).rfind("F:", 0), 0u);
  EXPECT_NE(error_of([] { yaml::parse("a: [1, 2\nb: 3\n", "F"); }).find("malformed YAML: "), std::string::npos);
  EXPECT_EQ(error_of([] { read_text_file("/nonexistent/t.csv", "cannot open t file"); }),
            "/nonexistent/t.csv: cannot open t file");
}

TEST(YamlUtil, LineOf) {
  const YAML::Node root = yaml::parse("a: 1\nb:\n  c: 2\n", "F");
  EXPECT_EQ(yaml::line_of(root["a"]), 1);
  EXPECT_EQ(yaml::line_of(root["b"]["c"]), 3);
  EXPECT_EQ(yaml::line_of(root["missing"]), 0);
}

TEST(YamlUtil, RequiredValues) {
  const YAML::Node root = yaml::parse("v: [1, 2, x]\nw: [1, 2]\np: -1\nq: {xyz_m: [1, 2, 3], rpy_deg: [0, 0, 90]}\n", "F");
  EXPECT_EQ(error_of([&] { yaml::read_vector<3>(root["v"], "F", "v"); }), "F:1: 'v' element 3 is not a number");
  EXPECT_EQ(error_of([&] { yaml::read_vector<3>(root["w"], "F", "w"); }), "F:2: 'w' must be a list of 3 numbers");
  EXPECT_EQ(error_of([&] { yaml::read_vector<3>(root["u"], "F", "u"); }), "F: missing key 'u'");
  EXPECT_EQ(error_of([&] { yaml::read_positive(root["p"], "F", "p"); }), "F:3: 'p' must be a positive number");
  EXPECT_EQ(error_of([&] { yaml::read_pose(root["p"], "F", "p"); }), "F:3: 'p' must be a map {xyz_m, rpy_deg}");
  const Pose T = yaml::read_pose(root["q"], "F", "q");
  EXPECT_TRUE(T.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_TRUE((T.linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY()));
}

TEST(YamlUtil, OptionalSettingsAndKeys) {
  const YAML::Node sec = yaml::parse("a: 2.5\nb: many\nc: 1.5\n", "F");
  EXPECT_EQ(yaml::number_or(sec, "a", 0.0, "F", "s."), 2.5);
  EXPECT_EQ(yaml::number_or(sec, "z", 7.0, "F", "s."), 7.0);
  EXPECT_EQ(yaml::integer_or(sec, "z", 3, "F", "s."), 3);
  EXPECT_EQ(error_of([&] { yaml::number_or(sec, "b", 0.0, "F", "s."); }), "F:2: s.b: not a number: 'many'");
  EXPECT_EQ(error_of([&] { yaml::integer_or(sec, "c", 0, "F", "s."); }), "F:3: s.c: not an integer: '1.5'");
  const char* allowed[] = {"a", "b"};
  const auto unknown = yaml::unknown_key(sec, allowed);
  ASSERT_TRUE(unknown.has_value());
  EXPECT_EQ(unknown->as<std::string>(), "c");
  EXPECT_EQ(yaml::line_of(*unknown), 3);
  EXPECT_EQ(yaml::key_list(allowed), "a, b");
  const char* all[] = {"a", "b", "c"};
  EXPECT_FALSE(yaml::unknown_key(sec, all).has_value());
}

TEST(YamlUtil, Section) {
  const YAML::Node root = yaml::parse("s:\n  a: 1\nt: 2\n", "F");
  EXPECT_EQ(yaml::section(root, "s", "F", "the s part")["a"].as<int>(), 1);
  EXPECT_EQ(error_of([&] { yaml::section(root, "u", "F", "the u part"); }), "F: missing section 'u' (the u part)");
  EXPECT_EQ(error_of([&] { yaml::section(root, "t", "F", "the t part"); }), "F:3: t: expected a map");
}

// MapReader: the one wording of every configuration reader (remote.yaml's
// sections, the tool, the video switch).
TEST(YamlUtil, MapReaderReadsValuesAndFallbacks) {
  const YAML::Node root = yaml::parse("rate: 2.5\nn: 7\nname: can0\nsub:\n  bits: 1000000\n", "F");
  const yaml::MapReader top(root, "F", "");
  EXPECT_EQ(top.get<double>("rate"), 2.5);
  EXPECT_EQ(top.get<int>("n"), 7);
  EXPECT_EQ(top.get<std::string>("name"), "can0");
  EXPECT_EQ(top.get_or<int>("absent", -4), -4);
  EXPECT_EQ(top.get_or<std::string>("absent", "tcp"), "tcp");
  const yaml::MapReader sub = top.map("sub");
  EXPECT_EQ(sub.get<std::uint32_t>("bits"), 1000000u);
  EXPECT_EQ(sub.line(), 5);
  EXPECT_EQ(sub.name("bits"), "sub.bits");
  EXPECT_EQ(top.name("rate"), "rate");
  EXPECT_EQ(top.label(), "top level");
  EXPECT_EQ(sub.label(), "sub");
}

TEST(YamlUtil, MapReaderMessages) {
  const YAML::Node root = yaml::parse(
      "a: 1\nlist: [1]\ns:\n  x: fast\n  y: 1.5\n  z: -3\n  w: {k: 1}\n  v:\n  gain: 3\nt: 5\n", "F");
  const yaml::MapReader top(root, "F", "");
  const yaml::MapReader s = top.map("s");
  EXPECT_EQ(error_of([&] { s.get<double>("x"); }), "F:4: s.x: not a number: 'fast'");
  EXPECT_EQ(error_of([&] { s.get<int>("y"); }), "F:5: s.y: not an integer: '1.5'");
  EXPECT_EQ(error_of([&] { s.get<std::uint32_t>("z"); }), "F:6: s.z: not an integer: '-3'");
  EXPECT_EQ(error_of([&] { s.get<std::string>("w"); }), "F:7: s.w: not a string (a map)");
  EXPECT_EQ(error_of([&] { s.get_or<double>("v", 1.0); }), "F:8: s.v: not a number (no value)");
  EXPECT_EQ(error_of([&] { top.get<int>("list"); }), "F:2: list: not an integer (a list)");
  EXPECT_EQ(error_of([&] { s.get<double>("u", "the u value"); }), "F:4: s: missing 'u' (the u value)");
  EXPECT_EQ(error_of([&] { top.get<double>("u"); }), "F:1: top level: missing 'u'");
  EXPECT_EQ(error_of([&] { s.check_keys({"x", "y", "z", "w", "v"}); }),
            "F:9: s.gain: unknown key (expected one of: x, y, z, w, v)");
  EXPECT_EQ(error_of([&] { top.check_keys({"a", "s", "t"}); }), "F:2: list: unknown key (expected one of: a, s, t)");
  EXPECT_EQ(error_of([&] { top.map("t"); }), "F:10: t: expected a map");
  EXPECT_EQ(error_of([&] { top.map("m", "the m part"); }), "F:1: top level: missing 'm' (the m part)");
  EXPECT_EQ(error_of([&] { s.fail_key("y", "1.5 is outside 2..3"); }), "F:5: s.y: 1.5 is outside 2..3");
  EXPECT_EQ(error_of([&] { s.fail_key("absent", "needed here"); }), "F:4: s.absent: needed here");
  EXPECT_EQ(error_of([] { yaml::MapReader(yaml::parse("- 1\n", "F"), "F", ""); }), "F:1: expected a map at the top level");
  // The optional settings speak the same words.
  EXPECT_EQ(error_of([&] { yaml::number_or(s.node(), "x", 0.0, "F", "s."); }), "F:4: s.x: not a number: 'fast'");
  EXPECT_EQ(error_of([&] { yaml::integer_or(s.node(), "w", 0, "F", "s."); }), "F:7: s.w: not an integer (a map)");
}

// A key given twice is an error anywhere in the file (yaml-cpp keeps both and
// finds the first: the second, often the intended one, was ignored), and so
// is a second document.
TEST(YamlUtil, DuplicateKeysAndASecondDocumentAreRefused) {
  EXPECT_EQ(error_of([] { yaml::parse("cycle_rate_hz: 500\ncycle_rate_hz: 1000000000\n", "F"); }),
            "F:2: duplicate key 'cycle_rate_hz' (first on line 1)");
  EXPECT_EQ(error_of([] { yaml::parse("drives:\n  - node_id: 1\n    joint: a\n    node_id: 2\n", "F"); }),
            "F:4: duplicate key 'node_id' (first on line 2)");
  EXPECT_EQ(error_of([] { yaml::parse("a: 1\n---\nb: 2\n", "F"); }),
            "F:2: a second YAML document (one document per file)");
  // A document followed by NUL bytes: YAML::LoadAll never ended on it (the
  // fuzzer's timeout); the reader asks for two documents at most.
  const std::string nuls = "a: 1\nb: [1, 2\n" + std::string("]\n") + std::string(64, '\0');
  EXPECT_NE(error_of([&] { yaml::parse(nuls, "F"); }), "");
  // Aliases nested ten deep, ten each: 1e10 nodes when expanded; refused at
  // a budget linear in the text, quickly.
  std::string bomb = "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n";
  for (int i = 1; i <= 10; ++i) {
    const std::string p = "*a" + std::to_string(i - 1);
    bomb += "a" + std::to_string(i) + ": &a" + std::to_string(i) + " [" + p + ", " + p + ", " + p + ", " + p + ", " + p +
            ", " + p + ", " + p + ", " + p + ", " + p + ", " + p + "]\n";
  }
  EXPECT_NE(error_of([&] { yaml::parse(bomb, "F"); }).find("too many YAML nodes for its size (aliases expanding)"),
            std::string::npos);
  EXPECT_EQ(error_of([] { yaml::parse("a: 1\nb: {c: 1, d: 2}\n", "F"); }), "");
  EXPECT_EQ(error_of([] { yaml::parse("", "F"); }), "");
}

// Every configured number's range in one wording; NaN and infinities fail it.
TEST(YamlUtil, RangesRefuseNaNAndNameKeyRangeAndUnit) {
  const YAML::Node root = yaml::parse("hb:\n  consumer_ms: 65536\n  producer_ms: .nan\n  ok: 100\n  inf: .inf\n", "F");
  const yaml::MapReader hb(root["hb"], "F", "hb");
  EXPECT_EQ(error_of([&] { hb.get_in("consumer_ms", 1, 65535, "ms"); }), "F:2: hb.consumer_ms: 65536 is outside [1, 65535] ms");
  EXPECT_EQ(error_of([&] { hb.get_in("producer_ms", 1, 65000, "ms"); }), "F:3: hb.producer_ms: nan is outside [1, 65000] ms");
  EXPECT_EQ(error_of([&] { hb.get_or_in("inf", 1.0, 0, 10, "s"); }), "F:5: hb.inf: inf is outside [0, 10] s");
  EXPECT_EQ(hb.get_in("ok", 1, 65535, "ms"), 100.0);
  EXPECT_EQ(hb.get_or_in("absent", 7.0, 1, 10, "s"), 7.0);
  EXPECT_EQ(error_of([&] { hb.get_in("absent", 1, 10, "s"); }), "F:2: hb: missing 'absent'");
}

// Counts, ids and codes: integers only, in one wording with their range.
TEST(YamlUtil, IntegerRangesRefuseFractionsAndNameKeyAndRange) {
  const YAML::Node root =
      yaml::parse("d:\n  node_id: 128\n  half: 5.5\n  ok: 42\n  huge: 99999999999999999999\n  word: many\n", "F");
  const yaml::MapReader d(root["d"], "F", "d");
  EXPECT_EQ(error_of([&] { d.get_int_in("node_id", 1, 127, ""); }), "F:2: d.node_id: 128 is outside [1, 127]");
  EXPECT_EQ(error_of([&] { d.get_int_in("half", 1, 10, "cycles"); }), "F:3: d.half: not an integer: '5.5'");
  EXPECT_EQ(error_of([&] { d.get_or_int_in("huge", 1, 0, 10, ""); }), "F:5: d.huge: not an integer: '99999999999999999999'");
  EXPECT_EQ(error_of([&] { d.get_or_int_in("word", 1, 0, 10, ""); }), "F:6: d.word: not an integer: 'many'");
  EXPECT_EQ(d.get_int_in("ok", 1, 127, ""), 42);
  EXPECT_EQ(d.get_or_int_in("absent", 7, 1, 10, "s"), 7);
  EXPECT_EQ(error_of([&] { d.get_or_int_in("ok", 7, -6, 0, "(10^x s)"); }), "F:4: d.ok: 42 is outside [-6, 0] (10^x s)");
}

}  // namespace
