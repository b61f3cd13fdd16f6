// Issue 13, "what a bad-input probe already found": every case through the
// real executable, with its exit status (2 bad input naming the file, line
// and key; 1 a failed computation), its exact message, the time it takes
// (nothing hangs) and the files it leaves (an old output survives a failed
// write).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "foresight/common/input_limits.hpp"
#include "foresight/test/cli.hpp"

using foresight::test::CliRun;
using foresight::test::read_file;
using foresight::test::run_foresight;
using foresight::test::temp_path;
using foresight::test::write_temp_file;

namespace {

/// `foresight <args>` under `ulimit -f <kib>` (a disk that is full past that
/// size; SIGXFSZ ignored so the write fails with EFBIG instead of killing).
CliRun run_with_file_limit(const std::string& args, int kib) {
  return foresight::test::run_shell("bash -c \"trap '' XFSZ; ulimit -f " + std::to_string(kib) + "; exec " +
                                    std::string(FORESIGHT_BIN_DIR) + "/foresight " + args + "\"");
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

std::string config(const std::string& file) { return std::string(FORESIGHT_CONFIG_DIR) + "/" + file; }

/// config/robot.urdf with `from` replaced by `to` (the first occurrence).
std::string urdf_with(const std::string& from, const std::string& to) {
  std::string text = read_file(config("robot.urdf"));
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return write_temp_file(text, ".urdf");
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

class BadInput : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cal_ = temp_path(".csv");
    oru_ = temp_path(".csv");
    q_ = temp_path(".txt");
    cams_ = temp_path(".yaml");
    loc_ = temp_path(".json");
    const auto r = run_foresight("synth-clicks --noise-px 0.3 --calibration-out " + cal_ + " --object-out " + oru_ +
                                 " --joints-out " + q_);
    ASSERT_EQ(r.status, 0) << r.err;
    for (const char* cam : {"side", "oblique"}) {
      const auto c = run_foresight("calibrate " + cal_ + " --camera " + cam + " --out " + cams_);
      ASSERT_EQ(c.status, 0) << cam << ": " << c.err;
    }
    const auto l = run_foresight("localize " + oru_ + " --cameras " + cams_ + " --views side,oblique --json > " + loc_);
    ASSERT_EQ(l.status, 0) << l.err;
    q_text_ = read_file(q_);
    while (!q_text_.empty() && q_text_.back() == '\n') q_text_.pop_back();
  }
  static std::string cal_, oru_, q_, cams_, loc_, q_text_;
};
std::string BadInput::cal_, BadInput::oru_, BadInput::q_, BadInput::cams_, BadInput::loc_, BadInput::q_text_;

// ---- crashes and hangs ----

// Issue 26: a wait of 1e300 s overflowed the clock arithmetic ("timed out
// after 0.0 s" at once while the remote went on): every wait is refused
// beyond a day, before anything is sent.
TEST_F(BadInput, WaitsBeyondADayExitTwoNamingTheOption) {
  for (const char* args : {"abort --timeout 1e300", "status --connect-timeout 1e300", "status --sample-timeout inf",
                           "recover --timeout 0"}) {
    const auto r = run_foresight(args);
    EXPECT_EQ(r.status, 2) << args << "\n" << r.err;
    EXPECT_TRUE(has(r.err, "--")) << args << "\n" << r.err;
    EXPECT_TRUE(has(r.err, "86400")) << args << "\n" << r.err;
  }
}

TEST_F(BadInput, AUrdfNestedOneHundredThousandDeepExitsTwo) {
  std::string deep;
  for (int i = 0; i < 100000; ++i) deep += "<a>";
  for (int i = 0; i < 100000; ++i) deep += "</a>";
  const std::string urdf = urdf_with("</robot>", deep + "\n</robot>");
  const auto r = run_foresight("robot --robot " + urdf);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, urdf + ":")) << r.err;
  EXPECT_TRUE(has(r.err, ": XML nested deeper than 64 elements")) << r.err;
}

TEST_F(BadInput, AUrdfLinkWithTwoParentsExitsTwoInRobotAndValidate) {
  const std::string urdf =
      urdf_with("</robot>", "<joint name=\"loop\" type=\"fixed\"><parent link=\"link3\"/><child link=\"link1\"/></joint>\n</robot>");
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = run_foresight("robot --robot " + urdf);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "joint 'loop': link 'link1' already has a parent (joint 'joint1' at line ")) << r.err;
  const std::string traj = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,0,0,0,0\n", ".csv");
  const auto v = run_foresight("validate " + traj + " --robot " + urdf);
  EXPECT_EQ(v.status, 2) << v.err;
  EXPECT_TRUE(has(v.err, "the links must form a tree")) << v.err;
  EXPECT_LT(seconds_since(t0), 60.0);
}

