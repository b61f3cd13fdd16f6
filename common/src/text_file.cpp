#include "foresight/common/text_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fstream>

#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"

namespace foresight {

void require_input_file(const std::string& path, const std::string& cannot_open) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw InputError(path, cannot_open);
  struct stat st {};
  const int rc = ::fstat(fd, &st);
  ::close(fd);
  if (rc != 0) throw InputError(path, cannot_open);
  if (S_ISFIFO(st.st_mode)) throw InputError(path, "is a FIFO, not a file (its reader would wait for a writer for ever)");
  if (S_ISSOCK(st.st_mode)) throw InputError(path, "is a socket, not a file");
  if (S_ISDIR(st.st_mode)) throw InputError(path, "is a directory");
}

std::string read_text_file(const std::string& path, const std::string& cannot_open, std::size_t max_bytes) {
  require_input_file(path, cannot_open);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, cannot_open);
  // Read in blocks up to the bound: an endless file (/dev/zero) is refused, not swallowed.
  std::string text;
  char block[1 << 16];
  for (;;) {
    in.read(block, sizeof block);
    const std::streamsize n = in.gcount();
    if (n > 0) {
      if (text.size() + static_cast<std::size_t>(n) > max_bytes)
        throw InputError(path, "file is larger than " + std::to_string(max_bytes) + " bytes");
      text.append(block, static_cast<std::size_t>(n));
    }
    if (!in) break;
  }
  if (in.bad()) throw InputError(path, "cannot read the file");
  return text;
}

}  // namespace foresight

namespace foresight {

LineReader::LineReader(std::istream& in, std::string source, std::size_t max_line_bytes)
    : in_(in), source_(std::move(source)), buffer_(max_line_bytes + 2, '\0') {}

bool LineReader::next(std::string& line) {
  if (!in_.good()) return false;
  in_.getline(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
  const std::streamsize n = in_.gcount();
  if (in_.fail() && !in_.eof()) {  // the buffer filled before a newline
    ++line_no_;
    throw InputError(source_, line_no_, "line longer than " + std::to_string(buffer_.size() - 2) + " bytes");
  }
  if (n == 0 && in_.eof()) return false;
  ++line_no_;
  const bool had_newline = !in_.eof();
  line.assign(buffer_.data(), static_cast<std::size_t>(n) - (had_newline ? 1 : 0));
  return true;
}

}  // namespace foresight
