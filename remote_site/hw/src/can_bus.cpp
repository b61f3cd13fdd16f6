#include "foresight/hw/can_bus.hpp"

#include <fcntl.h>
#include <linux/can/error.h>
#include <linux/can/netlink.h>
#include <linux/if_link.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>

namespace foresight::hw {

namespace {
std::string errno_text(int err) {
  const char* symbol = err == EAFNOSUPPORT ? "EAFNOSUPPORT"
                       : err == ENODEV     ? "ENODEV"
                       : err == EPERM      ? "EPERM"
                       : err == EACCES     ? "EACCES"
                                           : nullptr;
  std::string s = std::strerror(err);
  if (symbol) s += std::string(" (") + symbol + ")";
  return s;
}

void set_nonblocking(int fd, const std::string& what) {
  const int flags = ::fcntl(fd, F_GETFL, 0);
  if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) < 0) {
    const int err = errno;
    ::close(fd);
    throw CanError(what + ": cannot make the socket non-blocking: " + errno_text(err));
  }
}
}  // namespace

const char* to_string(RestartResult r) noexcept {
  switch (r) {
    case RestartResult::Requested: return "restart requested over netlink";
    case RestartResult::NotPermitted:
      return "netlink restart not permitted (needs CAP_NET_ADMIN): relies on the interface's restart-ms "
             "(ip link set <if> type can restart-ms 100)";
    case RestartResult::NotSupported: return "no netlink restart on this bus (mock bus or no CAN netlink)";
    case RestartResult::Failed: return "netlink restart failed";
  }
  return "?";
}

const char* to_string(CanIo io) noexcept {
  switch (io) {
    case CanIo::Ok: return "ok";
    case CanIo::WouldBlock: return "would block";
    case CanIo::ErrorFrame: return "error frame";
    case CanIo::Malformed: return "malformed datagram (not a struct can_frame)";
    case CanIo::BusOff: return "bus-off";
    case CanIo::NetDown: return "interface down (ENETDOWN)";
    case CanIo::Closed: return "bus closed";
    case CanIo::SysError: return "system error";
  }
  return "?";
}

CanBus::CanBus(std::string name, int fd) : name_(std::move(name)), fd_(fd) {
  // Kernel stamps for read(frame, stamp); without them (an old kernel) the stamp is 0.
  const int on = 1;
  (void)::setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on);
}

CanBus::~CanBus() {
  if (fd_ >= 0) ::close(fd_);
}

void CanBus::clear_health() noexcept {
  health_.bus_off = false;
  health_.error_passive = false;
  health_.error_warning = false;
}

void CanBus::set_filters(std::span<const can_filter> filters) {
  filters_.assign(filters.begin(), filters.end());
}

bool CanBus::passes_filters(canid_t id) const noexcept {
  if (filters_.empty()) return true;
  for (const can_filter& f : filters_) {
    const bool inverted = (f.can_id & CAN_INV_FILTER) != 0;
    const bool match = ((id & f.can_mask) == (f.can_id & ~CAN_INV_FILTER & f.can_mask));
    if (match != inverted) return true;
  }
  return false;
}

void CanBus::note_error_frame(const can_frame& frame) noexcept {
  ++health_.error_frames;
  const canid_t cls = frame.can_id & CAN_ERR_MASK;
  if (cls & CAN_ERR_BUSOFF) health_.bus_off = true;
  if (cls & CAN_ERR_RESTARTED) {
    health_.bus_off = false;
    health_.error_passive = false;
    health_.error_warning = false;
  }
  if ((cls & CAN_ERR_CRTL) && frame.can_dlc >= 2) {
    const std::uint8_t c = frame.data[1];
    if (c & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) health_.error_passive = true;
    if (c & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) health_.error_warning = true;
    if (c & (CAN_ERR_CRTL_RX_OVERFLOW | CAN_ERR_CRTL_TX_OVERFLOW)) ++health_.rx_overflows;
#ifdef CAN_ERR_CRTL_ACTIVE
    if (c & CAN_ERR_CRTL_ACTIVE) {
      health_.error_passive = false;
      health_.error_warning = false;
    }
#endif
  }
}

