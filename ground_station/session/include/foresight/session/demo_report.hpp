#pragma once
// `foresight demo`'s report: the round trip sampled over the run and its
// plot, the remote's timing of the script's commands (its journal) and the
// timeline, report.md. Set-up code, not real-time.

#include <atomic>
#include <cstdint>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <map>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "foresight/ground_link/ground_link.hpp"

namespace foresight::session {

/// Samples the monitor's round trips as they arrive (time of arrival on the
/// ground, seconds since the sampler started) on its own thread, until stopped.
class DelaySampler {
 public:
  explicit DelaySampler(const ground_link::GroundLink& link);
  ~DelaySampler();
  DelaySampler(const DelaySampler&) = delete;
  DelaySampler& operator=(const DelaySampler&) = delete;
  void stop();
  /// t_s,rtt_s with a header.
  void write_csv(const std::string& path) const;

 private:
  void loop();
  const ground_link::GroundLink& link_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::vector<std::pair<double, double>> samples_;
  std::thread thread_;
};

/// Nearest-rank percentile of `v` (sorted copy); NaN when empty.
double percentile(std::vector<double> v, double p);

/// The round trip over time from delay.csv as a PNG: the samples, the median
/// and p99 as horizontal lines, both axes labelled. Returns {file, samples,
/// median_s, p99_s}; throws when there is nothing to draw or the PNG cannot
/// be written.
nlohmann::json draw_delay_plot(const std::string& csv, const std::string& png);

/// The script's remote commands as the remote saw them (its journal, its
/// clock): each command's RECEIVED, EXECUTING and final stamps. work_s sums
/// EXECUTING -> final; remote_span_s runs from the first RECEIVED to the last
/// final state; overhead_s = span - work: the time the remote waited for the
/// link (and for the ground). `ids`: the command ids the script sent (its
/// run.jsonl), of session `session`.
nlohmann::json remote_timing(const nlohmann::json& journal, std::uint64_t session, const std::set<std::uint64_t>& ids,
                             double rtt_s, bool chain);

/// The steps against time (remote clock) as a PNG; throws when it cannot be written.
void draw_timeline(const nlohmann::json& timing, const std::string& png);

/// The command ids the task script sent (OUT/run.jsonl rows with a command_id).
std::set<std::uint64_t> script_command_ids(const std::string& out);

/// The contact sheets from the runner's journal (OUT/run.jsonl), by script line.
std::map<int, std::string> contact_sheets(const std::string& out);

/// The simulator's last truth (its sim_truth journal event) read through
/// `foresight-remote journal`; null when there is none.
nlohmann::json last_sim_truth(const std::string& remote_exe, const std::string& db, const std::string& out);

/// OUT/report.md from the report object.
void write_markdown(const nlohmann::json& report, const std::string& out);

/// j[key] when it is a number, else NaN.
double num(const nlohmann::json& j, const char* key);

}  // namespace foresight::session
