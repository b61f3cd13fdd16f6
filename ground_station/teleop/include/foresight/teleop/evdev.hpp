#pragma once
// A hand controller through Linux evdev (linux/input.h, no extra library):
// read() of `struct input_event` from /dev/input/eventN; EV_ABS axes
// normalised to [-1, 1] with the device's own absinfo (minimum, maximum, flat
// as the dead zone), EV_KEY buttons, SYN_REPORT closing one consistent sample,
// SYN_DROPPED resynchronised from the device's state (EVIOCGABS, EVIOCGKEY).
//
// Three layers, so each is tested on its own:
//   EvdevDecoder  events -> state (pure; no allocation after construction)
//   EvdevStream   bytes of input_event from any fd (a device, a pipe, a
//                 captured file) into a decoder, partial reads kept
//   EvdevDevice   opens /dev/input/eventN, reads its name and absinfo (set-up:
//                 may throw InputError), then polls like a stream
// Not used in the remote's real-time loop; poll()/apply() do not allocate.

#include <linux/input.h>

#include <array>
#include <bitset>
#include <cstddef>
#include <cstdint>
#include <string>

#include "foresight/teleop/teleop.hpp"

namespace foresight::teleop {

/// An absolute axis' range as the device reports it (struct input_absinfo).
struct AxisRange {
  int minimum = -32768;
  int maximum = 32767;
  int flat = 0;  ///< dead zone around the centre, in device units
};

/// The deflection of `value`: 0 at the centre of [minimum, maximum] and within
/// `flat` of it, +-1 at the ends, clamped outside. 0 for an empty range.
double normalise_axis(int value, const AxisRange& range) noexcept;

/// Which ABS code feeds each of the six deflections (x y z rx ry rz), with a
/// sign (a stick's "up" is often negative). code < 0: the deflection stays 0.
struct AxisBinding {
  int code = -1;
  double sign = 1.0;
};
using AxisMap = std::array<AxisBinding, 6>;
/// ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ (a 6-axis controller such as
/// a SpaceMouse).
AxisMap default_axis_map() noexcept;
/// "X,-Y,Z,RX,RY,RZ": six ABS names (ABS_ optional, any case; `-` flips the
/// sign, `none` leaves a deflection at 0) or numeric codes. InputError
/// "--axes: ..." naming the bad field.
AxisMap parse_axis_map(const std::string& text);
/// "ABS_X" for 0, ... ; the number as text for codes without a name here.
std::string abs_name(int code);

class EvdevDecoder {
 public:
  explicit EvdevDecoder(AxisMap map = default_axis_map()) noexcept : map_(map) {}

  void set_range(int abs_code, const AxisRange& range) noexcept;
  const AxisRange& range(int abs_code) const noexcept { return ranges_[clamp_abs(abs_code)]; }

  /// Applies one event. Values are staged until SYN_REPORT, which makes them
  /// current and returns true. After SYN_DROPPED events are ignored up to the
  /// next SYN_REPORT and needs_resync() turns true. Never allocates.
  bool apply(const input_event& event) noexcept;

  /// The six deflections of the current sample (via the axis map).
  Axes axes() const noexcept;
  /// An axis' raw current value (device units).
  int raw(int abs_code) const noexcept { return current_[clamp_abs(abs_code)]; }
  bool button(int key_code) const noexcept;
  /// Button presses (0 -> 1) counted since construction, any button.
  std::uint64_t presses() const noexcept { return presses_; }
  /// Complete samples (SYN_REPORTs) applied.
  std::uint64_t reports() const noexcept { return reports_; }
  /// Events lost by the kernel (SYN_DROPPED) since the last resync.
  bool needs_resync() const noexcept { return needs_resync_; }
  /// Sets an axis' and a button's state directly (a resync from the device).
  void resync_axis(int abs_code, int value) noexcept;
  void resync_button(int key_code, bool down) noexcept;
  void resynced() noexcept { needs_resync_ = false; }

 private:
  static std::size_t clamp_abs(int code) noexcept {
    return code >= 0 && code < ABS_CNT ? static_cast<std::size_t>(code) : 0;
  }
  AxisMap map_;
  std::array<AxisRange, ABS_CNT> ranges_{};
  std::array<int, ABS_CNT> staged_{}, current_{};
  std::bitset<KEY_CNT> keys_staged_, keys_;
  std::uint64_t presses_ = 0, reports_ = 0;
  bool dropping_ = false, needs_resync_ = false;
};

/// Reads whole `struct input_event`s from a file descriptor it does not own.
class EvdevStream {
 public:
  EvdevStream(int fd, EvdevDecoder& decoder) noexcept : fd_(fd), decoder_(decoder) {}
  /// Waits at most timeout_s for input (0: do not wait), then reads what is
  /// there (a pipe may split an event: the rest comes with the next read).
  /// Returns the SYN_REPORTs applied; -1 at end of file or when the writer
  /// closed; -2 on a read error (errno kept). Does not allocate.
  int poll(double timeout_s) noexcept;

 private:
  int fd_;
  EvdevDecoder& decoder_;
  std::array<unsigned char, 64 * sizeof(input_event)> buf_{};
  std::size_t have_ = 0;
};

class EvdevDevice {
 public:
  /// Opens an event device, reads its name and the absinfo of every mapped
  /// axis. InputError "<path>: cannot open ..." (with the reason, e.g.
  /// permission denied), "<path>: not an input event device", "<path>: has
  /// no axis ABS_RZ (the device's axes: ...)".
  EvdevDevice(const std::string& path, AxisMap map = default_axis_map());
  ~EvdevDevice();
  EvdevDevice(const EvdevDevice&) = delete;
  EvdevDevice& operator=(const EvdevDevice&) = delete;

  const std::string& name() const noexcept { return name_; }
  const EvdevDecoder& state() const noexcept { return decoder_; }
  /// As EvdevStream::poll, then a resync from the device after SYN_DROPPED.
  int poll(double timeout_s) noexcept;

 private:
  void resync() noexcept;
  std::string path_, name_;
  int fd_ = -1;
  AxisMap map_;
  EvdevDecoder decoder_;
  EvdevStream stream_;
};

}  // namespace foresight::teleop
