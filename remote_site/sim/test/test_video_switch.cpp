// The video switch client (foresight_hw) against the simulated switch over
// Modbus TCP on 127.0.0.1 (ephemeral ports): select, set point, grab, status;
// bad writes refused with exception 03 and nothing changed.
#include <gtest/gtest.h>
#include <modbus/modbus.h>

#include <cerrno>
#include <cmath>
#include <limits>

#include "foresight/common/error.hpp"
#include "foresight/hw/video_switch.hpp"
#include "foresight/sim/video_switch_server.hpp"

using namespace foresight;
using hw::CameraView;
using hw::VideoSwitch;
using hw::VideoSwitchError;
using hw::VideoSwitchStatus;

namespace {

hw::VideoSwitchConfig client_config(int port) {
  hw::VideoSwitchConfig c;
  c.port = port;
  c.response_timeout_s = 1.0;  // a descheduled server thread on a loaded machine
  c.retries = 1;
  return c;
}

sim::VideoSwitchServerOptions scene_options() {
  return sim::video_switch_options_from_scene(FORESIGHT_CONFIG_DIR "/scene.yaml");
}

}  // namespace

TEST(VideoSwitch, SceneHasTheFourCamerasInFileOrder) {
  const auto o = scene_options();
  ASSERT_EQ(o.camera_names.size(), 4u);
  EXPECT_EQ(o.camera_names[0], "side");
  EXPECT_EQ(o.camera_names[3], "overhead_zoom");
  EXPECT_DOUBLE_EQ(o.initial_focal_px[0], 700.0);
  EXPECT_DOUBLE_EQ(o.initial_focal_px[3], 1100.0);
}

TEST(VideoSwitch, RoundTripSelectSetPointGrab) {
  sim::VideoSwitchServer server(scene_options());
  ASSERT_GT(server.port(), 0);
  VideoSwitch sw(client_config(server.port()));
  ASSERT_FALSE(sw.connect()) << sw.last_error_message();

  VideoSwitchStatus s;
  ASSERT_FALSE(sw.read_status(s)) << sw.last_error_message();
  EXPECT_EQ(s.active_camera, 0);
  EXPECT_EQ(s.camera_count, 4);
  EXPECT_DOUBLE_EQ(s.focal_px, 700.0);
  EXPECT_EQ(s.grab_count, 0u);

  // Select the oblique camera and its set point in one request.
  const int oblique = server.camera_index("oblique");
  ASSERT_EQ(oblique, 1);
  ASSERT_FALSE(sw.set_view({oblique, 0.5, -0.2, 1500.0})) << sw.last_error_message();
  ASSERT_FALSE(sw.read_status(s));
  EXPECT_EQ(s.active_camera, oblique);
  EXPECT_NEAR(s.pan_rad, 0.5, 1e-12);
  EXPECT_NEAR(s.tilt_rad, -0.2, 1e-12);
  EXPECT_DOUBLE_EQ(s.focal_px, 1500.0);
  EXPECT_EQ(s.switches, 1);
  sim::VideoSwitchState truth = server.state();
  EXPECT_EQ(truth.active, oblique);
  EXPECT_EQ(truth.views[1].pan_mrad, 500);
  EXPECT_EQ(truth.views[1].tilt_mrad, -200);
  EXPECT_EQ(truth.views[1].focal_px, 1500);
  EXPECT_EQ(truth.views[0].focal_px, 700);  // the others untouched

  // Selecting another camera shows that camera's stored set point; coming
  // back shows the oblique one's again.
  ASSERT_FALSE(sw.select(3));
  CameraView v;
  ASSERT_FALSE(sw.read_view(v));
  EXPECT_EQ(v.camera, 3);
  EXPECT_DOUBLE_EQ(v.pan_rad, 0.0);
  EXPECT_DOUBLE_EQ(v.focal_px, 1100.0);
  ASSERT_FALSE(sw.select(oblique));
  ASSERT_FALSE(sw.read_view(v));
  EXPECT_NEAR(v.pan_rad, 0.5, 1e-12);
  EXPECT_NEAR(v.tilt_rad, -0.2, 1e-12);
  EXPECT_DOUBLE_EQ(v.focal_px, 1500.0);

  // A single-register pan write moves the selected camera only.
  ASSERT_FALSE(sw.write_register(hw::video::kHoldPan, static_cast<std::uint16_t>(static_cast<std::int16_t>(-1234))));
  ASSERT_FALSE(sw.read_status(s));
  EXPECT_NEAR(s.pan_rad, -1.234, 1e-12);
  EXPECT_EQ(server.state().views[1].pan_mrad, -1234);

  for (int i = 0; i < 3; ++i) ASSERT_FALSE(sw.grab()) << sw.last_error_message();
  ASSERT_FALSE(sw.read_status(s));
  EXPECT_EQ(s.grab_count, 3u);
  EXPECT_EQ(server.state().grabs, 3u);
  EXPECT_EQ(s.switches, 3);  // oblique, overhead_zoom, oblique
}

