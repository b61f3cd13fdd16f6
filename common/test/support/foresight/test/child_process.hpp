#pragma once
// A program a test runs beside itself (the daemon, a DDS peer, an X server):
// started with fork/exec, its stdout piped to the test when asked (to wait
// for a ready line) and its stderr to a file, stopped with a signal and a
// deadline, and never left behind: the destructor sends SIGTERM, then
// SIGKILL. Every wait has a deadline.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace foresight::test {

class ChildProcess {
 public:
  struct Options {
    bool pipe_stdout = false;  ///< false: stdout inherited (wait_for_line needs it piped)
    std::string stdout_path;   ///< with pipe_stdout false: stdout to this file ("" = inherited)
    std::string stderr_path;   ///< "" = inherited; "/dev/null" to silence it
    double stop_grace_s = 10.0;  ///< the destructor's SIGTERM-to-SIGKILL wait
  };

  /// Starts args[0] (a path) with args[1..]. std::runtime_error when fork fails.
  ChildProcess(std::vector<std::string> args, Options options) : options_(std::move(options)) {
    int out[2] = {-1, -1};
    if (options_.pipe_stdout && ::pipe(out) != 0) throw std::runtime_error("pipe failed");
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      if (options_.pipe_stdout) {
        ::dup2(out[1], 1);
        ::close(out[0]);
        ::close(out[1]);
      } else if (!options_.stdout_path.empty()) {
        const int fd = ::open(options_.stdout_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd >= 0) ::dup2(fd, 1);
      }
      if (!options_.stderr_path.empty()) {
        const int err = ::open(options_.stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (err >= 0) ::dup2(err, 2);
      }
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    if (options_.pipe_stdout) {
      ::close(out[1]);
      out_fd_ = out[0];
    }
  }
  explicit ChildProcess(std::vector<std::string> args) : ChildProcess(std::move(args), Options{}) {}

  ~ChildProcess() {
    if (running()) {
      ::kill(pid_, SIGTERM);
      if (wait_exit(options_.stop_grace_s) == -2) {
        ::kill(pid_, SIGKILL);
        wait_exit(5.0);
      }
    }
    if (out_fd_ >= 0) ::close(out_fd_);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }

  /// True while the program runs (reaps it once it has ended).
  bool running() {
    if (pid_ <= 0 || reaped_) return false;
    int st = 0;
    if (::waitpid(pid_, &st, WNOHANG) != pid_) return true;
    reap(st);
    return false;
  }

  /// Reads the piped stdout until `text` appears (true), the program closes
  /// it or exits (false), or `timeout_s` passes (false).
  bool wait_for_line(const std::string& text, double timeout_s) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < deadline) {
      if (stdout_.find(text) != std::string::npos) return true;
      if (out_fd_ < 0) return false;
      pollfd p{out_fd_, POLLIN, 0};
      const int ready = ::poll(&p, 1, 100);
      if (ready < 0 && errno != EINTR) return false;
      if (ready <= 0 || (p.revents & (POLLIN | POLLHUP)) == 0) continue;  // a signal or nothing yet
      char buf[512];
      const ssize_t n = ::read(out_fd_, buf, sizeof buf);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return stdout_.find(text) != std::string::npos;  // closed: the program ended
      stdout_.append(buf, static_cast<std::size_t>(n));
    }
    return stdout_.find(text) != std::string::npos;
  }

  /// Sends `sig` and waits up to `timeout_s` for the exit: the exit status,
  /// 128 + signal when killed by one, -2 on timeout.
  int stop(int sig = SIGTERM, double timeout_s = 20.0) {
    if (pid_ <= 0 || reaped_) return exit_status_;
    ::kill(pid_, sig);
    return wait_exit(timeout_s);
  }

  /// Waits up to `timeout_s` for the exit (as stop, without a signal).
  int wait_exit(double timeout_s) {
    if (pid_ <= 0 || reaped_) return exit_status_;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < deadline) {
      int st = 0;
      if (::waitpid(pid_, &st, WNOHANG) == pid_) {
        reap(st);
        return exit_status_;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return -2;
  }

 private:
  void reap(int st) {
    reaped_ = true;
    exit_status_ = WIFEXITED(st) ? WEXITSTATUS(st) : WIFSIGNALED(st) ? 128 + WTERMSIG(st) : -1;
  }

  Options options_;
  pid_t pid_ = -1;
  int out_fd_ = -1;
  std::string stdout_;
  bool reaped_ = false;
  int exit_status_ = -1;
};

}  // namespace foresight::test
