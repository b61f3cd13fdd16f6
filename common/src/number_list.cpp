#include "foresight/common/number_list.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <vector>

namespace foresight {

std::vector<std::string_view> split_commas(std::string_view text) {
  std::vector<std::string_view> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    out.push_back(text.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

Eigen::VectorXd parse_numbers(const std::string& text, const std::string& option) {
  std::vector<double> v;
  for (const std::string_view field : split_commas(text)) {
    const std::string item(field);
    char* end = nullptr;
    const double x = std::strtod(item.c_str(), &end);
    if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(x))
      throw std::invalid_argument(option + ": element " + std::to_string(v.size() + 1) + " ('" + item +
                                  "') is not a finite number");
    v.push_back(x);
  }
  return Eigen::Map<Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

Eigen::VectorXd parse_joints(const std::string& text, const std::string& option, const RobotModel& model,
                             bool degrees) {
  const Eigen::VectorXd typed = parse_numbers(text, option);
  if (typed.size() != model.dof())
    throw std::invalid_argument(option + " has " + std::to_string(typed.size()) + " values but the arm has " +
                                std::to_string(model.dof()) + " joints");
  const double to_rad = degrees ? M_PI / 180.0 : 1.0;
  const Eigen::VectorXd q = typed * to_rad;
  for (int i = 0; i < model.dof(); ++i) {
    const JointLimits& l = model.limits()[i];
    if (q[i] < l.lower_rad - 1e-9 || q[i] > l.upper_rad + 1e-9) {
      char buf[200];
      std::snprintf(buf, sizeof buf, ": %s = %g %s is outside its limits [%.*f, %.*f] %s", model.joint_names()[i].c_str(),
                    typed[i], degrees ? "deg" : "rad", degrees ? 1 : 4, l.lower_rad / to_rad, degrees ? 1 : 4,
                    l.upper_rad / to_rad, degrees ? "deg" : "rad");
      throw std::invalid_argument(option + buf);
    }
  }
  return q;
}

}  // namespace foresight
