// foresight run SCRIPT: a task script (the paper's auto sequence) against the
// remote: the script listed with the current command marked; step, auto,
// cancel (the current command), abort (the whole script), retry, skip from the
// keyboard when stdin is a terminal, or from flags (--auto, --keys). A stop
// names the command and why; rerun with --from-line to go on after a fix.
#include <poll.h>
#include "foresight/common/json_text.hpp"
#include <termios.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "command.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/script/executor.hpp"
#include "foresight/script/script.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"
#include "foresight/session/script_runner.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

std::atomic<bool> g_interrupt{false};
extern "C" void on_interrupt(int) { g_interrupt.store(true); }

/// The keyboard, unbuffered and without echo while the run lasts.
class TerminalControls : public script::Controls {
 public:
  TerminalControls() {
    if (tcgetattr(0, &saved_) == 0) {
      termios raw = saved_;
      raw.c_lflag &= static_cast<tcflag_t>(~(ICANON | ECHO));
      raw.c_cc[VMIN] = 0;
      raw.c_cc[VTIME] = 0;
      restore_ = tcsetattr(0, TCSANOW, &raw) == 0;
    }
  }
  ~TerminalControls() override {
    if (restore_) tcsetattr(0, TCSANOW, &saved_);
  }
  TerminalControls(const TerminalControls&) = delete;
  TerminalControls& operator=(const TerminalControls&) = delete;
  script::Key poll(double timeout_s) override {
    pollfd p{0, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout_s * 1000)) <= 0) return script::Key::None;
    char c = 0;
    if (::read(0, &c, 1) != 1) return script::Key::None;
    return script::key_from_char(c);
  }

 private:
  termios saved_{};
  bool restore_ = false;
};

/// Ctrl-C (SIGINT/SIGTERM) is an abort: the running motion is stopped on the remote.
class InterruptibleControls : public script::Controls {
 public:
  explicit InterruptibleControls(script::Controls& inner) : inner_(inner) {}
  script::Key poll(double timeout_s) override {
    if (g_interrupt.exchange(false)) return script::Key::Abort;
    return inner_.poll(timeout_s);
  }

 private:
  script::Controls& inner_;
};

struct Options {
  LinkOptions link;
  std::string script;
  bool auto_mode = false;
  std::string keys;
  int from_line = 1;
  bool dry_run = false;
  std::string joints, joints_deg;
  RunSettings settings;
  bool no_preview = false;
};

std::vector<script::Key> parse_keys(const std::string& text) {
  std::vector<script::Key> keys;
  if (text.empty()) return keys;
  for (const std::string_view field : split_commas(text)) {
    // wait[:N]: N polls pass with nothing pressed (0.1 s each while a remote
    // command runs), to place a cancel or abort later in a motion.
    if (field == "wait" || field.rfind("wait:", 0) == 0) {
      int n = 1;
      if (field.size() > 4) {
        const std::string count(field.substr(5));
        char* end = nullptr;
        const long v = std::strtol(count.c_str(), &end, 10);
        if (count.empty() || *end != '\0' || v < 1 || v > 100000)
          throw std::invalid_argument("--keys: '" + std::string(field) + "': wait:N needs N in 1..100000");
        n = static_cast<int>(v);
      }
      keys.insert(keys.end(), static_cast<std::size_t>(n), script::Key::None);
      continue;
    }
    const auto k = script::key_from_name(std::string(field));
    if (!k)
      throw std::invalid_argument("--keys: '" + std::string(field) +
                                  "' is not a key (step, auto, cancel, abort, retry, skip, quit, wait[:N])");
    keys.push_back(*k);
  }
  return keys;
}

const char* end_name(script::DriveEnd e) {
  switch (e) {
    case script::DriveEnd::Finished: return "finished";
    case script::DriveEnd::Aborted: return "aborted";
    case script::DriveEnd::Stopped: return "stopped";
    case script::DriveEnd::Quit: return "quit";
  }
  return "?";
}

