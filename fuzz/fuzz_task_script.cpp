// Task scripts (config/scripts/*.task): the parser, then the checks against
// the configuration `foresight run` makes before anything is sent (the ORU's
// tags, the work site's cameras, the arm's joint count and limits), and the
// goal lists of every TRAJECTORY/PREVIEW.
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/script/script.hpp"
#include "fuzz_support.hpp"

namespace {
foresight::script::ScriptContext make_context() {
  foresight::script::ScriptContext c;
  const auto oru = foresight::ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  for (const auto& [name, pose] : oru.tags) c.tags.insert(name);
  const auto scene = foresight::Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  for (const auto& name : scene.camera_order) c.cameras.insert(name);
  c.objects.insert(oru.name);
  const auto robot = foresight::RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  c.joints = robot.dof();
  for (const auto& l : robot.limits()) {
    c.lower_rad.push_back(l.lower_rad);
    c.upper_rad.push_back(l.upper_rad);
  }
  return c;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const foresight::script::ScriptContext context = make_context();
  foresight::fuzz::expect_input_errors([&] {
    const auto script = foresight::script::parse_script(foresight::fuzz::text_of(data, size), "fuzz.task");
    for (const auto& c : script.commands) {
      if (c.op == foresight::script::Op::Trajectory || c.op == foresight::script::Op::Preview)
        (void)foresight::script::goals_of(c);
      if (c.op == foresight::script::Op::InvokeAlgorithm) (void)c.parameters();
    }
    foresight::script::check_script(script, context);
  });
  return 0;
}
