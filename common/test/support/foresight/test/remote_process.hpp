#pragma once
// The real daemon `foresight-remote --sim` as a child process of a test: started
// with its own journal and DDS domain, ready once it printed its ready line,
// stopped with SIGTERM (its exit status checked) or killed with SIGKILL.
// Every wait has a deadline; the destructor never leaves the child behind.

#include <gtest/gtest.h>
#include <signal.h>

#include <memory>
#include <string>
#include <vector>

#include "foresight/test/child_process.hpp"
#include "foresight/test/cli.hpp"

namespace foresight::test {

class RemoteProcess {
 public:
  struct Options {
    int domain = 0;                       ///< FORESIGHT_DDS_DOMAIN / --domain
    std::string journal;                  ///< "" = a fresh temporary file
    std::string estop_file;               ///< --estop-file ("" = none)
    std::string config = FORESIGHT_CONFIG_DIR "/remote.yaml";
    std::vector<std::string> extra_args;
    double ready_timeout_s = 60.0;
  };

  explicit RemoteProcess(Options options) : options_(std::move(options)) {
    if (options_.journal.empty()) options_.journal = temp_path(".db");
    log_path_ = temp_path(".log");
    std::vector<std::string> args = {std::string(FORESIGHT_BIN_DIR) + "/foresight-remote", "--sim", "--config",
                                     options_.config, "--journal", options_.journal, "--domain",
                                     std::to_string(options_.domain)};
    if (!options_.estop_file.empty()) {
      args.push_back("--estop-file");
      args.push_back(options_.estop_file);
    }
    for (const auto& a : options_.extra_args) args.push_back(a);
    ChildProcess::Options o;
    o.pipe_stdout = true;
    o.stderr_path = log_path_;
    o.stop_grace_s = 15.0;
    process_ = std::make_unique<ChildProcess>(std::move(args), o);
    ready_ = process_->wait_for_line("foresight-remote: ready", options_.ready_timeout_s);
  }
  RemoteProcess(const RemoteProcess&) = delete;
  RemoteProcess& operator=(const RemoteProcess&) = delete;

  bool ready() const { return ready_; }
  pid_t pid() const { return process_->pid(); }
  const std::string& journal() const { return options_.journal; }
  std::string log() const { return read_file(log_path_); }

  /// Sends `sig` and waits up to timeout_s for the exit. Returns the exit
  /// status, 128 + signal when killed by one, -2 on timeout.
  int stop(int sig = SIGTERM, double timeout_s = 20.0) { return process_->stop(sig, timeout_s); }

 private:
  Options options_;
  std::string log_path_;
  std::unique_ptr<ChildProcess> process_;
  bool ready_ = false;
};

}  // namespace foresight::test