TEST_F(BadInput, ValidateOfAnEndlessFileExitsTwo) {
  const auto r = run_foresight("validate /dev/zero");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "foresight validate: error: /dev/zero:1: line longer than 65536 bytes")) << r.err;
}

TEST_F(BadInput, ValidateOfTheLargestTrajectoryWithEveryJointBeyondItsLimitIsLinear) {
  std::string text = "t,q1,q2,q3,q4,q5,q6,q7\n";
  const int n = foresight::limits::kMaxTrajectorySamples;
  for (int i = 0; i < n; ++i) text += std::to_string(0.001 * i) + ",9,9,9,9,9,9,9\n";
  const std::string traj = write_temp_file(text, ".csv");
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = run_foresight("validate " + traj);
  EXPECT_LT(seconds_since(t0), 60.0);
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_TRUE(has(r.err, "foresight validate: 1400000 violation(s); the remote would reject this trajectory")) << r.err;
  EXPECT_TRUE(has(r.out, "  ... and 1399900 more\n")) << r.out.substr(0, 300);
  const auto j = run_foresight("validate " + traj + " --json");
  EXPECT_EQ(j.status, 1);
  const auto json = nlohmann::json::parse(j.out);
  EXPECT_EQ(json["violation_count"].get<int>(), 1400000);
  EXPECT_EQ(json["violations"].size(), foresight::limits::kMaxListedViolations);
  // One row more than a trajectory may have is bad input, refused while reading.
  text += "1000,0,0,0,0,0,0,0\n";
  const std::string more = write_temp_file(text, ".csv");
  const auto m = run_foresight("validate " + more);
  EXPECT_EQ(m.status, 2) << m.err;
  EXPECT_TRUE(has(m.err, more + ":200002: more than 200000 samples (the most a trajectory may have)")) << m.err;
}

TEST_F(BadInput, APointsFileWithAMillionRowsExitsTwoQuickly) {
  std::string text = "n,cam,x,y,z,u,v\n";
  for (int i = 0; i < 1000000; ++i) text += "1,side,0.1,0.2,0.3,100,100\n";
  const std::string pts = write_temp_file(text, ".csv");
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = run_foresight("calibrate " + pts + " --camera side");
  EXPECT_LT(seconds_since(t0), 30.0);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, pts + ":100002: more than 100000 points (the most a points file may have)")) << r.err;
}

TEST_F(BadInput, ACamerasFileWithTwentyThousandCamerasExitsTwo) {
  std::string text;
  for (int i = 0; i < 20000; ++i)
    text += "c" + std::to_string(i) +
            ":\n  viewport: [646, 486]\n  f_px: 800\n  base_T_camera: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n";
  const std::string cams = write_temp_file(text, ".yaml");
  const auto r = run_foresight("localize " + oru_ + " --cameras " + cams);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, cams + ": 20000 cameras, at most 64 allowed")) << r.err;
}

// ---- silently accepted ----

TEST_F(BadInput, CalibrationRowsBeyondTheJointLimitsExitTwo) {
  for (const std::string q : {"100", "1e308"}) {
    std::string text = read_file(cal_);
    const auto row = text.find('\n') + 1;  // the first data row: n,cam,link,lx,ly,lz,q1,...
    std::size_t q1 = row;
    for (int commas = 0; commas < 6; ++commas) q1 = text.find(',', q1) + 1;
    text.replace(q1, text.find(',', q1) - q1, q);
    const std::string pts = write_temp_file(text, ".csv");
    const auto r = run_foresight("calibrate " + pts + " --camera side");
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_TRUE(has(r.err, pts + ":2: point on link '")) << r.err;
    EXPECT_TRUE(has(r.err, "': q1 = " + std::string(q == "100" ? "100" : "1e+308") +
                               " rad is outside the joint's limits [-2.96706, 2.96706] rad (+- 0.05)"))
        << r.err;
  }
}

TEST_F(BadInput, APointsHeaderNamingAnotherNumberOfJointsExitsTwo) {
  std::string text = read_file(cal_);
  text.replace(text.find(",q7,u,v"), 7, ",q7,q8,q9,u,v");
  const std::string pts = write_temp_file(text, ".csv");
  const auto r = run_foresight("calibrate " + pts + " --camera side");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, pts + ":2: the header names 9 joint angles, the robot has 7 joints (q1..q7)")) << r.err;
}

