#pragma once
// Errors raised while loading configuration and data (non-real-time code).
// Every message names where the problem is: a file, and a line or element.

#include <stdexcept>
#include <string>

namespace foresight {

/// A configuration or data file is missing, unreadable or malformed.
/// what() reads "<file>[:<line>]: <message>" so an operator can find it.
class InputError : public std::runtime_error {
 public:
  InputError(std::string file, int line, const std::string& message)
      : std::runtime_error(format(file, line, message)), file_(std::move(file)), line_(line) {}
  InputError(std::string file, const std::string& message) : InputError(std::move(file), 0, message) {}

  const std::string& file() const noexcept { return file_; }
  /// 1-based line number, 0 when the problem is not tied to a line.
  int line() const noexcept { return line_; }

 private:
  static std::string format(const std::string& file, int line, const std::string& message) {
    return line > 0 ? file + ":" + std::to_string(line) + ": " + message : file + ": " + message;
  }
  std::string file_;
  int line_;
};

}  // namespace foresight
