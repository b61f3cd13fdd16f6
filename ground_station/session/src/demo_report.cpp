// `foresight demo`'s report (demo_report.hpp).
#include "foresight/session/demo_report.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "foresight/common/format.hpp"
#include "foresight/session/processes.hpp"

namespace foresight::session {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

std::string axis_label(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", std::abs(v) < 1e-12 ? 0.0 : v);
  return buf;
}

/// "0.21 ms" below 10 ms, else "4.001 s".
std::string seconds_label(double v) {
  char buf[32];
  if (std::abs(v) < 0.01) std::snprintf(buf, sizeof buf, "%.2f ms", v * 1e3);
  else std::snprintf(buf, sizeof buf, "%.3f s", v);
  return buf;
}

/// A "nice" tick step for a span (1, 2 or 5 x 10^k), about `n` ticks.
double tick_step(double span, int n) {
  const double raw = span / n;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (raw <= m * mag) return m * mag;
  return 10.0 * mag;
}

}  // namespace

DelaySampler::DelaySampler(const ground_link::GroundLink& link) : link_(link), thread_([this] { loop(); }) {}
DelaySampler::~DelaySampler() { stop(); }

void DelaySampler::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void DelaySampler::write_csv(const std::string& path) const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::ofstream out(path);
  out << "t_s,rtt_s\n";
  char buf[64];
  for (const auto& [t, rtt] : samples_) {
    std::snprintf(buf, sizeof buf, "%.3f,%.6f\n", t, rtt);
    out << buf;
  }
}

void DelaySampler::loop() {
  const auto t0 = Clock::now();
  std::uint64_t seen = 0;
  // Bounded by stop(): the ground stage ends within its own deadlines.
  while (!stop_.load()) {
    const auto st = link_.delay().stats();
    if (st.received > seen) {
      const auto window = link_.delay().window();
      const std::size_t fresh = std::min<std::size_t>(st.received - seen, window.size());
      const double t = since(t0);
      std::lock_guard<std::mutex> lock(mutex_);
      for (std::size_t i = window.size() - fresh; i < window.size(); ++i)
        samples_.emplace_back(t, static_cast<double>(window[i].rtt_ns) * 1e-9);
      seen = st.received;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

/// Nearest-rank percentile of `v` (sorted copy); NaN when empty.
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const auto k = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, k > 0 ? k - 1 : 0)];
}

