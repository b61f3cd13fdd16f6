// foresight-remote simulate-insertions (simulate_insertions.hpp): the batch
// file's refusals with their exact messages, the runner's results on
// config/'s simulated plant, and the CLI as a child process (its --json
// contract and exit 2).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "foresight/common/error.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/daemon/simulate_insertions.hpp"
#include "foresight/test/cli.hpp"

namespace {

using namespace foresight;
using nlohmann::json;

const std::string kConfig = FORESIGHT_CONFIG_DIR;

/// tag_T_tip: translation (x, y, z), rotation tilt_deg about the x axis.
json pose_rows(double x, double y, double z, double tilt_deg = 0.0) {
  const double a = tilt_deg * M_PI / 180.0;
  return json::array({json::array({1.0, 0.0, 0.0, x}), json::array({0.0, std::cos(a), -std::sin(a), y}),
                      json::array({0.0, std::sin(a), std::cos(a), z}), json::array({0.0, 0.0, 0.0, 1.0})});
}

/// A batch file holding `doc`; removed with the object.
struct BatchFile {
  std::string path;
  explicit BatchFile(const std::string& text) : path(test::write_temp_file(text, ".json")) {}
  explicit BatchFile(const json& doc) : BatchFile(doc.dump()) {}
  ~BatchFile() { std::remove(path.c_str()); }
};

/// The message read_insertion_batch refuses `text` with ("" when it reads it).
std::string refusal(const std::string& text, std::string* path_out = nullptr) {
  const BatchFile f(text);
  if (path_out) *path_out = f.path;
  try {
    daemon::read_insertion_batch(f.path, sim_insertion::default_files(kConfig));
  } catch (const InputError& e) {
    const std::string msg = e.what();
    // Every message names the file first.
    EXPECT_EQ(msg.rfind(f.path + ": ", 0), 0u) << msg;
    return msg.substr(f.path.size() + 2);
  }
  return "";
}

json one_trial() { return json::array({{{"id", 1}, {"tag_T_tip", pose_rows(0.0, 0.0, -0.01)}}}); }

TEST(InsertionBatch, ReadsTheDefaultsAndTheParameters) {
  const BatchFile f(json{{"params", {{"depth_m", 0.05}, {"timeout_s", 30}}},
                         {"trials", {{{"id", 7}, {"tag_T_tip", pose_rows(0.001, -0.002, -0.01, 2.0)}}}}});
  const daemon::InsertionBatch b = daemon::read_insertion_batch(f.path, sim_insertion::default_files(kConfig));
  EXPECT_EQ(b.files.object_yaml, kConfig + "/oru.yaml");
  EXPECT_EQ(b.tag, "hole_entrance");
  EXPECT_DOUBLE_EQ(b.params.depth_m, 0.05);
  EXPECT_DOUBLE_EQ(b.params.timeout_s, 30.0);
  EXPECT_DOUBLE_EQ(b.params.spiral_max_radius_m, 0.005);  // the algorithm's default
  ASSERT_EQ(b.trials.size(), 1u);
  EXPECT_EQ(b.trials[0].id, 7);
  EXPECT_NEAR(b.trials[0].tag_T_tip.translation().y(), -0.002, 1e-15);
  EXPECT_NEAR(Eigen::AngleAxisd(b.trials[0].tag_T_tip.linear()).angle(), 2.0 * M_PI / 180.0, 1e-12);
}

TEST(InsertionBatch, RefusesBadInputNamingTheKeyOrTrial) {
  EXPECT_EQ(refusal("{\"trials\": ["), "malformed JSON: [json.exception.parse_error.101] parse error at line 1, "
                                       "column 13: syntax error while parsing value - unexpected end of input; "
                                       "expected '[', '{', or a literal");
  EXPECT_EQ(refusal("[1, 2]"), "expected a JSON object {\"trials\": [...]}");
  EXPECT_EQ(refusal(json{{"trial", one_trial()}}.dump()),
            "unknown key 'trial' (expected object, tag, params, trials)");
  std::string tags;  // the model's, sorted (config/oru.yaml: approach_20cm, hole_entrance, ...)
  for (const auto& [name, pose] : ObjectModel::from_file(kConfig + "/oru.yaml").tags)
    tags += (tags.empty() ? "" : ", ") + name;
  EXPECT_EQ(refusal(json{{"tag", "nope"}, {"trials", one_trial()}}.dump()),
            "tag: 'nope' is not a tag of " + kConfig + "/oru.yaml (tags: " + tags + ")");
  EXPECT_EQ(refusal(json{{"params", {{"depth", 0.06}}}, {"trials", one_trial()}}.dump()),
            "params: insert: unknown parameter 'depth' (expected one of: depth_m, depth_tolerance_m, speed_m_s, "
            "contact_force_n, max_force_n, lateral_stiffness_n_m, rotational_stiffness_nm_rad, "
            "lateral_damping_n_s_m, rotational_damping_nm_s_rad, stall_time_s, spiral_pitch_m, spiral_speed_m_s, "
            "spiral_max_radius_m)");
  EXPECT_EQ(refusal(json{{"params", {{"depth_m", 1}}}, {"trials", one_trial()}}.dump()),
            "params: insert: depth_m 1 out of range [0.001, 0.2] m");
  EXPECT_EQ(refusal(json{{"params", {{"timeout_s", 1000}}}, {"trials", one_trial()}}.dump()),
            "params: insert: timeout_s 1000 out of range [0, 600] s (0: the default)");
  EXPECT_EQ(refusal(json{{"params", {{"depth_m", "deep"}}}, {"trials", one_trial()}}.dump()),
            "params.depth_m: expected a number");
  EXPECT_EQ(refusal(json{{"tag", "hole_entrance"}}.dump()), "trials: missing (a list of {\"id\", \"tag_T_tip\"})");
  EXPECT_EQ(refusal(json{{"trials", json::array()}}.dump()), "trials: empty (at least one trial)");

  json non_rigid = one_trial();
  non_rigid.push_back({{"id", 2},
                       {"tag_T_tip", {{1.01, 0, 0, 0}, {0, 1.01, 0, 0}, {0, 0, 1.01, 0}, {0, 0, 0, 1}}}});
  EXPECT_EQ(refusal(json{{"trials", non_rigid}}.dump()),
            "trials[1].tag_T_tip: not a rigid transform (|R^T R - I| = 0.0201, det R = 1.0303; want <= 1e-06 and +1)");
  json mirrored = json::array({{{"id", 1}, {"tag_T_tip", {{-1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}}}});
  EXPECT_EQ(refusal(json{{"trials", mirrored}}.dump()),
            "trials[0].tag_T_tip: not a rigid transform (|R^T R - I| = 0, det R = -1; want <= 1e-06 and +1)");
  json last_row = json::array({{{"id", 1}, {"tag_T_tip", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 1, 1}}}}});
  EXPECT_EQ(refusal(json{{"trials", last_row}}.dump()),
            "trials[0].tag_T_tip: not a rigid transform (the last row is not [0, 0, 0, 1])");
  json three_rows = json::array({{{"id", 1}, {"tag_T_tip", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}}}});
  EXPECT_EQ(refusal(json{{"trials", three_rows}}.dump()),
            "trials[0].tag_T_tip: expected 4 rows of 4 numbers (a rigid transform)");
  json no_id = json::array({{{"tag_T_tip", pose_rows(0, 0, 0)}}});
  EXPECT_EQ(refusal(json{{"trials", no_id}}.dump()), "trials[0].id: expected an integer");
  json extra = json::array({{{"id", 1}, {"tag_T_tip", pose_rows(0, 0, 0)}, {"tilt", 1}}});
  EXPECT_EQ(refusal(json{{"trials", extra}}.dump()), "trials[0]: unknown key 'tilt' (expected id, tag_T_tip)");

  json many = json::array();
  for (int i = 0; i <= 10000; ++i) many.push_back({{"id", i}, {"tag_T_tip", pose_rows(0, 0, -0.01)}});
  EXPECT_EQ(refusal(json{{"trials", many}}.dump()), "trials: 10001 trials, at most 10000");
}

