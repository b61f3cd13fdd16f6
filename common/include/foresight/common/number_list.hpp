#pragma once
// Comma-separated numbers typed by an operator ("--joints 0,0.5,..."): one
// parser for every command, with messages that name the option and element.

#include <Eigen/Core>
#include <string>
#include <string_view>
#include <vector>

#include "foresight/common/robot_model.hpp"

namespace foresight {

/// "a,b,,c" -> {"a", "b", "", "c"}: every field, untrimmed; one field for
/// text without a comma. The views point into `text`.
std::vector<std::string_view> split_commas(std::string_view text);

/// "a,b,c" -> numbers. std::invalid_argument:
/// "<option>: element K ('x') is not a finite number".
Eigen::VectorXd parse_numbers(const std::string& text, const std::string& option);

/// Joint angles "q1,...,qN" in radians (degrees when `degrees`), checked
/// against the arm's joint count and joint position limits. Returns radians.
/// std::invalid_argument: "<option>: element K ('x') is not a finite number",
/// "<option> has N values but the arm has M joints",
/// "<option>: joint4 = 170 deg is outside its limits [-160.0, 160.0] deg".
Eigen::VectorXd parse_joints(const std::string& text, const std::string& option, const RobotModel& model,
                             bool degrees = false);

}  // namespace foresight