/// The round trip over time from delay.csv as a PNG: the samples, the median
/// and p99 as horizontal lines, both axes labelled. Returns {samples, median,
/// p99}; throws when there is nothing to draw or the PNG cannot be written.
nlohmann::json draw_delay_plot(const std::string& csv, const std::string& png) {
  std::vector<std::pair<double, double>> pts;
  std::istringstream in(read_log(csv));
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    double t = 0, r = 0;
    if (std::sscanf(line.c_str(), "%lf,%lf", &t, &r) == 2 && std::isfinite(t) && std::isfinite(r)) pts.emplace_back(t, r);
  }
  if (pts.empty()) throw std::runtime_error(csv + ": no round trips to plot");
  std::vector<double> rtts;
  for (const auto& p : pts) rtts.push_back(p.second);
  const double median = percentile(rtts, 0.5), p99 = percentile(rtts, 0.99);
  const double t_max = std::max(pts.back().first, 1.0);
  const double y_top = *std::max_element(rtts.begin(), rtts.end()) * 1.15 + 1e-9;
  // A round trip can come out a hair below 0 on loopback (four stamps from
  // two clocks): the axis then starts below 0 so every sample is shown.
  const double y_bottom = std::min(0.0, *std::min_element(rtts.begin(), rtts.end()) * 1.15);

  const int W = 900, H = 420, left = 90, right = 30, top = 40, bottom = 60;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  const auto X = [&](double t) { return left + static_cast<int>(std::lround(t / t_max * (W - left - right))); };
  const auto Y = [&](double r) {
    return H - bottom - static_cast<int>(std::lround((r - y_bottom) / (y_top - y_bottom) * (H - top - bottom)));
  };
  const cv::Scalar black(0, 0, 0), grey(200, 200, 200), blue(200, 90, 0), red(0, 0, 220), dot(60, 60, 60);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  for (double t = 0; t <= t_max + 1e-9; t += tick_step(t_max, 8)) {  // x ticks
    cv::line(img, {X(t), top}, {X(t), H - bottom}, grey, 1);
    cv::putText(img, axis_label(t), {X(t) - 10, H - bottom + 20}, font, 0.45, black, 1, cv::LINE_AA);
  }
  const double y_step = tick_step(y_top - y_bottom, 5);
  for (double r = std::ceil(y_bottom / y_step) * y_step; r <= y_top + 1e-12; r += y_step) {  // y ticks
    cv::line(img, {left, Y(r)}, {W - right, Y(r)}, grey, 1);
    cv::putText(img, axis_label(r), {8, Y(r) + 5}, font, 0.45, black, 1, cv::LINE_AA);
  }
  cv::rectangle(img, {left, top}, {W - right, H - bottom}, black, 1);
  for (std::size_t i = 1; i < pts.size(); ++i)
    cv::line(img, {X(pts[i - 1].first), Y(pts[i - 1].second)}, {X(pts[i].first), Y(pts[i].second)}, dot, 1, cv::LINE_AA);
  for (const auto& p : pts) cv::circle(img, {X(p.first), Y(p.second)}, 2, dot, cv::FILLED, cv::LINE_AA);
  cv::line(img, {left, Y(median)}, {W - right, Y(median)}, blue, 2, cv::LINE_AA);
  cv::line(img, {left, Y(p99)}, {W - right, Y(p99)}, red, 2, cv::LINE_AA);
  // The median's label below its line, above it when the line runs along the bottom.
  const int median_y = Y(median) + 18 < H - bottom - 2 ? Y(median) + 18 : Y(median) - 8;
  cv::putText(img, "median " + seconds_label(median), {W - right - 230, median_y}, font, 0.5, blue, 1, cv::LINE_AA);
  cv::putText(img, "p99 " + seconds_label(p99), {W - right - 230, Y(p99) - 8}, font, 0.5, red, 1, cv::LINE_AA);
  cv::putText(img, "round trip (s) over the run: " + std::to_string(pts.size()) + " pings", {left, 25}, font, 0.55,
              black, 1, cv::LINE_AA);
  cv::putText(img, "time since the ground connected (s)", {left + (W - left - right) / 2 - 140, H - 15}, font, 0.5,
              black, 1, cv::LINE_AA);
  cv::Mat ylabel(24, H - top - bottom, CV_8UC3, cv::Scalar(255, 255, 255));
  cv::putText(ylabel, "round trip (s)", {(H - top - bottom) / 2 - 60, 17}, font, 0.5, black, 1, cv::LINE_AA);
  cv::Mat rotated;
  cv::rotate(ylabel, rotated, cv::ROTATE_90_COUNTERCLOCKWISE);
  rotated.copyTo(img(cv::Rect(left - 28, top, rotated.cols, rotated.rows)));
  if (!cv::imwrite(png, img)) throw std::runtime_error(png + ": cannot write the delay plot");
  return {{"file", std::filesystem::path(png).filename().string()}, {"samples", pts.size()}, {"median_s", median},
          {"p99_s", p99}};
}

