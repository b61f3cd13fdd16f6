#pragma once
// Named network namespaces and TUN devices for the link emulator. All of it
// is set-up code (system calls, may throw); nothing here is real-time.
//
// A named namespace is what `ip netns add NAME` makes: a bind mount of a
// namespace's /proc/.../ns/net on /run/netns/NAME, so `ip netns exec NAME`,
// `ip netns list` and `foresight-linkemu exec NAME` all see it. The emulator
// names its namespaces PREFIX-PID-SIDE (e.g. fslemu-4242-ground), so a later
// start can tell namespaces whose owner died (SIGKILL) and remove them.
//
// Only the calling thread changes namespace (setns on the thread), so the
// process's other threads and the host's network are untouched; TUN devices
// and addresses are made only inside namespaces this module created.

#include <sys/types.h>

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace foresight::linkemu {

/// The machine does not let us make namespaces or TUN devices (not root, no
/// /dev/net/tun, ...). what() says which step failed and why. The tool exits
/// with kExitNotPermitted so tests can skip with the reason.
class NotPermitted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr int kExitNotPermitted = 77;
inline constexpr const char* kNetnsDir = "/run/netns";
inline constexpr const char* kDefaultPrefix = "fslemu";

/// "PREFIX-PID-SIDE".
std::string netns_name(const std::string& prefix, pid_t pid, const std::string& side);
/// The owner pid encoded in a name made by netns_name() with `prefix`, or
/// nothing when the name is not one of ours.
std::optional<pid_t> netns_owner(const std::string& name, const std::string& prefix);
/// Whether /run/netns/NAME exists.
bool netns_exists(const std::string& name);
/// Names in /run/netns starting with PREFIX- (sorted).
std::vector<std::string> list_netns(const std::string& prefix);
/// Whether `pid` is a live (not zombie) foresight-linkemu process.
bool owner_alive(pid_t pid);
/// Removes every PREFIX-PID-* namespace whose owner is not alive (or is
/// this very process: a leftover from a dead owner with a reused pid; call it
/// before creating this process's own namespaces); returns
/// the names removed. Errors on single entries are ignored (another start
/// may be removing the same one).
std::vector<std::string> remove_stale_netns(const std::string& prefix);
/// Unmounts and unlinks /run/netns/NAME; false if it was not there.
bool remove_netns(const std::string& name) noexcept;

/// Owns a named network namespace; removes it on destruction. Move-only.
class NamedNetns {
 public:
  /// Creates /run/netns/NAME (fails if it exists). Throws NotPermitted when
  /// the kernel refuses (EPERM), std::runtime_error otherwise.
  explicit NamedNetns(std::string name);
  ~NamedNetns();
  NamedNetns(NamedNetns&& other) noexcept;
  NamedNetns& operator=(NamedNetns&&) = delete;
  NamedNetns(const NamedNetns&) = delete;
  NamedNetns& operator=(const NamedNetns&) = delete;

  const std::string& name() const noexcept { return name_; }
  std::string path() const;
  void remove() noexcept;

 private:
  std::string name_;
};

/// Moves the calling thread into the named namespace; the destructor moves
/// it back. For a thread that should stay (exec), call release().
class EnterNetns {
 public:
  explicit EnterNetns(const std::string& name);
  ~EnterNetns();
  EnterNetns(const EnterNetns&) = delete;
  EnterNetns& operator=(const EnterNetns&) = delete;
  void release() noexcept;

 private:
  int original_fd_ = -1;
};

struct TunConfig {
  std::string ifname = "fsl0";
  std::string address;  ///< this side, e.g. 10.200.0.1
  std::string peer;     ///< the far side, e.g. 10.200.0.2
  int prefix_len = 30;
  int mtu = 1500;
  int txqueuelen = 4096;  ///< packets the kernel holds for the emulator to read
};

/// Creates a TUN device (IFF_TUN | IFF_NO_PI) inside namespace `netns`,
/// addresses it point-to-point, brings it and `lo` up, and returns its fd
/// (non-blocking, close-on-exec). The device is persistent: it stays after
/// the fd is closed (with nobody forwarding) and is destroyed with its
/// namespace, once the namespace's name is removed and no process is left in
/// it. So a process still inside when the emulator stops keeps its address
/// (Cyclone needs it to shut down) instead of seeing the interface vanish.
/// Throws NotPermitted when /dev/net/tun cannot be opened or TUNSETIFF is
/// refused, std::runtime_error on other failures.
int create_tun(const std::string& netns, const TunConfig& config);

struct InterfaceAddresses {
  std::string address;
  std::string peer;
};
/// Reads `ifname`'s address and point-to-point peer inside `netns`.
InterfaceAddresses interface_addresses(const std::string& netns, const std::string& ifname);

/// Checks, without changing anything, that this process may create
/// namespaces and TUN devices; throws NotPermitted with the reason if not.
void check_permitted();

}  // namespace foresight::linkemu
