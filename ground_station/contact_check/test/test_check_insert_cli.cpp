// `foresight check-insert` and the scripts' CHECK insert end to end on the
// synthetic work site: simulated clicks (1 px), the four cameras calibrated
// on the arm, the ORU localized from four views (a go) and from the side
// view alone (a no_go, with the view that would help most); the gate stops
// the auto-sequence, the operator's override goes on and is journaled; bad
// inputs exit 2 naming the input.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "foresight/test/cli.hpp"

namespace {

using foresight::test::CliRun;
using foresight::test::run_foresight;
using foresight::test::temp_path;

struct Site {
  std::string dir = temp_path("_site");
  std::string cameras, four_views, side_view, no_covariance;
  Site() {
    std::filesystem::create_directories(dir);
    const std::string arm = dir + "/arm.csv", oru = dir + "/oru.csv";
    cameras = dir + "/cameras.yaml";
    expect_ok(run_foresight("synth-clicks --calibration-out " + arm + " --object-out " + oru + " --seed 3"));
    for (const char* cam : {"side", "oblique", "overhead_wide", "overhead_zoom"})
      expect_ok(run_foresight("calibrate " + arm + " --camera " + cam + " --out " + cameras));
    four_views = dir + "/four.json";
    side_view = dir + "/side.json";
    std::ofstream(four_views) << expect_ok(run_foresight("localize " + oru + " --cameras " + cameras + " --json")).out;
    std::ofstream(side_view) << expect_ok(run_foresight("localize " + oru + " --cameras " + cameras + " --views side --json")).out;
    nlohmann::json j = nlohmann::json::parse(foresight::test::read_file(four_views));
    j.erase("covariance");
    no_covariance = dir + "/no_covariance.json";
    std::ofstream(no_covariance) << j.dump();
  }
  static CliRun expect_ok(CliRun r) {
    EXPECT_EQ(r.status, 0) << r.err;
    return r;
  }
};

const Site& site() {
  static const Site s;
  return s;
}

TEST(CheckInsertCli, FourViewsAreAGoAndTheSideViewAloneIsNot) {
  const CliRun go = run_foresight("check-insert --object-pose " + site().four_views + " --json");
  ASSERT_EQ(go.status, 0) << go.err;
  const auto g = nlohmann::json::parse(go.out);
  for (const char* key : {"p_success", "lateral95_m", "axial95_m", "tilt95_deg", "capture", "verdict", "advice"})
    EXPECT_TRUE(g.contains(key)) << key;
  EXPECT_EQ(g["verdict"], "go");
  EXPECT_GE(g["p_success"].get<double>(), 0.99);
  EXPECT_NEAR(g["capture"]["lateral_m"].get<double>(), 0.0075, 1e-12);  // 5 mm spiral + 1 mm clearance + 1.5 mm lead-in
  EXPECT_NEAR(g["capture"]["axial_min_m"].get<double>(), -0.015, 1e-12);  // 6.5 cm of travel, the latch needs 5 cm
  EXPECT_NEAR(g["tip_error"]["mean"][5].get<double>(), -0.005, 1e-9);     // insert_start: 5 mm in front of the hole
  EXPECT_LT(g["lateral95_m"].get<double>(), 0.0075);

  const CliRun no = run_foresight("check-insert --object-pose " + site().side_view + " --cameras " + site().cameras + " --json");
  ASSERT_EQ(no.status, 1) << no.err;
  const auto n = nlohmann::json::parse(no.out);
  EXPECT_EQ(n["verdict"], "no_go");
  EXPECT_LT(n["p_success"].get<double>(), 0.9);
  EXPECT_GT(n["lateral95_m"].get<double>(), g["lateral95_m"].get<double>());
  bool names_a_view = false;
  for (const auto& a : n["advice"]) names_a_view |= a.get<std::string>().rfind("add the view '", 0) == 0;
  EXPECT_TRUE(names_a_view) << n["advice"].dump();
}

TEST(CheckInsertCli, BadInputsExit2NamingTheInput) {
  const auto expect_bad = [](const std::string& args, const std::string& message) {
    const CliRun r = run_foresight("check-insert " + args);
    EXPECT_EQ(r.status, 2) << args << "\n" << r.out;
    EXPECT_EQ(r.err, "foresight check-insert: error: " + message + "\n") << args;
  };
  const std::string pose = "--object-pose " + site().four_views;
  expect_bad(pose + " --tag nowhere",
             "tag 'nowhere' is not in the object model 'oru' (its tags: approach_20cm, hole_entrance, insert_start, "
             "pulled_out_5cm, stow, tool_inserted, withdrawn_15cm)");
  expect_bad("--object-pose " + site().no_covariance,
             site().no_covariance + ": the object pose has no covariance (localize --json or align --json write it)");
  expect_bad(pose + " --spiral-max-radius-m 0", "insert.spiral_max_radius_m must be a positive number");
  expect_bad(pose + " --min-p 1", "min_p_success must be in (0, 1) (got 1.000000)");
  expect_bad(pose + " --min-p 0", "min_p_success must be in (0, 1) (got 0.000000)");
}

TEST(CheckInsertScript, ANoGoStopsTheSequenceAndTheOverrideIsJournaled) {
  const std::string script = foresight::test::write_temp_file(
      "OBJECT oru pose=" + site().side_view + "\nCHECK insert tag=insert_start\nTRAJECTORY to=insert_start\n", ".task");
  const std::string joints = " --dry-run --joints-deg 0,-30,0,-100,0,70,0 --no-preview --auto --cameras " + site().cameras;
  const std::string work1 = temp_path("_work"), work2 = temp_path("_work");
  const CliRun stopped = run_foresight("run " + script + joints + " --work " + work1);
  EXPECT_NE(stopped.status, 0);
  EXPECT_NE(stopped.out.find("CHECK insert: no_go, P(success) "), std::string::npos) << stopped.out << stopped.err;
  EXPECT_NE(stopped.out.find("(to go on anyway: --override-check insert)"), std::string::npos) << stopped.out;
  EXPECT_EQ(stopped.out.find("planned "), std::string::npos) << "the trajectory after a no_go was planned:\n" << stopped.out;

  const CliRun over = run_foresight("run " + script + joints + " --work " + work2 + " --override-check insert");
  EXPECT_EQ(over.status, 0) << over.out << over.err;
  EXPECT_NE(over.out.find("OVERRIDDEN by the operator (--override-check insert)"), std::string::npos) << over.out;
  EXPECT_NE(over.out.find("planned "), std::string::npos) << over.out;
  // The journal keeps the numbers and the override.
  std::istringstream journal(foresight::test::read_file(work2 + "/run.jsonl"));
  bool found = false;
  for (std::string line; std::getline(journal, line);) {
    const auto j = nlohmann::json::parse(line);
    if (!j.contains("check")) continue;
    found = true;
    EXPECT_EQ(j["check"]["verdict"], "no_go");
    EXPECT_EQ(j["overridden"], true);
  }
  EXPECT_TRUE(found);
}

}  // namespace
