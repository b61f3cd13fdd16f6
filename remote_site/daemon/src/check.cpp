#include "foresight/daemon/check.hpp"
#include "foresight/common/json_text.hpp"

#include <nlohmann/json.hpp>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/timex.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <exception>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <ostream>
#include <sstream>
#include <thread>

#include <linux/can.h>

#include "foresight/common/robot_model.hpp"
#include "foresight/hw/remote_config.hpp"
#include "foresight/hw/video_switch.hpp"
#include "foresight/journal/journal.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/security.hpp"
#include "foresight/remote_link/remote_link.hpp"
#include "foresight/daemon/daemon_config.hpp"
#include "foresight/daemon/site.hpp"

namespace foresight::daemon {

namespace fs = std::filesystem;
using nlohmann::json;

const char* to_string(CheckResult r) noexcept {
  switch (r) {
    case CheckResult::Pass: return "PASS";
    case CheckResult::Warn: return "WARN";
    case CheckResult::Fail: return "FAIL";
    case CheckResult::Skip: return "SKIP";
  }
  return "?";
}

bool CheckReport::fit() const noexcept { return count(CheckResult::Fail) == 0; }

int CheckReport::count(CheckResult r) const noexcept {
  int n = 0;
  for (const auto& i : items) n += i.result == r ? 1 : 0;
  return n;
}

const CheckItem* CheckReport::find(const std::string& name) const noexcept {
  for (const auto& i : items)
    if (i.name == name) return &i;
  return nullptr;
}

std::string CheckReport::text() const {
  std::size_t width = 0;
  for (const auto& i : items) width = std::max(width, i.name.size());
  std::ostringstream os;
  for (const auto& i : items)
    os << to_string(i.result) << "  " << i.name << std::string(width - i.name.size() + 2, ' ') << i.why << "\n";
  os << (fit() ? "fit to run" : "NOT fit to run") << ": " << count(CheckResult::Pass) << " passed, "
     << count(CheckResult::Warn) << " warnings, " << count(CheckResult::Fail) << " failed, "
     << count(CheckResult::Skip) << " skipped\n";
  return os.str();
}

std::string CheckReport::json() const {
  nlohmann::json j;
  j["fit"] = fit();
  j["counts"] = {{"pass", count(CheckResult::Pass)},
                 {"warn", count(CheckResult::Warn)},
                 {"fail", count(CheckResult::Fail)},
                 {"skip", count(CheckResult::Skip)}};
  j["items"] = nlohmann::json::array();
  for (const auto& i : items) j["items"].push_back({{"name", i.name}, {"result", to_string(i.result)}, {"why", i.why}});
  return json_text(j);
}

namespace {

CheckItem item(std::string name, CheckResult r, std::string why) { return {std::move(name), r, std::move(why)}; }

std::string read_first_line(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  if (in) std::getline(in, line);
  return line;
}

/// Runs `argv` (no shell), returns its stdout+stderr; exit status in *status.
std::string run_capture(const std::string& command_line, int* status) {
  std::string out;
  FILE* p = ::popen((command_line + " 2>&1").c_str(), "r");
  if (p == nullptr) {
    *status = -1;
    return std::strerror(errno);
  }
  std::array<char, 4096> buf{};
  for (int guard = 0; guard < 4096; ++guard) {  // at most 16 MB: bounded
    const std::size_t n = std::fread(buf.data(), 1, buf.size(), p);
    if (n == 0) break;
    out.append(buf.data(), n);
  }
  *status = ::pclose(p);
  return out;
}

bool safe_interface_name(const std::string& s) {
  if (s.empty() || s.size() > 15) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) return false;
  return true;
}

std::string errno_text(int e) { return std::string(std::strerror(e)); }

std::string describe_bitrate(std::uint32_t bps) {
  return bps % 1000 == 0 ? std::to_string(bps / 1000) + " kbit/s" : std::to_string(bps) + " bit/s";
}

}  // namespace

// ---- CAN --------------------------------------------------------------------------------

