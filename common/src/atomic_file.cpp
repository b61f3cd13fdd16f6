#include "foresight/common/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "foresight/common/error.hpp"

namespace foresight {

namespace {

std::string folder_of(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

}  // namespace

void check_output_path(const std::string& path) {
  if (path.empty()) throw InputError("output path is empty");
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "is a directory");
  const std::string dir = folder_of(path);
  if (!std::filesystem::is_directory(dir, ec)) throw InputError(path, "folder '" + dir + "' does not exist");
}

namespace {

/// Writes `content` to the device or FIFO `path` in place (/dev/stdout,
/// /dev/full): never replaced by a regular file, and a failed write is an
/// error (ComputationError "<path>: cannot write (<reason>)").
void write_in_place(const std::string& path, std::string_view content) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);  // a FIFO without a reader: ENXIO
  if (fd < 0) throw ComputationError(path + ": cannot write (" + std::strerror(errno) + ")");
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  std::size_t done = 0;
  for (int attempts = 0; done < content.size(); ++attempts) {
    const ssize_t n = ::write(fd, content.data() + done, content.size() - done);
    if (n < 0 && errno == EINTR && attempts < 1000) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : ENOSPC;
      ::close(fd);
      throw ComputationError(path + ": cannot write (" + std::strerror(err) + ")");
    }
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0) throw ComputationError(path + ": cannot write (" + std::strerror(errno) + ")");
}

}  // namespace

void write_file_atomic(const std::string& path, std::string_view content) {
  check_output_path(path);
  if (struct stat existing {}; ::stat(path.c_str(), &existing) == 0 && !S_ISREG(existing.st_mode)) {
    write_in_place(path, content);  // a device or FIFO: renaming a file over it would replace the device
    return;
  }
  std::string tmp_name = path + ".tmpXXXXXX";
  std::vector<char> tmp(tmp_name.begin(), tmp_name.end());
  tmp.push_back('\0');
  const int fd = ::mkstemp(tmp.data());
  if (fd < 0) throw ComputationError(path + ": cannot write (" + std::strerror(errno) + ")");
  const std::string tmp_path(tmp.data());
  auto fail = [&](int err) {
    ::close(fd);
    ::unlink(tmp_path.c_str());
    throw ComputationError(path + ": cannot write (" + std::strerror(err) + "); the old file is unchanged");
  };
  // Keep the permissions of the file being replaced (mkstemp makes 0600), else 0644 less the umask.
  struct stat st {};
  mode_t mode = 0644;
  if (::stat(path.c_str(), &st) == 0) {
    mode = st.st_mode & 07777;
  } else {
    const mode_t mask = ::umask(0);
    ::umask(mask);
    mode &= ~mask;
  }
  if (::fchmod(fd, mode) != 0) fail(errno);
  std::size_t done = 0;
  for (int attempts = 0; done < content.size(); ++attempts) {  // bounded: each pass writes >= 1 byte or fails
    const ssize_t n = ::write(fd, content.data() + done, content.size() - done);
    if (n < 0 && errno == EINTR && attempts < 1000) continue;
    if (n <= 0) fail(n < 0 ? errno : ENOSPC);
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0) fail(errno);
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp_path.c_str());
    throw ComputationError(path + ": cannot write (" + std::strerror(err) + "); the old file is unchanged");
  }
  if (::rename(tmp_path.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp_path.c_str());
    throw ComputationError(path + ": cannot write (" + std::strerror(err) + "); the old file is unchanged");
  }
  const int dfd = ::open(folder_of(path).c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {  // the rename itself durable; best effort (some filesystems refuse fsync on a folder)
    ::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace foresight