TEST_F(BadInput, PointIdsThatDoNotFitAnIntExitTwo) {
  std::string text = read_file(oru_);
  const auto row = text.find('\n') + 1;
  text.replace(row, text.find(',', row) - row, "1e10");
  const std::string pts = write_temp_file(text, ".csv");
  const auto r = run_foresight("localize " + pts + " --cameras " + cams_);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, pts + ":2: field 'n' must be an integer point number that fits an int, got '1e10'")) << r.err;
}

TEST_F(BadInput, ACameraWhoseLastRowIsNotHomogeneousExitsTwo) {
  const std::string cams = write_temp_file(
      "side:\n  viewport: [646, 486]\n  f_px: 800\n  base_T_camera: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]\n",
      ".yaml");
  const auto r = run_foresight("localize " + oru_ + " --cameras " + cams);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, cams + ":4: camera 'side': base_T_camera last row must be [0, 0, 0, 1]")) << r.err;
}

TEST_F(BadInput, ClicksOutsideTheViewportExitTwo) {
  const auto r = run_foresight("calibrate " + cal_ + " --camera side --viewport 1x1");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, cal_ + ":")) << r.err;
  EXPECT_TRUE(has(r.err, "is outside the 1x1 viewport of camera 'side'")) << r.err;
  // localize checks every view's clicks against that camera's viewport.
  std::string text = read_file(cams_);
  text.replace(text.find("viewport: [646, 486]"), 20, "viewport: [1, 1]");
  const std::string cams = write_temp_file(text, ".yaml");
  const auto l = run_foresight("localize " + oru_ + " --cameras " + cams);
  EXPECT_EQ(l.status, 2) << l.err;
  EXPECT_TRUE(has(l.err, "is outside the 1x1 viewport of camera '")) << l.err;
}

TEST_F(BadInput, PreviewRefusesATrajectoryThatCouldNeverBeSent) {
  const std::string image = temp_path(".png");  // never read: the trajectory is refused first
  const std::string out = temp_path(".mp4");
  const std::string nan = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,-1,0,0,0\n0.1,0,nan,0,-1,0,0,0\n", ".csv");
  auto r = run_foresight("preview " + nan + " --cameras " + cams_ + " --camera side --image " + image + " --out " + out);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, nan + ": row 2, joint q2: position is not finite: cannot be previewed")) << r.err;
  const std::string back = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,-1,0,0,0\n-1,0,0,0,-1,0,0,0\n", ".csv");
  r = run_foresight("preview " + back + " --cameras " + cams_ + " --camera side --image " + image + " --out " + out);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, back + ": row 2: t = -1 s does not increase (previous 0 s): cannot be previewed")) << r.err;
  const std::string ok = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,-1,0,0,0\n1,0,0,0,-1,0,0,0\n", ".csv");
  r = run_foresight("preview " + ok + " --cameras " + cams_ + " --camera side --image " + image + " --out " + out +
                    " --speed 1e-9");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "--speed 0.000000 and --fps 30.000000 give more than 100000 video frames for 1.000000 s")) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST_F(BadInput, ASyntheticNoiseOrStudyNoiseOutOfRangeExitsTwo) {
  const std::string out = temp_path(".csv");
  auto r = run_foresight("synth-clicks --noise-px 1e300 --calibration-out " + out);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "--noise-px must be a number in [0, 1000] px")) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
  r = run_foresight("eval localization --noise-px 1e300 --trials 2");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "--noise-px must be a number in (0, 1000] px")) << r.err;
}

TEST_F(BadInput, AUrdfWithNegativeMassOrAHugeOffsetExitsTwo) {
  const std::string mass = urdf_with("<mass value=\"", "<mass value=\"-");
  auto r = run_foresight("robot --robot " + mass);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "kg is not in [0, 100000] kg")) << r.err;
  const std::string far = urdf_with("<origin xyz=\"0 0 0.22\"", "<origin xyz=\"0 0 1e308\"");
  r = run_foresight("robot --robot " + far);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, ": joint 'joint1': origin (0, 0, 1e+308) m out of range (finite, each within 100 m)")) << r.err;
}

TEST_F(BadInput, PlanOptionsThatOverflowTheSampleCountExitTwoWithTheirCause) {
  const std::string out = temp_path(".csv");
  const std::string base = "plan --object-pose " + loc_ + " --from " + q_text_ + " --out " + out + " ";
  auto r = run_foresight(base + "--to approach_20cm --rate-hz 1e6");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "plan option rate_hz = 1e+06 Hz is not in (0, 1000] Hz")) << r.err;
  r = run_foresight(base + "--to approach_20cm --dwell-s 1e10");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "plan option dwell_s = 1e+10 s is not in [0, 1800] s")) << r.err;
  r = run_foresight(base + "--to approach_20cm --limit-fraction 1e-9");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "goal 'approach_20cm': the move would last ")) << r.err;
  EXPECT_TRUE(has(r.err, "longer than a trajectory may (1800 s): limit_fraction too small")) << r.err;
  r = run_foresight(base + "--to approach_20cm,hole_entrance:linear --tool-speed 1e-9");
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "goal 'hole_entrance': the move would last ")) << r.err;
  EXPECT_TRUE(has(r.err, "tool_speed_m_s / tool_accel_m_s2 / tool_rate_rad_s too small")) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// ---- exit codes ----