TEST(VideoSwitch, OutOfRangeWritesAreRefusedWithException03AndChangeNothing) {
  sim::VideoSwitchServer server(scene_options());
  VideoSwitch sw(client_config(server.port()));
  ASSERT_FALSE(sw.set_view({2, 0.1, 0.2, 420.0})) << sw.last_error_message();
  const sim::VideoSwitchState before = server.state();

  std::error_code ec = sw.select(4);  // 4 cameras: 0..3
  EXPECT_EQ(ec, VideoSwitchError::IllegalDataValue);
  EXPECT_EQ(ec.message(), "illegal data value (Modbus exception 03)");
  EXPECT_EQ(sw.last_error_message(),
            "write holding register 0 = 4 (tcp 127.0.0.1:" + std::to_string(server.port()) +
                " unit 1): illegal data value (Modbus exception 03)");
  EXPECT_EQ(sw.set_view({1, 3.5, 0.0, 700.0}), VideoSwitchError::IllegalDataValue);   // pan > 3000 mrad
  EXPECT_EQ(sw.set_view({1, 0.0, -1.6, 700.0}), VideoSwitchError::IllegalDataValue);  // tilt < -1500 mrad
  EXPECT_EQ(sw.set_view({1, 0.0, 0.0, 50.0}), VideoSwitchError::IllegalDataValue);    // focal < 100 px
  EXPECT_EQ(sw.set_view({1, 0.0, 0.0, 6000.0}), VideoSwitchError::IllegalDataValue);  // focal > 5000 px
  EXPECT_EQ(sw.write_register(hw::video::kHoldFocal, 99), VideoSwitchError::IllegalDataValue);
  // Unknown addresses: exception 02.
  EXPECT_EQ(sw.write_register(7, 1), VideoSwitchError::IllegalDataAddress);
  std::uint16_t regs[2] = {};
  EXPECT_EQ(sw.read_input_registers(8, 1, regs), VideoSwitchError::IllegalDataAddress);

  const sim::VideoSwitchState after = server.state();
  EXPECT_EQ(after.active, before.active);
  EXPECT_EQ(after.switches, before.switches);
  for (std::size_t i = 0; i < after.views.size(); ++i) {
    EXPECT_EQ(after.views[i].pan_mrad, before.views[i].pan_mrad) << i;
    EXPECT_EQ(after.views[i].tilt_mrad, before.views[i].tilt_mrad) << i;
    EXPECT_EQ(after.views[i].focal_px, before.views[i].focal_px) << i;
  }
  VideoSwitchStatus s;
  ASSERT_FALSE(sw.read_status(s));
  EXPECT_EQ(s.active_camera, 2);
  EXPECT_DOUBLE_EQ(s.focal_px, 420.0);
}

// FC 22 (mask write) and FC 23 (write and read) write holding registers too:
// the switch range-checks them as it does FC 6 and 16 (the shared
// modbus_serving::register_writes_ok; before it only 6 and 16 were checked,
// and a mask write could select camera 9 of 4). In range they act.
TEST(VideoSwitch, MaskWriteAndWriteReadAreRangeCheckedToo) {
  sim::VideoSwitchServer server(scene_options());
  modbus_t* ctx = modbus_new_tcp("127.0.0.1", server.port());
  ASSERT_NE(ctx, nullptr);
  modbus_set_response_timeout(ctx, 1, 0);
  ASSERT_EQ(modbus_connect(ctx), 0);
  std::uint16_t regs[4] = {};
  errno = 0;
  EXPECT_EQ(modbus_mask_write_register(ctx, hw::video::kHoldCamera, 0x0000, 9), -1);  // FC 22: camera 9 of 4
  EXPECT_EQ(errno, EMBXILVAL);
  const std::uint16_t far_pan = 5000;  // 5 rad: beyond the pan limit
  errno = 0;
  EXPECT_EQ(modbus_write_and_read_registers(ctx, hw::video::kHoldPan, 1, &far_pan, 0, 4, regs), -1);  // FC 23
  EXPECT_EQ(errno, EMBXILVAL);
  EXPECT_EQ(server.state().active, 0);
  EXPECT_EQ(server.state().views[0].pan_mrad, 0);
  // In range: camera 2 through FC 22, then its pan through FC 23.
  ASSERT_EQ(modbus_mask_write_register(ctx, hw::video::kHoldCamera, 0x0000, 2), 1);
  EXPECT_EQ(server.state().active, 2);
  const std::uint16_t pan = 300;
  ASSERT_EQ(modbus_write_and_read_registers(ctx, hw::video::kHoldPan, 1, &pan, 0, 4, regs), 4);
  EXPECT_EQ(regs[hw::video::kHoldCamera], 2);
  EXPECT_EQ(regs[hw::video::kHoldPan], 300);
  EXPECT_EQ(server.state().views[2].pan_mrad, 300);
  modbus_close(ctx);
  modbus_free(ctx);
}

