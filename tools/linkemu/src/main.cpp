// foresight-linkemu: a user-space link emulator between two network
// namespaces (this kernel has no netem). See
// docs/linkemu.md.
//
//   foresight-linkemu [--delay-ms D] [--jitter-ms J] [--loss P] [--reorder P]
//                     [--rate-kbit R] ... [--]
//       creates PREFIX-PID-ground and PREFIX-PID-remote, a TUN device in each,
//       prints one JSON line {"event":"ready",...} and forwards until
//       SIGINT/SIGTERM/SIGHUP (or --lifetime-s); SIGUSR1 takes the link down
//       (an outage: every packet entering is dropped) and SIGUSR2 brings it
//       back, each printing {"event":"link","state":"down"|"up"}; then prints one JSON line
//       {"event":"stats",...}, removes both namespaces and exits 0.
//   foresight-linkemu exec NAME [--keep-dds-env] [--exit-with-parent] -- CMD [ARGS...]
//       runs CMD inside namespace NAME with CYCLONEDDS_URI set for the link
//       (unless --keep-dds-env). --exit-with-parent: CMD runs as a child in its
//       own process group, which gets SIGTERM when the caller dies (or when
//       this process is signalled).
//   foresight-linkemu dds-config NAME     prints that side's Cyclone XML.
//   foresight-linkemu cleanup [--prefix P] removes namespaces of dead owners.
//   foresight-linkemu check               exit 0 if permitted, 77 if not.
//
// Exit status: 0 ok, 1 failure, 2 bad usage, 77 namespaces/TUN not permitted.

#include <signal.h>
#include <sys/prctl.h>
#include <sys/signalfd.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "foresight/linkemu/dds_config.hpp"
#include "foresight/linkemu/forwarder.hpp"
#include "foresight/linkemu/netns.hpp"

namespace le = foresight::linkemu;
using json = nlohmann::ordered_json;

namespace {

constexpr const char* kUsage =
    "usage: foresight-linkemu [--delay-ms D] [--jitter-ms J] [--loss P] [--reorder P] [--reorder-gap-ms G]\n"
    "                         [--rate-kbit R] [--burst-bytes B] [--queue-bytes Q] [--queue-packets N]\n"
    "                         [--mtu M] [--subnet N] [--prefix NAME] [--seed S] [--lifetime-s T]\n"
    "                         [--exit-with-parent] [--]\n"
    "       foresight-linkemu exec NAMESPACE [--keep-dds-env] [--exit-with-parent] -- COMMAND [ARGS...]\n"
    "       foresight-linkemu dds-config NAMESPACE\n"
    "       foresight-linkemu cleanup [--prefix NAME]\n"
    "       foresight-linkemu check\n"
    "Delay and jitter are one way (round trip = 2 x delay); loss and reorder are per direction.\n";

constexpr const char* kInterface = "fsl0";

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

double parse_number(const std::string& option, const std::string& text, double lo, double hi) {
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || errno != 0 || !std::isfinite(v) || v < lo || v > hi) {
    char range[96];
    std::snprintf(range, sizeof range, "a number in [%g, %g]", lo, hi);
    throw UsageError(option + " wants " + range + ", got '" + text + "'");
  }
  return v;
}

struct RunOptions {
  double delay_ms = 0.0;
  double jitter_ms = 0.0;
  double loss = 0.0;
  double reorder = 0.0;
  double reorder_gap_ms = 10.0;
  double rate_kbit = 0.0;
  double burst_bytes = 3000;
  double queue_bytes = 65536;
  double queue_packets = 8192;
  double mtu = 1500;
  double subnet = 0;
  double lifetime_s = 0.0;
  std::string prefix = le::kDefaultPrefix;
  std::optional<std::uint64_t> seed;
  bool exit_with_parent = false;
};

