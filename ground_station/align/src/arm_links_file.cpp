#include "foresight/align/arm_links_file.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>

#include "foresight/common/atomic_file.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight::align {

namespace {

constexpr double kMaxCorrection_m = 0.1;

std::vector<double> read_list(const YAML::Node& root, const char* key, const std::string& path, std::size_t n) {
  const YAML::Node node = root[key];
  if (!node.IsSequence())
    throw InputError(path, std::string(key) + ": expected a list of " + std::to_string(n) + " numbers (m, one per chain segment)");
  if (node.size() != n)
    throw InputError(path, std::string(key) + ": " + std::to_string(node.size()) + " values for the arm's " +
                               std::to_string(n) + " chain segments");
  std::vector<double> out;
  for (std::size_t i = 0; i < n; ++i) {
    double v = 0.0;
    try {
      v = node[i].as<double>();
    } catch (const YAML::Exception&) {
      throw InputError(path, std::string(key) + "[" + std::to_string(i) + "]: not a number");
    }
    if (!std::isfinite(v)) throw InputError(path, std::string(key) + "[" + std::to_string(i) + "]: not finite");
    out.push_back(v);
  }
  return out;
}

}  // namespace

ArmLinkCorrections load_arm_links(const std::string& path, const RobotModel& arm) {
  const YAML::Node root = yaml::load_file(path, "cannot read the arm's link corrections");
  if (!root.IsMap()) throw InputError(path, "expected arm_link_delta_m: [...] (m, one per chain segment)");
  const std::size_t n = arm.segment_count();
  ArmLinkCorrections out;
  out.delta_m = read_list(root, "arm_link_delta_m", path, n);
  if (root["arm_link_sigma_m"]) {
    out.sigma_m = read_list(root, "arm_link_sigma_m", path, n);
    for (std::size_t i = 0; i < n; ++i)
      if (out.sigma_m[i] < 0.0)
        throw InputError(path, "arm_link_sigma_m[" + std::to_string(i) + "]: negative");
  }
  const std::vector<int> offsets = arm.offset_segments();
  for (std::size_t i = 0; i < n; ++i) {
    const bool has_offset = std::find(offsets.begin(), offsets.end(), static_cast<int>(i)) != offsets.end();
    if (!has_offset && out.delta_m[i] != 0.0)
      throw InputError(path, "arm_link_delta_m[" + std::to_string(i) + "]: segment " + std::to_string(i) +
                                 " has no length offset in the arm model and cannot be corrected");
    if (std::abs(out.delta_m[i]) > kMaxCorrection_m)
      throw InputError(path, "arm_link_delta_m[" + std::to_string(i) + "]: " + std::to_string(out.delta_m[i]) +
                                 " m is not a link-length error (limit 0.1 m): is this file for another arm?");
  }
  return out;
}

void save_arm_links(const std::string& path, const ArmLinkCorrections& links, const std::string& robot_file,
                    const std::string& date_iso) {
  YAML::Emitter em;
  em.SetDoublePrecision(12);
  em << YAML::BeginMap;
  em << YAML::Key << "robot" << YAML::Value << robot_file;
  em << YAML::Key << "date" << YAML::Value << date_iso;
  em << YAML::Key << "arm_link_delta_m" << YAML::Value << YAML::Flow << links.delta_m;
  if (!links.sigma_m.empty()) em << YAML::Key << "arm_link_sigma_m" << YAML::Value << YAML::Flow << links.sigma_m;
  em << YAML::EndMap;
  write_file_atomic(path, std::string("# foresight align --arm-out: the arm model's link-length corrections (m, one per "
                                      "chain segment)\n") +
                              em.c_str() + "\n");
}

}  // namespace foresight::align
