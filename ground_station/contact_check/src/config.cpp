#include "foresight/contact_check/config.hpp"

#include <filesystem>

#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight::contact_check {

ContactCheckConfig load_contact_check_config(const std::string& path) {
  ContactCheckConfig c;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return c;
  const YAML::Node root = yaml::parse(read_text_file(path, "cannot open the ground configuration"), path);
  if (!root.IsMap() || !root["contact_check"]) return c;
  const yaml::MapReader m(root["contact_check"], path, "contact_check");
  m.check_keys({"min_p_success", "socket_diameter_m", "required_depth_m", "lead_in_m", "encoder_sigma_rad", "arm_link_sigma_m"});
  c.min_p_success = m.get_or_in("min_p_success", c.min_p_success, 0.0, 1.0, "");
  if (c.min_p_success <= 0.0 || c.min_p_success >= 1.0)
    m.fail_key("min_p_success", "must be in (0, 1) (got " + std::to_string(c.min_p_success) + ")");
  c.socket_diameter_m = m.get_or_in("socket_diameter_m", c.socket_diameter_m, 1e-6, 1.0, "m");
  c.required_depth_m = m.get_or_in("required_depth_m", c.required_depth_m, 1e-6, 1.0, "m");
  c.lead_in_m = m.get_or_in("lead_in_m", c.lead_in_m, 0.0, 0.05, "m");
  c.encoder_sigma_rad = m.get_or_in("encoder_sigma_rad", c.encoder_sigma_rad, 0.0, 0.05, "rad");
  c.arm_link_sigma_m = m.get_or_in("arm_link_sigma_m", c.arm_link_sigma_m, 0.0, 0.05, "m");
  return c;
}

}  // namespace foresight::contact_check
