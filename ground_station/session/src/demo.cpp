// `foresight demo` (demo.hpp).
#include "foresight/session/demo.hpp"

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "foresight/common/error.hpp"
#include "foresight/common/format.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/script/executor.hpp"
#include "foresight/script/script.hpp"
#include "foresight/session/demo_report.hpp"
#include "foresight/session/link_session.hpp"
#include "foresight/session/operations.hpp"
#include "foresight/session/processes.hpp"
#include "foresight/session/script_runner.hpp"

namespace foresight::session {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

void say(const std::string& line) { std::cout << line << "\n" << std::flush; }

/// Drives the task script's commands to the remote in auto mode; Ctrl-C aborts.
class InterruptControls : public script::Controls {
 public:
  explicit InterruptControls(std::function<bool()> interrupted) : interrupted_(std::move(interrupted)) {}
  script::Key poll(double timeout_s) override {
    if (interrupted_ && interrupted_()) return script::Key::Abort;
    return inner_.poll(timeout_s);
  }

 private:
  std::function<bool()> interrupted_;
  script::ScriptedControls inner_{{}};
};

/// The ground chain in this process, with the operations the commands call:
/// the simulated operator's clicks, the calibration of every camera, the
/// localization, the calibrated overlay the operator sees.
json ground_chain(const std::string& out) {
  json report;
  const Scene scene = Scene::from_file(default_config("scene.yaml"));
  say("== simulated operator: clicks on the arm (4 poses) and the ORU in every view, 1 px noise ==");
  SynthClicksRequest clicks;
  clicks.calibration_out = out + "/arm_clicks.csv";
  clicks.object_out = out + "/oru_clicks.csv";
  clicks.joints_out = out + "/arm_pose.txt";
  clicks.noise_px = 1.0;
  clicks.seed = 7;
  synth_clicks(clicks);
  std::string q = read_log(out + "/arm_pose.txt");
  while (!q.empty() && (q.back() == '\n' || q.back() == ' ')) q.pop_back();

  say("== calibration of every camera, the arm as the fixture ==");
  fs::remove(out + "/cameras.yaml");
  json cal = json::array();
  for (const auto& cam : scene.camera_order) {
    CalibrateRequest request;
    request.points = out + "/arm_clicks.csv";
    request.camera = cam;
    request.out = out + "/cameras.yaml";
    const Calibrated c = calibrate_from_clicks(request);
    add_camera(request.out, cam, c);
    const json j = calibrated_json(request, c);
    std::ofstream(out + "/calibrate_" + cam + ".json") << j.dump(2) << "\n";
    const double err = (c.result.position_m() - scene.cameras.at(cam).position_m).norm();
    cal.push_back({{"camera", cam}, {"rms_px", j["rms_px"]}, {"position_error_m", err}, {"f_px", j["f_px"]}});
    char buf[200];
    std::snprintf(buf, sizeof buf, "  %-14s rms %.3f px, camera position %.1f mm from the truth", cam.c_str(),
                  c.result.rms_px, err * 1e3);
    say(buf);
  }
  report["calibration"] = cal;

  say("== localization of the ORU from every view ==");
  LocalizeRequest where;
  where.points = out + "/oru_clicks.csv";
  where.cameras = out + "/cameras.yaml";
  const Localized l = localize_from_clicks(where);
  std::ofstream(out + "/localize.json") << localized_json(l).dump(2) << "\n";
  const Pose est = localization::read_object_pose_json(out + "/localize.json");
  const double dp = (est.translation() - scene.base_T_object.translation()).norm();
  const double dr =
      Eigen::AngleAxisd(est.linear().transpose() * scene.base_T_object.linear()).angle() * 180.0 / M_PI;
  report["localization"] = {{"position_error_m", dp}, {"rotation_error_deg", dr}, {"views", l.result.views},
                            {"rms_px", l.result.rms_px}};
  char buf[200];
  std::snprintf(buf, sizeof buf, "  %zu views: %.2f mm, %.3f deg from the true pose", l.result.views.size(), dp * 1e3, dr);
  say(buf);

  say("== what the operator sees: the calibrated overlay (camera oblique) ==");
  SynthRequest frame;
  frame.camera = "oblique";
  frame.joints = q;
  frame.out = out + "/video_oblique.png";
  synth_frame(frame);
  OverlayRequest overlay;
  overlay.cameras = out + "/cameras.yaml";
  overlay.camera = "oblique";
  overlay.image = frame.out;
  overlay.joints = q;
  overlay.object_pose = out + "/localize.json";
  overlay.tags = true;
  overlay.mode = "hidden";
  overlay.out = out + "/overlay_oblique.png";
  overlay_frame(overlay);
  report["overlays"] = json::array({"overlay_oblique.png"});
  return report;
}

/// TAKE_CONTROL, RECOVER (the drives come up) and a first tare, as an operator does first.
void take_control(ground_link::GroundLink& link, const std::function<bool()>& interrupted) {
  const std::vector<std::pair<protocol::CommandKind, protocol::Payload>> first = {
      {protocol::CommandKind::TakeControl, protocol::NoPayload{}},
      {protocol::CommandKind::Recover, protocol::NoPayload{}},
      {protocol::CommandKind::InvokeAlgorithm, protocol::InvokeAlgorithm{"tare", {}, 0.0}}};
  for (const auto& [kind, payload] : first) {
    const auto r = send_and_wait(link, kind, payload, final_ack_timeout(link, 5.0, 0.0), interrupted);
    say("  " + result_line(kind, r));
    if (!r.succeeded()) throw LinkFailure(result_line(kind, r));
  }
}

int ground_stage(const DemoOptions& o, const std::string& out, const std::function<bool()>& interrupted) {
  json report;
  int rc = kExitOk;
  std::unique_ptr<ground_link::GroundLink> monitor;  // pings the whole run: the delay figures
  std::unique_ptr<DelaySampler> sampler;             // ... and their times (the plot)
  try {
    report = ground_chain(out);
    say("== the ORU changeout over DDS (domain " + std::to_string(o.domain) + "): " + o.script + " ==");
    auto link = connect_remote(o.domain, o.fast ? 30.0 : 60.0);
    monitor = connect_remote(o.domain, o.fast ? 30.0 : 60.0);
    sampler = std::make_unique<DelaySampler>(*monitor);
    take_control(*link, interrupted);
    report["session_id"] = link->session_id();  // the timing picks the script's commands of this session
    report["chain"] = o.chain;

    RunSettings s;
    s.work_dir = out;
    s.robot = default_config("robot.urdf");
    s.object = default_config("oru.yaml");
    s.scene = default_config("scene.yaml");
    s.preview = true;
    s.chain = o.chain;
    s.preview_speed = o.fast ? 8.0 : 4.0;
    const script::Script parsed = script::load_script(o.script);
    script::check_script(parsed, ScriptRunner::context_for(RobotModel::from_file(s.robot),
                                                           ObjectModel::from_file(s.object), Scene::from_file(s.scene)));
    ScriptRunner runner(s, std::move(link));
    script::Executor ex(parsed, 0);
    ex.set_auto(true);
    InterruptControls controls(interrupted);
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

/// The link the demo runs over: the emulator's namespaces (its pid and
/// their names), or loopback (emulator -1) with the reason in `text`.
struct EmulatedLink {
  std::string text;
  pid_t emulator = -1;
  std::string ground_ns, remote_ns;
};

EmulatedLink start_link(const DemoOptions& o, const std::string& emu_exe, const std::string& out,
                        const std::function<bool()>& interrupted) {
  EmulatedLink link;
  if (o.fast || o.rtt_s <= 0) {
    link.text = "loopback (--fast: no emulated delay)";
  } else if (!fs::exists(emu_exe)) {
    link.text = "loopback: no " + emu_exe + " (no emulated delay)";
  } else {
    const int half_ms = static_cast<int>(std::lround(o.rtt_s * 500.0));
    link.emulator = spawn({emu_exe, "--delay-ms", std::to_string(half_ms), "--exit-with-parent"}, out + "/linkemu.out",
                out + "/linkemu.log");
    int code = -1;
    std::string ready;
    if (wait_for_line(out + "/linkemu.out", "\"event\":\"ready\"", link.emulator, 30.0, &code, &ready, interrupted)) {
      const json j = json::parse(ready);
      link.ground_ns = j["ground_netns"].get<std::string>();
      link.remote_ns = j["remote_netns"].get<std::string>();
      link.text = "link emulator, " + printf_text("%.2f", o.rtt_s) + " s round trip (" + link.ground_ns + " <-> " + link.remote_ns + ")";
    } else {
      std::string why = read_log(out + "/linkemu.log");
      while (!why.empty() && why.back() == '\n') why.pop_back();
      if (code == -1) stop_child(link.emulator, 10.0);
      link.emulator = -1;
      link.text = "loopback: the link emulator cannot run here (exit " + std::to_string(code) + ": " + why +
                  "), so NO emulated delay";
    }
  }
  return link;
}

/// The report's parts made after the daemon stopped: the simulator's final
/// truth, the remote's timing of the script (its journal) and the timeline,
/// the compared run, the contact sheets, the delay plot.
void complete_report(json& report, const DemoOptions& o, const json& compare, const std::string& remote_exe,
                     const std::string& db, const std::string& out) {
  const json truth = last_sim_truth(remote_exe, db, out);
  if (report.contains("session_id")) {
    const json journal = json::parse(read_log(out + "/remote_journal.json"), nullptr, false);
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
  report["domain"] = o.domain;
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
}

}  // namespace

int run_demo(DemoOptions& o, const std::function<bool()>& interrupted) {
  const auto t0 = Clock::now();
  json compare = nullptr;  // checked before anything runs or is made
  if (!o.compare.empty()) {
    if (!fs::is_regular_file(o.compare)) throw InputError(o.compare, "--compare: cannot open the report");
    compare = json::parse(read_log(o.compare), nullptr, false);
    if (compare.is_discarded() || !compare.contains("timing") || !compare["timing"].is_object())
      throw InputError(o.compare, "--compare: not a demo report with timing (report.json of foresight demo)");
  }
  fs::create_directories(o.out);
  const std::string out = fs::absolute(o.out).lexically_normal().string();
  if (o.rtt_s < 0) throw std::invalid_argument("--rtt must be >= 0");
  if (o.stage == "ground") return ground_stage(o, out, interrupted);
  if (o.stage == "plot") {  // internal: (re)draw OUT/delay.png from OUT/delay.csv
    if (!fs::exists(out + "/delay.csv")) throw InputError(out + "/delay.csv", "cannot open the delay samples");
    std::cout << draw_delay_plot(out + "/delay.csv", out + "/delay.png").dump() << "\n";
    return kExitOk;
  }
  if (!o.stage.empty()) throw std::invalid_argument("--stage: 'ground', 'plot' or nothing");
  if (o.domain < 0) o.domain = static_cast<int>(protocol::claim_free_domain(100, 219));
  fs::remove(out + "/run.jsonl");
  fs::remove(out + "/ground.json");

  const std::string bin = executable_dir();
  const std::string remote_exe = bin + "/foresight-remote", emu_exe = bin + "/foresight-linkemu";
  const std::string self = bin + "/foresight";
  const std::string db = out + "/remote_journal.db";
  fs::remove(db);

  const EmulatedLink link = start_link(o, emu_exe, out, interrupted);
  const std::string& link_text = link.text;
  const pid_t emu = link.emulator;
  const std::string& ground_ns = link.ground_ns;
  const std::string& remote_ns = link.remote_ns;
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
  if (!wait_for_line(out + "/remote.out", "foresight-remote: ready", remote, o.ready_timeout_s, &code, nullptr, interrupted)) {
    report["error"] = interrupted() ? std::string("interrupted")
                                         : "foresight-remote did not print its ready line within " +
                                               printf_text("%.0f", o.ready_timeout_s) + " s (exit " + std::to_string(code) +
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
      int grc = wait_for(ground, 7200.0, interrupted, [ground] { ::kill(ground, SIGINT); });
      if (grc == -1) grc = stop_child(ground, 30.0);
      rc = grc == 0 ? kExitOk : kExitFailure;
    } else {
      rc = ground_stage(o, out, interrupted);
    }
    const json g = json::parse(read_log(out + "/ground.json"), nullptr, false);
    if (!g.is_discarded()) report = g;
    else report["error"] = "the ground half wrote no report (" + out + "/ground.json)";
  }

  // Stop the daemon (clean: exit 0), then the emulator.
  const int remote_rc = stop_child(remote, 30.0);
  say("foresight-remote stopped (exit " + std::to_string(remote_rc) + ")");
  if (emu > 0) stop_child(emu, 15.0);

  complete_report(report, o, compare, remote_exe, db, out);
  report["link"] = link_text;
  report["remote_exit"] = remote_rc;
  report["total_seconds"] = since(t0);
  if (interrupted()) {
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
  say("foresight demo: " + report["result"].get<std::string>() + " in " + printf_text("%.0f", since(t0)) + " s; " + out +
      "/report.md");
  return rc;
}

}  // namespace foresight::session