/// The script's remote commands as the remote saw them (its journal, its
/// clock): each command's RECEIVED, EXECUTING and final stamps. work_s sums
/// EXECUTING -> final; remote_span_s runs from the first RECEIVED to the last
/// final state; overhead_s = span - work: the time the remote waited for the
/// link (and for the ground). `ids`: the command ids the script sent (its
/// run.jsonl), of session `session`.
json remote_timing(const json& journal, std::uint64_t session, const std::set<std::uint64_t>& ids, double rtt_s,
                   bool chain) {
  struct Times {
    std::string kind;
    double received = NAN, executing = NAN, end = NAN;
    std::string state;
  };
  std::map<std::uint64_t, Times> by_id;
  for (const auto& c : journal.value("commands", json::array())) {
    const auto id = c.value("command_id", std::uint64_t{0});
    if (c.value("session_id", std::uint64_t{0}) != session || ids.count(id) == 0) continue;
    Times& t = by_id[id];
    t.kind = c.value("kind", "");
    const std::string st = c.value("state", "");
    const double at = static_cast<double>(c.value("stamp_ns", std::int64_t{0})) * 1e-9;
    if (st == "RECEIVED") t.received = at;
    else if (st == "EXECUTING") t.executing = at;
    else if (st == "COMPLETED" || st == "FAILED" || st == "CANCELED" || st == "REJECTED") {
      t.end = at;
      t.state = st;
    }
  }
  double first = INFINITY, last = -INFINITY, work = 0.0;
  for (const auto& [id, t] : by_id) {
    if (std::isfinite(t.received)) first = std::min(first, t.received);
    if (std::isfinite(t.end)) last = std::max(last, t.end);
    if (std::isfinite(t.executing) && std::isfinite(t.end)) work += t.end - t.executing;
  }
  json steps = json::array();
  for (const auto& [id, t] : by_id) {
    const auto rel = [&](double v) { return std::isfinite(v) ? json(v - first) : json(nullptr); };
    steps.push_back({{"command_id", id}, {"kind", t.kind}, {"received_s", rel(t.received)},
                     {"executing_s", rel(t.executing)}, {"end_s", rel(t.end)}, {"state", t.state}});
  }
  const double span = std::isfinite(first) && std::isfinite(last) ? last - first : 0.0;
  return {{"chain", chain},         {"commands", by_id.size()}, {"work_s", work}, {"remote_span_s", span},
          {"overhead_s", span - work}, {"rtt_s", std::isfinite(rtt_s) ? json(rtt_s) : json(nullptr)},
          {"steps", steps}};
}

/// The steps against time (remote clock, from the first command received):
/// each command a row, queued (light) then running (its colour), the sent time
/// estimated half a round trip before it was received, and the round trip as a
/// scale bar. Throws when the PNG cannot be written.
void draw_timeline(const json& timing, const std::string& png) {
  const auto& steps = timing["steps"];
  const double span = std::max(1.0, timing["remote_span_s"].get<double>());
  const double rtt = timing["rtt_s"].is_number() ? timing["rtt_s"].get<double>() : 0.0;
  const int row = 16, W = 1000, left = 150, right = 20, top = 50;
  const int H = top + row * static_cast<int>(std::max<std::size_t>(steps.size(), 1)) + 60;
  const double t0 = -0.5 * rtt;  // room for the first command's send
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  const auto X = [&](double t) { return left + static_cast<int>(std::lround((t - t0) / (span - t0) * (W - left - right))); };
  const cv::Scalar black(0, 0, 0), grey(200, 200, 200), queued(225, 215, 190), run(200, 90, 0), algo(40, 140, 40),
      bad(0, 0, 220), sent(60, 60, 60);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  for (double t = 0; t <= span + 1e-9; t += tick_step(span, 10)) {
    cv::line(img, {X(t), top - 5}, {X(t), H - 55}, grey, 1);
    cv::putText(img, axis_label(t), {X(t) - 10, H - 38}, font, 0.42, black, 1, cv::LINE_AA);
  }
  int y = top;
  for (const auto& s : steps) {
    cv::putText(img, std::to_string(s["command_id"].get<std::uint64_t>()) + " " + s["kind"].get<std::string>(),
                {6, y + 12}, font, 0.4, black, 1, cv::LINE_AA);
    const bool ok = s["state"] == "COMPLETED";
    if (s["received_s"].is_number()) {
      const double r = s["received_s"].get<double>();
      const double e = s["executing_s"].is_number() ? s["executing_s"].get<double>()
                                                     : (s["end_s"].is_number() ? s["end_s"].get<double>() : r);
      if (rtt > 0) cv::line(img, {X(r - 0.5 * rtt), y + 8}, {X(r), y + 8}, sent, 1, cv::LINE_AA);
      cv::rectangle(img, {X(r), y + 3}, {std::max(X(e), X(r) + 1), y + 13}, queued, cv::FILLED);
      if (s["executing_s"].is_number() && s["end_s"].is_number())
        cv::rectangle(img, {X(e), y + 2}, {std::max(X(s["end_s"].get<double>()), X(e) + 2), y + 14},
                      ok ? (s["kind"] == "INVOKE_ALGORITHM" ? algo : run) : bad, cv::FILLED);
    }
    y += row;
  }
  if (rtt > 0) {
    cv::line(img, {X(0), H - 18}, {X(rtt), H - 18}, bad, 3);
    cv::putText(img, "one round trip (" + seconds_label(rtt) + ")", {X(rtt) + 8, H - 13}, font, 0.45, bad, 1,
                cv::LINE_AA);
  }
  char title[200];
  std::snprintf(title, sizeof title, "%s: work %.1f s, remote span %.1f s, waiting %.1f s (remote clock, s)",
                timing["chain"].get<bool>() ? "chained (--chain)" : "step by step", timing["work_s"].get<double>(),
                timing["remote_span_s"].get<double>(), timing["overhead_s"].get<double>());
  cv::putText(img, title, {left, 22}, font, 0.5, black, 1, cv::LINE_AA);
  cv::putText(img, "thin line: sent (half a round trip before received); light: queued; dark: running", {left, 40},
              font, 0.4, sent, 1, cv::LINE_AA);
  if (!cv::imwrite(png, img)) throw std::runtime_error(png + ": cannot write the timeline");
}