// The runner on config/'s plant: centred (straight in), 4.5 mm off (the
// spiral), 12 mm off (beyond the spiral's 5 mm: unreachable), a start out of
// the arm's reach; ids kept, in order.
TEST(SimulateInsertions, RunsEachTrialToItsEnd) {
  daemon::InsertionBatch b;
  b.files = sim_insertion::default_files(kConfig);
  b.trials = {{7, Pose(Eigen::Translation3d(0.0, 0.0, -0.01))},
              {8, Pose(Eigen::Translation3d(0.0045, 0.0, -0.01))},
              {9, Pose(Eigen::Translation3d(0.012, 0.0, -0.01))},
              {10, Pose(Eigen::Translation3d(0.0, 0.0, -5.0))},
              // The approach ends 2 mm into the face, 40 mm off the axis (the
              // whole end face on it): 2e5 N/m x 2 mm = 400 N, above 80 N.
              {11, Pose(Eigen::Translation3d(0.040, 0.0, 0.002))},
              // 2 mm into the hole, within the clearance: in the hole already.
              {12, Pose(Eigen::Translation3d(0.0005, 0.0, 0.002))}};
  const daemon::InsertionReport r = daemon::simulate_insertions(b);
  ASSERT_EQ(r.results.size(), 6u);
  EXPECT_EQ(r.results[4].reason, "approach_collision");
  EXPECT_FALSE(r.results[4].success);
  EXPECT_NEAR(r.results[4].peak_force_n, 400.0, 1.0);
  EXPECT_EQ(r.results[4].text.rfind("the approach ends 2.0", 0), 0u) << r.results[4].text;
  EXPECT_DOUBLE_EQ(r.results[4].sim_s, 0.0);
  EXPECT_TRUE(r.results[5].success) << r.results[5].text;
  EXPECT_EQ(r.results[0].id, 7);
  EXPECT_TRUE(r.results[0].success);
  EXPECT_EQ(r.results[0].reason, "none");
  EXPECT_FALSE(r.results[0].searched);
  EXPECT_NEAR(r.results[0].sim_s, 12.0, 0.1);

  EXPECT_TRUE(r.results[1].success);
  EXPECT_TRUE(r.results[1].searched);
  EXPECT_TRUE(r.results[1].face_contact);

  EXPECT_FALSE(r.results[2].success);
  EXPECT_FALSE(r.results[2].completed);
  EXPECT_EQ(r.results[2].reason, "unreachable");
  EXPECT_TRUE(r.results[2].searched);

  EXPECT_EQ(r.results[3].id, 10);
  EXPECT_FALSE(r.results[3].success);
  EXPECT_EQ(r.results[3].reason, "unreachable_start");
  EXPECT_DOUBLE_EQ(r.results[3].sim_s, 0.0);
  EXPECT_DOUBLE_EQ(r.success_rate, 0.5);  // 7, 8, 12 of six
  EXPECT_GT(r.compute_s, 0.0);
}

