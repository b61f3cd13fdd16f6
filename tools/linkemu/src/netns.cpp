#include "foresight/linkemu/netns.hpp"

#include <arpa/inet.h>
#include <dirent.h>
#include <fcntl.h>
#include <linux/if_tun.h>
#include <net/if.h>
#include <netinet/in.h>
#include <sched.h>
#include <signal.h>
#include <sys/ioctl.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <utility>

namespace foresight::linkemu {

namespace {

std::string errno_text(int err) { return std::strerror(err); }

[[noreturn]] void fail(const std::string& what, int err) {
  if (err == EPERM || err == EACCES) throw NotPermitted(what + ": " + errno_text(err));
  throw std::runtime_error(what + ": " + errno_text(err));
}

std::string netns_path(const std::string& name) { return std::string(kNetnsDir) + "/" + name; }

/// Closes an fd on scope exit.
struct Fd {
  int fd = -1;
  explicit Fd(int f) : fd(f) {}
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int release() { return std::exchange(fd, -1); }
};

void set_ifreq_name(ifreq& ifr, const std::string& ifname) {
  if (ifname.empty() || ifname.size() >= IFNAMSIZ) {
    throw std::invalid_argument("interface name '" + ifname + "' must be 1.." + std::to_string(IFNAMSIZ - 1) +
                                " characters");
  }
  std::memset(&ifr, 0, sizeof ifr);
  std::memcpy(ifr.ifr_name, ifname.c_str(), ifname.size());
}

void set_ifreq_addr(ifreq& ifr, const std::string& address, const std::string& what) {
  sockaddr_in sin{};
  sin.sin_family = AF_INET;
  if (inet_pton(AF_INET, address.c_str(), &sin.sin_addr) != 1) {
    throw std::invalid_argument(what + " '" + address + "' is not an IPv4 address");
  }
  std::memcpy(&ifr.ifr_addr, &sin, sizeof sin);
}

std::string ifreq_addr_text(const ifreq& ifr) {
  sockaddr_in sin{};
  std::memcpy(&sin, &ifr.ifr_addr, sizeof sin);
  char text[INET_ADDRSTRLEN] = {};
  inet_ntop(AF_INET, &sin.sin_addr, text, sizeof text);
  return text;
}

void interface_up(int sock, const std::string& ifname) {
  ifreq ifr;
  set_ifreq_name(ifr, ifname);
  if (ioctl(sock, SIOCGIFFLAGS, &ifr) != 0) fail("get flags of " + ifname, errno);
  ifr.ifr_flags = static_cast<short>(ifr.ifr_flags | IFF_UP | IFF_RUNNING);
  if (ioctl(sock, SIOCSIFFLAGS, &ifr) != 0) fail("bring up " + ifname, errno);
}

}  // namespace

std::string netns_name(const std::string& prefix, pid_t pid, const std::string& side) {
  return prefix + "-" + std::to_string(pid) + "-" + side;
}

std::optional<pid_t> netns_owner(const std::string& name, const std::string& prefix) {
  const std::string head = prefix + "-";
  if (name.size() <= head.size() || name.compare(0, head.size(), head) != 0) return std::nullopt;
  const std::string rest = name.substr(head.size());
  const auto dash = rest.find('-');
  if (dash == std::string::npos || dash == 0 || dash + 1 >= rest.size()) return std::nullopt;
  const std::string digits = rest.substr(0, dash);
  if (!std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) return std::nullopt;
  if (digits.size() > 9) return std::nullopt;
  return static_cast<pid_t>(std::stol(digits));
}

bool netns_exists(const std::string& name) {
  struct stat st{};
  return ::stat(netns_path(name).c_str(), &st) == 0;
}

std::vector<std::string> list_netns(const std::string& prefix) {
  std::vector<std::string> names;
  DIR* dir = ::opendir(kNetnsDir);
  if (dir == nullptr) return names;
  const std::string head = prefix + "-";
  for (dirent* e = ::readdir(dir); e != nullptr; e = ::readdir(dir)) {
    const std::string name = e->d_name;
    if (name.compare(0, head.size(), head) == 0) names.push_back(name);
  }
  ::closedir(dir);
  std::sort(names.begin(), names.end());
  return names;
}

bool owner_alive(pid_t pid) {
  if (pid <= 0) return false;
  if (::kill(pid, 0) != 0 && errno == ESRCH) return false;
  // A zombie (killed, not yet reaped) holds nothing any more.
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  const auto close_paren = line.rfind(')');
  if (close_paren == std::string::npos || close_paren + 2 >= line.size()) return false;
  const char state = line[close_paren + 2];
  if (state == 'Z' || state == 'X') return false;
  // The pid may have been reused by an unrelated process.
  const auto open_paren = line.find('(');
  const std::string comm = line.substr(open_paren + 1, close_paren - open_paren - 1);
  return comm.rfind("foresight-link", 0) == 0;
}

bool remove_netns(const std::string& name) noexcept {
  const std::string path = netns_path(name);
  (void)::umount2(path.c_str(), MNT_DETACH);
  return ::unlink(path.c_str()) == 0;
}

std::vector<std::string> remove_stale_netns(const std::string& prefix) {
  std::vector<std::string> removed;
  for (const auto& name : list_netns(prefix)) {
    const auto owner = netns_owner(name, prefix);
    if (!owner) continue;
    // Our own pid: a dead emulator's leftover whose pid we reuse (we have not
    // made ours yet). Any other live foresight-linkemu owns its names.
    if (*owner != ::getpid() && owner_alive(*owner)) continue;
    if (remove_netns(name)) removed.push_back(name);
  }
  return removed;
}

NamedNetns::NamedNetns(std::string name) : name_(std::move(name)) {
  if (name_.empty() || name_.find('/') != std::string::npos || name_ == "." || name_ == "..") {
    throw std::invalid_argument("bad namespace name '" + name_ + "'");
  }
  if (::mkdir(kNetnsDir, 0755) != 0 && errno != EEXIST) fail(std::string("create ") + kNetnsDir, errno);
  const std::string path = netns_path(name_);
  {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0);
    if (fd < 0) {
      const int err = errno;
      name_.clear();  // not ours: do not remove it
      if (err == EEXIST) throw std::runtime_error("namespace " + path + " already exists");
      fail("create " + path, err);
    }
    ::close(fd);
  }
  // unshare on this thread only, bind the new namespace to its name, return.
  Fd original(::open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC));
  if (original.fd < 0) {
    const int err = errno;
    remove();
    fail("open /proc/thread-self/ns/net", err);
  }
  if (::unshare(CLONE_NEWNET) != 0) {
    const int err = errno;
    remove();
    fail("unshare(CLONE_NEWNET) (needs CAP_SYS_ADMIN)", err);
  }
  const int mount_rc = ::mount("/proc/thread-self/ns/net", path.c_str(), "none", MS_BIND, nullptr);
  const int mount_err = errno;
  if (::setns(original.fd, CLONE_NEWNET) != 0) {
    // The thread is stuck in the new namespace: nothing sane can follow.
    std::fprintf(stderr, "foresight-linkemu: cannot return to the original namespace: %s\n", std::strerror(errno));
    std::abort();
  }
  if (mount_rc != 0) {
    remove();
    fail("bind-mount the namespace on " + path, mount_err);
  }
}

