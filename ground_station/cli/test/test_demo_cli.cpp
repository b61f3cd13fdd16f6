// `foresight demo --fast` end to end: the daemon on the simulated robot, the
// ground chain, the ORU changeout over DDS (loopback, its motions chained), the
// report; step by step on a short script. Known
// answers: every step completed, the re-inserted ORU seated within 5 mm of its
// slot (the simulator's truth), the localization within docs/estimation.md's
// figures (four views at 1 px: 2.49 mm / 0.425 deg RMSE; bound here 3 x that).
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "foresight/test/cli.hpp"

namespace {

// The delay plot from known samples: round trips 0.01..1.00 s, one every 0.5 s.
// Nearest rank: the median is the 50th (0.50 s), p99 the 99th (0.99 s); the
// plot's y axis spans 1.15 x the largest, so on the 900 x 420 image (plot area
// y 40..360) the median line is at row 360 - 0.50/1.15 x 320 = 221 (blue) and
// the p99 line at row 360 - 0.99/1.15 x 320 = 85 (red).
TEST(DemoCli, DelayPlotDrawsMedianAndP99FromTheSamples) {
  const std::string out = foresight::test::temp_path("_plot");
  std::filesystem::create_directories(out);
  {
    std::ofstream csv(out + "/delay.csv");
    csv << "t_s,rtt_s\n";
    for (int i = 1; i <= 100; ++i) csv << i * 0.5 << "," << i * 0.01 << "\n";
  }
  const auto r = foresight::test::run_foresight("demo --stage plot --out " + out);
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["file"], "delay.png");
  EXPECT_EQ(j["samples"], 100);
  EXPECT_DOUBLE_EQ(j["median_s"].get<double>(), 0.50);
  EXPECT_DOUBLE_EQ(j["p99_s"].get<double>(), 0.99);
  const cv::Mat img = cv::imread(out + "/delay.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 900);
  EXPECT_EQ(img.rows, 420);
  const cv::Vec3b median = img.at<cv::Vec3b>(221, 200), p99 = img.at<cv::Vec3b>(85, 200);  // BGR
  EXPECT_GT(median[0], 150) << "median line blue";
  EXPECT_LT(median[2], 100);
  EXPECT_GT(p99[2], 150) << "p99 line red";
  EXPECT_LT(p99[0], 100);
  const cv::Vec3b blank = img.at<cv::Vec3b>(150, 200);  // between the lines, away from points and grid
  EXPECT_EQ(blank, cv::Vec3b(255, 255, 255));
  std::filesystem::remove_all(out);
  // No samples: the demo's report says why instead of a picture.
  const std::string empty = foresight::test::temp_path("_plot");
  std::filesystem::create_directories(empty);
  std::ofstream(empty + "/delay.csv") << "t_s,rtt_s\n";
  const auto e = foresight::test::run_foresight("demo --stage plot --out " + empty);
  EXPECT_EQ(e.status, 1);
  EXPECT_EQ(e.err, "foresight demo: error: " + empty + "/delay.csv: no round trips to plot\n");
  std::filesystem::remove_all(empty);
}

/// Runs `foresight demo --fast ARGS --out OUT` (bounded by `timeout`) and
/// returns its report; the test fails with the log's tail when it did not exit 0.
nlohmann::json run_demo(const std::string& args, const std::string& out, std::string* log_text) {
  const std::string log = out + ".log";
  // The whole job takes minutes on a loaded 2-core machine; `timeout` bounds it.
  const std::string cmd = "timeout -s INT 840 " + std::string(FORESIGHT_BIN_DIR) + "/foresight demo --fast " + args +
                          " --out " + out + " >" + log + " 2>&1";
  const int st = std::system(cmd.c_str());
  *log_text = foresight::test::read_file(log);
  std::remove(log.c_str());
  EXPECT_TRUE(WIFEXITED(st) && WEXITSTATUS(st) == 0)
      << log_text->substr(log_text->size() > 6000 ? log_text->size() - 6000 : 0);
  return nlohmann::json::parse(foresight::test::read_file(out + "/report.json"));
}

// The whole changeout, its motions sent ahead as chains (issue 29): every step
// completes, the ORU is fastened within 5 mm of its slot, and the remote is
// idle only where the script says WAIT: on loopback its waiting (span - work,
// the remote's own clock) stays under 3 s, where step by step it waits for
// every preview (5.1 s measured here).
TEST(DemoCli, FastChainedRunCompletesEveryStepAndReseatsTheOru) {
  const std::string out = foresight::test::temp_path("_demo_chain");
  std::string text;
  const auto r = run_demo("--chain", out, &text);
  if (HasFailure()) return;
  for (const char* key : {"steps", "calibration", "localization", "final_alignment_error_m", "rtt_s", "timing"})
    EXPECT_TRUE(r.contains(key)) << key;
  EXPECT_EQ(r["result"], "completed");
  ASSERT_GE(r["steps"].size(), 17u);
  for (const auto& s : r["steps"]) {
    EXPECT_EQ(s["outcome"], "completed") << s.dump();
    EXPECT_TRUE(s.contains("n") && s.contains("command") && s.contains("seconds")) << s.dump();
  }
  int sent_ahead = 0;
  for (std::size_t at = text.find(" sent ("); at != std::string::npos; at = text.find(" sent (", at + 1)) ++sent_ahead;
  EXPECT_GE(sent_ahead, 15) << "the motions went ahead as chains";
  EXPECT_NE(text.find("after command "), std::string::npos);
  ASSERT_EQ(r["calibration"].size(), 4u);
  for (const auto& c : r["calibration"]) {
    EXPECT_LT(c["rms_px"].get<double>(), 2.0) << c.dump();
    EXPECT_TRUE(c.contains("camera") && c.contains("position_error_m")) << c.dump();
  }
  EXPECT_EQ(r["localization"]["views"].size(), 4u);
  EXPECT_LT(r["localization"]["position_error_m"].get<double>(), 3 * 0.00249);
  EXPECT_LT(r["localization"]["rotation_error_deg"].get<double>(), 3 * 0.425);
  ASSERT_TRUE(r["final_alignment_error_m"].is_number()) << r["final_sim_truth"].dump();
  EXPECT_LT(r["final_alignment_error_m"].get<double>(), 0.005);
  EXPECT_EQ(r["final_sim_truth"]["oru_state"], "fastened") << r["final_sim_truth"].dump();
  EXPECT_TRUE(r["rtt_s"]["median"].is_number());
  EXPECT_TRUE(r["rtt_s"]["p99"].is_number());
  EXPECT_EQ(r["remote_exit"], 0);  // the daemon stopped cleanly on SIGTERM
  EXPECT_TRUE(std::filesystem::exists(out + "/overlay_oblique.png"));
  // The delay plot: a PNG drawn from every measured round trip, its median and
  // p99 those of the samples (the same nearest-rank rule as the ground's
  // statistics over a window), linked from report.md.
  ASSERT_TRUE(r.contains("delay_plot")) << r.dump();
  const auto& plot = r["delay_plot"];
  ASSERT_TRUE(plot.contains("file")) << plot.dump();
  EXPECT_EQ(plot["file"], "delay.png");
  EXPECT_GE(plot["samples"].get<int>(), 10) << "5 pings a second over minutes";
  EXPECT_LE(plot["median_s"].get<double>(), plot["p99_s"].get<double>());
  EXPECT_GT(plot["median_s"].get<double>(), 0.0);
  const std::string png = foresight::test::read_file(out + "/delay.png");
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  EXPECT_GT(png.size(), 5000u) << "axes, labels and points drawn";
  const std::string csv = foresight::test::read_file(out + "/delay.csv");
  EXPECT_EQ(csv.rfind("t_s,rtt_s\n", 0), 0u);
  const std::string md = foresight::test::read_file(out + "/report.md");
  EXPECT_NE(md.find("![round trip over time, median and p99](delay.png)"), std::string::npos);
  // The remote's timing of the script's commands (its journal).
  const auto& t = r["timing"];
  EXPECT_EQ(t["chain"], true);
  EXPECT_GE(t["commands"].get<int>(), 17);
  EXPECT_GT(t["work_s"].get<double>(), 60.0) << "the changeout's motions and contact steps";
  EXPECT_NEAR(t["overhead_s"].get<double>(), t["remote_span_s"].get<double>() - t["work_s"].get<double>(), 1e-9);
  EXPECT_LT(t["overhead_s"].get<double>(), 3.0) << t.dump();
  // The steps' own times: queued before running, never two running at once.
  double last_end = -1.0;
  for (const auto& s : t["steps"]) {
    ASSERT_TRUE(s["end_s"].is_number()) << s.dump();
    EXPECT_EQ(s["state"], "COMPLETED") << s.dump();
    if (s["executing_s"].is_number()) {
      EXPECT_GE(s["executing_s"].get<double>(), s["received_s"].get<double>());
      EXPECT_GE(s["executing_s"].get<double>() + 1e-6, last_end) << "two commands ran at once: " << s.dump();
      last_end = s["end_s"].get<double>();
    }
  }
  EXPECT_EQ(t["timeline"], "timeline.png");
  EXPECT_GT(foresight::test::read_file(out + "/timeline.png").size(), 5000u);
  EXPECT_NE(md.find("| this run: chained (--chain) |"), std::string::npos);
  std::filesystem::remove_all(out);
}

// Step by step (no --chain), on a short script (the whole changeout is the
// test above): every remote step waits for the one before, and the remote's
// timing shows it; `--compare` puts another run's timing beside this one's.
TEST(DemoCli, FastStepByStepRunReportsItsTimingBesideAnotherRun) {
  const std::string script = foresight::test::temp_path(".task");
  std::ofstream(script) << "OBJECT oru\nVIDEO oblique\nCALIBRATE\nLOCALIZE\n"
                           "TRAJECTORY to=approach_20cm\nINVOKE_ALGORITHM tare timeout_s=10\n"
                           "GOTO_JOINT start speed=0.5\nREQUEST status\n";
  // The other run: a report whose timing is known.
  const std::string other = foresight::test::temp_path("_other.json");
  std::ofstream(other) << R"({"timing": {"chain": true, "commands": 3, "work_s": 10.0, "remote_span_s": 14.0,)"
                       << R"( "overhead_s": 4.0, "rtt_s": 4.0, "steps": []}})";
  const std::string out = foresight::test::temp_path("_demo");
  std::string text;
  const auto r = run_demo("--script " + script + " --compare " + other, out, &text);
  if (HasFailure()) return;
  EXPECT_EQ(r["result"], "completed");
  ASSERT_EQ(r["steps"].size(), 8u);
  for (const auto& s : r["steps"]) EXPECT_EQ(s["outcome"], "completed") << s.dump();
  EXPECT_EQ(text.find(" sent ("), std::string::npos) << "a step went ahead without --chain";
  const auto& t = r["timing"];
  EXPECT_EQ(t["chain"], false);
  EXPECT_EQ(t["commands"].get<int>(), 4);  // the TRAJECTORY, tare, GOTO_JOINT and REQUEST
  EXPECT_GT(t["work_s"].get<double>(), 2.0);
  EXPECT_NEAR(t["overhead_s"].get<double>(), t["remote_span_s"].get<double>() - t["work_s"].get<double>(), 1e-9);
  EXPECT_GT(t["overhead_s"].get<double>(), 0.0);
  EXPECT_EQ(r["timing_compare"]["overhead_s"], 4.0);
  const std::string md = foresight::test::read_file(out + "/report.md");
  EXPECT_NE(md.find("| this run: step by step | 4 | "), std::string::npos) << md;
  EXPECT_NE(md.find("| chained (--chain) (--compare) | 3 | 10.0 | 14.0 | 4.0 | 4.00 |"), std::string::npos) << md;
  std::filesystem::remove_all(out);
  std::remove(script.c_str());
  std::remove(other.c_str());
}

TEST(DemoCli, ACompareFileThatIsNotADemoReportIsRefusedBeforeAnythingRuns) {
  const std::string missing = foresight::test::temp_path("_none.json");
  auto e = foresight::test::run_foresight("demo --fast --compare " + missing);
  EXPECT_EQ(e.status, 2);
  EXPECT_EQ(e.err, "foresight demo: error: " + missing + ": --compare: cannot open the report\n");
  const std::string bad = foresight::test::temp_path("_bad.json");
  std::ofstream(bad) << R"({"steps": []})";
  e = foresight::test::run_foresight("demo --fast --compare " + bad);
  EXPECT_EQ(e.status, 2);
  EXPECT_EQ(e.err, "foresight demo: error: " + bad +
                       ": --compare: not a demo report with timing (report.json of foresight demo)\n");
  std::remove(bad.c_str());
}

}  // namespace