CheckItem assess_can_link(const std::string& name, const std::string& interface, std::uint32_t bitrate_bps,
                          const std::string& ip_json) {
  json links;
  try {
    links = json::parse(ip_json);
  } catch (const std::exception& e) {
    return item(name, CheckResult::Fail, "cannot read `ip -details -json link show " + interface + "`: " + e.what());
  }
  if (!links.is_array() || links.empty() || !links[0].is_object())
    return item(name, CheckResult::Fail, "no interface " + interface);
  const json& l = links[0];
  const std::string link_type = l.value("link_type", "");
  const json info = l.contains("linkinfo") ? l["linkinfo"] : json::object();
  const std::string kind = info.value("info_kind", "");
  if (link_type != "can" && kind != "can" && kind != "vcan")
    return item(name, CheckResult::Fail,
                interface + " is not a CAN interface (link type '" + link_type + "'); check `buses:` in remote.yaml");
  bool up = false;
  if (l.contains("flags") && l["flags"].is_array())
    for (const auto& f : l["flags"]) up = up || (f.is_string() && f.get<std::string>() == "UP");
  if (!up)
    return item(name, CheckResult::Fail,
                interface + " is down: bring it up (remote_site/deploy/can, systemd-networkd or can-setup.sh)");
  const json data = info.contains("info_data") ? info["info_data"] : json::object();
  const std::string state = data.value("state", "");
  std::uint32_t bitrate = 0;
  if (data.contains("bittiming") && data["bittiming"].is_object())
    bitrate = data["bittiming"].value("bitrate", 0u);
  const int restart_ms = data.value("restart_ms", 0);
  const int txqlen = l.value("txqlen", 0);
  std::string facts = interface + " up, " + (state.empty() ? std::string("state unknown") : state);
  if (bitrate != 0) facts += ", " + describe_bitrate(bitrate);
  facts += ", restart-ms " + std::to_string(restart_ms) + ", txqueuelen " + std::to_string(txqlen);
  if (kind == "can" && bitrate != bitrate_bps)
    return item(name, CheckResult::Fail,
                facts + ": the configuration says " + describe_bitrate(bitrate_bps) + " (set the same bit rate on both)");
  if (state == "BUS-OFF" || state == "ERROR-PASSIVE" || state == "STOPPED")
    return item(name, CheckResult::Fail,
                facts + ": the controller is " + state + " (wiring, termination, bit rate of the nodes, drive power)");
  if (state == "ERROR-WARNING")
    return item(name, CheckResult::Warn, facts + ": error counters above 96 (check termination and wiring)");
  if (kind == "can" && restart_ms == 0)
    return item(name, CheckResult::Warn, facts + ": no automatic bus-off recovery (set restart-ms, e.g. 100)");
  return item(name, CheckResult::Pass, facts);
}

CheckItem check_can_interface(const std::string& bus_name, const std::string& interface, std::uint32_t bitrate_bps) {
  const std::string name = "CAN " + bus_name + " (" + interface + ")";
  if (interface == "mock")
    return item(name, CheckResult::Fail,
                "bus " + bus_name + " has interface 'mock': a real cabinet needs a SocketCAN interface (can0...); "
                "or check the simulated site with --sim");
  if (!safe_interface_name(interface))
    return item(name, CheckResult::Fail, "'" + interface + "' is not a network interface name");
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) {
    const int e = errno;
    if (e == EAFNOSUPPORT)
      return item(name, CheckResult::Fail,
                  "this kernel has no SocketCAN support (socket(PF_CAN) failed: EAFNOSUPPORT, " + errno_text(e) +
                      "), so interface " + interface + " cannot exist: a cabinet kernel needs CONFIG_CAN, CONFIG_CAN_RAW "
                      "and the adapter's driver");
    return item(name, CheckResult::Fail, "cannot open a CAN socket: " + errno_text(e));
  }
  ::close(fd);
  if (!fs::exists("/sys/class/net/" + interface))
    return item(name, CheckResult::Fail,
                "no interface " + interface + " on this machine (adapter not plugged in, driver not loaded, or "
                "renamed: see `ip link` and remote_site/deploy/can)");
  int status = 0;
  const std::string out = run_capture("ip -details -json link show dev " + interface, &status);
  if (status != 0) return item(name, CheckResult::Fail, "`ip -details -json link show " + interface + "`: " + out);
  return assess_can_link(name, interface, bitrate_bps, out);
}

