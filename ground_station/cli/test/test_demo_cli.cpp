// `foresight demo --fast` end to end: the daemon on the simulated robot, the
// ground chain, the ORU changeout over DDS (loopback), the report. Known
// answers: every step completed, the re-inserted ORU seated within 5 mm of its
// slot (the simulator's truth), the localization within docs/estimation.md's
// figures (four views at 1 px: 2.49 mm / 0.425 deg RMSE; bound here 3 x that).
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "foresight/test/cli.hpp"

namespace {

TEST(DemoCli, FastRunCompletesEveryStepAndReseatsTheOru) {
  const std::string out = foresight::test::temp_path("_demo");
  const std::string log = out + ".log";
  // The whole job takes minutes on a loaded 2-core machine; `timeout` bounds it.
  const std::string cmd = "timeout -s INT 840 " + std::string(FORESIGHT_BIN_DIR) + "/foresight demo --fast --out " +
                          out + " >" + log + " 2>&1";
  const int st = std::system(cmd.c_str());
  const std::string text = foresight::test::read_file(log);
  ASSERT_TRUE(WIFEXITED(st)) << text;
  ASSERT_EQ(WEXITSTATUS(st), 0) << text.substr(text.size() > 6000 ? text.size() - 6000 : 0);

  const auto r = nlohmann::json::parse(foresight::test::read_file(out + "/report.json"));
  for (const char* key : {"steps", "calibration", "localization", "final_alignment_error_m", "rtt_s"})
    EXPECT_TRUE(r.contains(key)) << key;
  EXPECT_EQ(r["result"], "completed");
  ASSERT_GE(r["steps"].size(), 17u);
  for (const auto& s : r["steps"]) {
    EXPECT_EQ(s["outcome"], "completed") << s.dump();
    EXPECT_TRUE(s.contains("n") && s.contains("command") && s.contains("seconds")) << s.dump();
  }
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
  EXPECT_TRUE(std::filesystem::exists(out + "/report.md"));
  EXPECT_TRUE(std::filesystem::exists(out + "/overlay_oblique.png"));
  std::filesystem::remove_all(out);
  std::remove(log.c_str());
}

}  // namespace