NamedNetns::~NamedNetns() { remove(); }

NamedNetns::NamedNetns(NamedNetns&& other) noexcept : name_(std::exchange(other.name_, std::string())) {}

std::string NamedNetns::path() const { return netns_path(name_); }

void NamedNetns::remove() noexcept {
  if (name_.empty()) return;
  (void)remove_netns(name_);
  name_.clear();
}

EnterNetns::EnterNetns(const std::string& name) {
  original_fd_ = ::open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC);
  if (original_fd_ < 0) fail("open /proc/thread-self/ns/net", errno);
  const std::string path = netns_path(name);
  Fd target(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (target.fd < 0) {
    const int err = errno;
    ::close(original_fd_);
    if (err == ENOENT) throw std::runtime_error("no network namespace " + name + " (" + path + ")");
    fail("open " + path, err);
  }
  if (::setns(target.fd, CLONE_NEWNET) != 0) {
    const int err = errno;
    ::close(original_fd_);
    fail("enter network namespace " + name, err);
  }
}

EnterNetns::~EnterNetns() {
  if (original_fd_ < 0) return;
  if (::setns(original_fd_, CLONE_NEWNET) != 0) {
    std::fprintf(stderr, "foresight-linkemu: cannot return to the original namespace: %s\n", std::strerror(errno));
    std::abort();
  }
  ::close(original_fd_);
}

void EnterNetns::release() noexcept {
  if (original_fd_ >= 0) ::close(original_fd_);
  original_fd_ = -1;
}

