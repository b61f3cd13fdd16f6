#pragma once
// Number formatting for text meant for a person (the CLI's lines, reasons).

#include <cstdio>
#include <string>

namespace foresight {

/// `v` with `digits` digits after the point ("%.*f").
inline std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

}  // namespace foresight
