// foresight demo: the project's main job end to end. Starts the controller
// daemon (`foresight-remote --sim`, the embedded simulated robot) on a fresh
// DDS domain -- through the link emulator (`foresight-linkemu`, --rtt seconds
// of round trip) where network namespaces can be made, else on loopback (said
// so) -- waits for its ready line, runs the ground chain (simulated operator
// clicks -> calibration of every camera -> localization of the ORU -> overlay),
// takes control, then the ORU changeout task script over DDS with a preview
// of every motion (the same ScriptRunner as `foresight run --auto`), stops the
// daemon, and writes OUT/report.json and OUT/report.md. Ctrl-C aborts the
// running command, then stops the daemon. Set-up code, not real-time.
//
// With the link emulator the ground half runs as a child in the ground's
// namespace (`foresight demo --stage ground`, hidden), which writes
// OUT/ground.json; on loopback it runs in this process.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <set>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <thread>

#include "command.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/script/executor.hpp"
#include "foresight/script/script.hpp"
#include "link_session.hpp"
#include "script_runner.hpp"

namespace foresight::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

std::atomic<bool> g_interrupt{false};
extern "C" void on_demo_interrupt(int) { g_interrupt.store(true); }

struct Options {
  std::string out = "demo";
  double rtt_s = 4.0;  // the paper's round trip
  bool fast = false;
  bool chain = false;  ///< --chain: the changeout's motions sent ahead as chains
  int domain = -1;
  std::string stage;  ///< "" (everything) or "ground" (the ground half only, hidden)
  std::string compare;  ///< --compare: another run's report.json whose timing report.md shows beside this one's
  std::string script = default_config("scripts/oru_changeout.task");
  double ready_timeout_s = 60.0;
};

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

std::string exe_dir() { return fs::read_symlink("/proc/self/exe").parent_path().string(); }

void say(const std::string& line) { std::cout << line << "\n" << std::flush; }

/// A child process in its own process group (a terminal's Ctrl-C reaches only
/// this process, which stops its children in order). stdout/stderr to files
/// ("" = inherit).
pid_t spawn(const std::vector<std::string>& args, const std::string& out_path, const std::string& err_path) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    ::setpgid(0, 0);
    if (!out_path.empty()) {
      const int fd = ::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 1);
    }
    if (!err_path.empty()) {
      const int fd = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 2);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

