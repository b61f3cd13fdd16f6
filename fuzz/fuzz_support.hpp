#pragma once
// Shared by the libFuzzer targets in fuzz/ (scripts/fuzz.sh runs them).
//
// Every target feeds hostile bytes to one parser or decoder the way the
// program does and accepts exactly the failures the program handles: a
// foresight::Error (InputError with file/line, ComputationError). Any other
// exception escaping a parser is what a CLI would report without a file or
// line (issue 13, "Exit codes"); with FORESIGHT_FUZZ_STRICT=1 it aborts, so
// the fuzzer keeps the input (see fuzz/README.md). Crashes, sanitizer reports,
// hangs (-timeout) and memory blow-ups (-rss_limit_mb) always fail.
//
// Set-up code, not real-time.

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <string>
#include <typeinfo>

#include "foresight/common/error.hpp"

namespace foresight::fuzz {

inline std::string text_of(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

inline bool strict() {
  static const bool on = [] {
    const char* v = std::getenv("FORESIGHT_FUZZ_STRICT");
    return v != nullptr && v[0] == '1';
  }();
  return on;
}

/// Runs `f`; a foresight::Error is the expected answer to bad input.
template <class F>
void expect_input_errors(F&& f) {
  try {
    f();
  } catch (const foresight::Error&) {
    // the documented answer to bad input
  } catch (const std::exception& e) {
    if (strict()) {
      std::fprintf(stderr, "fuzz: a non-foresight exception escaped (%s): %s\n", typeid(e).name(), e.what());
      std::abort();
    }
  }
}

/// A scratch file of this process (for the parsers that only take a path):
/// on tmpfs when there is one, removed at exit.
class ScratchFile {
 public:
  explicit ScratchFile(const char* suffix) {
    const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    path_ = std::string(dir) + "/foresight_fuzz_" + std::to_string(getpid()) + suffix;
  }
  ~ScratchFile() { std::remove(path_.c_str()); }
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;

  /// Replaces the file's content; returns its path.
  const std::string& write(const std::uint8_t* data, std::size_t size) {
    std::ofstream out(path_, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    return path_;
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace foresight::fuzz
