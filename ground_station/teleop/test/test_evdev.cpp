// The evdev hand-controller reader: axis normalisation with the device's
// absinfo, the axis map, the decoder (a sample is complete at SYN_REPORT,
// SYN_DROPPED discards up to the next one, button presses), whole
// `struct input_event`s read from a pipe even when a write splits one, and a
// real event device made with uinput where /dev/uinput is writable (skipped,
// with the reason, where it is not).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <linux/uinput.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <thread>

#include "foresight/common/error.hpp"
#include "foresight/teleop/evdev.hpp"

namespace foresight::teleop {
namespace {

input_event ev(int type, int code, int value) {
  input_event e{};
  e.type = static_cast<__u16>(type);
  e.code = static_cast<__u16>(code);
  e.value = value;
  return e;
}

TEST(EvdevAxis, NormalisedWithTheDevicesRangeAndFlat) {
  const AxisRange stick{0, 255, 15};  // an 8-bit gamepad stick, centre 127.5
  EXPECT_DOUBLE_EQ(normalise_axis(128, stick), 0.0);    // within flat
  EXPECT_DOUBLE_EQ(normalise_axis(142, stick), 0.0);    // 14.5 from the centre: within flat
  EXPECT_DOUBLE_EQ(normalise_axis(255, stick), 1.0);
  EXPECT_DOUBLE_EQ(normalise_axis(0, stick), -1.0);
  EXPECT_NEAR(normalise_axis(191, stick), 63.5 / 127.5, 1e-12);
  EXPECT_DOUBLE_EQ(normalise_axis(400, stick), 1.0);    // clamped
  const AxisRange space{-350, 350, 0};  // a SpaceMouse axis
  EXPECT_NEAR(normalise_axis(175, space), 0.5, 1e-12);
  EXPECT_NEAR(normalise_axis(-350, space), -1.0, 1e-12);
  EXPECT_DOUBLE_EQ(normalise_axis(5, AxisRange{3, 3, 0}), 0.0);  // empty range
}

TEST(EvdevAxis, MapParsesNamesSignsAndNone) {
  const AxisMap m = parse_axis_map("X,-y,abs_z,RX,none,53");
  EXPECT_EQ(m[0].code, ABS_X);
  EXPECT_EQ(m[1].code, ABS_Y);
  EXPECT_DOUBLE_EQ(m[1].sign, -1.0);
  EXPECT_EQ(m[2].code, ABS_Z);
  EXPECT_EQ(m[3].code, ABS_RX);
  EXPECT_EQ(m[4].code, -1);
  EXPECT_EQ(m[5].code, 53);
  EXPECT_EQ(abs_name(ABS_RZ), "ABS_RZ");
}

TEST(EvdevAxis, BadMapsNameTheField) {
  const auto message = [](const std::string& text) {
    try {
      parse_axis_map(text);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message("X,Y,Z"), "--axes: expected 6 axes (x,y,z,rx,ry,rz), got 3");
  EXPECT_EQ(message("X,Y,Z,RX,RY,TWIST"),
            "--axes: 'TWIST' is not an axis (X, Y, Z, RX, RY, RZ, THROTTLE, RUDDER, WHEEL, GAS, BRAKE, HAT0X.., a "
            "number, or none)");
  EXPECT_EQ(message("X,Y,Z,RX,RY,99"), "--axes: '99' is not an ABS code (0-63)");
}

EvdevDecoder stick_decoder() {
  EvdevDecoder d(parse_axis_map("X,-Y,Z,RX,RY,RZ"));
  for (int c : {ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ}) d.set_range(c, AxisRange{-1000, 1000, 20});
  return d;
}

TEST(EvdevDecoder, ASampleIsCompleteAtSynReport) {
  EvdevDecoder d = stick_decoder();
  EXPECT_FALSE(d.apply(ev(EV_ABS, ABS_X, 500)));
  EXPECT_FALSE(d.apply(ev(EV_ABS, ABS_Y, 1000)));
  EXPECT_DOUBLE_EQ(d.axes()[0], 0.0) << "staged values are not current before SYN_REPORT";
  EXPECT_TRUE(d.apply(ev(EV_SYN, SYN_REPORT, 0)));
  EXPECT_DOUBLE_EQ(d.axes()[0], 0.5);
  EXPECT_DOUBLE_EQ(d.axes()[1], -1.0);  // the map flips y
  EXPECT_EQ(d.raw(ABS_X), 500);
  // Unchanged axes are not repeated by the kernel: they keep their value.
  d.apply(ev(EV_ABS, ABS_RZ, -250));
  d.apply(ev(EV_SYN, SYN_REPORT, 0));
  EXPECT_DOUBLE_EQ(d.axes()[0], 0.5);
  EXPECT_DOUBLE_EQ(d.axes()[5], -0.25);
  EXPECT_EQ(d.reports(), 2u);
}

TEST(EvdevDecoder, DroppedEventsAreDiscardedUntilTheNextReport) {
  EvdevDecoder d = stick_decoder();
  d.apply(ev(EV_ABS, ABS_X, 300));
  d.apply(ev(EV_SYN, SYN_REPORT, 0));
  d.apply(ev(EV_ABS, ABS_X, 900));
  d.apply(ev(EV_SYN, SYN_DROPPED, 0));
  d.apply(ev(EV_ABS, ABS_X, 800));             // part of an incomplete sample
  EXPECT_FALSE(d.apply(ev(EV_SYN, SYN_REPORT, 0)));
  EXPECT_DOUBLE_EQ(d.axes()[0], 0.3);
  EXPECT_TRUE(d.needs_resync());
  d.resync_axis(ABS_X, 600);  // what the device says now (EVIOCGABS)
  d.resynced();
  EXPECT_DOUBLE_EQ(d.axes()[0], 0.6);
  d.apply(ev(EV_ABS, ABS_X, -1000));
  EXPECT_TRUE(d.apply(ev(EV_SYN, SYN_REPORT, 0)));
  EXPECT_DOUBLE_EQ(d.axes()[0], -1.0);
}

TEST(EvdevDecoder, ButtonsAndPresses) {
  EvdevDecoder d = stick_decoder();
  d.apply(ev(EV_KEY, BTN_TRIGGER, 1));
  d.apply(ev(EV_SYN, SYN_REPORT, 0));
  EXPECT_TRUE(d.button(BTN_TRIGGER));
  EXPECT_EQ(d.presses(), 1u);
  d.apply(ev(EV_KEY, BTN_TRIGGER, 2));  // autorepeat: not a new press
  d.apply(ev(EV_SYN, SYN_REPORT, 0));
  EXPECT_EQ(d.presses(), 1u);
  d.apply(ev(EV_KEY, BTN_TRIGGER, 0));
  d.apply(ev(EV_KEY, BTN_THUMB, 1));
  d.apply(ev(EV_SYN, SYN_REPORT, 0));
  EXPECT_FALSE(d.button(BTN_TRIGGER));
  EXPECT_TRUE(d.button(BTN_THUMB));
  EXPECT_EQ(d.presses(), 2u);
}

TEST(EvdevStream, WholeEventsFromAPipeEvenWhenAWriteSplitsOne) {
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  EvdevDecoder d = stick_decoder();
  EvdevStream s(fds[0], d);
  EXPECT_EQ(s.poll(0.0), 0) << "nothing written yet";
  const input_event batch[] = {ev(EV_ABS, ABS_X, 1000), ev(EV_ABS, ABS_Z, -500), ev(EV_SYN, SYN_REPORT, 0),
                               ev(EV_ABS, ABS_RY, 250), ev(EV_SYN, SYN_REPORT, 0)};
  const auto* bytes = reinterpret_cast<const char*>(batch);
  const std::size_t split = sizeof(input_event) * 3 + 7;  // mid-way through the 4th event
  ASSERT_EQ(write(fds[1], bytes, split), static_cast<ssize_t>(split));
  int reports = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (reports < 1 && std::chrono::steady_clock::now() < deadline) reports += std::max(0, s.poll(0.1));
  EXPECT_EQ(reports, 1);
  EXPECT_DOUBLE_EQ(d.axes()[0], 1.0);
  EXPECT_DOUBLE_EQ(d.axes()[2], -0.5);
  EXPECT_DOUBLE_EQ(d.axes()[4], 0.0);
  ASSERT_EQ(write(fds[1], bytes + split, sizeof batch - split), static_cast<ssize_t>(sizeof batch - split));
  while (reports < 2 && std::chrono::steady_clock::now() < deadline) reports += std::max(0, s.poll(0.1));
  EXPECT_EQ(reports, 2);
  EXPECT_DOUBLE_EQ(d.axes()[4], 0.25);
  close(fds[1]);
  int r = 0;
  for (int i = 0; i < 50 && r == 0; ++i) r = s.poll(0.1);
  EXPECT_EQ(r, -1) << "end of input once the writer closed";
  close(fds[0]);
}

TEST(EvdevDevice, NotADeviceAndMissingPathAreNamed) {
  const std::string file = "/tmp/foresight_test_evdev_not_a_device.bin";
  std::ofstream(file) << "x";
  try {
    EvdevDevice dev(file);
    ADD_FAILURE() << "a regular file opened as a device";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), file + ": not an input event device");
  }
  std::remove(file.c_str());
  try {
    EvdevDevice dev("/nonexistent/event7");
    ADD_FAILURE() << "a missing device opened";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/nonexistent/event7: cannot open the input device: No such file or directory");
  }
}

/// A virtual 6-axis controller with one button through uinput.
class VirtualController {
 public:
  VirtualController() {
    fd_ = ::open("/dev/uinput", O_WRONLY | O_NONBLOCK);
    if (fd_ < 0) {
      why_ = std::string("/dev/uinput: ") + std::strerror(errno);
      return;
    }
    ioctl(fd_, UI_SET_EVBIT, EV_ABS);
    ioctl(fd_, UI_SET_EVBIT, EV_KEY);
    ioctl(fd_, UI_SET_EVBIT, EV_SYN);
    ioctl(fd_, UI_SET_KEYBIT, BTN_TRIGGER);
    for (int c : {ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ}) {
      ioctl(fd_, UI_SET_ABSBIT, c);
      uinput_abs_setup a{};
      a.code = static_cast<__u16>(c);
      a.absinfo.minimum = -512;
      a.absinfo.maximum = 511;
      a.absinfo.flat = 8;
      if (ioctl(fd_, UI_ABS_SETUP, &a) < 0) why_ = "UI_ABS_SETUP failed";
    }
    uinput_setup s{};
    s.id.bustype = BUS_VIRTUAL;
    std::snprintf(s.name, sizeof s.name, "foresight test controller");
    if (ioctl(fd_, UI_DEV_SETUP, &s) < 0 || ioctl(fd_, UI_DEV_CREATE) < 0) {
      why_ = std::string("uinput device creation failed: ") + std::strerror(errno);
      return;
    }
    char sys[64] = {};
    if (ioctl(fd_, UI_GET_SYSNAME(sizeof sys), sys) < 0) {
      why_ = "UI_GET_SYSNAME failed";
      return;
    }
    // /sys/devices/virtual/input/<sys>/eventN -> /dev/input/eventN (udev may take a moment).
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (path_.empty() && std::chrono::steady_clock::now() < deadline) {
      for (int n = 0; n < 64 && path_.empty(); ++n) {
        const std::string p = "/sys/devices/virtual/input/" + std::string(sys) + "/event" + std::to_string(n);
        if (access(p.c_str(), F_OK) == 0 && access(("/dev/input/event" + std::to_string(n)).c_str(), R_OK) == 0)
          path_ = "/dev/input/event" + std::to_string(n);
      }
      if (path_.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    if (path_.empty()) why_ = "the uinput device has no readable /dev/input/eventN";
  }
  ~VirtualController() {
    if (fd_ >= 0) {
      ioctl(fd_, UI_DEV_DESTROY);
      close(fd_);
    }
  }
  const std::string& unavailable() const { return why_; }
  const std::string& path() const { return path_; }
  void emit(int type, int code, int value) {
    const input_event e = ev(type, code, value);
    ASSERT_EQ(write(fd_, &e, sizeof e), static_cast<ssize_t>(sizeof e));
  }

 private:
  int fd_ = -1;
  std::string path_, why_;
};

TEST(EvdevDevice, AUinputControllerIsReadNormalised) {
  VirtualController vc;
  if (!vc.unavailable().empty()) GTEST_SKIP() << "no virtual input device here: " << vc.unavailable();
  EvdevDevice dev(vc.path());
  EXPECT_EQ(dev.name(), "foresight test controller");
  EXPECT_DOUBLE_EQ(dev.state().range(ABS_RZ).maximum, 511);
  vc.emit(EV_ABS, ABS_X, 511);
  vc.emit(EV_ABS, ABS_RZ, -512);
  vc.emit(EV_KEY, BTN_TRIGGER, 1);
  vc.emit(EV_SYN, SYN_REPORT, 0);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  int reports = 0;
  while (reports < 1 && std::chrono::steady_clock::now() < deadline) reports += std::max(0, dev.poll(0.1));
  ASSERT_EQ(reports, 1);
  EXPECT_DOUBLE_EQ(dev.state().axes()[0], 1.0);
  EXPECT_DOUBLE_EQ(dev.state().axes()[5], -1.0);
  EXPECT_TRUE(dev.state().button(BTN_TRIGGER));
}

}  // namespace
}  // namespace foresight::teleop