/// Waits for `pid` at most `timeout_s`; the exit status, or -1 when it did not
/// end in time (still running), -2 when killed by a signal.
int wait_for(pid_t pid, double timeout_s, const std::function<void()>& on_interrupt = {}) {
  const auto t0 = Clock::now();
  int status = 0;
  bool forwarded = false;
  while (since(t0) < timeout_s) {
    const pid_t w = ::waitpid(pid, &status, WNOHANG);
    if (w == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
    if (w < 0) return -2;
    if (!forwarded && on_interrupt && g_interrupt.load()) {
      on_interrupt();
      forwarded = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return -1;
}

/// SIGTERM, then SIGKILL after `grace_s`; the exit status (as wait_for).
int stop_child(pid_t pid, double grace_s) {
  if (pid <= 0) return 0;
  ::kill(pid, SIGTERM);
  int rc = wait_for(pid, grace_s);
  if (rc == -1) {
    ::kill(pid, SIGKILL);
    rc = wait_for(pid, 5.0);
  }
  return rc;
}

/// Runs one `foresight` subcommand to its end (10 min at most); stdout kept
/// in OUT/<log>; throws with the command's stderr when it fails.
void run_step(const std::string& self, const std::vector<std::string>& args, const std::string& out_path,
              const std::string& log_path) {
  std::vector<std::string> argv = {self};
  argv.insert(argv.end(), args.begin(), args.end());
  const pid_t pid = spawn(argv, out_path, log_path);
  const int rc = wait_for(pid, 600.0);
  if (rc != 0) {
    if (rc == -1) stop_child(pid, 5.0);
    std::string err = read_text(log_path);
    while (!err.empty() && err.back() == '\n') err.pop_back();
    throw std::runtime_error("foresight " + args[0] + " failed (exit " + std::to_string(rc) + "): " + err);
  }
}

/// Polls `path` for a line containing `needle`; false when `pid` exits or the
/// deadline passes first (*exit_code: its status, or -1 when it is still up).
bool wait_for_line(const std::string& path, const std::string& needle, pid_t pid, double timeout_s, int* exit_code,
                   std::string* line_found = nullptr) {
  const auto t0 = Clock::now();
  *exit_code = -1;
  while (since(t0) < timeout_s && !g_interrupt.load()) {
    std::istringstream in(read_text(path));
    for (std::string line; std::getline(in, line);)
      if (line.find(needle) != std::string::npos) {
        if (line_found) *line_found = line;
        return true;
      }
    int status = 0;
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      *exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -2;
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

// ---- the delay over time ----------------------------------------------------------

/// Samples the monitor's round trips as they arrive (time of arrival on the
/// ground, seconds since the sampler started) on its own thread, until stopped.
class DelaySampler {
 public:
  explicit DelaySampler(const ground_link::GroundLink& link) : link_(link), thread_([this] { loop(); }) {}
  ~DelaySampler() { stop(); }
  DelaySampler(const DelaySampler&) = delete;
  DelaySampler& operator=(const DelaySampler&) = delete;
  void stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  /// t_s,rtt_s with a header.
  void write_csv(const std::string& path) const {
    std::lock_guard<std::mutex> lock(mutex_);
    std::ofstream out(path);
    out << "t_s,rtt_s\n";
    char buf[64];
    for (const auto& [t, rtt] : samples_) {
      std::snprintf(buf, sizeof buf, "%.3f,%.6f\n", t, rtt);
      out << buf;
    }
  }

 private:
  void loop() {
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
  const ground_link::GroundLink& link_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::vector<std::pair<double, double>> samples_;
  std::thread thread_;
};

/// Nearest-rank percentile of `v` (sorted copy); NaN when empty.
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const auto k = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, k > 0 ? k - 1 : 0)];
}

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

/// The round trip over time from delay.csv as a PNG: the samples, the median
/// and p99 as horizontal lines, both axes labelled. Returns {samples, median,
/// p99}; throws when there is nothing to draw or the PNG cannot be written.
json draw_delay_plot(const std::string& csv, const std::string& png) {
  std::vector<std::pair<double, double>> pts;
  std::istringstream in(read_text(csv));
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

// ---- the ground half: clicks, calibration, localization, the task script -----------

/// Drives the task script's commands to the remote in auto mode; Ctrl-C aborts.
class InterruptControls : public script::Controls {
 public:
  script::Key poll(double timeout_s) override {
    if (g_interrupt.load()) return script::Key::Abort;
    return inner_.poll(timeout_s);
  }

 private:
  script::ScriptedControls inner_{{}};
};

json ground_chain(const Options& o, const std::string& self, const std::string& out) {
  json report;
  const Scene scene = Scene::from_file(default_config("scene.yaml"));
  say("== simulated operator: clicks on the arm (4 poses) and the ORU in every view, 1 px noise ==");
  run_step(self,
           {"synth-clicks", "--calibration-out", out + "/arm_clicks.csv", "--object-out", out + "/oru_clicks.csv",
            "--joints-out", out + "/arm_pose.txt", "--noise-px", "1.0", "--seed", "7"},
           out + "/synth_clicks.txt", out + "/child.log");
  std::string q = read_text(out + "/arm_pose.txt");
  while (!q.empty() && (q.back() == '\n' || q.back() == ' ')) q.pop_back();

  say("== calibration of every camera, the arm as the fixture ==");
  fs::remove(out + "/cameras.yaml");
  json cal = json::array();
  for (const auto& cam : scene.camera_order) {
    const std::string jpath = out + "/calibrate_" + cam + ".json";
    run_step(self, {"calibrate", out + "/arm_clicks.csv", "--camera", cam, "--out", out + "/cameras.yaml", "--json"},
             jpath, out + "/child.log");
    const json j = json::parse(read_text(jpath));
    const auto p = j["position_m"].get<std::vector<double>>();
    const double err = (Eigen::Vector3d(p[0], p[1], p[2]) - scene.cameras.at(cam).position_m).norm();
    cal.push_back({{"camera", cam}, {"rms_px", j["rms_px"]}, {"position_error_m", err}, {"f_px", j["f_px"]}});
    char buf[200];
    std::snprintf(buf, sizeof buf, "  %-14s rms %.3f px, camera position %.1f mm from the truth", cam.c_str(),
                  j["rms_px"].get<double>(), err * 1e3);
    say(buf);
  }
  report["calibration"] = cal;

  say("== localization of the ORU from every view ==");
  run_step(self, {"localize", out + "/oru_clicks.csv", "--cameras", out + "/cameras.yaml", "--json"},
           out + "/localize.json", out + "/child.log");
  const json lj = json::parse(read_text(out + "/localize.json"));
  const Pose est = read_object_pose_json(out + "/localize.json");
  const double dp = (est.translation() - scene.base_T_object.translation()).norm();
  const double dr =
      Eigen::AngleAxisd(est.linear().transpose() * scene.base_T_object.linear()).angle() * 180.0 / M_PI;
  report["localization"] = {{"position_error_m", dp}, {"rotation_error_deg", dr}, {"views", lj["views"]},
                            {"rms_px", lj["rms_px"]}};
  char buf[200];
  std::snprintf(buf, sizeof buf, "  %zu views: %.2f mm, %.3f deg from the true pose", lj["views"].size(), dp * 1e3, dr);
  say(buf);

  say("== what the operator sees: the calibrated overlay (camera oblique) ==");
  run_step(self, {"synth", "--camera", "oblique", "--joints", q, "--out", out + "/video_oblique.png"}, "",
           out + "/child.log");
  run_step(self,
           {"overlay", "--cameras", out + "/cameras.yaml", "--camera", "oblique", "--image", out + "/video_oblique.png",
            "--joints", q, "--object-pose", out + "/localize.json", "--tags", "--mode", "hidden", "--out",
            out + "/overlay_oblique.png"},
           "", out + "/child.log");
  report["overlays"] = json::array({"overlay_oblique.png"});
  (void)o;
  return report;
}

/// TAKE_CONTROL, RECOVER (the drives come up) and a first tare, as an operator does first.
void take_control(ground_link::GroundLink& link) {
  const std::vector<std::pair<protocol::CommandKind, protocol::Payload>> first = {
      {protocol::CommandKind::TakeControl, protocol::NoPayload{}},
      {protocol::CommandKind::Recover, protocol::NoPayload{}},
      {protocol::CommandKind::InvokeAlgorithm, protocol::InvokeAlgorithm{"tare", {}, 0.0}}};
  for (const auto& [kind, payload] : first) {
    const auto r = send_and_wait(link, kind, payload, final_ack_timeout(link, 5.0, 0.0), [] { return g_interrupt.load(); });
    say("  " + result_line(kind, r));
    if (!r.succeeded()) throw LinkFailure(result_line(kind, r));
  }
}

int ground_stage(const Options& o, const std::string& out) {
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  json report;
  int rc = kExitOk;
  std::unique_ptr<ground_link::GroundLink> monitor;  // pings the whole run: the delay figures
  std::unique_ptr<DelaySampler> sampler;             // ... and their times (the plot)
  try {
    report = ground_chain(o, self, out);
    say("== the ORU changeout over DDS (domain " + std::to_string(o.domain) + "): " + o.script + " ==");
    auto link = connect_remote(o.domain, o.fast ? 30.0 : 60.0);
    monitor = connect_remote(o.domain, o.fast ? 30.0 : 60.0);
    sampler = std::make_unique<DelaySampler>(*monitor);
    take_control(*link);
    report["session_id"] = link->session_id();  // the timing picks the script's commands of this session
    report["chain"] = o.chain;

    RunSettings s;
    s.work_dir = out;
    s.robot = default_config("robot.urdf");
    s.object = default_config("oru.yaml");
    s.scene = default_config("scene.yaml");
    s.self_exe = self;
    s.preview = true;
    s.chain = o.chain;
    s.preview_speed = o.fast ? 8.0 : 4.0;
    const script::Script parsed = script::load_script(o.script);
    script::check_script(parsed, ScriptRunner::context_for(RobotModel::from_file(s.robot),
                                                           ObjectModel::from_file(s.object), Scene::from_file(s.scene)));
    ScriptRunner runner(s, std::move(link));
    script::Executor ex(parsed, 0);
    ex.set_auto(true);
    InterruptControls controls;
    std::vector<script::CommandState> printed(parsed.commands.size(), script::CommandState::Pending);
    const auto n_total = parsed.commands.size();
    const auto on_change = [&](const script::Executor& e) {
      const script::Command* c = e.current_command();
      if (e.state() == script::RunState::Running && c != nullptr)
        say("> [" + std::to_string(static_cast<std::size_t>(c - e.script().commands.data()) + 1) + "/" +
            std::to_string(n_total) + "] line " +
            std::to_string(c->line) + ": " + c->text + (c->note.empty() ? "" : "   # " + c->note));
      for (std::size_t i = 0; i < e.script().commands.size() && i < printed.size(); ++i) {
        const auto st = e.command_state(i);
        if (st == printed[i]) continue;  // a chained step prints when sent and when it ended
        printed[i] = st;
        if (st == script::CommandState::Pending || st == script::CommandState::Running) continue;
        const auto& oc = e.outcome(i);
        char buf[64];
        std::snprintf(buf, sizeof buf, " (%.2f s)", oc.seconds);
        say(std::string("  line ") + std::to_string(e.script().commands[i].line) + " " + script::to_string(st) + buf +
            (oc.message.empty() ? "" : ": " + oc.message));
      }
    };
    const auto end = script::drive(ex, runner, controls, on_change);
    json steps = json::array();
    for (std::size_t i = 0; i < parsed.commands.size(); ++i) {
      const auto& c = parsed.commands[i];
      const auto& oc = ex.outcome(i);
      steps.push_back({{"n", i + 1}, {"line", c.line}, {"command", c.text}, {"note", c.note},
                       {"outcome", script::to_string(oc.state)}, {"message", oc.message}, {"seconds", oc.seconds}});
    }
    report["steps"] = steps;
    report["script"] = o.script;
    report["script_end"] = end == script::DriveEnd::Finished ? "finished" : ex.stop_reason();
    if (end != script::DriveEnd::Finished) {
      const script::Command* at = ex.current_command();
      report["failed_step"] = at != nullptr ? "line " + std::to_string(at->line) + ": " + at->text : "?";
      rc = kExitFailure;
    }
  } catch (const std::exception& e) {
    report["error"] = e.what();
    rc = kExitFailure;
  }
  // The round trip as the ground measured it over the whole run.
  if (sampler) {
    sampler->stop();
    sampler->write_csv(out + "/delay.csv");
  }
  if (monitor) report["rtt_s"] = status_json(*monitor)["rtt_s"];
  else report["rtt_s"] = {{"median", nullptr}, {"p99", nullptr}};
  std::ofstream(out + "/ground.json") << report.dump(2) << "\n";
  return rc;
}

// ---- the report ------------------------------------------------------------------

json last_sim_truth(const std::string& remote_exe, const std::string& db, const std::string& out) {
  const pid_t pid = spawn({remote_exe, "journal", "--db", db, "--json"}, out + "/remote_journal.json",
                          out + "/remote_journal.log");
  if (wait_for(pid, 60.0) != 0) return nullptr;
  json truth = nullptr;
  const json j = json::parse(read_text(out + "/remote_journal.json"), nullptr, false);
  if (j.is_discarded() || !j.contains("events")) return nullptr;
  for (const auto& e : j["events"])
    if (e.value("kind", "") == "sim_truth") truth = e["detail"];
  return truth;
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
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
    md << "| " << c["camera"].get<std::string>() << " | " << fmt("%.3f", c["rms_px"].get<double>()) << " | "
       << fmt("%.1f", c["position_error_m"].get<double>() * 1e3) << " |\n";
  if (r.contains("localization")) {
    const auto& l = r["localization"];
    md << "\n## Localization\n\n" << l["views"].size() << " views: "
       << fmt("%.2f", l["position_error_m"].get<double>() * 1e3) << " mm, "
       << fmt("%.3f", l["rotation_error_deg"].get<double>())
       << " deg from the true pose (docs/estimation.md: 2.49 mm / 0.425 deg RMSE at 1 px with four views).\n\n"
       << "![overlay](overlay_oblique.png)\n";
  }
  md << "\n## The changeout script\n\n| n | command | outcome | s | preview |\n|---|---|---|---|---|\n";
  for (const auto& s : r.value("steps", json::array())) {
    md << "| " << s["n"] << " | `" << s["command"].get<std::string>() << "` | " << s["outcome"].get<std::string>()
       << " | " << fmt("%.1f", s["seconds"].get<double>()) << " | ";
    if (s.contains("contact_sheet")) md << "[sheet](" << s["contact_sheet"].get<std::string>() << ")";
    md << " |\n";
  }
  if (r.contains("timing")) {
    md << "\n## Timing (the remote's clock: its journal)\n\n"
          "Work is the sum of the script's commands' EXECUTING-to-final times; the span runs from the first "
          "command received to the last final state; waiting = span - work (the remote idle for the link or "
          "the ground).\n\n| run | commands | work s | span s | waiting s | round trip s |\n|---|---|---|---|---|---|\n";
    const auto row = [&](const json& t, const std::string& name) {
      md << "| " << name << " | " << t.value("commands", 0) << " | " << fmt("%.1f", num(t, "work_s")) << " | "
         << fmt("%.1f", num(t, "remote_span_s")) << " | " << fmt("%.1f", num(t, "overhead_s")) << " | "
         << fmt("%.2f", num(t, "rtt_s")) << " |\n";
    };
    const auto name = [](const json& t) { return std::string(t.value("chain", false) ? "chained (--chain)" : "step by step"); };
    row(r["timing"], "this run: " + name(r["timing"]));
    if (r.contains("timing_compare")) row(r["timing_compare"], name(r["timing_compare"]) + " (--compare)");
    if (r["timing"].contains("timeline")) md << "\n![the steps against time](timeline.png)\n";
  }
  md << "\nFinal alignment of the re-inserted ORU against its slot (the simulator's truth): ";
  if (r["final_alignment_error_m"].is_number())
    md << fmt("%.2f", r["final_alignment_error_m"].get<double>() * 1e3) << " mm";
  else
    md << "not reported";
  md << "\n\n## Delay (round trip measured by the ground's pings)\n\n| median s | p95 s | p99 s | max s | pings |\n"
        "|---|---|---|---|---|\n";
  const auto& d = r["rtt_s"];
  md << "| " << fmt("%.3f", num(d, "median")) << " | " << fmt("%.3f", num(d, "p95")) << " | "
     << fmt("%.3f", num(d, "p99")) << " | " << fmt("%.3f", num(d, "max")) << " | " << fmt("%.0f", num(d, "count"))
     << " |\n";
  if (r.contains("delay_plot") && r["delay_plot"].contains("file")) {
    const auto& p = r["delay_plot"];
    md << "\n![round trip over time, median and p99](" << p["file"].get<std::string>() << ")\n\n"
       << "[delay.png](" << p["file"].get<std::string>() << "): " << p["samples"] << " round trips over the run (delay.csv); "
       << "median " << fmt("%.3f", p["median_s"].get<double>()) << " s, p99 " << fmt("%.3f", p["p99_s"].get<double>())
       << " s.\n";
  } else if (r.contains("delay_plot")) {
    md << "\nNo delay plot: " << r["delay_plot"].value("error", std::string("?")) << "\n";
  }
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
  std::istringstream in(read_text(out + "/run.jsonl"));
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
  std::istringstream in(read_text(out + "/run.jsonl"));
  for (std::string line; std::getline(in, line);) {
    const json j = json::parse(line, nullptr, false);
    if (!j.is_discarded() && j.contains("contact_sheet") && j.contains("line"))
      sheets[j["line"].get<int>()] = fs::path(j["contact_sheet"].get<std::string>()).filename().string();
  }
  return sheets;
}

int demo(Options& o) {
  const auto t0 = Clock::now();
  json compare = nullptr;  // checked before anything runs or is made
  if (!o.compare.empty()) {
    if (!fs::is_regular_file(o.compare)) throw InputError(o.compare, "--compare: cannot open the report");
    compare = json::parse(read_text(o.compare), nullptr, false);
    if (compare.is_discarded() || !compare.contains("timing") || !compare["timing"].is_object())
      throw InputError(o.compare, "--compare: not a demo report with timing (report.json of foresight demo)");
  }
  fs::create_directories(o.out);
  const std::string out = fs::absolute(o.out).lexically_normal().string();
  if (o.rtt_s < 0) throw std::invalid_argument("--rtt must be >= 0");
  std::signal(SIGINT, on_demo_interrupt);
  std::signal(SIGTERM, on_demo_interrupt);
  if (o.stage == "ground") return ground_stage(o, out);
  if (o.stage == "plot") {  // internal: (re)draw OUT/delay.png from OUT/delay.csv
    if (!fs::exists(out + "/delay.csv")) throw InputError(out + "/delay.csv", "cannot open the delay samples");
    std::cout << draw_delay_plot(out + "/delay.csv", out + "/delay.png").dump() << "\n";
    return kExitOk;
  }
  if (!o.stage.empty()) throw std::invalid_argument("--stage: 'ground', 'plot' or nothing");
  if (o.domain < 0) o.domain = static_cast<int>(protocol::claim_free_domain(100, 219));
  fs::remove(out + "/run.jsonl");
  fs::remove(out + "/ground.json");

  const std::string bin = exe_dir();
  const std::string remote_exe = bin + "/foresight-remote", emu_exe = bin + "/foresight-linkemu";
  const std::string self = bin + "/foresight";
  const std::string db = out + "/remote_journal.db";
  fs::remove(db);

  // The link: the emulator's namespaces, or loopback.
  std::string link_text;
  pid_t emu = -1;
  std::string ground_ns, remote_ns;
  if (o.fast || o.rtt_s <= 0) {
    link_text = "loopback (--fast: no emulated delay)";
  } else if (!fs::exists(emu_exe)) {
    link_text = "loopback: no " + emu_exe + " (no emulated delay)";
  } else {
    const int half_ms = static_cast<int>(std::lround(o.rtt_s * 500.0));
    emu = spawn({emu_exe, "--delay-ms", std::to_string(half_ms), "--exit-with-parent"}, out + "/linkemu.out",
                out + "/linkemu.log");
    int code = -1;
    std::string ready;
    if (wait_for_line(out + "/linkemu.out", "\"event\":\"ready\"", emu, 30.0, &code, &ready)) {
      const json j = json::parse(ready);
      ground_ns = j["ground_netns"].get<std::string>();
      remote_ns = j["remote_netns"].get<std::string>();
      link_text = "link emulator, " + fmt("%.2f", o.rtt_s) + " s round trip (" + ground_ns + " <-> " + remote_ns + ")";
    } else {
      std::string why = read_text(out + "/linkemu.log");
      while (!why.empty() && why.back() == '\n') why.pop_back();
      if (code == -1) stop_child(emu, 10.0);
      emu = -1;
      link_text = "loopback: the link emulator cannot run here (exit " + std::to_string(code) + ": " + why +
                  "), so NO emulated delay";
    }
  }
  // Loopback: Cyclone on `lo` with unicast discovery (no multicast here); the
  // daemon and the ground's children inherit it. A user's CYCLONEDDS_URI wins.
  if (emu <= 0) protocol::use_loopback_if_unconfigured();
  say("foresight demo: link " + link_text + "; outputs in " + out);

  // The daemon.
  std::vector<std::string> remote_cmd = {remote_exe, "--sim", "--domain", std::to_string(o.domain), "--journal", db};
  if (emu > 0) remote_cmd.insert(remote_cmd.begin(), {emu_exe, "exec", remote_ns, "--exit-with-parent", "--"});
  const pid_t remote = spawn(remote_cmd, out + "/remote.out", out + "/remote.log");
  int code = -1;
  json report;
  int rc = kExitOk;
  if (!wait_for_line(out + "/remote.out", "foresight-remote: ready", remote, o.ready_timeout_s, &code)) {
    report["error"] = g_interrupt.load() ? std::string("interrupted")
                                         : "foresight-remote did not print its ready line within " +
                                               fmt("%.0f", o.ready_timeout_s) + " s (exit " + std::to_string(code) +
                                               "; log " + out + "/remote.log)";
    rc = kExitFailure;
  } else {
    say("foresight-remote --sim: ready (DDS domain " + std::to_string(o.domain) + ")");
    if (emu > 0) {
      std::vector<std::string> g = {emu_exe, "exec",  ground_ns,      "--exit-with-parent", "--",       self,
                                    "demo",  "--out", out,            "--domain",           std::to_string(o.domain),
                                    "--stage", "ground", "--script",  o.script};
      if (o.chain) g.push_back("--chain");
      const pid_t ground = spawn(g, "", "");
      int grc = wait_for(ground, 7200.0, [ground] { ::kill(ground, SIGINT); });
      if (grc == -1) grc = stop_child(ground, 30.0);
      rc = grc == 0 ? kExitOk : kExitFailure;
    } else {
      rc = ground_stage(o, out);
    }
    const json g = json::parse(read_text(out + "/ground.json"), nullptr, false);
    if (!g.is_discarded()) report = g;
    else report["error"] = "the ground half wrote no report (" + out + "/ground.json)";
  }

  // Stop the daemon (clean: exit 0), then the emulator.
  const int remote_rc = stop_child(remote, 30.0);
  say("foresight-remote stopped (exit " + std::to_string(remote_rc) + ")");
  if (emu > 0) stop_child(emu, 15.0);

  const json truth = last_sim_truth(remote_exe, db, out);
  if (report.contains("session_id")) {
    const json journal = json::parse(read_text(out + "/remote_journal.json"), nullptr, false);
    if (!journal.is_discarded()) {
      const double rtt = num(report["rtt_s"], "median");
      report["timing"] = remote_timing(journal, report["session_id"].get<std::uint64_t>(), script_command_ids(out),
                                       rtt, report.value("chain", false));
      try {
        draw_timeline(report["timing"], out + "/timeline.png");
        report["timing"]["timeline"] = "timeline.png";
      } catch (const std::exception& e) {
        report["timing"]["timeline_error"] = e.what();
      }
    }
  }
  if (compare.is_object()) {  // another run's timing (e.g. without --chain), side by side in report.md
    report["timing_compare"] = compare["timing"];
    report["timing_compare"].erase("steps");
    report["timing_compare"]["report"] = o.compare;
  }
  report["link"] = link_text;
  report["domain"] = o.domain;
  report["remote_exit"] = remote_rc;
  report["final_sim_truth"] = truth;
  report["final_alignment_error_m"] =
      truth.is_object() && truth.contains("alignment_error_m") ? truth["alignment_error_m"] : json(nullptr);
  if (!report.contains("rtt_s")) report["rtt_s"] = {{"median", nullptr}, {"p99", nullptr}};
  if (!report.contains("steps")) report["steps"] = json::array();
  const auto sheets = contact_sheets(out);
  for (auto& s : report["steps"])
    if (auto it = sheets.find(s["line"].get<int>()); it != sheets.end()) s["contact_sheet"] = it->second;
  if (fs::exists(out + "/delay.csv")) {
    try {
      report["delay_plot"] = draw_delay_plot(out + "/delay.csv", out + "/delay.png");
    } catch (const std::exception& e) {
      report["delay_plot"] = {{"error", e.what()}};
    }
  }
  report["total_seconds"] = since(t0);
  if (g_interrupt.load()) {
    rc = kExitFailure;
    report["error"] = "interrupted (Ctrl-C): the running command was aborted and the daemon stopped";
  }
  report["result"] = rc == kExitOk ? "completed" : "failed";
  std::ofstream(out + "/report.json") << report.dump(2) << "\n";
  write_markdown(report, out);

  if (rc != kExitOk) {
    std::string why = report.contains("failed_step") ? "step " + report["failed_step"].get<std::string>() : "";
    for (const auto& s : report["steps"])
      if (s["outcome"] == "failed" || s["outcome"] == "canceled")
        why = "step " + std::to_string(s["n"].get<int>()) + " (line " + std::to_string(s["line"].get<int>()) + ": " +
              s["command"].get<std::string>() + ") " + s["outcome"].get<std::string>() + ": " +
              s["message"].get<std::string>();
    if (report.contains("error")) why += (why.empty() ? "" : "; ") + report["error"].get<std::string>();
    std::cerr << "foresight demo: failed: " << why << "\n";
  }
  say("foresight demo: " + report["result"].get<std::string>() + " in " + fmt("%.0f", since(t0)) + " s; " + out +
      "/report.md");
  return rc;
}

const bool registered = register_command(
    {"demo",
     "the main job: the daemon on the simulated robot, the ground chain, the ORU changeout over DDS, a report",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("--out", o->out, "folder for report.json, report.md and everything the run makes")
           ->capture_default_str();
       sub.add_option("--rtt", o->rtt_s, "round trip of the emulated link, seconds (loopback where namespaces "
                                         "cannot be made)")
           ->capture_default_str();
       sub.add_flag("--fast", o->fast, "loopback, no emulated delay, faster previews (tests)");
       sub.add_flag("--chain", o->chain,
                    "send the changeout's motions ahead as chains (foresight run --chain): the work plus about "
                    "one round trip per WAIT, not one per step");
       sub.add_option("--domain", o->domain, "DDS domain id (default: one in 100-219 that no other process on this host holds)")
           ->check(check::Range(0, 232));
       sub.add_option("--script", o->script, "the task script")->capture_default_str();
       sub.add_option("--ready-timeout", o->ready_timeout_s, "seconds to wait for the daemon's ready line")
           ->check(check::WaitSeconds)
           ->capture_default_str();
       sub.add_option("--compare", o->compare,
                      "another run's report.json (e.g. without --chain): its timing beside this run's in report.md");
       sub.add_option("--stage", o->stage)->group("");  // internal: the ground half in the emulator's namespace
       return [o] { return demo(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
