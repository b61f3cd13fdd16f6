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
/// Objects the master writes itself at every boot (node_config.cpp, from
/// remote.yaml and the URDF): a file that wrote them too would be silently
/// overwritten, or would fight the cycle. Name, or nullptr when not one.
const char* master_owned(std::uint16_t index) noexcept {
  switch (index) {
    case 0x1005: return "SYNC COB-ID";
    case 0x1006: return "communication cycle period";
    case 0x1016: return "consumer heartbeat time";
    case 0x1017: return "producer heartbeat time";
    case 0x1019: return "SYNC counter overflow";
    case 0x6040: return "controlword";
    case 0x6060: return "modes of operation";
    case 0x6065: return "following error window";
    case 0x6066: return "following error time out";
    case 0x607A: return "target position";
    case 0x607D: return "software position limit";
    case 0x607F: return "max profile velocity";
    case 0x60C2: return "interpolation time period";
    default: break;
  }
  if (index >= 0x1400 && index <= 0x1BFF) return "PDO communication or mapping";
  return nullptr;
}

/// The objects that govern how a drive stops, checked against what the
/// master's stop handling relies on (docs/control.md, stop table): throws
/// InputError naming the line, the object and the allowed values.
void check_stop_object(const SdoEntry& e, long long v, const std::string& source, int n) {
  auto refuse = [&](const char* what, const std::string& allowed) {
    char obj[16];
    std::snprintf(obj, sizeof obj, "0x%04X:%02X", e.index, e.sub);
    throw InputError(source, n, std::string(what) + " " + obj + " = " + std::to_string(v) + " " + allowed);
  };
  switch (e.index) {
    case 0x605A:  // quick stop option code
      // The master stops category 0 with Disable Voltage, and uses Quick
      // Stop only when it shuts down with the drives enabled: the drive must
      // then end without power, never hold in Quick stop active with nobody
      // commanding it.
      if (v != 1 && v != 2)
        refuse("quick stop option code",
               "contradicts the master's stop handling: allowed 1 or 2 (ramp, then Switch on disabled: power off)");
      return;
    case 0x605E:  // fault reaction option code
      if (v < 0 || v > 2) refuse("fault reaction option code", "is outside 0..2 (coast, or ramp; then Fault)");
      return;
    case 0x6007:  // abort connection option code
      if (v < 1 || v > 3)
        refuse("abort connection option code",
               "is outside 1..3 (fault, disable voltage, quick stop): with 0 a drive whose master died keeps "
               "following its last target");
      return;
    case 0x6084:  // profile deceleration (the slow-down ramp)
    case 0x6085:  // quick stop deceleration
      if (v <= 0) refuse(e.index == 0x6084 ? "profile deceleration" : "quick stop deceleration",
                         "must be above 0 counts/s^2 (a zero ramp never stops)");
      return;
    default: return;
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
    if (const char* owned = master_owned(e.index); owned != nullptr && !e.expect_only)
      throw InputError(source, n, "object " + object + " (" + owned +
                                      ") is written by the master itself at every boot; remove it from the file");
    check_stop_object(e, v, source, n);
    if (out.size() >= kMaxSdoEntries)
      throw InputError(source, n, "more than " + std::to_string(kMaxSdoEntries) +
                                      " entries (a drive's configurable objects are dozens; each costs two SDO "
                                      "transfers at every start-up)");
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