RunOptions parse_run(const std::vector<std::string>& args) {
  RunOptions o;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--") {
      if (i + 1 != args.size()) {
        throw UsageError("nothing may follow '--' (run commands with 'foresight-linkemu exec NAMESPACE -- CMD' or "
                         "scripts/linkemu_session.sh)");
      }
      break;
    }
    if (a == "--exit-with-parent") {
      o.exit_with_parent = true;
      continue;
    }
    if (i + 1 >= args.size()) throw UsageError("missing value after " + a);
    const std::string& v = args[++i];
    if (a == "--delay-ms") o.delay_ms = parse_number(a, v, 0, 600000);
    else if (a == "--jitter-ms") o.jitter_ms = parse_number(a, v, 0, 600000);
    else if (a == "--loss") o.loss = parse_number(a, v, 0, 1);
    else if (a == "--reorder") o.reorder = parse_number(a, v, 0, 1);
    else if (a == "--reorder-gap-ms") o.reorder_gap_ms = parse_number(a, v, 0, 600000);
    else if (a == "--rate-kbit") o.rate_kbit = parse_number(a, v, 0, 1e8);
    else if (a == "--burst-bytes") o.burst_bytes = parse_number(a, v, 1, 1e9);
    else if (a == "--queue-bytes") o.queue_bytes = parse_number(a, v, 1, 1e10);
    else if (a == "--queue-packets") o.queue_packets = parse_number(a, v, 1, 1048576);
    else if (a == "--mtu") o.mtu = parse_number(a, v, 576, 65535);
    else if (a == "--subnet") o.subnet = parse_number(a, v, 0, 255);
    else if (a == "--lifetime-s") o.lifetime_s = parse_number(a, v, 0, 1e9);
    else if (a == "--seed") o.seed = static_cast<std::uint64_t>(parse_number(a, v, 0, 9e15));
    else if (a == "--prefix") {
      if (v.empty() || v.size() > 40 || v.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_") != std::string::npos) {
        throw UsageError("--prefix wants 1..40 characters of [a-z0-9_], got '" + v + "'");
      }
      o.prefix = v;
    } else {
      throw UsageError("unknown option " + a);
    }
  }
  if (o.burst_bytes < o.mtu && o.rate_kbit > 0) {
    throw UsageError("--burst-bytes must be at least the MTU (" + std::to_string(static_cast<int>(o.mtu)) + ")");
  }
  return o;
}

json stats_json(const le::DirectionStats& s, std::size_t in_flight) {
  return {{"packets_in", s.packets_in},
          {"bytes_in", s.bytes_in},
          {"packets_out", s.packets_out},
          {"bytes_out", s.bytes_out},
          {"in_flight_at_exit", in_flight},
          {"dropped", s.dropped()},
          {"dropped_loss", s.dropped_loss},
          {"dropped_queue", s.dropped_queue},
          {"dropped_overflow", s.dropped_overflow},
          {"dropped_write", s.dropped_write},
          {"dropped_outage", s.dropped_outage},
          {"reordered", s.reordered},
          {"max_queued", s.max_queued}};
}

void print_line(const json& j) {
  std::printf("%s\n", j.dump().c_str());
  std::fflush(stdout);
}

