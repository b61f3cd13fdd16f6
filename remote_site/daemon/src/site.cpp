#include "foresight/daemon/site.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "foresight/common/error.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/hw/can_bus.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/sim/lst_server.hpp"
#include "foresight/sim/plant.hpp"
#include "foresight/sim/video_switch_server.hpp"

namespace foresight::daemon {

SimulatedSite::SimulatedSite() = default;
SimulatedSite::~SimulatedSite() {
  // The plant first: it is the F/T sensor's wrench source on the simulator thread.
  if (plant) plant->detach();
  plant.reset();
  video.reset();
  lst.reset();
  if (can) can->stop();
}
SimulatedSite::SimulatedSite(SimulatedSite&&) noexcept = default;
SimulatedSite& SimulatedSite::operator=(SimulatedSite&&) noexcept = default;

Site::Site() = default;
Site::~Site() {
  // The master side first (its destructor quick-stops enabled drives over the
  // buses), then the simulated far ends.
  drives.reset();
  simulated.reset();
}
Site::Site(Site&&) noexcept = default;
Site& Site::operator=(Site&&) noexcept = default;

std::string sibling(const std::string& path, const std::string& name) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? name : path.substr(0, slash + 1) + name;
}

Site build_site(SiteOptions options) {
  if (options.urdf.empty()) options.urdf = sibling(options.remote_yaml, "robot.urdf");
  if (options.scene_yaml.empty()) options.scene_yaml = sibling(options.remote_yaml, "scene.yaml");
  if (options.oru_yaml.empty()) options.oru_yaml = sibling(options.remote_yaml, "oru.yaml");

  Site site;
  site.options = options;
  site.hw_config = hw::load_remote_config(options.remote_yaml);
  site.tool_config = hw::load_lst_tool_config(options.remote_yaml);
  // Read and checked in both modes (check runs the same loaders): --sim
  // replaces its address with the simulated switch's, and its cameras with
  // the scene's.
  const std::optional<hw::VideoSwitchSection> video_section = hw::load_video_switch_section(options.remote_yaml);
  site.model = std::make_unique<RobotModel>(RobotModel::from_file(options.urdf));
  if (site.hw_config.drives.size() != static_cast<std::size_t>(site.model->dof()))
    throw InputError(options.remote_yaml, std::to_string(site.hw_config.drives.size()) + " drives configured, the robot " +
                                              options.urdf + " has " + std::to_string(site.model->dof()) + " joints");
  for (std::size_t j = 0; j < site.hw_config.drives.size(); ++j)
    if (site.hw_config.drives[j].joint != site.model->joint_names()[j])
      throw InputError(options.remote_yaml, site.hw_config.drives[j].line,
                       "drive " + std::to_string(j + 1) + " is for joint '" + site.hw_config.drives[j].joint +
                           "', the robot's joint " + std::to_string(j + 1) + " is '" + site.model->joint_names()[j] +
                           "' (drives must be listed in chain order)");

  std::vector<std::unique_ptr<hw::CanBus>> master;
  if (options.sim) {
    for (auto& bus : site.hw_config.buses) bus.interface = "mock";  // --sim: every bus simulated
    // The simulated drives answer from an ordinary thread on a shared
    // machine, not from their own hardware: late TPDOs and heartbeats are
    // scheduling, not a silent drive. Half a second of TPDOs and a second of
    // heartbeat silence before a fault (as the control loop's own tests);
    // a real cabinet keeps the configured values.
    site.hw_config.tpdo_miss_limit =
        std::max(site.hw_config.tpdo_miss_limit, static_cast<int>(0.5 * site.hw_config.cycle_rate_hz));
    site.hw_config.heartbeat_consumer_s = std::max(site.hw_config.heartbeat_consumer_s, 1.0);
    SimulatedSite sim;
    auto buses = sim::make_mock_buses(site.hw_config);
    sim.can = sim::CanSimulator::from_config(site.hw_config, std::move(buses.far));
    master = std::move(buses.master);

    sim::LstServerOptions lst = sim::lst_server_options(site.tool_config, options.scene_yaml);
    lst.transport = sim::LstServerOptions::Transport::Tcp;
    lst.host = "127.0.0.1";
    lst.port = 0;  // ephemeral: daemons side by side never collide
    sim.lst = std::make_unique<sim::LstServer>(lst);
    site.tool_config.transport = hw::LstToolConfig::Transport::Tcp;
    site.tool_config.host = "127.0.0.1";
    site.tool_config.port = sim.lst->port();

    sim::VideoSwitchServerOptions video = sim::video_switch_options_from_scene(options.scene_yaml);
    video.host = "127.0.0.1";
    video.port = 0;
    sim.video = std::make_unique<sim::VideoSwitchServer>(video);
    site.video_config.host = "127.0.0.1";
    site.video_config.port = sim.video->port();
    site.camera_names = video.camera_names;

    sim.plant = sim::Plant::from_files(options.urdf, options.oru_yaml, options.scene_yaml);
    sim.plant->attach(*sim.can, sim.lst.get());
    sim.can->start(options.sim_rt_priority);  // power-on: the nodes send their boot-up messages
    site.simulated = std::move(sim);
    spdlog::info("simulated site: {} drives and the F/T sensor on {} mock bus(es), LST on 127.0.0.1:{}, "
                 "video switch on 127.0.0.1:{}",
                 site.hw_config.drives.size(), site.hw_config.buses.size(), site.tool_config.port,
                 site.video_config.port);
  } else {
    for (const auto& bus : site.hw_config.buses) {
      if (bus.is_mock())
        throw InputError(options.remote_yaml, bus.line,
                         "bus " + bus.name + " has interface 'mock': a real cabinet needs a SocketCAN interface "
                                             "(can0...), or run with --sim");
      master.push_back(std::make_unique<hw::SocketCanBus>(bus.interface));
    }
    // The cabinet's video switch, when remote.yaml has one (CAMERA is
    // refused "no video switch configured" otherwise).
    if (video_section) {
      site.video_config = video_section->link;
      site.camera_names = video_section->camera_names;
    }
  }
  site.drives = std::make_unique<hw::DriveSystem>(site.hw_config, std::move(master),
                                                  hw::joint_limits_by_name(*site.model));
  return site;
}

}  // namespace foresight::daemon
