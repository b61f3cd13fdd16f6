#pragma once
// Reading a whole input file (configuration, CSV) into memory before parsing
// it, so that the parsers work on text and name the file in their messages.
// The size is bounded (input_limits.hpp): an endless or huge file is refused.

#include <cstddef>
#include <string>

#include "foresight/common/input_limits.hpp"

namespace foresight {

/// Refuses what is not a file to read to its end: InputError "<path>: is a
/// FIFO, not a file (its reader would wait for a writer for ever)", "... is a
/// socket, not a file", "<path>: is a directory"; "<path>: <cannot_open>"
/// when it cannot be opened. Checked without blocking (O_NONBLOCK), before
/// any reader opens it. Character devices (/dev/zero) pass: the size and line
/// bounds stop those.
void require_input_file(const std::string& path, const std::string& cannot_open);

/// The contents of the file `path` (require_input_file first). InputError "<path>: <cannot_open>" when
/// it cannot be opened, "<path>: file is larger than N bytes" beyond
/// `max_bytes` (read stops there).
std::string read_text_file(const std::string& path, const std::string& cannot_open,
                           std::size_t max_bytes = limits::kMaxTextFileBytes);

}  // namespace foresight

#include <istream>

namespace foresight {

/// Reads a text stream line by line with a bounded line length, so that a
/// file without newlines (/dev/zero) is refused instead of read whole.
class LineReader {
 public:
  /// `source` names the stream in messages.
  LineReader(std::istream& in, std::string source, std::size_t max_line_bytes = limits::kMaxLineBytes);
  /// The next line without its '\n' (a trailing '\r' kept); false at the end.
  /// InputError "<source>:<line>: line longer than N bytes".
  bool next(std::string& line);
  /// 1-based number of the line last returned.
  int line_no() const { return line_no_; }

 private:
  std::istream& in_;
  std::string source_;
  std::string buffer_;
  int line_no_ = 0;
};

}  // namespace foresight
