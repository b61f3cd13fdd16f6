// Temporary bodies so the API links while the implementation lands.
#include "foresight/control/control_loop.hpp"

namespace foresight::control {

Controller::Controller(const RobotModel& model, const ControllerConfig& config)
    : model_(model), config_(config), ws_(model),
      comp_(config.tool, config.filter, config.cycle_rate_hz, model.gravity()),
      adm_(config.admittance, config.cycle_rate_hz) {}
void Controller::command(const MotionCommand&) noexcept {}
void Controller::step(const CycleInputs&, CycleOutputs&) noexcept {}
void Controller::drive_request_done(DriveRequest, bool, const char*, const JointArray&) noexcept {}

ControlLoop::ControlLoop(hw::DriveSystem& drives, const RobotModel& model, const ControllerConfig& config,
                         LoopOptions options)
    : drives_(drives), options_(options), controller_(std::make_unique<Controller>(model, config)) {}
ControlLoop::~ControlLoop() = default;
void ControlLoop::start() {}
void ControlLoop::stop() {}
LoopStats ControlLoop::stats() const noexcept { return {}; }
std::vector<std::string> ControlLoop::warnings() const { return warnings_; }
double LoopStats::percentile_us(const std::array<std::uint64_t, kBins>&, double) noexcept { return 0.0; }

}  // namespace foresight::control