int run(const RunOptions& o) {
  // Signals first: a SIGTERM during set-up is then handled after it, by the
  // same clean-up path. SIGPIPE ignored: a closed stdout must not kill us
  // before the namespaces are removed.
  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, SIGINT);
  sigaddset(&mask, SIGTERM);
  sigaddset(&mask, SIGHUP);
  sigaddset(&mask, SIGUSR1);
  sigaddset(&mask, SIGUSR2);
  if (sigprocmask(SIG_BLOCK, &mask, nullptr) != 0) throw std::runtime_error("sigprocmask failed");
  std::signal(SIGPIPE, SIG_IGN);
  const int stop_fd = signalfd(-1, &mask, SFD_CLOEXEC | SFD_NONBLOCK);
  if (stop_fd < 0) throw std::runtime_error(std::string("signalfd: ") + std::strerror(errno));
  if (o.exit_with_parent) {
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() == 1) return 0;  // the parent is already gone
  }

  le::check_permitted();
  const auto removed = le::remove_stale_netns(o.prefix);
  const pid_t pid = getpid();
  le::NamedNetns ground(le::netns_name(o.prefix, pid, "ground"));
  le::NamedNetns remote(le::netns_name(o.prefix, pid, "remote"));
  const std::string net = "10.200." + std::to_string(static_cast<int>(o.subnet)) + ".";
  le::TunConfig gcfg{kInterface, net + "1", net + "2", 30, static_cast<int>(o.mtu), 4096};
  le::TunConfig rcfg{kInterface, net + "2", net + "1", 30, static_cast<int>(o.mtu), 4096};
  struct CloseFd {
    int fd;
    ~CloseFd() {
      if (fd >= 0) ::close(fd);
    }
  };
  // Destroyed in reverse order: the fds close (nobody forwards any more), then
  // the names go; the persistent TUN devices go with their namespaces once no
  // process is left in them (netns.hpp).
  CloseFd ground_tun{le::create_tun(ground.name(), gcfg)};
  CloseFd remote_tun{le::create_tun(remote.name(), rcfg)};

  le::LinkParams p;
  p.delay_ns = std::llround(o.delay_ms * 1e6);
  p.jitter_ns = std::llround(o.jitter_ms * 1e6);
  p.loss = o.loss;
  p.reorder = o.reorder;
  p.reorder_gap_ns = std::llround(o.reorder_gap_ms * 1e6);
  p.rate_bit_s = o.rate_kbit * 1000.0;
  p.burst_bytes = std::llround(o.burst_bytes);
  p.queue_bytes = std::llround(o.queue_bytes);
  le::ForwarderOptions fo;
  fo.ground_to_remote = p;
  fo.remote_to_ground = p;
  fo.queue_packets = static_cast<std::size_t>(o.queue_packets);
  fo.mtu = static_cast<std::size_t>(o.mtu);
  fo.seed = o.seed ? *o.seed : (static_cast<std::uint64_t>(std::random_device{}()) << 20) ^ static_cast<std::uint64_t>(pid);
  le::Forwarder forwarder(ground_tun.fd, remote_tun.fd, fo);

  print_line({{"event", "ready"},
              {"pid", pid},
              {"prefix", o.prefix},
              {"ground_netns", ground.name()},
              {"remote_netns", remote.name()},
              {"interface", kInterface},
              {"ground_address", gcfg.address},
              {"remote_address", rcfg.address},
              {"delay_ms", o.delay_ms},
              {"jitter_ms", o.jitter_ms},
              {"loss", o.loss},
              {"reorder", o.reorder},
              {"rate_kbit", o.rate_kbit},
              {"queue_bytes", p.queue_bytes},
              {"mtu", fo.mtu},
              {"seed", fo.seed},
              {"removed_stale", removed},
              {"cyclonedds_uri",
               {{"ground", le::cyclone_config_xml(kInterface, rcfg.address)},
                {"remote", le::cyclone_config_xml(kInterface, gcfg.address)}}}});

  const std::int64_t deadline = o.lifetime_s > 0 ? le::monotonic_ns() + std::llround(o.lifetime_s * 1e9) : 0;
  int err = 0;
  std::string reason = "lifetime";
  for (;;) {
    err = forwarder.run(stop_fd, deadline);
    signalfd_siginfo info{};
    if (err != 0 || ::read(stop_fd, &info, sizeof info) != static_cast<ssize_t>(sizeof info)) break;
    const int signo = static_cast<int>(info.ssi_signo);
    if (signo == SIGUSR1 || signo == SIGUSR2) {  // outage control; go on forwarding
      const bool down = signo == SIGUSR1;
      if (down != forwarder.down()) {
        forwarder.set_down(down);
        print_line({{"event", "link"}, {"state", down ? "down" : "up"}, {"t_ns", le::monotonic_ns()}});
      }
      continue;
    }
    reason = strsignal(signo);
    break;
  }
  if (err != 0) reason = std::string("ppoll: ") + std::strerror(err);
  print_line({{"event", "stats"},
              {"reason", reason},
              {"ground_to_remote",
               stats_json(forwarder.stats(le::kGroundToRemote), forwarder.queued(le::kGroundToRemote))},
              {"remote_to_ground",
               stats_json(forwarder.stats(le::kRemoteToGround), forwarder.queued(le::kRemoteToGround))}});
  const auto& g = forwarder.stats(le::kGroundToRemote);
  const auto& r = forwarder.stats(le::kRemoteToGround);
  std::fprintf(stderr,
               "foresight-linkemu: stopped (%s); ground->remote %llu packets %llu bytes, %llu dropped; "
               "remote->ground %llu packets %llu bytes, %llu dropped\n",
               reason.c_str(), static_cast<unsigned long long>(g.packets_in),
               static_cast<unsigned long long>(g.bytes_in), static_cast<unsigned long long>(g.dropped()),
               static_cast<unsigned long long>(r.packets_in), static_cast<unsigned long long>(r.bytes_in),
               static_cast<unsigned long long>(r.dropped()));
  return err == 0 ? 0 : 1;
}

