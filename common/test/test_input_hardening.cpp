// Issue 13, "what a bad-input probe found": the common parsers and validators
// under hostile input, each case with its exact message (input_limits.hpp
// holds the rules): bounded sizes, physical ranges, a URDF tree that is a
// tree, linear validation, atomic writes that survive a full disk.

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "foresight/common/atomic_file.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/test/cli.hpp"

using namespace foresight;
using foresight::test::read_file;
using foresight::test::temp_path;
using foresight::test::write_temp_file;

namespace {

// A small valid arm: base -j1-> l1 -j2-> l2 -tip_joint-> tip. One element a line.
std::string small_urdf(const std::string& l1_mass = "2", const std::string& j2_origin = "0 0 0.4",
                       const std::string& extra = "") {
  return std::string("<?xml version=\"1.0\"?>\n") +                                         // 1
         "<robot name=\"small\">\n" +                                                        // 2
         "<link name=\"base\"/>\n" +                                                         // 3
         "<link name=\"l1\"><inertial><mass value=\"" + l1_mass +
         "\"/><inertia ixx=\"0.1\" ixy=\"0\" ixz=\"0\" iyy=\"0.1\" iyz=\"0\" izz=\"0.1\"/></inertial></link>\n" +  // 4
         "<link name=\"l2\"/>\n" +                                                           // 5
         "<link name=\"tip\"/>\n" +                                                          // 6
         "<joint name=\"j1\" type=\"revolute\">\n" +                                        // 7
         "<parent link=\"base\"/><child link=\"l1\"/>\n" +                                   // 8
         "<origin xyz=\"0 0 0.5\"/><axis xyz=\"0 0 1\"/>\n" +                               // 9
         "<limit lower=\"-2\" upper=\"2\" velocity=\"1\" acceleration=\"3\" effort=\"50\"/>\n" +  // 10
         "</joint>\n" +                                                                      // 11
         "<joint name=\"j2\" type=\"revolute\">\n" +                                        // 12
         "<parent link=\"l1\"/><child link=\"l2\"/>\n" +                                     // 13
         "<origin xyz=\"" + j2_origin + "\"/><axis xyz=\"0 1 0\"/>\n" +                     // 14
         "<limit lower=\"-1\" upper=\"1\" velocity=\"1\" acceleration=\"2\" effort=\"10\"/>\n" +  // 15
         "</joint>\n" +                                                                      // 16
         "<joint name=\"tip_joint\" type=\"fixed\">\n" +                                    // 17
         "<parent link=\"l2\"/><child link=\"tip\"/><origin xyz=\"0 0 0.3\"/>\n" +          // 18
         "</joint>\n" +                                                                      // 19
         extra +                                                                             // 20...
         "</robot>\n";
}

std::string urdf_error(const std::string& xml) {
  RobotModelOptions o;
  o.tip_link = "tip";
  try {
    RobotModel::from_xml(xml, "test.urdf", o);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

template <typename F>
std::string input_error(F f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// ---- URDF: nesting, tree structure, physical ranges ----

TEST(UrdfHardening, DeeplyNestedXmlIsRefusedBeforeTheRecursiveParser) {
  // 100,000 nested elements after a valid robot crashed `foresight robot` (stack exhaustion).
  std::string deep;
  for (int i = 0; i < 100000; ++i) deep += "<a>";
  for (int i = 0; i < 100000; ++i) deep += "</a>";
  std::string xml = small_urdf();
  xml.insert(xml.rfind("</robot>"), deep + "\n");
  EXPECT_EQ(urdf_error(xml), "test.urdf:20: XML nested deeper than 64 elements");
  // Comments, CDATA and quoted '>' do not count as nesting; a valid arm still loads.
  std::string ok = small_urdf("2", "0 0 0.4",
                              "<!-- <a><a><a> --><![CDATA[<b><b>]]><material name=\"m\" note=\"a>b<c\"><color "
                              "rgba=\"1 1 1 1\"/></material>\n");
  EXPECT_EQ(urdf_error(ok), "(no error)");
}

TEST(UrdfHardening, ALinkWithTwoParentsIsRefused) {
  // An extra joint link2 -> link1: it hung `robot` and `validate`.
  const std::string extra =
      "<joint name=\"loop\" type=\"fixed\"><parent link=\"l2\"/><child link=\"l1\"/></joint>\n";  // line 20
  EXPECT_EQ(urdf_error(small_urdf("2", "0 0 0.4", extra)),
            "test.urdf:20: joint 'loop': link 'l1' already has a parent (joint 'j1' at line 7): the links must form a "
            "tree");
}

TEST(UrdfHardening, ALoopOfJointsIsRefused) {
  // Every link one parent, but l3 -> l4 -> l3 is a loop detached from the base.
  const std::string extra =
      "<link name=\"l3\"/><link name=\"l4\"/>\n"
      "<joint name=\"a\" type=\"fixed\"><parent link=\"l3\"/><child link=\"l4\"/></joint>\n"   // line 21
      "<joint name=\"b\" type=\"fixed\"><parent link=\"l4\"/><child link=\"l3\"/></joint>\n";  // line 22
  const std::string e = urdf_error(small_urdf("2", "0 0 0.4", extra));
  EXPECT_TRUE(e == "test.urdf:22: link 'l3' is its own ancestor (a loop of joints): the links must form a tree" ||
              e == "test.urdf:21: link 'l4' is its own ancestor (a loop of joints): the links must form a tree")
      << e;
}

TEST(UrdfHardening, MassesMustBeFiniteAndNotNegative) {
  EXPECT_EQ(urdf_error(small_urdf("-1")), "test.urdf:4: link 'l1': mass -1 kg is not in [0, 100000] kg");
  // urdfdom logs this one and carried on with mass 0: a logged error is a refusal.
  EXPECT_EQ(urdf_error(small_urdf("nan")),
            "test.urdf: URDF rejected by urdfdom: Inertial: mass [nan] is not a float");
}

TEST(UrdfHardening, JointOffsetsMustBeOfASaneSize) {
  EXPECT_EQ(urdf_error(small_urdf("2", "0 0 1e308")),
            "test.urdf:12: joint 'j2': origin (0, 0, 1e+308) m out of range (finite, each within 100 m)");
}

// ---- text files: bounded ----

TEST(TextFileHardening, AnEndlessFileIsRefusedAtTheBound) {
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(input_error([] { read_text_file("/dev/zero", "cannot open", 1 << 20); }),
            "/dev/zero: file is larger than 1048576 bytes");
  // The trajectory reader streams: /dev/zero has no newline, the line bound stops it.
  EXPECT_EQ(input_error([] { read_trajectory_csv("/dev/zero"); }), "/dev/zero:1: line longer than 65536 bytes");
  EXPECT_LT(seconds_since(t0), 10.0);
}

// A FIFO nobody writes: refused at once (opening it to read would wait for a
// writer for ever); so are a socket's path and a directory.
TEST(TextFileHardening, AFifoIsRefusedWithoutWaitingForAWriter) {
  const std::string fifo = (std::filesystem::temp_directory_path() / ("fs_fifo_" + std::to_string(getpid()))).string();
  std::remove(fifo.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string why = fifo + ": is a FIFO, not a file (its reader would wait for a writer for ever)";
  EXPECT_EQ(input_error([&] { read_text_file(fifo, "cannot open"); }), why);
  EXPECT_EQ(input_error([&] { read_trajectory_csv(fifo); }), why);
  EXPECT_EQ(input_error([&] { RobotModel::from_file(fifo); }).rfind(fifo + ": is a FIFO", 0), 0u);
  std::remove(fifo.c_str());
  const std::string dir = std::filesystem::temp_directory_path().string();
  EXPECT_EQ(input_error([&] { read_text_file(dir, "cannot open"); }), dir + ": is a directory");
}

// ---- trajectories: bounded rows, bounded and linear validation ----

TEST(TrajectoryHardening, MoreRowsThanATrajectoryMayHaveAreRefused) {
  std::string text = "t,q1\n";
  text.reserve(static_cast<std::size_t>(limits::kMaxTrajectorySamples + 2) * 12);
  for (int i = 0; i <= limits::kMaxTrajectorySamples; ++i) text += std::to_string(i) + ",0\n";
  EXPECT_EQ(input_error([&] { parse_trajectory_csv(text, "big.csv"); }),
            "big.csv:200002: more than 200000 samples (the most a trajectory may have)");
}

TEST(TrajectoryHardening, MillionsOfViolationsAreCountedInLinearTimeAndListedUpToTheBound) {
  // 200,000 rows with every one of 7 joints beyond its limit: 1.4e6 violations.
  const int n = limits::kMaxTrajectorySamples, dof = 7;
  Trajectory t;
  t.time_s.resize(n);
  t.positions_rad = Eigen::MatrixXd::Constant(n, dof, 5.0);
  for (int i = 0; i < n; ++i) t.time_s[i] = 0.001 * i;
  TrajectoryLimits l;
  l.joints = dof;
  l.joint_limits.assign(dof, JointLimits{-1.0, 1.0, 1.0, 10.0, 10.0});
  std::size_t total = 0;
  const auto t0 = std::chrono::steady_clock::now();
  const auto v = validate(t, l, &total);
  EXPECT_LT(seconds_since(t0), 5.0);
  EXPECT_EQ(total, static_cast<std::size_t>(n) * dof);
  ASSERT_EQ(v.size(), limits::kMaxListedViolations);
  EXPECT_EQ(v.front().message, "row 1, joint q1: position 5 rad outside [-1, 1] rad");
  EXPECT_EQ(v.back().row, static_cast<int>(limits::kMaxListedViolations / dof) + 1);
}

// ---- atomic writes ----

namespace {

/// Runs write_file_atomic(path, content) in a child whose file size limit is
/// `limit_bytes` (RLIMIT_FSIZE: the disk is "full" past it; SIGXFSZ ignored so
/// write() fails with EFBIG). Returns the child's exit status: 0 written,
/// 1 ComputationError, 2 InputError, 3 anything else.
int write_in_child(const std::string& path, const std::string& content, rlim_t limit_bytes) {
  const pid_t pid = fork();
  if (pid == 0) {
    signal(SIGXFSZ, SIG_IGN);
    const rlimit rl{limit_bytes, limit_bytes};
    setrlimit(RLIMIT_FSIZE, &rl);
    int rc = 0;
    try {
      write_file_atomic(path, content);
    } catch (const InputError&) {
      rc = 2;
    } catch (const ComputationError& e) {
      std::fprintf(stderr, "%s\n", e.what());
      rc = 1;
    } catch (...) {
      rc = 3;
    }
    _exit(rc);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

TEST(AtomicWrite, ReplacesTheFileWhole) {
  const std::string p = temp_path(".yaml");
  write_file_atomic(p, "old\n");
  write_file_atomic(p, "new content\n");
  EXPECT_EQ(read_file(p), "new content\n");
  std::filesystem::remove(p);
}

TEST(AtomicWrite, TheOldFileSurvivesAFullDisk) {
  const std::string dir = temp_path("_dir");
  std::filesystem::create_directory(dir);
  const std::string p = dir + "/cameras.yaml";
  const std::string old_content = "side: {f_px: 800}\noblique: {f_px: 700}\n";
  write_file_atomic(p, old_content);
  // The new content is larger than the disk has room for (4 KiB).
  EXPECT_EQ(write_in_child(p, std::string(64 * 1024, 'x'), 4096), 1);
  EXPECT_EQ(read_file(p), old_content);  // untouched, not truncated
  // No temporary file is left behind.
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 1);
  std::filesystem::remove_all(dir);
}

TEST(AtomicWrite, ADirectoryOrAMissingFolderIsBadInput) {
  const std::string dir = temp_path("_dir");
  std::filesystem::create_directory(dir);
  EXPECT_EQ(input_error([&] { write_file_atomic(dir, "x"); }), dir + ": is a directory");
  EXPECT_EQ(input_error([&] { write_file_atomic(dir + "/no/such.csv", "x"); }),
            dir + "/no/such.csv: folder '" + dir + "/no' does not exist");
  std::filesystem::remove_all(dir);
}

// ---- YAML: conversions name the file and line; bounded cameras ----

TEST(YamlHardening, ABadConversionInTheObjectModelNamesTheFileAndLine) {
  std::string text = read_file(std::string(FORESIGHT_CONFIG_DIR) + "/oru.yaml");
  const auto at = text.find("object:");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, text.find('\n', at) - at, "object: {a: 1}");  // a map where a name belongs
  const std::string p = write_temp_file(text, ".yaml");
  const std::string e = input_error([&] { ObjectModel::from_file(p); });
  EXPECT_EQ(e.rfind(p + ":", 0), 0u) << e;
  EXPECT_NE(e.find("bad value: bad conversion"), std::string::npos) << e;
}

TEST(YamlHardening, ASceneWithTooManyCamerasIsRefused) {
  std::string text = "object_pose: {xyz_m: [0, 0, 0], rpy_deg: [0, 0, 0]}\n"
                     "panel: {size_m: [1, 1, 1], xyz_m: [0, 0, 0], rpy_deg: [0, 0, 0]}\ncameras:\n";
  for (int i = 0; i < 20000; ++i)
    text += "  c" + std::to_string(i) +
            ": {viewport: [646, 486], f_px: 800, position_m: [2, 0, 1], look_at_m: [0, 0, 1], up: [0, 0, 1]}\n";
  const std::string p = write_temp_file(text, ".yaml");
  EXPECT_EQ(input_error([&] { Scene::from_file(p); }), p + ":4: 20000 cameras, at most 64 allowed");
}

// ---- plan options: ranges, and sample counts that fit ----

namespace {

std::string plan_error(const PlanOptions& o) {
  const RobotModel robot = RobotModel::from_file(std::string(FORESIGHT_CONFIG_DIR) + "/robot.urdf");
  Goal g;
  g.name = "there";
  g.is_pose = false;
  g.q = robot.mid_configuration();
  g.q[1] += 0.5;
  return input_error([&] { plan_motion(robot, robot.mid_configuration(), {g}, o); });
}

}  // namespace

TEST(PlanHardening, OptionsOutsideTheirRangeAreBadInputWithTheRightCause) {
  PlanOptions o;
  o.rate_hz = 1e6;
  EXPECT_EQ(plan_error(o), "plan option rate_hz = 1e+06 Hz is not in (0, 1000] Hz");
  o = {};
  o.dwell_s = 1e10;
  EXPECT_EQ(plan_error(o), "plan option dwell_s = 1e+10 s is not in [0, 1800] s");
  o = {};
  o.limit_fraction = 1e-9;
  EXPECT_EQ(plan_error(o).rfind("goal 'there': the move would last ", 0), 0u) << plan_error(o);
  EXPECT_NE(plan_error(o).find("longer than a trajectory may (1800 s): limit_fraction too small"), std::string::npos);
  o = {};
  o.limit_fraction = 1.5;
  EXPECT_EQ(plan_error(o), "plan option limit_fraction = 1.5 is not in (0, 1]");
}

TEST(YamlHardening, DeeplyNestedYamlIsRefusedNotACrash) {
  const std::string p = write_temp_file(std::string(100000, '[') + std::string(100000, ']') + "\n", ".yaml");
  const std::string e = input_error([&] { Scene::from_file(p); });
  EXPECT_EQ(e.rfind(p + ":", 0), 0u) << e;  // yaml-cpp's own depth guard
  EXPECT_NE(e.find(": malformed YAML: "), std::string::npos) << e;
}