// ---- tool ---------------------------------------------------------------------------------

CheckItem check_tool(const hw::LstToolConfig& config, double timeout_s) {
  hw::LstToolConfig c = config;
  c.response_timeout_s = timeout_s;
  c.retries = 0;
  const std::string name = "tool";
  try {
    hw::LstTool tool(c);
    hw::LstStatus s;
    if (const std::error_code ec = tool.read_status(s))
      return item(name, CheckResult::Fail,
                  "the LST at " + c.describe() + " does not answer: " + tool.last_error_message() +
                      " (tool powered? cable? `tool.modbus` in remote.yaml)");
    const std::string bits = s.describe();
    if (s.fault())
      return item(name, CheckResult::Warn,
                  c.describe() + " answered, but reports a fault: " + bits + " (reset it before a tool step)");
    return item(name, CheckResult::Pass, c.describe() + " answered: " + (bits.empty() ? "no status bits" : bits));
  } catch (const std::exception& e) {
    return item(name, CheckResult::Fail, e.what());
  }
}

// ---- real time ----------------------------------------------------------------------------

CheckItem check_rt_priority(int priority, bool required) {
  rlimit rl{};
  ::getrlimit(RLIMIT_RTPRIO, &rl);
  const std::string limit =
      rl.rlim_cur == RLIM_INFINITY ? std::string("unlimited") : std::to_string(static_cast<long long>(rl.rlim_cur));
  int rc = 0;
  std::thread probe([&] {
    sched_param sp{};
    sp.sched_priority = priority;
    rc = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &sp);
  });
  probe.join();
  const std::string name = "rt priority";
  const bool by_limit = rl.rlim_cur == RLIM_INFINITY || rl.rlim_cur >= static_cast<rlim_t>(priority);
  if (rc == 0)
    return item(name, CheckResult::Pass,
                "SCHED_FIFO " + std::to_string(priority) + " granted (RLIMIT_RTPRIO " + limit +
                    (by_limit ? ")" : "; by CAP_SYS_NICE)"));
  return item(name, required ? CheckResult::Fail : CheckResult::Warn,
              "SCHED_FIFO " + std::to_string(priority) + " refused (" + errno_text(rc) + "; RLIMIT_RTPRIO " + limit +
                  "): the control loop would run as a normal thread; the unit sets LimitRTPRIO=95, a shell needs "
                  "`ulimit -r 95` or CAP_SYS_NICE" + (required ? "" : " (--sim: not required)"));
}

CheckItem check_memlock(bool required) {
  rlimit rl{};
  ::getrlimit(RLIMIT_MEMLOCK, &rl);
  const std::string name = "memory lock";
  if (rl.rlim_cur == RLIM_INFINITY) return item(name, CheckResult::Pass, "RLIMIT_MEMLOCK unlimited");
  const std::string limit = std::to_string(static_cast<unsigned long long>(rl.rlim_cur / 1024)) + " KiB";
  if (::mlockall(MCL_CURRENT) == 0) {
    ::munlockall();
    return item(name, CheckResult::Pass, "mlockall permitted (CAP_IPC_LOCK; RLIMIT_MEMLOCK " + limit + ")");
  }
  const int e = errno;
  return item(name, required ? CheckResult::Fail : CheckResult::Warn,
              "RLIMIT_MEMLOCK " + limit + " and mlockall refused (" + errno_text(e) +
                  "): page faults could stall the control cycle; the unit sets LimitMEMLOCK=infinity" +
                  (required ? "" : " (--sim: not required)"));
}

CheckItem check_kernel() {
  const std::string name = "kernel";
  utsname u{};
  ::uname(&u);
  const bool rt = read_first_line("/sys/kernel/realtime") == "1" || std::strstr(u.version, "PREEMPT_RT") != nullptr;
  const std::string isolated = read_first_line("/sys/devices/system/cpu/isolated");
  const std::string facts = std::string(u.release) + ", " + std::to_string(std::thread::hardware_concurrency()) +
                            " CPUs, isolated: " + (isolated.empty() ? "none" : isolated);
  if (!rt)
    return item(name, CheckResult::Warn,
                facts + ": not a PREEMPT_RT kernel (cycle latency is not bounded; docs/deploy.md, linux-image-rt-amd64)");
  if (isolated.empty())
    return item(name, CheckResult::Warn, facts + ": PREEMPT_RT, but no CPU isolated for the loop (isolcpus=, nohz_full=)");
  return item(name, CheckResult::Pass, facts + ", PREEMPT_RT");
}

