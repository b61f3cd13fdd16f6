#pragma once
// JSON out, whatever bytes the values hold: nlohmann's dump() throws on a
// string that is not UTF-8 (a file name, a key or a reason may hold any
// bytes). Every JSON that carries text from outside is written through this:
// invalid bytes become U+FFFD, the rest is exactly dump()'s.

#include <nlohmann/json.hpp>
#include <string>

namespace foresight {

/// `j` as JSON text (`indent` as nlohmann's dump: -1 one line), never throwing
/// on bytes that are not UTF-8.
inline std::string json_text(const nlohmann::json& j, int indent = -1) {
  return j.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace foresight
