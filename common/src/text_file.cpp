#include "foresight/common/text_file.hpp"

#include <fstream>
#include <sstream>

#include "foresight/common/error.hpp"

namespace foresight {

std::string read_text_file(const std::string& path, const std::string& cannot_open) {
  std::ifstream in(path);
  if (!in) throw InputError(path, cannot_open);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace foresight
