#pragma once
// The real daemon `foresight-remote --sim` as a child process of a test: started
// with its own journal and DDS domain, ready once it printed its ready line,
// stopped with SIGTERM (its exit status checked) or killed with SIGKILL.
// Every wait has a deadline; the destructor never leaves the child behind.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

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
    int out[2];
    if (pipe(out) != 0) throw std::runtime_error("pipe failed");
    pid_ = fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      dup2(out[1], 1);
      const int err = ::open(log_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (err >= 0) dup2(err, 2);
      ::close(out[0]);
      ::close(out[1]);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    ::close(out[1]);
    out_fd_ = out[0];
    ready_ = wait_for_line("foresight-remote: ready", options_.ready_timeout_s);
  }

  ~RemoteProcess() {
    if (pid_ > 0 && !reaped_) {
      ::kill(pid_, SIGTERM);
      if (wait_exit(15.0) < -1) {
        ::kill(pid_, SIGKILL);
        wait_exit(5.0);
      }
    }
    if (out_fd_ >= 0) ::close(out_fd_);
  }
  RemoteProcess(const RemoteProcess&) = delete;
  RemoteProcess& operator=(const RemoteProcess&) = delete;

  bool ready() const { return ready_; }
  pid_t pid() const { return pid_; }
  const std::string& journal() const { return options_.journal; }
  std::string log() const { return read_file(log_path_); }

  /// Sends `sig` and waits up to timeout_s for the exit. Returns the exit
  /// status, 128 + signal when killed by one, -2 on timeout.
  int stop(int sig = SIGTERM, double timeout_s = 20.0) {
    if (pid_ <= 0 || reaped_) return exit_status_;
    ::kill(pid_, sig);
    return wait_exit(timeout_s);
  }

 private:
  bool wait_for_line(const std::string& line, double timeout_s) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    std::string seen;
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd p{out_fd_, POLLIN, 0};
      if (::poll(&p, 1, 100) > 0) {
        char buf[512];
        const ssize_t n = ::read(out_fd_, buf, sizeof buf);
        if (n <= 0) return false;  // the daemon exited
        seen.append(buf, static_cast<std::size_t>(n));
        if (seen.find(line) != std::string::npos) return true;
      }
    }
    return false;
  }

  int wait_exit(double timeout_s) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < deadline) {
      int st = 0;
      const pid_t r = ::waitpid(pid_, &st, WNOHANG);
      if (r == pid_) {
        reaped_ = true;
        exit_status_ = WIFEXITED(st) ? WEXITSTATUS(st) : WIFSIGNALED(st) ? 128 + WTERMSIG(st) : -1;
        return exit_status_;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -2;
  }

  Options options_;
  std::string log_path_;
  pid_t pid_ = -1;
  int out_fd_ = -1;
  bool ready_ = false;
  bool reaped_ = false;
  int exit_status_ = -1;
};

}  // namespace foresight::test