/// Runs the command as a child in its own process group and stays beside it:
/// SIGTERM/SIGINT/SIGHUP (also the SIGTERM the kernel sends when our parent
/// dies) go to the whole group, so a shell's children stop too. Returns the
/// command's exit status (128 + signal when it was killed).
int supervise(std::vector<char*>& argv, pid_t parent) {
  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, SIGTERM);
  sigaddset(&mask, SIGINT);
  sigaddset(&mask, SIGHUP);
  sigaddset(&mask, SIGCHLD);
  sigset_t old_mask;
  sigprocmask(SIG_BLOCK, &mask, &old_mask);
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  if (getppid() != parent) return 143;  // the parent died before we asked
  const pid_t child = fork();
  if (child < 0) throw std::runtime_error(std::string("fork: ") + std::strerror(errno));
  if (child == 0) {
    setpgid(0, 0);
    sigprocmask(SIG_SETMASK, &old_mask, nullptr);
    execvp(argv[0], argv.data());
    std::fprintf(stderr, "foresight-linkemu: exec %s: %s\n", argv[0], std::strerror(errno));
    _exit(127);
  }
  setpgid(child, child);  // also here: no window where a signal misses the group
  const timespec tick{0, 200'000'000};
  int kill_ticks = -1;  // after a forwarded signal: ticks until SIGKILL
  for (;;) {
    int status = 0;
    const pid_t done = waitpid(child, &status, WNOHANG);
    if (done == child) {
      if (WIFEXITED(status)) return WEXITSTATUS(status);
      return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    }
    siginfo_t info{};
    const int sig = sigtimedwait(&mask, &info, &tick);
    if (sig == SIGTERM || sig == SIGINT || sig == SIGHUP) {
      kill(-child, sig);
      if (kill_ticks < 0) kill_ticks = 15;  // 3 s to stop (linkemu_session.sh waits longer)
    }
    if (kill_ticks > 0 && --kill_ticks == 0) kill(-child, SIGKILL);
  }
}

int exec_in(const std::vector<std::string>& args) {
  if (args.empty()) throw UsageError("exec wants a namespace name");
  const std::string name = args[0];
  bool keep_env = false;
  bool exit_with_parent = false;
  const pid_t parent = getppid();
  std::size_t i = 1;
  for (; i < args.size() && args[i] != "--"; ++i) {
    if (args[i] == "--keep-dds-env") keep_env = true;
    else if (args[i] == "--exit-with-parent") exit_with_parent = true;
    else throw UsageError("unknown exec option " + args[i]);
  }
  if (i + 1 >= args.size()) throw UsageError("exec wants '-- COMMAND [ARGS...]'");
  if (!keep_env) {
    const auto addr = le::interface_addresses(name, kInterface);
    const std::string xml = le::cyclone_config_xml(kInterface, addr.peer);
    setenv("CYCLONEDDS_URI", xml.c_str(), 1);
  }
  le::EnterNetns inside(name);
  inside.release();
  std::vector<char*> argv;
  for (std::size_t k = i + 1; k < args.size(); ++k) argv.push_back(const_cast<char*>(args[k].c_str()));
  argv.push_back(nullptr);
  if (!exit_with_parent) {
    execvp(argv[0], argv.data());
    std::fprintf(stderr, "foresight-linkemu: exec %s: %s\n", argv[0], std::strerror(errno));
    return 127;
  }
  return supervise(argv, parent);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  try {
    if (!args.empty() && (args[0] == "-h" || args[0] == "--help")) {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (!args.empty() && args[0] == "exec") return exec_in({args.begin() + 1, args.end()});
    if (!args.empty() && args[0] == "dds-config") {
      if (args.size() != 2) throw UsageError("dds-config wants one namespace name");
      const auto addr = le::interface_addresses(args[1], kInterface);
      std::printf("%s\n", le::cyclone_config_xml(kInterface, addr.peer).c_str());
      return 0;
    }
    if (!args.empty() && args[0] == "cleanup") {
      std::string prefix = le::kDefaultPrefix;
      if (args.size() == 3 && args[1] == "--prefix") prefix = args[2];
      else if (args.size() != 1) throw UsageError("cleanup takes only [--prefix NAME]");
      print_line({{"event", "cleanup"}, {"removed_stale", le::remove_stale_netns(prefix)}});
      return 0;
    }
    if (!args.empty() && args[0] == "check") {
      if (args.size() != 1) throw UsageError("check takes no arguments");
      le::check_permitted();
      std::printf("foresight-linkemu: namespaces and TUN devices are permitted\n");
      return 0;
    }
    return run(parse_run(args));
  } catch (const UsageError& e) {
    std::fprintf(stderr, "foresight-linkemu: %s\n%s", e.what(), kUsage);
    return 2;
  } catch (const le::NotPermitted& e) {
    std::fprintf(stderr, "foresight-linkemu: not permitted here: %s\n", e.what());
    return le::kExitNotPermitted;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "foresight-linkemu: %s\n", e.what());
    return 1;
  }
}
