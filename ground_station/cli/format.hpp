#pragma once
// Number formatting for the CLI's text output.

#include <cstdio>
#include <string>

namespace foresight::cli {

/// `v` with `digits` digits after the point ("%.*f").
inline std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

}  // namespace foresight::cli
