// foresight-remote: the robot-cabinet daemon.
//
//   foresight-remote [--config config/remote.yaml] [--sim] [--journal FILE]
//                    [--domain N] [--estop-file F]
//   foresight-remote journal [--db FILE] [--since T] [--json]
//   foresight-remote check [--config FILE] [--sim] [--json] [--security DIR]
//                    (fitness before first motion: check.hpp; exit 1 when unfit)
//   foresight-remote simulate-insertions --batch FILE [--json] [--config FILE]
//                    (the insert on the simulated plant, in-process, per trial:
//                    simulate_insertions.hpp; the ground's `eval insertion`)
//
// Under systemd (remote_site/deploy/systemd/foresight-remote.service,
// Type=notify): READY=1 when the ready line is printed, STOPPING=1 at
// shutdown, WATCHDOG=1 from a watchdog thread every WatchdogSec/2 while the
// control loop's cycle counter and the supervisor's status reports advance.
//
// Exit status: 0 after a clean shutdown (SIGINT/SIGTERM: controlled stop,
// category 1, journal flushed, drives disabled); 2 on a bad configuration
// (the message names the file, line and key); 1 when the hardware cannot be
// brought up or the daemon fails.
#include <CLI/CLI.hpp>
#include "foresight/common/json_text.hpp"
#include <nlohmann/json.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <systemd/sd-daemon.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>

#include "foresight/common/error.hpp"
#include "foresight/control/control_loop.hpp"
#include "foresight/journal/journal.hpp"
#include "foresight/journal/reader.hpp"
#include "foresight/daemon/check.hpp"
#include "foresight/protocol/error.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/security.hpp"
#include "foresight/daemon/daemon_config.hpp"
#include "foresight/daemon/site.hpp"
#include "foresight/daemon/sim_faults.hpp"
#include "foresight/daemon/simulate_insertions.hpp"
#include "foresight/daemon/supervisor.hpp"
#include "foresight/daemon/tool_worker.hpp"
#include "foresight/remote_link/remote_link.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/sim/plant.hpp"

namespace {

std::atomic<bool> g_quit{false};
std::atomic<int> g_signal{0};

extern "C" void on_signal(int sig) {
  g_signal.store(sig);
  g_quit.store(true);
}

std::string default_config() {
  if (const char* dir = std::getenv("FORESIGHT_CONFIG_DIR")) return std::string(dir) + "/remote.yaml";
  // The build tree's config/, else the installed one (the foresight-remote package).
  const std::string built = FORESIGHT_DEFAULT_CONFIG_DIR "/remote.yaml";
  if (std::FILE* f = std::fopen(built.c_str(), "r")) {
    std::fclose(f);
    return built;
  }
  return "/etc/foresight/remote.yaml";
}

/// The systemd watchdog (WatchdogSec= in the unit): a thread pings WATCHDOG=1
/// every half period, but only when, since its previous wake-up, the control
/// loop's cycle counter advanced AND the supervisor published a status report
/// (counted in the outbox: `beats`, at controller.reports.status_hz). So a
/// stalled loop thread or a supervisor thread stuck for a whole period is
/// killed by systemd and restarted (Restart=on-failure), coming up holding.
/// Limitation: the supervisor is seen only through its status reports, so
/// status_hz must be above 2/WatchdogSec (default 2 Hz against 10 s); a
/// supervisor that still reports status while stuck elsewhere is not caught.
/// Not real-time: its own thread, nothing on the control cycle.
class SystemdWatchdog {
 public:
  SystemdWatchdog(const foresight::control::ControlLoop& loop, const std::atomic<std::uint64_t>& beats,
                  double status_hz)
      : loop_(loop), beats_(beats) {
    std::uint64_t usec = 0;
    if (sd_watchdog_enabled(0, &usec) <= 0 || usec == 0) return;  // not under a watchdog
    const auto half = std::chrono::microseconds(usec / 2);
    if (status_hz * static_cast<double>(usec) / 2e6 < 1.0)
      spdlog::warn("watchdog: controller.reports.status_hz {} is too low for WatchdogSec {} s (needs > {:.2f} Hz)",
                   status_hz, static_cast<double>(usec) / 1e6, 2e6 / static_cast<double>(usec));
    spdlog::info("systemd watchdog: {} s, pinged every {} ms while the loop and the supervisor progress",
                 static_cast<double>(usec) / 1e6, usec / 2000);
    thread_ = std::thread([this, half] { run(half); });
  }
  ~SystemdWatchdog() { stop(); }
  SystemdWatchdog(const SystemdWatchdog&) = delete;
  SystemdWatchdog& operator=(const SystemdWatchdog&) = delete;
  void stop() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

