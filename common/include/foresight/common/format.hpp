#pragma once
// Formatting of text meant for a person (the CLI's lines, reasons, journal
// codes): numbers, and names in capitals.

#include <cctype>
#include <cstdio>
#include <string>

namespace foresight {

/// `v` with `digits` digits after the point ("%.*f").
inline std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

/// printf-style text of up to three numbers ("%.1f s", "%g of %g"), for
/// reasons and log lines; at most 255 characters. Every argument is a
/// double, so the format's conversions are f, e, g (never d or s).
inline std::string printf_text(const char* format, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, format, a, b, c);
  return buf;
}

/// `s` in capitals (ASCII): "insert" -> "INSERT", a code as the journal and the wire spell it.
inline std::string upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace foresight