CanIo CanBus::read(can_frame& frame) noexcept { return receive(frame, nullptr); }

CanIo CanBus::read(can_frame& frame, std::int64_t& stamp_ns) noexcept { return receive(frame, &stamp_ns); }

CanIo CanBus::receive(can_frame& frame, std::int64_t* stamp_ns) noexcept {
  if (stamp_ns != nullptr) *stamp_ns = 0;
  // Bounded: a burst of filtered frames cannot keep us here forever.
  for (int attempt = 0; attempt < 64; ++attempt) {
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec))];
    iovec iov{&frame, sizeof frame};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    if (stamp_ns != nullptr) {  // the master's cycle reads without: no control data, no clock reads
      msg.msg_control = control;
      msg.msg_controllen = sizeof control;
    }
    const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT | MSG_TRUNC);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) return CanIo::WouldBlock;
      if (errno == EINTR) continue;
      const CanIo io = detail::io_from_errno(errno, health_);
      if (io == CanIo::SysError) last_errno_ = errno;
      return io == CanIo::BusOff ? CanIo::WouldBlock : io;  // nothing to read: not a read error
    }
    if (n == 0) return CanIo::Closed;
    if (static_cast<std::size_t>(n) != sizeof frame || frame.can_dlc > CAN_MAX_DLEN) {
      ++health_.malformed;
      return CanIo::Malformed;
    }
    if (frame.can_id & CAN_ERR_FLAG) {
      note_error_frame(frame);
      return CanIo::ErrorFrame;
    }
    const canid_t id = frame.can_id & ((frame.can_id & CAN_EFF_FLAG) ? CAN_EFF_MASK : CAN_SFF_MASK);
    if (!passes_filters(id)) {
      ++health_.filtered;
      continue;
    }
    for (cmsghdr* c = stamp_ns ? CMSG_FIRSTHDR(&msg) : nullptr; c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
      if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SO_TIMESTAMPNS) continue;
      timespec sent{}, real{}, mono{};
      std::memcpy(&sent, CMSG_DATA(c), sizeof sent);
      ::clock_gettime(CLOCK_REALTIME, &real);
      ::clock_gettime(CLOCK_MONOTONIC, &mono);
      const std::int64_t age_ns = (real.tv_sec - sent.tv_sec) * 1000000000LL + (real.tv_nsec - sent.tv_nsec);
      *stamp_ns = mono.tv_sec * 1000000000LL + mono.tv_nsec - std::max<std::int64_t>(0, age_ns);
    }
    return CanIo::Ok;
  }
  return CanIo::WouldBlock;
}

CanIo CanBus::write(const can_frame& frame) noexcept {
  if (frame.can_dlc > CAN_MAX_DLEN) return CanIo::Malformed;
  for (int attempt = 0; attempt < 4; ++attempt) {
    const ssize_t n = ::send(fd_, &frame, sizeof frame, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(sizeof frame)) return CanIo::Ok;
    if (n >= 0) return CanIo::SysError;
    if (errno == EINTR) continue;
    const CanIo io = detail::io_from_errno(errno, health_);
    if (io == CanIo::SysError) last_errno_ = errno;
    return io;
  }
  return health_.bus_off ? CanIo::BusOff : CanIo::WouldBlock;
}

namespace detail {
CanIo io_from_errno(int err, const BusHealth& health) noexcept {
  if (err == EAGAIN || err == EWOULDBLOCK || err == ENOBUFS) return health.bus_off ? CanIo::BusOff : CanIo::WouldBlock;
  if (err == ENETDOWN) return CanIo::NetDown;  // interface not up; bus-off comes as an error frame
  if (err == EPIPE || err == ECONNRESET || err == ENXIO) return CanIo::Closed;
  return CanIo::SysError;
}

std::vector<can_filter> kernel_filters(std::span<const can_filter> filters) {
  if (filters.empty()) return {can_filter{0, 0}};  // mask 0: every data frame passes
  return {filters.begin(), filters.end()};
}
}  // namespace detail

