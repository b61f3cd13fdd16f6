#pragma once
// The project's exceptions: one root, two branches (as libfranka's
// franka::Exception). Only set-up and ground-side code throws; real-time code
// returns errors as values.
//
//   foresight::Error                 (std::runtime_error)
//   ├── InputError        bad input: a file, option or data set that cannot be
//   │                     used as given. The CLI exits 2.
//   └── ComputationError  the input was usable but a computation or an
//                         operation failed (an estimate did not converge, IK
//                         found no solution, a plan breaks a limit, a bus or DDS
//                         call failed). The CLI exits 1.
//
// Branch members elsewhere: EstimationInputError (InputError) and
// EstimationError (ComputationError) in calibration, PlanError
// (ComputationError) in common/plan, hw::HwError (ComputationError) in
// remote_site/hw, protocol::ProtocolError (ComputationError), journal::JournalError,
// sim::LstServerError and sim::VideoSwitchServerError (ComputationError), the
// CLI's LinkFailure (ComputationError).

#include <stdexcept>
#include <string>

namespace foresight {

/// The programs' exit statuses: the branch of the exception that ended them.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;   ///< the computation failed (ComputationError; e.g. IK did not converge)
constexpr int kExitBadInput = 2;  ///< bad arguments or input files (InputError)

/// The root of every Foresight exception.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A configuration or data file is missing, unreadable or malformed, or the
/// data cannot be used as given. what() reads "<file>[:<line>]: <message>"
/// so an operator can find it (just "<message>" when no file is involved).
class InputError : public Error {
 public:
  InputError(std::string file, int line, const std::string& message)
      : Error(format(file, line, message)), file_(std::move(file)), line_(line) {}
  InputError(std::string file, const std::string& message) : InputError(std::move(file), 0, message) {}
  /// Bad input not tied to a file (e.g. a data set that determines nothing).
  explicit InputError(const std::string& message) : Error(message), line_(0) {}

  /// Empty when the problem is not tied to a file.
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

/// The input was usable but the computation or operation failed.
class ComputationError : public Error {
 public:
  using Error::Error;
};

}  // namespace foresight