 private:
  void run(std::chrono::microseconds half) {
    std::uint64_t last_cycles = loop_.stats().cycles;
    std::uint64_t last_beats = beats_.load();
    bool warned = false;
    std::unique_lock lock(mu_);
    while (!cv_.wait_for(lock, half, [this] { return stop_; })) {
      const std::uint64_t cycles = loop_.stats().cycles;
      const std::uint64_t beats = beats_.load();
      if (cycles != last_cycles && beats != last_beats) {
        sd_notify(0, "WATCHDOG=1");
        warned = false;
      } else if (!warned) {
        spdlog::error("watchdog: no progress for {} ms (loop cycles {} -> {}, supervisor reports {} -> {}): "
                      "not pinging systemd", half.count() / 1000, last_cycles, cycles, last_beats, beats);
        warned = true;
      }
      last_cycles = cycles;
      last_beats = beats;
    }
  }

  const foresight::control::ControlLoop& loop_;
  const std::atomic<std::uint64_t>& beats_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

struct Options {
  std::string config = default_config();
  bool sim = false;
  std::string journal;
  int domain = -1;  ///< -1: $FORESIGHT_DDS_DOMAIN, else 0
  std::string estop_file;
  std::string sim_faults;
  std::string security_dir;
  std::string security_identity;  ///< "": controller.link.identity (remote)
  bool ros2 = false;
  int loop_cpu = -1;      ///< pin the control loop thread (an isolated CPU); -1: not pinned
  int rt_priority = 80;   ///< the control loop's SCHED_FIFO priority
  bool allow_non_rt = false;       ///< off the simulator: enable the drives without SCHED_FIFO/mlockall
  int max_missed_cycles = -1;      ///< periods missed in a row that stop the arm; -1: 3, off on --sim
};

using namespace foresight;

/// --security / --identity over controller.link.security / identity; the
/// DDS Security files read and checked before any hardware is touched (a
/// damaged certificate, key or signed document is named here: Cyclone would
/// say only "create participant: Error", after the drives were configured);
/// off the simulator an open link is refused unless the configuration says
/// so. InputError (exit 2).
void settle_link_security(const Options& o, daemon::DaemonConfig& config) {
  const bool security_flag = !o.security_dir.empty();
  if (security_flag) config.security_dir = o.security_dir;
  if (!o.security_identity.empty()) config.security_identity = o.security_identity;
  if (security_flag && config.insecure)
    throw InputError(o.config, "controller.link.insecure: true contradicts --security " + o.security_dir);
  if (!config.security_dir.empty()) {
    try {
      const protocol::SecurityFacts facts = protocol::verify_security_files(config.security_dir, config.security_identity);
      spdlog::info("DDS Security: {}", facts.describe());
    } catch (const protocol::ProtocolError& e) {
      throw InputError(security_flag ? "--security" : o.config + ": controller.link.security", e.what());
    }
  } else if (!o.sim && !config.insecure) {
    // Off the simulator an open link would take commands from every
    // participant of the domain: refused unless the configuration says so.
    throw InputError(o.config, "controller.link.security is not set: the DDS link would be open to every participant "
                               "of domain " + std::to_string(o.domain) +
                               ". Make the identities (make_dds_security.sh DIR, docs/deploy.md) and set "
                               "controller.link.security: DIR (or --security DIR), or say controller.link.insecure: "
                               "true to run it open");
  } else if (config.insecure) {
    spdlog::warn("controller.link.insecure: true: the DDS link runs without DDS Security (any participant of domain "
                 "{} can reach it)", o.domain);
  }
}

/// The controller's configuration from remote.yaml and the site.
control::ControllerConfig controller_config(const daemon::DaemonConfig& config, const daemon::Site& site) {
  control::ControllerConfig cc;
  cc.cycle_rate_hz = site.hw_config.cycle_rate_hz;
  cc.start_tolerance_rad = config.start_tolerance_rad;
  cc.rate_limit_acceleration_fraction = config.rate_limit_acceleration_fraction;
  cc.rate_limit_jerk_per_s = config.rate_limit_jerk_per_s;
  cc.rate_limit_compliant_acceleration_fraction = config.rate_limit_compliant_acceleration_fraction;
  cc.drive_velocity_max_age_cycles = 2 * site.hw_config.velocity_tpdo_every;  // 0: TPDO2 not mapped
  // The following error as the drives see it: against the command the loop's
  // latency ago (a target written in cycle k is latched at SYNC k+1, reached
  // and sampled at SYNC k+2, read in cycle k+3), at 0.8 of each drive's own
  // window (0x6065), so the master stops the arm (Cat1, with its evidence)
  // before a drive faults on it (Cat0).
  cc.following_error_delay_cycles = 3;
  for (std::size_t j = 0; j < site.hw_config.drives.size() && j < control::kMaxJoints; ++j)
    cc.following_error_joint_rad[j] = 0.8 * site.hw_config.drives[j].following_error_limit_rad;
  cc.link_loss = config.link_loss_policy == daemon::LinkLossPolicy::Stop ? control::LinkLossPolicy::Stop
                                                                         : control::LinkLossPolicy::FinishThenHold;
  // The payload (docs/control.md "Payload"): controller.payload, the tool's
  // and the carried ORU's mass and centre of mass. The simulated plant keeps
  // its own truth (scene.yaml, the URDF), so a configured value that is wrong
  // shows as apparent force; only with nothing configured does --sim take the
  // tool's from the plant (and knows no ORU). A cabinet needs it configured.
  const daemon::PayloadSettings& pl = config.payload;
  if (pl.configured) {
    cc.tool.mass_kg = pl.tool_mass_kg;
    cc.tool.com_sensor_m = pl.tool_com_m;
    cc.oru.mass_kg = pl.oru_mass_kg;
    cc.oru.com_sensor_m = pl.oru_com_m;
    cc.tare_max_force_n = pl.tare_max_force_n;
  } else if (site.simulated && site.simulated->plant) {
    const auto& plant = *site.simulated->plant;
    cc.tool.mass_kg = plant.tool_mass_kg();
    for (int i = 0; i < 3; ++i) cc.tool.com_sensor_m[static_cast<std::size_t>(i)] = plant.tool_com_sensor_m()[i];
    spdlog::warn("{}: no controller.payload: the simulated tool's mass {:.3f} kg from the plant, no ORU compensation",
                 config.source, cc.tool.mass_kg);
  } else {
    throw foresight::InputError(config.source, "missing controller.payload (the tool's mass_kg and com_m, the "
                                               "carried ORU's: docs/control.md \"Payload\")");
  }
  if (site.simulated && site.simulated->plant) cc.tool.sensor_T_tip = site.simulated->plant->sensor_T_tip();
  return cc;
}

/// The loop's scheduling and its real-time rules.
control::LoopOptions loop_options_for(const Options& o) {
  control::LoopOptions loop_options;
  loop_options.cpu = o.loop_cpu;
  loop_options.rt_priority = o.rt_priority;
  // Real time is enforced off the simulator: the drives are not enabled
  // without SCHED_FIFO and mlockall (unless --allow-non-rt), and 3 periods
  // missed in a row stop the arm (category 1). The simulator on a shared
  // test machine keeps neither unless asked (--max-missed-cycles).
  loop_options.require_realtime = !o.sim && !o.allow_non_rt;
  loop_options.max_missed_cycles = o.max_missed_cycles >= 0 ? o.max_missed_cycles : o.sim ? 0 : 3;
  return loop_options;
}

/// The loop's grant of real time and its rules, logged and journaled.
void journal_loop_start(const Options& o, const control::ControlLoop& loop, const control::LoopOptions& loop_options,
                        journal::Journal& journal) {
  const control::LoopStats st = loop.stats();
  journal::EventRow row;
  row.kind = "loop_start";
  row.text = std::string("control loop: SCHED_FIFO ") + (st.realtime ? "granted" : "refused") + ", mlockall " +
             (st.memory_locked ? "granted" : "refused") + "; " +
             (loop_options.require_realtime ? "real time required to enable the drives"
              : o.sim                       ? "simulated drives: real time not required"
                                            : "--allow-non-rt: the drives may be enabled without real time") +
             "; " +
             (loop_options.max_missed_cycles > 0
                  ? std::to_string(loop_options.max_missed_cycles) + " missed periods in a row stop the arm"
                  : std::string("missed periods do not stop the arm"));
  if (o.allow_non_rt && !o.sim && !(st.realtime && st.memory_locked))
    spdlog::warn("--allow-non-rt: the drives may be enabled although the control loop is not real time");
  spdlog::info("{}", row.text);
  journal.record_event(row);
}

/// The simulator's truth for the journal (the demo's final alignment).
std::function<std::string()> sim_truth_of(const daemon::Site& site) {
  if (!(site.simulated && site.simulated->plant)) return {};
  const sim::Plant* plant = site.simulated->plant.get();
  return [plant] {
    const sim::PlantTruth t = plant->truth();
    nlohmann::json j;
    j["oru_state"] = sim::to_string(t.state);
    j["gripped"] = t.gripped;
    const Eigen::Vector3d p = t.base_T_oru.translation();
    j["base_T_oru_xyz_m"] = {p.x(), p.y(), p.z()};
    const Eigen::Vector3d tip = t.base_T_tip.translation();
    j["base_T_tip_xyz_m"] = {tip.x(), tip.y(), tip.z()};
    j["tip_depth_m"] = t.tip_depth_m;
    j["oru_slot_depth_m"] = t.oru_slot_depth_m;
    j["alignment_error_m"] = t.alignment_error_m;
    j["alignment_error_deg"] = t.alignment_error_rad * 180.0 / M_PI;
    return json_text(j);
  };
}

/// The link's configuration.
remote_link::Config link_config(const Options& o, const daemon::DaemonConfig& config, const RobotModel& model) {
  remote_link::Config lc;
  lc.domain = o.domain;
  lc.link_loss_s = config.link_loss_timeout_s;
  lc.trajectory_limits = TrajectoryLimits::from_model(model);
  lc.session_idle_s = config.session_idle_s;
  lc.security_dir = config.security_dir;
  lc.security_identity = config.security_identity;
  lc.ros2 = o.ros2;
  lc.ros2_joint_names = model.joint_names();
  return lc;
}

/// The start, as the journal keeps it.
void journal_start(const Options& o, const daemon::DaemonConfig& config, journal::Journal& journal) {
  journal::EventRow start;
  start.kind = "start";
  start.text = std::string("foresight-remote started") + (o.sim ? " (--sim)" : "") + ", config " + o.config +
               ", DDS domain " + std::to_string(o.domain) +
               (!config.security_dir.empty() ? ", DDS Security as '" + config.security_identity + "' (" +
                                                   config.security_dir + ")"
                : config.insecure ? ", WITHOUT DDS Security (controller.link.insecure: true)"
                                  : ", without DDS Security (--sim)");
  journal.record_event(start);
}

/// The loop's timing over the whole run, for the engineer (and the README).
void report_loop_stats(const control::ControlLoop& loop, journal::Journal& journal) {
  const control::LoopStats st = loop.stats();
  using LS = control::LoopStats;
  nlohmann::json j;
  j["cycles"] = st.cycles;
  j["overruns"] = st.overruns;
  j["realtime"] = st.realtime;
  j["compute_us"] = {{"mean", st.compute_us_mean},
                     {"p99", LS::percentile_us(st.compute_hist, 0.99)},
                     {"max", st.compute_us_max}};
  j["wakeup_latency_us"] = {{"mean", st.wakeup_latency_us_mean},
                            {"p99", LS::percentile_us(st.latency_hist, 0.99)},
                            {"p999", LS::percentile_us(st.latency_hist, 0.999)},
                            {"max", st.wakeup_latency_us_max}};
  spdlog::info("control loop: {}", json_text(j));
  journal::EventRow row;
  row.kind = "loop_stats";
  row.text = std::to_string(st.cycles) + " cycles, " + std::to_string(st.overruns) + " overruns";
  row.detail = json_text(j);
  try {
    journal.record_event(row);
  } catch (const std::exception& e) {
    spdlog::error("journal: {}", e.what());
  }
}

int run_daemon(Options o) {
  using namespace foresight;
  if (o.domain < 0) o.domain = protocol::domain_from_environment().value_or(0);  // InputError: exit 2
  // ---- configuration (exit 2 on any error) -----------------------------------------
  daemon::DaemonConfig config = daemon::load_daemon_config(o.config);
  settle_link_security(o, config);
  // The DDS network (controller.link.network), before the first participant.
  // A user's own CYCLONEDDS_URI wins; otherwise a missing interface or a
  // peer that does not resolve is named here, before the hardware.
  if (protocol::use_network(config.network))
    spdlog::info("DDS network: {}", config.network.describe());
  else
    spdlog::info("DDS network: CYCLONEDDS_URI is set; it wins over controller.link.network");
  if (!o.journal.empty()) config.journal.path = o.journal;
  if (!o.estop_file.empty()) config.estop_file = o.estop_file;
  daemon::SiteOptions site_options;
  site_options.remote_yaml = o.config;
  site_options.sim = o.sim;
  site_options.sim_rt_priority = std::max(1, o.rt_priority - 1);
  if (!o.sim_faults.empty() && !o.sim)
    throw foresight::InputError("--sim-faults", "fault injection needs --sim (a real cabinet breaks by itself)");
  daemon::Site site = daemon::build_site(site_options);
  const RobotModel& model = *site.model;
  std::unique_ptr<daemon::SimFaultWatcher> faults;
  if (!o.sim_faults.empty()) faults = std::make_unique<daemon::SimFaultWatcher>(site, o.sim_faults);

  journal::JournalOptions jo;
  jo.path = config.journal.path;
  jo.max_bytes = static_cast<std::uint64_t>(config.journal.max_mb * 1024.0 * 1024.0);
  jo.keep_files = config.journal.keep_files;
  jo.telemetry_rate_hz = config.journal.telemetry_hz;
  journal::Journal journal(jo);
  if (!journal.previous_shutdown_clean())
    spdlog::warn("journal {}: the previous run did not shut down cleanly; coming up holding, drives disabled",
                 journal.path());

  // ---- hardware: configured, NOT enabled (nothing moves until the ground says so)
  spdlog::info("configuring {} drives on {} bus(es) at {} Hz", site.hw_config.drives.size(),
               site.hw_config.buses.size(), site.hw_config.cycle_rate_hz);
  for (const auto& load : site.drives->bus_loads()) spdlog::info("{}", load.describe());
  site.drives->configure();
  // What bring-up recovered from (an SDO retry that was answered): worth a
  // commissioning engineer's look, not a failure.
  for (const auto& notice : site.drives->setup_notices()) spdlog::warn("bring-up: {}", notice);
  if (site.simulated && site.simulated->can) {  // its thread answered configure(): started
    if (site.simulated->can->realtime() == 1)
      spdlog::info("simulated drives: SCHED_FIFO priority {}", site_options.sim_rt_priority);
    else
      spdlog::warn("simulated drives: SCHED_FIFO not permitted, a normal thread (late TPDOs on a busy host are "
                   "scheduling, not the drives)");
  }

  const control::ControllerConfig cc = controller_config(config, site);
  const control::LoopOptions loop_options = loop_options_for(o);
  control::ControlLoop loop(*site.drives, model, cc, loop_options);
  loop.start();
  for (const auto& w : loop.warnings()) spdlog::warn("control loop: {}", w);
  journal_loop_start(o, loop, loop_options, journal);

  daemon::ToolWorker tool(site.tool_config, config.tool_poll_hz);
  std::unique_ptr<daemon::CameraWorker> camera;
  if (!site.camera_names.empty()) camera = std::make_unique<daemon::CameraWorker>(site.video_config);

  remote_link::RemoteLink* link_ptr = nullptr;
  daemon::SupervisorParts parts;
  parts.model = &model;
  parts.config = config;
  if (!config.security_dir.empty()) parts.identities = protocol::known_identities(config.security_dir);
  parts.loop = &loop;
  parts.drives = site.drives.get();
  parts.journal = &journal;
  parts.tool = &tool;
  parts.camera = camera.get();
  parts.camera_names = site.camera_names;
  for (const auto& d : site.hw_config.drives) parts.drive_nodes.push_back(d.node_id);
  parts.outbox.ack = [&](const protocol::Ack& a) { if (link_ptr) link_ptr->ack(a); };
  parts.outbox.joints = [&](const protocol::JointReport& r) { if (link_ptr) link_ptr->publish(r); };
  parts.outbox.wrench = [&](const protocol::WrenchReport& r) { if (link_ptr) link_ptr->publish(r); };
  parts.outbox.tool = [&](const protocol::ToolReport& r) { if (link_ptr) link_ptr->publish(r); };
  std::atomic<std::uint64_t> supervisor_beats{0};  // status reports published: the watchdog's sign of life
  parts.outbox.status = [&](const protocol::StatusReport& r) {
    supervisor_beats.fetch_add(1, std::memory_order_relaxed);
    if (link_ptr) link_ptr->publish(r);
  };
  parts.outbox.republish_uploads = [&] { if (link_ptr) link_ptr->republish_uploads(); };
  parts.outbox.commander = [&](const protocol::ParticipantGuid& g) { if (link_ptr) link_ptr->set_commander(g); };
  parts.sim_truth = sim_truth_of(site);
  daemon::Supervisor supervisor(std::move(parts));

  const remote_link::Config lc = link_config(o, config, model);
  remote_link::Handlers handlers;
  handlers.on_command = [&](const remote_link::CommandEvent& e) { supervisor.submit(e); };
  handlers.on_upload = [&](const remote_link::UploadEvent& e) { supervisor.upload(e); };
  handlers.on_link = [&](const remote_link::LinkEvent& e) { supervisor.link_event(e); };
  std::unique_ptr<remote_link::RemoteLink> link_holder;
  try {
    link_holder = std::make_unique<remote_link::RemoteLink>(lc, handlers);
  } catch (const protocol::ProtocolError& e) {
    if (config.security_dir.empty()) throw;
    // The permissions do not grant what the link needs: say whose and where.
    throw InputError(config.security_dir + "/permissions.p7s",
                     "identity '" + config.security_identity + "' is not granted what the daemon's link needs: " + e.what());
  }
  remote_link::RemoteLink& link = *link_holder;
  link_ptr = &link;
  link.start();

  journal_start(o, config, journal);
  spdlog::info("foresight-remote ready: DDS domain {}, journal {}, drives disabled until RECOVER", o.domain,
               journal.path());
  std::cout << "foresight-remote: ready" << std::endl;  // tests and scripts wait for this line
  sd_notify(0, "READY=1\nSTATUS=ready: holding, drives disabled until RECOVER");
  SystemdWatchdog watchdog(loop, supervisor_beats, config.reports.status_hz);

  supervisor.run(g_quit);

  watchdog.stop();
  sd_notify(0, "STOPPING=1\nSTATUS=controlled stop (category 1), drives off");

  const int sig = g_signal.load();
  const std::string why = sig == SIGTERM ? "SIGTERM" : sig == SIGINT ? "SIGINT" : "stop requested";
  spdlog::info("{}: controlled stop (category 1), drives off", why);
  supervisor.shutdown(why);
  report_loop_stats(loop, journal);
  link_ptr = nullptr;
  link.stop();
  if (!journal.flush()) spdlog::warn("journal: telemetry not flushed within the timeout");
  journal.close();
  spdlog::info("foresight-remote stopped");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Logs on stderr: stdout carries only the ready line (scripts wait for it).
  spdlog::set_default_logger(spdlog::stderr_color_mt("foresight-remote"));
  spdlog::set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  CLI::App app{"foresight-remote: the Foresight robot-cabinet daemon (real-time control, DDS link, journal)"};
  Options o;
  app.add_option("--config", o.config, "remote configuration (config/remote.yaml)");
  app.add_flag("--sim", o.sim, "embedded simulated robot: mock CAN buses with simulated drives and F/T sensor, the "
                               "simulated LST and video switch on 127.0.0.1");
  app.add_option("--journal", o.journal, "journal database (overrides controller.journal.path)");
  app.add_option("--domain", o.domain, "DDS domain id (default $FORESIGHT_DDS_DOMAIN or 0)")->check(CLI::Range(0, 232));
  app.add_option("--estop-file", o.estop_file, "E-stop (category 0) while this file exists (HIL tests, --sim)");
  app.add_option("--security", o.security_dir,
                 "DDS Security: the folder made by scripts/make_dds_security.sh (authentication, access control, "
                 "encryption; docs/protocol.md; default controller.link.security). Off --sim the daemon refuses to "
                 "start without it unless controller.link.insecure: true");
  app.add_option("--identity", o.security_identity,
                 "DDS Security identity in that folder (default controller.link.identity, remote)");
  app.add_flag("--ros2", o.ros2, "also publish rt/joint_states and rt/wrench as ROS 2 types");
  app.add_option("--sim-faults", o.sim_faults,
                 "with --sim: fault injection folder (tool_jam, ft_fault, oru_stuck, video_silent, drive_emcy_J, drive_silent_J, bus_loss_B files; drive_record out; HIL tests)");

  foresight::journal::JournalQuery q;
  CLI::App* jcmd = app.add_subcommand("journal", "print the journal: commands, faults, uploads, events");
  jcmd->add_option("--db", q.db, "journal database");
  jcmd->add_option("--since", q.since, "only rows at or after T (ns since the epoch, or ISO-8601 UTC)");
  jcmd->add_flag("--json", q.json, "one JSON object");

  foresight::daemon::CheckOptions check;
  check.remote_yaml = default_config();
  bool check_json = false;
  CLI::App* ccmd = app.add_subcommand("check", "fitness before first motion: config, URDF, bus budget, CAN, tool, "
                                               "real-time permissions, clock, journal, DDS security (exit 1 when unfit)");
  ccmd->add_option("--config", check.remote_yaml, "remote configuration (robot.urdf beside it)");
  ccmd->add_flag("--sim", check.sim, "check the simulated site (mock CAN, simulated LST) instead of the hardware");
  ccmd->add_flag("--json", check_json, "one JSON object");
  ccmd->add_option("--security", check.security_dir, "DDS security folder (scripts/make_dds_security.sh)");
  ccmd->add_option("--identity", check.security_identity, "this side's identity in it (default remote)");
  ccmd->add_option("--journal", check.journal_path, "journal database (overrides controller.journal.path)");
  ccmd->add_option("--rt-priority", check.rt_priority, "SCHED_FIFO priority to test (the loop's)")->check(CLI::Range(1, 99));
  std::string batch_path;
  std::string sim_config = default_config();
  bool sim_json = false;
  CLI::App* scmd = app.add_subcommand(
      "simulate-insertions",
      "run the insert algorithm (the controller's code) on the simulated plant in-process, faster than real time, "
      "once per trial of a batch file (docs/control.md, \"Simulated insertions\")");
  scmd->add_option("--batch", batch_path, "the batch file (JSON: object, tag, params, trials)")->required();
  scmd->add_flag("--json", sim_json, "one JSON object");
  scmd->add_option("--config", sim_config, "remote configuration (robot.urdf, oru.yaml, scene.yaml beside it)");
  app.add_option("--loop-cpu", o.loop_cpu, "pin the control loop thread to this CPU (an isolated one; -1: no)")
      ->check(CLI::Range(-1, 1023));
  app.add_option("--rt-priority", o.rt_priority, "the control loop's SCHED_FIFO priority (1-99, default 80)")
      ->check(CLI::Range(1, 99));
  app.add_flag("--allow-non-rt", o.allow_non_rt,
               "enable the drives even when SCHED_FIFO or mlockall is refused (journaled; never on a cabinet in use)");
  app.add_option("--max-missed-cycles", o.max_missed_cycles,
                 "control periods missed in a row that stop the arm, category 1 (0: never; default 3, 0 with --sim)")
      ->check(CLI::Range(0, 1000));

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  if (jcmd->parsed()) return foresight::journal::run_journal_command(q, std::cout, std::cerr);
  if (ccmd->parsed()) return foresight::daemon::run_check_command(check, check_json, std::cout);
  if (scmd->parsed()) {
    const std::string dir = std::filesystem::path(sim_config).parent_path().string();
    return foresight::daemon::run_simulate_insertions_command(batch_path, dir.empty() ? "." : dir, sim_json,
                                                              std::cout, std::cerr);
  }

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  try {
    return run_daemon(o);
  } catch (const foresight::InputError& e) {
    std::cerr << "foresight-remote: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "foresight-remote: error: " << e.what() << "\n";
    return 1;
  }
}