// ---- SocketCAN --------------------------------------------------------------

namespace {
int open_can_socket(const std::string& interface) {
  const std::string what = "SocketCAN interface '" + interface + "'";
  if (interface.empty() || interface.size() >= IFNAMSIZ)
    throw CanError(what + ": interface name must be 1.." + std::to_string(IFNAMSIZ - 1) + " characters");
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) {
    const int err = errno;
    std::string msg = what + ": socket(PF_CAN, SOCK_RAW, CAN_RAW) failed: " + errno_text(err);
    if (err == EAFNOSUPPORT)
      msg += ": this kernel has no CAN support (modules can, can-raw); use a mock bus "
             "(interface: mock) and the simulator instead";
    throw CanError(msg);
  }
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, interface.c_str(), interface.size() + 1);
  if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
    const int err = errno;
    ::close(fd);
    throw CanError(what + ": no such interface (" + errno_text(err) +
                   "); bring it up with `ip link set " + interface + " up type can bitrate <bps>`");
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int err = errno;
    ::close(fd);
    throw CanError(what + ": bind failed: " + errno_text(err));
  }
  can_err_mask_t err_mask = CAN_ERR_MASK;  // every error class, decoded in CanBus::read
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) < 0) {
    const int err = errno;
    ::close(fd);
    throw CanError(what + ": cannot enable error frames: " + errno_text(err));
  }
  // Our own frames come back in bus order: the master uses its own SYNC as a
  // marker to tell a TPDO answering this SYNC from a late one (DriveSystem).
  const int own = 1;
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &own, sizeof own) < 0) {
    const int err = errno;
    ::close(fd);
    throw CanError(what + ": cannot enable CAN_RAW_RECV_OWN_MSGS: " + errno_text(err));
  }
  set_nonblocking(fd, what);
  return fd;
}
}  // namespace

SocketCanBus::SocketCanBus(const std::string& interface) : CanBus(interface, open_can_socket(interface)) {
  ifindex_ = static_cast<int>(::if_nametoindex(interface.c_str()));
  // For request_restart(): failing here only means no netlink restart later.
  netlink_fd_ = ::socket(AF_NETLINK, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, NETLINK_ROUTE);
}

SocketCanBus::~SocketCanBus() {
  if (netlink_fd_ >= 0) ::close(netlink_fd_);
}

RestartResult CanBus::request_restart() noexcept {
  ++restart_requests_;
  return RestartResult::NotSupported;
}

RestartResult MockCanBus::request_restart() noexcept {
  ++restart_requests_;
  return restart_result_;
}

