#include "foresight/hw/sdo_list.hpp"

#include <cstdio>
#include <sstream>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight::hw {

namespace {
bool parse_int(const std::string& s, long long& out) {
  if (s.empty()) return false;
  try {
    std::size_t used = 0;
    const bool hex = s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X');
    out = std::stoll(s, &used, hex ? 16 : 10);
    return used == s.size();
  } catch (const std::exception&) {
    return false;
  }
}
}  // namespace

std::vector<SdoEntry> parse_sdo_list(const std::string& text, const std::string& source) {
  std::vector<SdoEntry> out;
  std::istringstream in(text);
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    if (const auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::istringstream words(line);
    std::string first;
    if (!(words >> first)) continue;  // blank or comment
    SdoEntry e;
    e.origin = source + ":" + std::to_string(n);
    std::string object = first;
    if (first == "expect") {
      e.expect_only = true;
      if (!(words >> object)) throw InputError(source, n, "'expect' needs index:sub type value");
    }
    std::string type, value, extra;
    if (!(words >> type >> value))
      throw InputError(source, n, "expected 'index:sub type value' (e.g. 0x605A:00 i16 6), got '" + line + "'");
    if (words >> extra) throw InputError(source, n, "unexpected '" + extra + "' after the value");
    const auto colon = object.find(':');
    long long index = 0, sub = 0, v = 0;
    const std::string bad_object = "object '" + object + "' is not index:sub in hex (0x1000:00 .. 0xFFFF:FF)";
    if (colon == std::string::npos || object.rfind("0x", 0) != 0 || !parse_int(object.substr(0, colon), index) ||
        index < 0x1000 || index > 0xFFFF)
      throw InputError(source, n, bad_object);
    std::string sub_text = object.substr(colon + 1);
    if (sub_text.rfind("0x", 0) != 0) sub_text = "0x" + sub_text;  // the sub-index is hex, 0x optional
    if (!parse_int(sub_text, sub) || sub < 0 || sub > 0xFF) throw InputError(source, n, bad_object);
    e.index = static_cast<std::uint16_t>(index);
    e.sub = static_cast<std::uint8_t>(sub);
    if (type == "u8" || type == "i8") e.size = 1;
    else if (type == "u16" || type == "i16") e.size = 2;
    else if (type == "u32" || type == "i32") e.size = 4;
    else throw InputError(source, n, "type '" + type + "' is not one of u8 u16 u32 i8 i16 i32");
    e.is_signed = type[0] == 'i';
    if (!parse_int(value, v)) throw InputError(source, n, "value '" + value + "' is not an integer");
    const int bits = 8 * e.size;
    const long long lo = e.is_signed ? -(1LL << (bits - 1)) : 0;
    const long long hi = e.is_signed ? (1LL << (bits - 1)) - 1 : (1LL << bits) - 1;
    if (v < lo || v > hi)
      throw InputError(source, n, "value " + value + " is outside " + type + " (" + std::to_string(lo) + ".." +
                                      std::to_string(hi) + ")");
    const std::uint64_t mask = bits == 32 ? 0xFFFFFFFFull : ((1ull << bits) - 1);
    e.value = static_cast<std::uint32_t>(static_cast<std::uint64_t>(v) & mask);
    out.push_back(e);
  }
  return out;
}

std::vector<SdoEntry> load_sdo_list(const std::string& path) {
  return parse_sdo_list(read_text_file(path, "cannot open the drive's SDO configuration file"), path);
}

std::string sdo_value_text(const SdoEntry& e, std::uint32_t raw) {
  const int bits = 8 * e.size;
  const std::uint32_t mask = bits == 32 ? 0xFFFFFFFFu : ((1u << bits) - 1);
  raw &= mask;
  if (e.is_signed) {
    long long v = raw;
    if (raw & (1u << (bits - 1))) v -= (1LL << bits);
    return std::to_string(v);
  }
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%0*X", 2 * e.size, raw);
  return buf;
}

}  // namespace foresight::hw