CheckItem check_clock() {
  const std::string name = "clock";
  timex tx{};
  tx.modes = 0;  // read only
  const int state = ::adjtimex(&tx);
  if (state < 0) return item(name, CheckResult::Warn, "adjtimex failed: " + errno_text(errno));
  if (state == TIME_ERROR || (tx.status & STA_UNSYNC) != 0)
    return item(name, CheckResult::Warn,
                "system clock not synchronised (adjtimex: STA_UNSYNC): journal and telemetry times may drift from the "
                "ground's; enable systemd-timesyncd or chrony (the ground still measures the offset)");
  return item(name, CheckResult::Pass,
              "synchronised (estimated error " + std::to_string(tx.esterror) + " us, maximum error " +
                  std::to_string(tx.maxerror) + " us)");
}

CheckItem check_journal_dir(const std::string& journal_path) {
  const std::string name = "journal";
  // The writer's own checks, writing nothing: the folder, the file's type, an
  // SQLite database, a Foresight journal, its schema, read-only, locked.
  try {
    return item(name, CheckResult::Pass, journal::probe_journal(journal_path).describe);
  } catch (const std::exception& e) {
    return item(name, CheckResult::Fail, e.what());
  }
}

// ---- DDS security -------------------------------------------------------------------------

/// `dir` and `identity` as the daemon takes them (--security, else
/// controller.link.security); `insecure`: controller.link.insecure.
CheckItem check_security(const std::string& dir, const std::string& identity, bool sim, bool insecure) {
  const std::string name = "DDS security";
  if (dir.empty() && insecure)
    return item(name, CheckResult::Warn,
                "controller.link.insecure: true: the link runs without DDS Security; any participant of the DDS "
                "domain can command the arm (make_dds_security.sh, docs/deploy.md)");
  if (dir.empty() && sim)
    return item(name, CheckResult::Skip, "not configured (no --security folder): the simulated link runs unauthenticated");
  if (dir.empty())
    return item(name, CheckResult::Fail,
                "not configured: the daemon refuses to start off --sim without controller.link.security (or "
                "--security DIR), unless controller.link.insecure: true");
  protocol::SecurityFacts facts;
  try {
    facts = protocol::verify_security_files(dir, identity);  // what the daemon's participant reads, read the same way
  } catch (const std::exception& e) {
    return item(name, CheckResult::Fail, e.what());
  }
  const std::string plugins = protocol::security_plugin_dir();
  if (!plugins.empty())
    for (const char* lib : {"libdds_security_auth.so", "libdds_security_ac.so", "libdds_security_crypto.so"})
      if (!fs::exists(fs::path(plugins) / lib))
        return item(name, CheckResult::Fail, "Cyclone's security plugin " + (fs::path(plugins) / lib).string() + " is missing");
  if (facts.days_left < 30)
    return item(name, CheckResult::Warn, facts.describe() + " (renew it soon: scripts/make_dds_security.sh)");
  return item(name, CheckResult::Pass, facts.describe());
}

// ---- DDS network --------------------------------------------------------------------------

CheckItem check_network(const protocol::NetworkSettings& n) {
  const std::string name = "DDS network";
  if (const char* uri = std::getenv("CYCLONEDDS_URI"); uri != nullptr && *uri != '\0')
    return item(name, CheckResult::Skip,
                "CYCLONEDDS_URI is set in this environment: a daemon started from it uses that instead of " +
                    n.source);
  const auto problems = protocol::network_problems(n);
  if (problems.empty()) return item(name, CheckResult::Pass, n.describe() + " (" + n.source + ")");
  std::string why = n.source + ": ";
  for (std::size_t i = 0; i < problems.size(); ++i) why += (i ? "; " : "") + problems[i];
  return item(name, CheckResult::Fail, why);
}