/// The command ids the task script sent (run.jsonl rows with a command_id).
std::set<std::uint64_t> script_command_ids(const std::string& out) {
  std::set<std::uint64_t> ids;
  std::istringstream in(read_log(out + "/run.jsonl"));
  for (std::string line; std::getline(in, line);) {
    const json j = json::parse(line, nullptr, false);
    if (!j.is_discarded() && j.contains("command_id") && j["command_id"].is_number_unsigned())
      ids.insert(j["command_id"].get<std::uint64_t>());
  }
  return ids;
}

/// The contact sheets from the runner's journal (run.jsonl), by script line.
std::map<int, std::string> contact_sheets(const std::string& out) {
  std::map<int, std::string> sheets;
  std::istringstream in(read_log(out + "/run.jsonl"));
  for (std::string line; std::getline(in, line);) {
    const json j = json::parse(line, nullptr, false);
    if (!j.is_discarded() && j.contains("contact_sheet") && j.contains("line"))
      sheets[j["line"].get<int>()] = fs::path(j["contact_sheet"].get<std::string>()).filename().string();
  }
  return sheets;
}

json last_sim_truth(const std::string& remote_exe, const std::string& db, const std::string& out) {
  const pid_t pid = spawn({remote_exe, "journal", "--db", db, "--json"}, out + "/remote_journal.json",
                          out + "/remote_journal.log");
  if (wait_for(pid, 60.0) != 0) return nullptr;
  json truth = nullptr;
  const json j = json::parse(read_log(out + "/remote_journal.json"), nullptr, false);
  if (j.is_discarded() || !j.contains("events")) return nullptr;
  for (const auto& e : j["events"])
    if (e.value("kind", "") == "sim_truth") truth = e["detail"];
  return truth;
}

double num(const json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : std::nan("");
}