int run(Options& o) {
  RunSettings& s = o.settings;
  const script::Script parsed = script::load_script(o.script);
  const RobotModel model = RobotModel::from_file(s.robot);
  script::check_script(parsed, ScriptRunner::context_for(model, ObjectModel::from_file(s.object), Scene::from_file(s.scene)));
  if (o.from_line < 1) throw std::invalid_argument("--from-line must be >= 1");
  std::vector<script::Key> keys = parse_keys(o.keys);
  const bool interactive = o.keys.empty() && !o.auto_mode && isatty(0);
  if (o.keys.empty() && !o.auto_mode && !interactive)
    throw std::invalid_argument("stdin is not a terminal: give --auto or --keys");
  s.dry_run = o.dry_run;
  s.preview = !o.no_preview;
  s.quiet = o.link.json;
  s.timeout_s = o.link.timeout_s;
  if (o.dry_run) {
    if (o.joints.empty() && o.joints_deg.empty()) throw std::invalid_argument("--dry-run needs --joints or --joints-deg");
    s.q_from = !o.joints.empty() ? parse_joints(o.joints, "--joints", model)
                                 : parse_joints(o.joints_deg, "--joints-deg", model, true);
  }
  std::unique_ptr<ground_link::GroundLink> link;
  if (!o.dry_run) link = connect_remote(o.link);
  ScriptRunner runner(s, std::move(link));

  script::Executor ex(parsed, script::Executor::index_at_line(parsed, o.from_line));
  ex.set_auto(o.auto_mode);
  std::ostream& out = o.link.json ? std::cerr : std::cout;
  std::signal(SIGINT, on_interrupt);
  std::signal(SIGTERM, on_interrupt);
  std::unique_ptr<script::Controls> base;
  if (interactive) base = std::make_unique<TerminalControls>();
  else base = std::make_unique<script::ScriptedControls>(keys);
  InterruptibleControls controls(*base);

  // Each command's state as last printed: a chained command is printed when
  // sent and again when it ended; a retried one again when it ends anew.
  std::vector<script::CommandState> printed(parsed.commands.size(), script::CommandState::Pending);
  bool first = true;
  const auto on_change = [&](const script::Executor& e) {
    if (interactive) {
      out << "\033[H\033[J" << o.script << (o.dry_run ? "  (dry run)" : "") << "\n\n" << e.listing() << "\n"
          << (e.auto_mode() ? "auto" : "step") << " | " << script::to_string(e.state())
          << (e.stop_reason().empty() ? "" : ": " + e.stop_reason()) << "\n"
          << "keys: s step  g auto  c cancel  a abort  r retry  k skip  q quit\n"
          << std::flush;
      return;
    }
    if (first) {
      out << e.listing() << std::flush;
      first = false;
    }
    const script::Command* c = e.current_command();
    if (e.state() == script::RunState::Running && c != nullptr)
      out << "> line " << c->line << ": " << c->text << "\n" << std::flush;
    for (std::size_t i = 0; i < e.script().commands.size() && i < printed.size(); ++i) {
      const auto st = e.command_state(i);
      if (st == printed[i]) continue;
      printed[i] = st;
      if (st == script::CommandState::Pending || st == script::CommandState::Running) continue;
      const auto& oc = e.outcome(i);
      char buf[64];
      std::snprintf(buf, sizeof buf, " (%.2f s)", oc.seconds);
      out << "  line " << e.script().commands[i].line << " " << script::to_string(st)
          << (st == script::CommandState::Skipped ? "" : buf) << (oc.message.empty() ? "" : ": " + oc.message) << "\n"
          << std::flush;
    }
  };
  const script::DriveEnd end = script::drive(ex, runner, controls, on_change);

  const script::Command* at = ex.current_command();
  if (!o.link.json) {
    std::cout << "\n" << ex.listing() << o.script << ": " << end_name(end);
    if (!ex.stop_reason().empty()) std::cout << " (" << ex.stop_reason() << ")";
    std::cout << "\n";
    if (end != script::DriveEnd::Finished && at != nullptr)
      std::cout << "go on after a fix: foresight run " << o.script << " --from-line " << at->line << "\n";
  } else {
    nlohmann::json steps = nlohmann::json::array();
    for (std::size_t i = 0; i < ex.script().commands.size(); ++i) {
      const auto& c = ex.script().commands[i];
      const auto& oc = ex.outcome(i);
      steps.push_back({{"n", i + 1},
                       {"line", c.line},
                       {"command", c.text},
                       {"note", c.note},
                       {"remote", script::is_remote(c.op)},
                       {"outcome", script::to_string(oc.state)},
                       {"message", oc.message},
                       {"seconds", oc.seconds}});
    }
    nlohmann::json j = {{"script", o.script}, {"end", end_name(end)}, {"dry_run", o.dry_run},
                        {"stop_reason", ex.stop_reason()}, {"steps", steps}};
    j["resume_line"] = at != nullptr && end != script::DriveEnd::Finished ? nlohmann::json(at->line) : nlohmann::json(nullptr);
    const Eigen::VectorXd& q = runner.q_current();
    j["final_q_rad"] = std::vector<double>(q.data(), q.data() + q.size());
    std::cout << json_text(j, 2) << "\n";
  }
  return end == script::DriveEnd::Finished ? kExitOk : kExitFailure;
}

