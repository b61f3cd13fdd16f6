#pragma once
// Reading a whole input file (configuration, CSV) into memory before parsing
// it, so that the parsers work on text and name the file in their messages.

#include <string>

namespace foresight {

/// The contents of the file `path`. InputError "<path>: <cannot_open>" when
/// it cannot be opened.
std::string read_text_file(const std::string& path, const std::string& cannot_open);

}  // namespace foresight
