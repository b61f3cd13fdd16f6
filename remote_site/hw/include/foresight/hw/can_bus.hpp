#pragma once
// One fd-based CAN bus interface. Two implementations carry the same 16-byte
// Linux `struct can_frame`, one frame per read/write:
//   SocketCanBus  a real SocketCAN interface (can0 ...), raw socket;
//   MockCanBus    one end of an AF_UNIX SOCK_SEQPACKET socketpair; the other
//                 end (also a MockCanBus) may live in another thread or, after
//                 fork(), in another process. Tests and the simulator use it.
// Error frames (CAN_ERR_FLAG) are decoded into BusHealth on both, so a
// simulator can inject controller errors (error passive, bus-off) exactly as
// a SocketCAN controller reports them.
//
// Real-time safety: read(), write(), health(), fd() are noexcept, never
// allocate and never block (the fd is O_NONBLOCK). Construction and
// set_filters() are set-up calls: they may allocate and throw CanError.

#include <linux/can.h>

#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "foresight/common/error.hpp"

namespace foresight::hw {

/// A bus could not be opened or configured (set-up only).
class CanError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

/// Result of one non-blocking read or write.
enum class CanIo : std::uint8_t {
  Ok,          ///< one data frame read / written
  WouldBlock,  ///< nothing to read / transmit queue full (frame not sent)
  ErrorFrame,  ///< read: a controller error frame; health() updated, frame returned
  Malformed,   ///< read: a datagram that is not one struct can_frame (size wrong, dlc > 8)
  BusOff,      ///< write refused: the transmit queue is full while the controller is
               ///< bus-off (learned from a CAN_ERR_BUSOFF error frame, never from errno)
  NetDown,     ///< ENETDOWN: the interface is not up (`ip link set can0 up`); not bus-off
  Closed,      ///< the peer closed the bus (mock) or the interface went away
  SysError,    ///< any other errno (see last_errno())
};
const char* to_string(CanIo io) noexcept;

/// Result of CanBus::request_restart().
enum class RestartResult : std::uint8_t {
  Requested,     ///< the kernel accepted the restart (CAN_ERR_RESTARTED follows)
  NotPermitted,  ///< EPERM: the process lacks CAP_NET_ADMIN (the interface's restart-ms must do it)
  NotSupported,  ///< no netlink restart on this bus (mock bus, or no CAN netlink in the kernel)
  Failed,        ///< any other error (last_errno())
};
const char* to_string(RestartResult r) noexcept;

/// Controller state as learned from error frames (CAN_ERR_BUSOFF,
/// CAN_ERR_CRTL, CAN_ERR_RESTARTED). errno never sets bus_off: ENETDOWN means
/// the interface is down (CanIo::NetDown), which is a different fault.
struct BusHealth {
  bool bus_off = false;
  bool error_passive = false;
  bool error_warning = false;
  std::uint32_t error_frames = 0;   ///< error frames seen since open
  std::uint32_t rx_overflows = 0;   ///< controller/socket receive overflows reported
  std::uint32_t malformed = 0;      ///< datagrams dropped because they were not a can_frame
  std::uint32_t filtered = 0;       ///< data frames dropped by the receive filters
};

class CanBus {
 public:
  virtual ~CanBus();
  CanBus(const CanBus&) = delete;
  CanBus& operator=(const CanBus&) = delete;

  /// Name for messages ("can0", "mock:arm_a").
  const std::string& name() const noexcept { return name_; }
  /// The non-blocking fd, for poll()/epoll in the caller's loop.
  int fd() const noexcept { return fd_; }

  /// Read one frame. Data frames that do not pass the receive filters are
  /// skipped (counted in health().filtered). Real-time safe.
  CanIo read(can_frame& frame) noexcept;
  /// read() that also gives when the kernel queued the frame, as
  /// CLOCK_MONOTONIC ns (SO_TIMESTAMPNS, converted from CLOCK_REALTIME at the
  /// read; 0 when the kernel gave no stamp): on the mock bus the moment the
  /// other end wrote it, on SocketCAN its reception. A simulated node times
  /// the bus by it, not by when its thread got round to reading (a lagging
  /// thread would see two SYNCs at once). Real-time safe.
  CanIo read(can_frame& frame, std::int64_t& stamp_ns) noexcept;
  /// Write one frame. Real-time safe; never blocks (WouldBlock when full).
  CanIo write(const can_frame& frame) noexcept;
  /// errno of the last SysError.
  int last_errno() const noexcept { return last_errno_; }
  const BusHealth& health() const noexcept { return health_; }
  /// Forget bus-off/passive state (after a controller restart).
  void clear_health() noexcept;
  /// Ask the controller to leave bus-off now. SocketCanBus: one rtnetlink
  /// RTM_NEWLINK with IFLA_CAN_RESTART (as `ip link set can0 type can
  /// restart`), needs CAP_NET_ADMIN; sent on a non-blocking netlink socket
  /// opened at construction, the kernel's synchronous ack read without
  /// waiting. Real-time safe (no allocation, no blocking). The base (and the
  /// mock bus unless told otherwise) answers NotSupported.
  virtual RestartResult request_restart() noexcept;
  /// request_restart() calls so far.
  std::uint32_t restart_requests() const noexcept { return restart_requests_; }

