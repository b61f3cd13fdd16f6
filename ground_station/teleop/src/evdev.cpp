// A hand controller through Linux evdev (evdev.hpp).
#include "foresight/teleop/evdev.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/common/format.hpp"

namespace foresight::teleop {

namespace {

struct AbsName {
  int code;
  const char* name;
};
constexpr AbsName kAbsNames[] = {
    {ABS_X, "ABS_X"},         {ABS_Y, "ABS_Y"},         {ABS_Z, "ABS_Z"},         {ABS_RX, "ABS_RX"},
    {ABS_RY, "ABS_RY"},       {ABS_RZ, "ABS_RZ"},       {ABS_THROTTLE, "ABS_THROTTLE"},
    {ABS_RUDDER, "ABS_RUDDER"}, {ABS_WHEEL, "ABS_WHEEL"}, {ABS_GAS, "ABS_GAS"},   {ABS_BRAKE, "ABS_BRAKE"},
    {ABS_HAT0X, "ABS_HAT0X"}, {ABS_HAT0Y, "ABS_HAT0Y"}, {ABS_HAT1X, "ABS_HAT1X"}, {ABS_HAT1Y, "ABS_HAT1Y"},
};

}  // namespace

double normalise_axis(int value, const AxisRange& r) noexcept {
  if (r.maximum <= r.minimum) return 0.0;
  const double centre = 0.5 * (static_cast<double>(r.minimum) + r.maximum);
  const double half = 0.5 * (static_cast<double>(r.maximum) - r.minimum);
  const double d = value - centre;
  if (std::abs(d) <= r.flat) return 0.0;
  return std::clamp(d / half, -1.0, 1.0);
}

AxisMap default_axis_map() noexcept {
  return {AxisBinding{ABS_X, 1.0}, AxisBinding{ABS_Y, 1.0}, AxisBinding{ABS_Z, 1.0},
          AxisBinding{ABS_RX, 1.0}, AxisBinding{ABS_RY, 1.0}, AxisBinding{ABS_RZ, 1.0}};
}

std::string abs_name(int code) {
  for (const auto& n : kAbsNames)
    if (n.code == code) return n.name;
  return std::to_string(code);
}

AxisMap parse_axis_map(const std::string& text) {
  std::vector<std::string> fields;
  std::stringstream ss(text);
  for (std::string f; std::getline(ss, f, ',');) fields.push_back(f);
  if (fields.size() != 6)
    throw InputError("--axes: expected 6 axes (x,y,z,rx,ry,rz), got " + std::to_string(fields.size()));
  AxisMap map;
  for (std::size_t i = 0; i < 6; ++i) {
    std::string f = fields[i];
    f.erase(0, f.find_first_not_of(" \t"));
    f.erase(f.find_last_not_of(" \t") + 1);
    AxisBinding b;
    if (!f.empty() && (f[0] == '-' || f[0] == '+')) {
      b.sign = f[0] == '-' ? -1.0 : 1.0;
      f.erase(0, 1);
    }
    std::string u = upper(f);
    if (u == "NONE") {
      map[i] = AxisBinding{-1, 1.0};
      continue;
    }
    if (!u.empty() && std::all_of(u.begin(), u.end(), [](unsigned char c) { return std::isdigit(c) != 0; })) {
      b.code = u.size() > 3 ? ABS_CNT : std::stoi(u);
      if (b.code >= ABS_CNT) throw InputError("--axes: '" + fields[i] + "' is not an ABS code (0-" + std::to_string(ABS_CNT - 1) + ")");
    } else {
      if (u.rfind("ABS_", 0) != 0) u = "ABS_" + u;
      for (const auto& n : kAbsNames)
        if (u == n.name) b.code = n.code;
      if (b.code < 0) throw InputError("--axes: '" + fields[i] + "' is not an axis (X, Y, Z, RX, RY, RZ, THROTTLE, RUDDER, WHEEL, GAS, BRAKE, HAT0X.., a number, or none)");
    }
    map[i] = b;
  }
  return map;
}

// ---- the decoder -----------------------------------------------------------------

void EvdevDecoder::set_range(int abs_code, const AxisRange& range) noexcept {
  if (abs_code >= 0 && abs_code < ABS_CNT) ranges_[static_cast<std::size_t>(abs_code)] = range;
}

bool EvdevDecoder::apply(const input_event& e) noexcept {
  if (e.type == EV_SYN) {
    if (e.code == SYN_DROPPED) {
      dropping_ = true;
      needs_resync_ = true;
      return false;
    }
    if (e.code != SYN_REPORT) return false;
    if (dropping_) {  // the events since the drop are incomplete: throw them away
      dropping_ = false;
      staged_ = current_;
      keys_staged_ = keys_;
      return false;
    }
    current_ = staged_;
    presses_ += (keys_staged_ & ~keys_).count();
    keys_ = keys_staged_;
    ++reports_;
    return true;
  }
  if (dropping_) return false;
  if (e.type == EV_ABS && e.code < ABS_CNT) staged_[e.code] = e.value;
  if (e.type == EV_KEY && e.code < KEY_CNT && e.value != 2) keys_staged_[e.code] = e.value != 0;  // 2: autorepeat
  return false;
}

Axes EvdevDecoder::axes() const noexcept {
  Axes a{};
  for (std::size_t i = 0; i < 6; ++i) {
    const AxisBinding& b = map_[i];
    if (b.code < 0 || b.code >= ABS_CNT) continue;
    const auto c = static_cast<std::size_t>(b.code);
    a[i] = b.sign * normalise_axis(current_[c], ranges_[c]);
  }
  return a;
}

bool EvdevDecoder::button(int key_code) const noexcept {
  return key_code >= 0 && key_code < KEY_CNT && keys_[static_cast<std::size_t>(key_code)];
}

void EvdevDecoder::resync_axis(int abs_code, int value) noexcept {
  if (abs_code < 0 || abs_code >= ABS_CNT) return;
  staged_[static_cast<std::size_t>(abs_code)] = current_[static_cast<std::size_t>(abs_code)] = value;
}

void EvdevDecoder::resync_button(int key_code, bool down) noexcept {
  if (key_code < 0 || key_code >= KEY_CNT) return;
  keys_staged_[static_cast<std::size_t>(key_code)] = keys_[static_cast<std::size_t>(key_code)] = down;
}

// ---- the stream ------------------------------------------------------------------

int EvdevStream::poll(double timeout_s) noexcept {
  pollfd p{fd_, POLLIN, 0};
  const int ms = timeout_s <= 0 ? 0 : static_cast<int>(std::ceil(timeout_s * 1000.0));
  const int pr = ::poll(&p, 1, ms);
  if (pr < 0) return errno == EINTR ? 0 : -2;
  if (pr == 0) return 0;
  const ssize_t n = ::read(fd_, buf_.data() + have_, buf_.size() - have_);
  if (n == 0) return -1;
  if (n < 0) return errno == EAGAIN || errno == EINTR ? 0 : -2;
  have_ += static_cast<std::size_t>(n);
  int reports = 0;
  std::size_t at = 0;
  while (have_ - at >= sizeof(input_event)) {
    input_event e;
    std::memcpy(&e, buf_.data() + at, sizeof e);
    if (decoder_.apply(e)) ++reports;
    at += sizeof e;
  }
  std::memmove(buf_.data(), buf_.data() + at, have_ - at);  // a split event waits for its rest
  have_ -= at;
  return reports;
}

// ---- the device ------------------------------------------------------------------

namespace {

int open_device(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw InputError(path, std::string("cannot open the input device: ") + std::strerror(errno));
  return fd;
}

}  // namespace

EvdevDevice::EvdevDevice(const std::string& path, AxisMap map)
    : path_(path), fd_(open_device(path)), map_(map), decoder_(map), stream_(fd_, decoder_) {
  try {
    char name[256] = {};
    if (::ioctl(fd_, EVIOCGNAME(sizeof name - 1), name) < 0) throw InputError(path, "not an input event device");
    name_ = name;
    unsigned long bits[(ABS_CNT + 8 * sizeof(unsigned long) - 1) / (8 * sizeof(unsigned long))] = {};
    if (::ioctl(fd_, EVIOCGBIT(EV_ABS, sizeof bits), bits) < 0) throw InputError(path, "not an input event device");
    const auto has = [&](int code) {
      const std::size_t w = static_cast<std::size_t>(code) / (8 * sizeof(unsigned long));
      return ((bits[w] >> (static_cast<std::size_t>(code) % (8 * sizeof(unsigned long)))) & 1UL) != 0;
    };
    std::string present;
    for (int c = 0; c < ABS_CNT; ++c)
      if (has(c)) present += (present.empty() ? "" : ", ") + abs_name(c);
    for (const auto& b : map_) {
      if (b.code < 0) continue;
      if (!has(b.code))
        throw InputError(path, "has no axis " + abs_name(b.code) + " (the device's axes: " +
                                   (present.empty() ? "none" : present) + "); map them with --axes");
      input_absinfo info{};
      if (::ioctl(fd_, EVIOCGABS(b.code), &info) < 0) throw InputError(path, "cannot read the absinfo of " + abs_name(b.code));
      decoder_.set_range(b.code, AxisRange{info.minimum, info.maximum, info.flat});
      decoder_.resync_axis(b.code, info.value);
    }
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

EvdevDevice::~EvdevDevice() {
  if (fd_ >= 0) ::close(fd_);
}

void EvdevDevice::resync() noexcept {
  for (const auto& b : map_) {
    if (b.code < 0) continue;
    input_absinfo info{};
    if (::ioctl(fd_, EVIOCGABS(b.code), &info) == 0) decoder_.resync_axis(b.code, info.value);
  }
  unsigned char keys[KEY_CNT / 8 + 1] = {};
  if (::ioctl(fd_, EVIOCGKEY(sizeof keys), keys) >= 0)
    for (int k = BTN_MISC; k < KEY_CNT; ++k) decoder_.resync_button(k, (keys[k / 8] >> (k % 8)) & 1);
  decoder_.resynced();
}

int EvdevDevice::poll(double timeout_s) noexcept {
  const int r = stream_.poll(timeout_s);
  if (decoder_.needs_resync()) resync();
  return r;
}

}  // namespace foresight::teleop