RestartResult SocketCanBus::request_restart() noexcept {
  ++restart_requests_;
  if (netlink_fd_ < 0 || ifindex_ <= 0) return RestartResult::NotSupported;
  // RTM_NEWLINK { ifinfomsg, IFLA_LINKINFO { IFLA_INFO_KIND "can", IFLA_INFO_DATA { IFLA_CAN_RESTART u32 1 } } }
  alignas(NLMSG_ALIGNTO) std::uint8_t buf[256] = {};
  auto* nh = reinterpret_cast<nlmsghdr*>(buf);
  nh->nlmsg_type = RTM_NEWLINK;
  nh->nlmsg_flags = NLM_F_REQUEST | NLM_F_ACK;
  nh->nlmsg_seq = ++netlink_seq_;
  nh->nlmsg_len = NLMSG_LENGTH(sizeof(ifinfomsg));
  auto* ifi = reinterpret_cast<ifinfomsg*>(NLMSG_DATA(nh));
  ifi->ifi_family = AF_UNSPEC;
  ifi->ifi_index = ifindex_;
  auto put = [&](unsigned short type, const void* data, std::size_t len) -> rtattr* {
    auto* a = reinterpret_cast<rtattr*>(buf + NLMSG_ALIGN(nh->nlmsg_len));
    a->rta_type = type;
    a->rta_len = static_cast<unsigned short>(RTA_LENGTH(len));
    if (len) std::memcpy(RTA_DATA(a), data, len);
    nh->nlmsg_len = NLMSG_ALIGN(nh->nlmsg_len) + RTA_ALIGN(a->rta_len);
    return a;
  };
  rtattr* linkinfo = put(IFLA_LINKINFO, nullptr, 0);
  put(IFLA_INFO_KIND, "can", 4);
  rtattr* data = put(IFLA_INFO_DATA, nullptr, 0);
  const std::uint32_t one = 1;
  put(IFLA_CAN_RESTART, &one, sizeof one);
  data->rta_len = static_cast<unsigned short>(buf + nh->nlmsg_len - reinterpret_cast<std::uint8_t*>(data));
  linkinfo->rta_len = static_cast<unsigned short>(buf + nh->nlmsg_len - reinterpret_cast<std::uint8_t*>(linkinfo));
  sockaddr_nl kernel{};
  kernel.nl_family = AF_NETLINK;
  if (::sendto(netlink_fd_, buf, nh->nlmsg_len, MSG_DONTWAIT, reinterpret_cast<const sockaddr*>(&kernel),
               sizeof kernel) < 0) {
    set_errno(errno);
    return errno == EPERM || errno == EACCES ? RestartResult::NotPermitted : RestartResult::Failed;
  }
  // rtnetlink handles the request inside sendto(): the ack is already queued.
  alignas(NLMSG_ALIGNTO) std::uint8_t ack[512];
  const ssize_t n = ::recv(netlink_fd_, ack, sizeof ack, MSG_DONTWAIT);
  if (n < static_cast<ssize_t>(NLMSG_LENGTH(sizeof(nlmsgerr)))) return RestartResult::Requested;  // no ack yet: sent
  const auto* ah = reinterpret_cast<const nlmsghdr*>(ack);
  if (ah->nlmsg_type != NLMSG_ERROR) return RestartResult::Requested;
  const int err = -reinterpret_cast<const nlmsgerr*>(NLMSG_DATA(ah))->error;
  if (err == 0) return RestartResult::Requested;
  set_errno(err);
  return err == EPERM || err == EACCES ? RestartResult::NotPermitted
         : err == EOPNOTSUPP          ? RestartResult::NotSupported
                                      : RestartResult::Failed;
}

void SocketCanBus::set_filters(std::span<const can_filter> filters) {
  const std::vector<can_filter> k = detail::kernel_filters(filters);
  if (::setsockopt(fd(), SOL_CAN_RAW, CAN_RAW_FILTER, k.data(),
                   static_cast<socklen_t>(k.size() * sizeof(can_filter))) < 0) {
    const int err = errno;
    throw CanError("SocketCAN interface '" + name() + "': CAN_RAW_FILTER failed: " + errno_text(err));
  }
  CanBus::set_filters(filters);  // also checked in user space (harmless, same result)
}

// ---- mock -------------------------------------------------------------------

std::pair<std::unique_ptr<MockCanBus>, std::unique_ptr<MockCanBus>> MockCanBus::create_pair(
    const std::string& name) {
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) < 0) {
    const int err = errno;
    throw CanError("mock bus '" + name + "': socketpair(AF_UNIX, SOCK_SEQPACKET) failed: " + errno_text(err));
  }
  // Room for a few hundred frames each way, like a controller's queue.
  const int buf = 256 * 1024;
  for (int fd : sv) {
    ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &buf, sizeof buf);
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buf, sizeof buf);
  }
  set_nonblocking(sv[0], "mock bus '" + name + "'");
  set_nonblocking(sv[1], "mock bus '" + name + "'");
  std::unique_ptr<MockCanBus> a(new MockCanBus("mock:" + name, sv[0]));
  std::unique_ptr<MockCanBus> b(new MockCanBus("mock:" + name + "(far end)", sv[1]));
  return {std::move(a), std::move(b)};
}

}  // namespace foresight::hw