const bool registered = register_command(
    {"run", "run a task script against the remote: step / auto / cancel / abort, the current command marked",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       o->settings.robot = default_config("robot.urdf");
       o->settings.object = default_config("oru.yaml");
       o->settings.scene = default_config("scene.yaml");
       sub.add_option("script", o->script, "task script (docs/operator.md, Task scripts)")->required();
       sub.add_flag("--auto", o->auto_mode, "run every command until one fails (no keyboard needed)");
       sub.add_option("--keys", o->keys, "the operator's keys in order: step,auto,cancel,abort,retry,skip,quit; wait:N lets N polls "
                      "(0.1 s each while a command runs) pass");
       sub.add_option("--from-line", o->from_line, "go on from the command at or after this line (earlier: skipped)")
           ->capture_default_str();
       sub.add_flag("--chain", o->settings.chain,
                    "send the motions ahead as a chain: each planned from the planned end of the one before, "
                    "previewed, sent without waiting; WAIT, CALIBRATE, LOCALIZE, REQUEST and CAMERA wait for it");
       sub.add_flag("--recover", o->settings.recover, "send RECOVER after taking control (drives on, holding)");
       sub.add_flag("--dry-run", o->dry_run, "plan and preview every motion without a remote");
       sub.add_option("--joints", o->joints, "dry run: the start joint angles (rad)");
       sub.add_option("--joints-deg", o->joints_deg, "dry run: the start joint angles (deg)");
       sub.add_option("--work", o->settings.work_dir, "folder for trajectories, previews, cameras.yaml, the journal")
           ->capture_default_str();
       sub.add_option("--cameras", o->settings.cameras, "calibrated cameras (default: what CALIBRATE writes)");
       sub.add_option("--image", o->settings.image, "video frame for previews (default: the synthetic camera)");
       sub.add_option("--object-pose", o->settings.object_pose,
                      "the object's pose: localize JSON, or 'scene' for the work site's true pose");
       sub.add_option("--override-check", o->settings.override_checks,
                      "go on past a no_go of this CHECK step (insert), journaled as the operator's override")
           ->check(check::IsMember({"insert"}));
       sub.add_flag("--no-preview", o->no_preview, "do not render previews (tests only: nothing should be sent unseen)");
       sub.add_option("--preview-speed", o->settings.preview_speed, "preview playback speed")
           ->check(check::PositiveNumber)
           ->capture_default_str();
       sub.add_option("--robot", o->settings.robot, "robot URDF")->capture_default_str();
       sub.add_option("--object", o->settings.object, "task object model")->capture_default_str();
       sub.add_option("--scene", o->settings.scene, "work site (cameras, the object's true pose)")->capture_default_str();
       add_link_options(sub, o->link);
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
