#pragma once
// The hardware the daemon runs: the same code path on a real cabinet and in
// --sim; only the CAN buses and the Modbus endpoints differ.
//
//   real:  SocketCanBus per configured bus (can0, can1...), the LST at the
//          configured Modbus address, the video switch at its address.
//   --sim: every bus a mock bus whose far end is the CAN simulator (CiA 402
//          drives + F/T sensor), the physical plant (sim::Plant: contact of
//          the tool with the ORU, the carried ORU) feeding the F/T sensor, the
//          simulated LST and video switch as Modbus servers on 127.0.0.1
//          (ephemeral ports, so several daemons can run side by side).
//
// Set-up only (throws InputError for configuration, hw::CanError/HwError for
// hardware, LstServerError for the simulated servers).

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "foresight/common/robot_model.hpp"
#include "foresight/hw/drive_system.hpp"
#include "foresight/hw/lst_tool.hpp"
#include "foresight/hw/remote_config.hpp"
#include "foresight/hw/video_switch.hpp"

namespace foresight::sim {
class CanSimulator;
class LstServer;
class Plant;
class VideoSwitchServer;
}  // namespace foresight::sim

namespace foresight::daemon {

struct SiteOptions {
  std::string remote_yaml;  ///< config/remote.yaml
  std::string urdf;         ///< the robot (default: robot.urdf beside remote_yaml)
  std::string scene_yaml;   ///< --sim: the simulated work site (default: scene.yaml beside remote_yaml)
  std::string oru_yaml;     ///< --sim: the ORU model (default: oru.yaml beside remote_yaml)
  bool sim = false;
  /// --sim: SCHED_FIFO priority of the simulated drives' thread (0: a normal
  /// thread). The daemon gives it the loop's priority minus one: simulated
  /// hardware answers on time even on a busy host, as real drives do.
  int sim_rt_priority = 0;
};

/// The simulated far ends (--sim only).
struct SimulatedSite {
  std::unique_ptr<sim::CanSimulator> can;
  std::unique_ptr<sim::LstServer> lst;
  std::unique_ptr<sim::VideoSwitchServer> video;
  std::unique_ptr<sim::Plant> plant;
  SimulatedSite();
  ~SimulatedSite();
  SimulatedSite(SimulatedSite&&) noexcept;
  SimulatedSite& operator=(SimulatedSite&&) noexcept;
};

struct Site {
  SiteOptions options;
  hw::RemoteConfig hw_config;
  hw::LstToolConfig tool_config;
  hw::VideoSwitchConfig video_config;
  std::vector<std::string> camera_names;  ///< index on the video switch = position
  std::unique_ptr<RobotModel> model;
  std::unique_ptr<hw::DriveSystem> drives;
  std::optional<SimulatedSite> simulated;  ///< --sim: the far ends (destroyed first: plant, servers, simulator)
  Site();
  ~Site();
  Site(Site&&) noexcept;
  Site& operator=(Site&&) noexcept;
};

/// The file `name` in the folder of `path` ("config/remote.yaml", "robot.urdf"
/// -> "config/robot.urdf").
std::string sibling(const std::string& path, const std::string& name);

/// Loads every configuration (throws InputError naming file and line), builds
/// the buses and the drive system (not yet configured) and, with --sim,
/// starts the simulated site.
Site build_site(SiteOptions options);

}  // namespace foresight::daemon