  /// Receive filters, SocketCAN semantics: a data frame passes when
  /// (id & mask) == (filter.can_id & mask) for any filter (CAN_INV_FILTER in
  /// can_id inverts that filter). An empty list passes everything. Error
  /// frames always pass. Set-up only: may throw CanError.
  virtual void set_filters(std::span<const can_filter> filters);

 protected:
  CanBus(std::string name, int fd);
  bool passes_filters(canid_t id) const noexcept;
  // read() and the stamped read(): the stamp (and its clock reads) only when asked.
  CanIo receive(can_frame& frame, std::int64_t* stamp_ns) noexcept;
  std::uint32_t restart_requests_ = 0;
  void set_errno(int e) noexcept { last_errno_ = e; }
  void note_error_frame(const can_frame& frame) noexcept;

 private:
  std::string name_;
  int fd_ = -1;
  int last_errno_ = 0;
  BusHealth health_;
  std::vector<can_filter> filters_;
};

namespace detail {
/// What a failed send()/recv() with `err` means (EAGAIN/ENOBUFS: WouldBlock,
/// or BusOff when health says the controller is bus-off; ENETDOWN: NetDown;
/// EPIPE/ECONNRESET/ENXIO: Closed; else SysError). Real-time safe.
CanIo io_from_errno(int err, const BusHealth& health) noexcept;
/// The list given to CAN_RAW_FILTER: the kernel delivers no data frame for an
/// empty list, so "everything" (empty) becomes one filter {0, 0}. Set-up only.
std::vector<can_filter> kernel_filters(std::span<const can_filter> filters);
}  // namespace detail

/// A real SocketCAN interface. The bit rate is set outside the program
/// (`ip link set can0 type can bitrate 1000000`); the constructor checks that
/// the interface exists. Throws CanError with the reason; on a kernel without
/// CAN the message says "EAFNOSUPPORT" and that the kernel has no CAN support.
class SocketCanBus final : public CanBus {
 public:
  explicit SocketCanBus(const std::string& interface);
  ~SocketCanBus() override;
  void set_filters(std::span<const can_filter> filters) override;
  RestartResult request_restart() noexcept override;

 private:
  int ifindex_ = 0;
  int netlink_fd_ = -1;  // -1: no rtnetlink socket (request_restart: NotSupported)
  std::uint32_t netlink_seq_ = 0;
};

/// One end of an in-memory bus (AF_UNIX SOCK_SEQPACKET socketpair).
class MockCanBus final : public CanBus {
 public:
  /// Both ends of a new bus: {master end, far end}. Frames written on one end
  /// are read on the other. Throws CanError if the socketpair fails.
  static std::pair<std::unique_ptr<MockCanBus>, std::unique_ptr<MockCanBus>> create_pair(
      const std::string& name);
  /// What request_restart() answers (tests: a cabinet with or without
  /// CAP_NET_ADMIN); NotSupported by default. The restart itself is the far
  /// end's (the simulator's recover_bus: CAN_ERR_RESTARTED).
  void set_restart_result(RestartResult r) noexcept { restart_result_ = r; }
  RestartResult request_restart() noexcept override;

 private:
  MockCanBus(std::string name, int fd) : CanBus(std::move(name), fd) {}
  RestartResult restart_result_ = RestartResult::NotSupported;
};

// ---- frame helpers (real-time safe) ---------------------------------------

inline can_frame make_frame(canid_t id, std::initializer_list<std::uint8_t> data) noexcept {
  can_frame f{};
  f.can_id = id;
  std::uint8_t n = 0;
  for (std::uint8_t b : data) {
    if (n == CAN_MAX_DLEN) break;
    f.data[n++] = b;
  }
  f.can_dlc = n;
  return f;
}
inline std::uint16_t get_u16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
inline void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

}  // namespace foresight::hw