// ---- the whole check ----------------------------------------------------------------------

CheckReport run_check(const CheckOptions& o) {
  CheckReport report;
  auto add = [&](CheckItem i) { report.items.push_back(std::move(i)); };
  const bool required = !o.sim;

  std::optional<hw::RemoteConfig> hw_config;
  std::optional<hw::LstToolConfig> tool_config;
  std::optional<DaemonConfig> daemon_config;
  try {
    // Every loader the daemon runs on remote.yaml (build_site and run_daemon):
    // what the daemon would refuse, check fails.
    hw_config = hw::load_remote_config(o.remote_yaml);
    tool_config = hw::load_lst_tool_config(o.remote_yaml);
    const auto video = hw::load_video_switch_section(o.remote_yaml);
    daemon_config = load_daemon_config(o.remote_yaml);
    add(item("config", CheckResult::Pass,
             o.remote_yaml + ": " + std::to_string(hw_config->buses.size()) + " bus(es), " +
                 std::to_string(hw_config->drives.size()) + " drives at " +
                 std::to_string(static_cast<int>(hw_config->cycle_rate_hz)) + " Hz" +
                 (hw_config->ft.present ? ", F/T sensor on " + hw_config->ft.bus : std::string(", no F/T sensor")) +
                 "; tool " + tool_config->describe() + "; " +
                 (video ? "video switch " + video->link.host + ":" + std::to_string(video->link.port) + " (" +
                              std::to_string(video->camera_names.size()) + " cameras)"
                        : std::string("no video switch")) +
                 "; start-up " + hw::estimate_startup(*hw_config).describe()));
  } catch (const std::exception& e) {
    add(item("config", CheckResult::Fail, e.what()));
  }

  const std::string urdf = o.urdf.empty() ? sibling(o.remote_yaml, "robot.urdf") : o.urdf;
  bool model_ok = false;
  std::optional<TrajectoryLimits> limits;  // the link's, for the DDS security probe
  try {
    if (!fs::exists(urdf)) throw std::runtime_error("missing URDF: " + urdf + " does not exist");
    const RobotModel model = RobotModel::from_file(urdf);
    limits = TrajectoryLimits::from_model(model);
    std::string mismatch;
    if (hw_config) {
      if (hw_config->drives.size() != static_cast<std::size_t>(model.dof()))
        mismatch = std::to_string(hw_config->drives.size()) + " drives configured, the robot has " +
                   std::to_string(model.dof()) + " joints";
      for (std::size_t j = 0; mismatch.empty() && j < hw_config->drives.size(); ++j)
        if (hw_config->drives[j].joint != model.joint_names()[j])
          mismatch = "drive " + std::to_string(j + 1) + " is for joint '" + hw_config->drives[j].joint +
                     "', the robot's joint " + std::to_string(j + 1) + " is '" + model.joint_names()[j] + "'";
    }
    if (!mismatch.empty()) {
      add(item("robot model", CheckResult::Fail, urdf + ": " + mismatch));
    } else {
      add(item("robot model", CheckResult::Pass, urdf + ": " + std::to_string(model.dof()) + " joints"));
      model_ok = true;
    }
  } catch (const std::exception& e) {
    add(item("robot model", CheckResult::Fail, e.what()));
  }

  if (hw_config) {
    std::string loads;
    bool over = false;
    for (const auto& l : hw::compute_bus_loads(*hw_config)) {
      char pct[32];
      std::snprintf(pct, sizeof pct, "%.1f%%", l.load * 100.0);
      loads += (loads.empty() ? "" : ", ") + l.bus + " " + pct;
      over = over || l.load > hw_config->max_bus_load;
    }
    char limit[32];
    std::snprintf(limit, sizeof limit, "%.0f%%", hw_config->max_bus_load * 100.0);
    add(item("bus budget", over ? CheckResult::Fail : CheckResult::Pass,
             loads + " worst case at " + std::to_string(static_cast<int>(hw_config->cycle_rate_hz)) + " Hz (limit " +
                 limit + ")"));
  } else {
    add(item("bus budget", CheckResult::Skip, "the configuration did not load"));
  }

  // CAN and tool: the hardware, or the simulated site.
  if (!hw_config || !tool_config) {
    add(item("CAN", CheckResult::Skip, "the configuration did not load"));
    add(item("tool", CheckResult::Skip, "the configuration did not load"));
  } else if (!o.sim) {
    for (const auto& bus : hw_config->buses) add(check_can_interface(bus.name, bus.interface, bus.bitrate_bps));
    add(check_tool(*tool_config, o.tool_timeout_s));
  } else if (!model_ok) {
    add(item("CAN (simulated)", CheckResult::Skip, "the robot model did not load"));
    add(item("tool", CheckResult::Skip, "the robot model did not load"));
  } else {
    try {
      SiteOptions so;
      so.remote_yaml = o.remote_yaml;
      so.urdf = urdf;
      so.sim = true;
      Site site = build_site(so);
      std::string buses;
      for (const auto& b : site.hw_config.buses) buses += (buses.empty() ? "" : ", ") + b.name;
      try {
        site.drives->configure();
        add(item("CAN (simulated)", CheckResult::Pass,
                 std::to_string(site.hw_config.drives.size()) + " simulated drives" +
                     (site.hw_config.ft.present ? " and the F/T sensor" : "") + " answered on mock buses " + buses +
                     " (boot-up, SDO, PDO mapping); drive 1: '" + site.drives->device_name(0) + "'"));
      } catch (const std::exception& e) {
        add(item("CAN (simulated)", CheckResult::Fail, e.what()));
      }
      add(check_tool(site.tool_config, o.tool_timeout_s));
    } catch (const std::exception& e) {
      add(item("CAN (simulated)", CheckResult::Fail, std::string("the simulated site did not start: ") + e.what()));
      add(item("tool", CheckResult::Skip, "the simulated site did not start"));
    }
  }

  add(check_rt_priority(o.rt_priority, required));
  add(check_memlock(required));
  add(check_kernel());
  add(check_clock());
  if (daemon_config || !o.journal_path.empty())
    add(check_journal_dir(o.journal_path.empty() ? daemon_config->journal.path : o.journal_path));
  else
    add(item("journal", CheckResult::Skip, "the configuration did not load"));
  if (daemon_config)
    add(check_network(daemon_config->network));
  else
    add(item("DDS network", CheckResult::Skip, "the configuration did not load"));
  {
    std::string dir = o.security_dir, identity = o.security_identity;
    if (dir.empty() && daemon_config) dir = daemon_config->security_dir;
    if (identity.empty()) identity = daemon_config ? daemon_config->security_identity : "remote";
    CheckItem sec = check_security(dir, identity, o.sim, o.security_dir.empty() && daemon_config && daemon_config->insecure);
    if (!dir.empty() && sec.result != CheckResult::Fail && limits) {
      // The grants, as the daemon will use them: its link's every reader and
      // writer made with this identity (nothing started, nothing sent).
      try {
        if (daemon_config) protocol::apply_network(daemon_config->network);  // its problems: the "DDS network" item
        remote_link::Config lc;
        lc.domain = protocol::domain_from_environment().value_or(0);
        lc.security_dir = dir;
        lc.security_identity = identity;
        lc.trajectory_limits = *limits;
        remote_link::Handlers none;
        none.on_command = [](const remote_link::CommandEvent&) {};
        remote_link::RemoteLink probe(lc, none);
        sec.why += "; its grants cover every topic the daemon reads and writes";
      } catch (const std::exception& e) {
        sec = item("DDS security", CheckResult::Fail,
                   "identity '" + identity + "' in " + dir + ": its permissions (permissions.p7s) do not cover the daemon's "
                   "link: " + e.what());
      }
    }
    add(sec);
  }
  return report;
}

int run_check_command(const CheckOptions& options, bool json_out, std::ostream& out) {
  const CheckReport report = run_check(options);
  if (json_out)
    out << report.json() << "\n";
  else
    out << "foresight-remote check: " << options.remote_yaml << (options.sim ? " (--sim)" : "") << "\n" << report.text();
  return report.fit() ? 0 : 1;
}

}  // namespace foresight::daemon