void write_markdown(const json& r, const std::string& out) {
  std::ofstream md(out + "/report.md");
  md << "# foresight demo\n\n";
  md << "Link: " << r["link"].get<std::string>() << "; DDS domain " << r["domain"] << "; "
     << r["total_seconds"].get<double>() << " s in all. Outcome: **" << r["result"].get<std::string>() << "**\n\n";
  if (r.contains("error")) md << "Error: " << r["error"].get<std::string>() << "\n\n";
  md << "## Calibration (the arm as the fixture, 1 px clicks)\n\n| camera | rms px | position error mm |\n|---|---|---|\n";
  for (const auto& c : r.value("calibration", json::array()))
    md << "| " << c["camera"].get<std::string>() << " | " << printf_text("%.3f", c["rms_px"].get<double>()) << " | "
       << printf_text("%.1f", c["position_error_m"].get<double>() * 1e3) << " |\n";
  if (r.contains("localization")) {
    const auto& l = r["localization"];
    md << "\n## Localization\n\n" << l["views"].size() << " views: "
       << printf_text("%.2f", l["position_error_m"].get<double>() * 1e3) << " mm, "
       << printf_text("%.3f", l["rotation_error_deg"].get<double>())
       << " deg from the true pose (docs/estimation.md: 2.49 mm / 0.425 deg RMSE at 1 px with four views).\n\n"
       << "![overlay](overlay_oblique.png)\n";
  }
  md << "\n## The changeout script\n\n| n | command | outcome | s | preview |\n|---|---|---|---|---|\n";
  for (const auto& s : r.value("steps", json::array())) {
    md << "| " << s["n"] << " | `" << s["command"].get<std::string>() << "` | " << s["outcome"].get<std::string>()
       << " | " << printf_text("%.1f", s["seconds"].get<double>()) << " | ";
    if (s.contains("contact_sheet")) md << "[sheet](" << s["contact_sheet"].get<std::string>() << ")";
    md << " |\n";
  }
  if (r.contains("timing")) {
    md << "\n## Timing (the remote's clock: its journal)\n\n"
          "Work is the sum of the script's commands' EXECUTING-to-final times; the span runs from the first "
          "command received to the last final state; waiting = span - work (the remote idle for the link or "
          "the ground).\n\n| run | commands | work s | span s | waiting s | round trip s |\n|---|---|---|---|---|---|\n";
    const auto row = [&](const json& t, const std::string& name) {
      md << "| " << name << " | " << t.value("commands", 0) << " | " << printf_text("%.1f", num(t, "work_s")) << " | "
         << printf_text("%.1f", num(t, "remote_span_s")) << " | " << printf_text("%.1f", num(t, "overhead_s")) << " | "
         << printf_text("%.2f", num(t, "rtt_s")) << " |\n";
    };
    const auto name = [](const json& t) { return std::string(t.value("chain", false) ? "chained (--chain)" : "step by step"); };
    row(r["timing"], "this run: " + name(r["timing"]));
    if (r.contains("timing_compare")) row(r["timing_compare"], name(r["timing_compare"]) + " (--compare)");
    if (r["timing"].contains("timeline")) md << "\n![the steps against time](timeline.png)\n";
  }
  md << "\nFinal alignment of the re-inserted ORU against its slot (the simulator's truth): ";
  if (r["final_alignment_error_m"].is_number())
    md << printf_text("%.2f", r["final_alignment_error_m"].get<double>() * 1e3) << " mm";
  else
    md << "not reported";
  md << "\n\n## Delay (round trip measured by the ground's pings)\n\n| median s | p95 s | p99 s | max s | pings |\n"
        "|---|---|---|---|---|\n";
  const auto& d = r["rtt_s"];
  md << "| " << printf_text("%.3f", num(d, "median")) << " | " << printf_text("%.3f", num(d, "p95")) << " | "
     << printf_text("%.3f", num(d, "p99")) << " | " << printf_text("%.3f", num(d, "max")) << " | " << printf_text("%.0f", num(d, "count"))
     << " |\n";
  if (r.contains("delay_plot") && r["delay_plot"].contains("file")) {
    const auto& p = r["delay_plot"];
    md << "\n![round trip over time, median and p99](" << p["file"].get<std::string>() << ")\n\n"
       << "[delay.png](" << p["file"].get<std::string>() << "): " << p["samples"] << " round trips over the run (delay.csv); "
       << "median " << printf_text("%.3f", p["median_s"].get<double>()) << " s, p99 " << printf_text("%.3f", p["p99_s"].get<double>())
       << " s.\n";
  } else if (r.contains("delay_plot")) {
    md << "\nNo delay plot: " << r["delay_plot"].value("error", std::string("?")) << "\n";
  }
}

}  // namespace foresight::session
