#pragma once
// A drive's SDO configuration from a file next to remote.yaml, in the CiA 306
// "concise" style a CANopen engineer already keeps: one object per line,
//
//     # comment
//     0x605A:00  i16  6        # quick stop option code
//     expect 0x1018:01 u32 0x0000F5E0   # identity: read and compared, never written
//
// index:sub (hex), type (u8 u16 u32 i8 i16 i32), value (decimal or 0x hex,
// negative for signed types). Plain lines are written at boot, in file order,
// and read back; `expect` lines are only read and compared. Set-up code only.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace foresight::hw {

struct SdoEntry {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::uint32_t value = 0;    ///< raw bytes, little-endian on the wire (signed values two's complement)
  std::uint8_t size = 4;      ///< bytes, 1..4
  bool is_signed = false;
  bool expect_only = false;   ///< `expect`: read and compare, never written
  std::string origin;         ///< "config/drives/simdrive.sdo:12", for messages
};

/// Entries one file may hold: a drive's configurable objects are dozens, and
/// every entry costs two SDO transfers at each start-up (estimate_startup).
inline constexpr std::size_t kMaxSdoEntries = 1024;

/// Parse the list; `source` names the file in messages. Throws InputError
/// "<source>:<line>: ..." for a malformed line, and at the entry past
/// kMaxSdoEntries.
std::vector<SdoEntry> parse_sdo_list(const std::string& text, const std::string& source);
/// Read and parse a file. Throws InputError (cannot open, malformed line).
std::vector<SdoEntry> load_sdo_list(const std::string& path);
/// The value as the file wrote it ("6", "-3", "0x0000F5E0").
std::string sdo_value_text(const SdoEntry& e, std::uint32_t raw);

}  // namespace foresight::hw