TEST(VideoSwitch, ValuesNotRepresentableAreRefusedBeforeSending) {
  sim::VideoSwitchServer server(scene_options());
  VideoSwitch sw(client_config(server.port()));
  ASSERT_FALSE(sw.connect());
  const std::uint64_t answered = server.requests_answered();
  EXPECT_EQ(sw.set_view({0, std::numeric_limits<double>::quiet_NaN(), 0.0, 700.0}), VideoSwitchError::InvalidArgument);
  EXPECT_EQ(sw.set_view({0, 40.0, 0.0, 700.0}), VideoSwitchError::InvalidArgument);  // beyond int16 mrad
  EXPECT_EQ(sw.set_view({-1, 0.0, 0.0, 700.0}), VideoSwitchError::InvalidArgument);
  EXPECT_EQ(sw.select(70000), VideoSwitchError::InvalidArgument);
  EXPECT_EQ(sw.last_error_message(),
            "select camera 70000 (tcp 127.0.0.1:" + std::to_string(server.port()) + " unit 1): invalid argument");
  EXPECT_EQ(server.requests_answered(), answered);
}

TEST(VideoSwitch, NoServerIsConnectionFailed) {
  int port = 0;
  {
    sim::VideoSwitchServer server(scene_options());
    port = server.port();
  }
  hw::VideoSwitchConfig c = client_config(port);
  c.retries = 1;
  c.reconnect_delay_s = 0.001;
  VideoSwitch sw(c);
  EXPECT_EQ(sw.select(0), VideoSwitchError::ConnectionFailed);
  EXPECT_NE(sw.last_error_message().find("connection failed"), std::string::npos) << sw.last_error_message();
  EXPECT_NE(sw.last_error_message().find("after 2 attempts"), std::string::npos) << sw.last_error_message();
}

TEST(VideoSwitch, BadOptionsAreRefused) {
  sim::VideoSwitchServerOptions o;
  o.camera_names = {"a", "b"};
  o.initial_focal_px = {700.0};
  EXPECT_THROW(
      {
        try {
          sim::VideoSwitchServer s(o);
        } catch (const sim::VideoSwitchServerError& e) {
          EXPECT_STREQ(e.what(), "VideoSwitchServer: 2 cameras but 1 initial focal lengths");
          throw;
        }
      },
      sim::VideoSwitchServerError);
  hw::VideoSwitchConfig c;
  c.port = 0;
  EXPECT_THROW(VideoSwitch{c}, InputError);
}

TEST(VideoSwitch, PartialWritesLoadTheSelectedCamerasOtherSetPoints) {
  sim::VideoSwitchServer server(scene_options());
  VideoSwitch sw(client_config(server.port()));
  ASSERT_FALSE(sw.set_view({3, 0.3, 0.4, 2000.0})) << sw.last_error_message();
  ASSERT_FALSE(sw.select(0));
  // Camera 3 and its pan in one FC 16: its stored tilt and focal come back.
  const std::uint16_t regs[2] = {3, static_cast<std::uint16_t>(static_cast<std::int16_t>(-100))};
  ASSERT_FALSE(sw.write_registers(hw::video::kHoldCamera, 2, regs)) << sw.last_error_message();
  CameraView v;
  ASSERT_FALSE(sw.read_view(v));
  EXPECT_EQ(v.camera, 3);
  EXPECT_NEAR(v.pan_rad, -0.1, 1e-12);
  EXPECT_NEAR(v.tilt_rad, 0.4, 1e-12);
  EXPECT_DOUBLE_EQ(v.focal_px, 2000.0);
  EXPECT_EQ(server.state().views[0].pan_mrad, 0);  // camera 0 untouched
  // A write running past the map is exception 02 and changes nothing.
  const std::uint16_t five[5] = {1, 0, 0, 700, 0};
  EXPECT_EQ(sw.write_registers(0, 5, five), VideoSwitchError::IllegalDataAddress);
  EXPECT_EQ(server.state().active, 3);
}

TEST(VideoSwitch, ANewClientReplacesTheOldOne) {
  sim::VideoSwitchServer server(scene_options());
  VideoSwitch a(client_config(server.port()));
  ASSERT_FALSE(a.select(1)) << a.last_error_message();
  VideoSwitch b(client_config(server.port()));
  ASSERT_FALSE(b.select(2)) << b.last_error_message();
  VideoSwitchStatus s;
  ASSERT_FALSE(b.read_status(s));
  EXPECT_EQ(s.active_camera, 2);
  // The first client's link was closed by the server; it reconnects (retry).
  ASSERT_FALSE(a.read_status(s)) << a.last_error_message();
  EXPECT_EQ(s.active_camera, 2);
}