TEST_F(BadInput, YamlBadConversionsAndAHugeJsonNumberExitTwoNamingTheFile) {
  std::string text = read_file(cams_);
  const auto at = text.find("f_px: ");
  text.replace(at, text.find('\n', at) - at, "f_px: [1, 2]");
  const std::string cams = write_temp_file(text, ".yaml");
  auto r = run_foresight("localize " + oru_ + " --cameras " + cams);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, cams + ":")) << r.err;
  EXPECT_TRUE(has(r.err, "bad conversion")) << r.err;

  std::string oru = read_file(config("oru.yaml"));
  const auto o = oru.find("object:");
  oru.replace(o, oru.find('\n', o) - o, "object: [a, b]");
  const std::string model = write_temp_file(oru, ".yaml");
  r = run_foresight("localize " + oru_ + " --cameras " + cams_ + " --object " + model);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, model + ":")) << r.err;
  EXPECT_TRUE(has(r.err, "bad value: bad conversion")) << r.err;

  std::string loc = read_file(loc_);
  const auto b = loc.find("\"base_T_object\"");
  const auto first = loc.find_first_of("-0123456789", loc.find('[', loc.find('[', b) + 1));
  loc.replace(first, loc.find_first_of(",]", first) - first, "1e400");
  const std::string json = write_temp_file(loc, ".json");
  r = run_foresight("plan --object-pose " + json + " --from " + q_text_ + " --to approach_20cm --out " +
                    temp_path(".csv"));
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, json + ": malformed JSON: ")) << r.err;
}

TEST_F(BadInput, OutADirectoryExitsTwoBeforeAnyWork) {
  const std::string dir = temp_path("_dir");
  std::filesystem::create_directory(dir);
  auto r = run_foresight("calibrate " + cal_ + " --camera side --out " + dir);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "foresight calibrate: error: " + dir + ": is a directory")) << r.err;
  r = run_foresight("plan --object-pose " + loc_ + " --from " + q_text_ + " --to approach_20cm --out " + dir);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_TRUE(has(r.err, "foresight plan: error: " + dir + ": is a directory")) << r.err;
  std::filesystem::remove_all(dir);
}

// A device is written in place and its failure is the command's: /dev/full
// exits 1 naming it (it used to exit 0 having lost the write; as root the
// rename would have replaced the device with a file).
TEST_F(BadInput, OutAFullDeviceFailsAndTheDeviceStays) {
  if (!std::filesystem::is_character_file("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const auto r = run_foresight("plan --object-pose " + loc_ + " --from " + q_text_ + " --to approach_20cm --out /dev/full");
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_TRUE(has(r.err, "foresight plan: error: /dev/full: cannot write (No space left on device)")) << r.err;
  EXPECT_TRUE(std::filesystem::is_character_file("/dev/full"));
}

// ---- atomic writes ----

TEST_F(BadInput, AFullDiskDuringCalibrateOrPlanLeavesTheOldFileWhole) {
  const std::string dir = temp_path("_dir");
  std::filesystem::create_directory(dir);
  const std::string cams = dir + "/cameras.yaml";
  std::filesystem::copy_file(cams_, cams);
  const std::string before = read_file(cams);
  ASSERT_GT(before.size(), 2048u);  // two cameras with their covariances
  const auto r = run_with_file_limit("calibrate " + cal_ + " --camera overhead_wide --out " + cams, 1);
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_TRUE(has(r.err, cams + ": cannot write (File too large); the old file is unchanged")) << r.err;
  EXPECT_EQ(read_file(cams), before);  // both cameras still there, not truncated

  const std::string traj = dir + "/traj.csv";
  const auto p = run_foresight("plan --object-pose " + loc_ + " --from " + q_text_ + " --to approach_20cm --out " + traj);
  ASSERT_EQ(p.status, 0) << p.err;
  const std::string plan_before = read_file(traj);
  const auto f = run_with_file_limit(
      "plan --object-pose " + loc_ + " --from " + q_text_ + " --to approach_20cm,start --out " + traj, 1);
  EXPECT_EQ(f.status, 1) << f.err;
  EXPECT_EQ(read_file(traj), plan_before);
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 2) << "no temporary file left behind";
  std::filesystem::remove_all(dir);
}