int create_tun(const std::string& netns, const TunConfig& config) {
  EnterNetns inside(netns);
  Fd tun(::open("/dev/net/tun", O_RDWR | O_NONBLOCK | O_CLOEXEC));
  if (tun.fd < 0) {
    const int err = errno;
    throw NotPermitted("cannot open /dev/net/tun: " + errno_text(err));
  }
  ifreq ifr;
  set_ifreq_name(ifr, config.ifname);
  ifr.ifr_flags = IFF_TUN | IFF_NO_PI;
  if (ioctl(tun.fd, TUNSETIFF, &ifr) != 0) fail("TUNSETIFF " + config.ifname + " (needs CAP_NET_ADMIN)", errno);
  // Persistent: the device (and its address) outlives our fd and goes with
  // its namespace, when the last process in it exits. A DDS process still in
  // the namespace when the emulator stops can then shut down: Cyclone wakes
  // its receive threads with a packet to its own address and, were that
  // address gone, dds_delete() would wait for them forever (seen).
  if (ioctl(tun.fd, TUNSETPERSIST, 1) != 0) fail("TUNSETPERSIST " + config.ifname, errno);

  // No IPv6 on the link: no router solicitations or DAD in the statistics.
  // /proc/sys/net follows the opening thread's namespace. Best effort.
  if (FILE* f = std::fopen(("/proc/sys/net/ipv6/conf/" + config.ifname + "/disable_ipv6").c_str(), "w")) {
    std::fputs("1", f);
    std::fclose(f);
  }

  Fd sock(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (sock.fd < 0) fail("socket", errno);
  set_ifreq_name(ifr, config.ifname);
  ifr.ifr_mtu = config.mtu;
  if (ioctl(sock.fd, SIOCSIFMTU, &ifr) != 0) fail("set MTU " + std::to_string(config.mtu) + " on " + config.ifname, errno);
  // A longer transmit queue than TUN's 500 packets: a burst from DDS (a
  // trajectory upload) waits for the emulator instead of being dropped
  // before it, where the emulator's statistics cannot see it.
  set_ifreq_name(ifr, config.ifname);
  ifr.ifr_qlen = config.txqueuelen;
  if (ioctl(sock.fd, SIOCSIFTXQLEN, &ifr) != 0) fail("set txqueuelen on " + config.ifname, errno);
  set_ifreq_name(ifr, config.ifname);
  set_ifreq_addr(ifr, config.address, "address");
  if (ioctl(sock.fd, SIOCSIFADDR, &ifr) != 0) fail("set address " + config.address + " on " + config.ifname, errno);
  set_ifreq_name(ifr, config.ifname);
  set_ifreq_addr(ifr, config.peer, "peer");
  if (ioctl(sock.fd, SIOCSIFDSTADDR, &ifr) != 0) fail("set peer " + config.peer + " on " + config.ifname, errno);
  if (config.prefix_len < 1 || config.prefix_len > 32) throw std::invalid_argument("prefix length must be in 1..32");
  const std::uint32_t mask = config.prefix_len == 32 ? 0xffffffffu : ~((1u << (32 - config.prefix_len)) - 1u);
  char mask_text[INET_ADDRSTRLEN];
  in_addr mask_addr{htonl(mask)};
  inet_ntop(AF_INET, &mask_addr, mask_text, sizeof mask_text);
  set_ifreq_name(ifr, config.ifname);
  set_ifreq_addr(ifr, mask_text, "netmask");
  if (ioctl(sock.fd, SIOCSIFNETMASK, &ifr) != 0) fail("set netmask on " + config.ifname, errno);
  interface_up(sock.fd, config.ifname);
  interface_up(sock.fd, "lo");
  return tun.release();
}

InterfaceAddresses interface_addresses(const std::string& netns, const std::string& ifname) {
  EnterNetns inside(netns);
  Fd sock(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (sock.fd < 0) fail("socket", errno);
  InterfaceAddresses out;
  ifreq ifr;
  set_ifreq_name(ifr, ifname);
  if (ioctl(sock.fd, SIOCGIFADDR, &ifr) != 0) fail("no IPv4 address on " + ifname + " in " + netns, errno);
  out.address = ifreq_addr_text(ifr);
  set_ifreq_name(ifr, ifname);
  if (ioctl(sock.fd, SIOCGIFDSTADDR, &ifr) != 0) fail("no peer address on " + ifname + " in " + netns, errno);
  out.peer = ifreq_addr_text(ifr);
  return out;
}

void check_permitted() {
  // Effective capabilities: CAP_NET_ADMIN (12) for TUN, CAP_SYS_ADMIN (21)
  // for unshare and the bind mount.
  std::ifstream status("/proc/self/status");
  std::string line;
  unsigned long long cap_eff = 0;
  bool found = false;
  while (std::getline(status, line)) {
    if (line.rfind("CapEff:", 0) == 0) {
      cap_eff = std::stoull(line.substr(7), nullptr, 16);
      found = true;
      break;
    }
  }
  if (found) {
    if ((cap_eff & (1ull << 21)) == 0) {
      throw NotPermitted("cannot create network namespaces: no CAP_SYS_ADMIN (run as root)");
    }
    if ((cap_eff & (1ull << 12)) == 0) {
      throw NotPermitted("cannot create TUN devices: no CAP_NET_ADMIN (run as root)");
    }
  }
  const int fd = ::open("/dev/net/tun", O_RDWR | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    throw NotPermitted("cannot open /dev/net/tun: " + errno_text(err));
  }
  ::close(fd);
}

}  // namespace foresight::linkemu
