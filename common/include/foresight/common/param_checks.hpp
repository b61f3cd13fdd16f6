#pragma once
// Range checks of model parameters (the simulated contact and screw, the
// insert's capture region). Messages name the setting: "<section>.<name> ...".

#include <cmath>
#include <stdexcept>
#include <string>

namespace foresight {

/// std::invalid_argument "<section>.<name> must be a positive number" unless v is finite and > 0.
inline void require_positive(double v, const char* section, const char* name) {
  if (!(v > 0.0) || !std::isfinite(v))
    throw std::invalid_argument(std::string(section) + "." + name + " must be a positive number");
}

/// std::invalid_argument "<section>.<name> must be a non-negative number" unless v is finite and >= 0.
inline void require_non_negative(double v, const char* section, const char* name) {
  if (!(v >= 0.0) || !std::isfinite(v))
    throw std::invalid_argument(std::string(section) + "." + name + " must be a non-negative number");
}

}  // namespace foresight