// The CLI as the ground runs it: --json on stdout, the contract's keys;
// bad input exit 2 with the message on stderr.
TEST(SimulateInsertionsCli, PrintsTheContractAndRefusesBadInput) {
  const BatchFile good(json{{"object", kConfig + "/oru.yaml"},
                            {"tag", "hole_entrance"},
                            {"params", {{"depth_m", 0.06}, {"timeout_s", 30}}},
                            {"trials",
                             {{{"id", 7}, {"tag_T_tip", pose_rows(0.0, 0.0, -0.01)}},
                              {{"id", 3}, {"tag_T_tip", pose_rows(0.012, 0.0, -0.01)}}}}});
  const test::CliRun run = test::run_program("foresight-remote", "simulate-insertions --json --batch " + good.path);
  ASSERT_EQ(run.status, 0) << run.err;
  const json out = json::parse(run.out);
  EXPECT_EQ(out["trials"], 2);
  ASSERT_EQ(out["results"].size(), 2u);
  const json& a = out["results"][0];
  EXPECT_EQ(a["id"], 7);
  EXPECT_EQ(a["success"], true);
  EXPECT_EQ(a["completed"], true);
  EXPECT_EQ(a["in_hole"], true);
  EXPECT_EQ(a["reason"], "none");
  EXPECT_EQ(a["searched"], false);
  EXPECT_EQ(a["face_contact"], false);
  EXPECT_LT(a["peak_force_n"].get<double>(), 1.0);
  EXPECT_NEAR(a["sim_s"].get<double>(), 12.0, 0.1);
  const json& b = out["results"][1];
  EXPECT_EQ(b["id"], 3);
  EXPECT_EQ(b["success"], false);
  EXPECT_EQ(b["reason"], "unreachable");
  EXPECT_EQ(b.size(), 9u);  // exactly the contract's keys
  EXPECT_DOUBLE_EQ(out["success_rate"].get<double>(), 0.5);
  EXPECT_GT(out["compute_s"].get<double>(), 0.0);
  EXPECT_EQ(out.size(), 4u);

  const test::CliRun text = test::run_program("foresight-remote", "simulate-insertions --batch " + good.path);
  ASSERT_EQ(text.status, 0) << text.err;
  EXPECT_NE(text.out.find("2 trials, success rate 0.500"), std::string::npos) << text.out;

  const BatchFile empty(json{{"trials", json::array()}});
  const test::CliRun bad = test::run_program("foresight-remote", "simulate-insertions --json --batch " + empty.path);
  EXPECT_EQ(bad.status, 2);
  EXPECT_EQ(bad.out, "");
  EXPECT_EQ(bad.err, "foresight-remote: error: " + empty.path + ": trials: empty (at least one trial)\n");
}

}  // namespace
