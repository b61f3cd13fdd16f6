// Child processes for the ground's orchestration (processes.hpp).
#include "foresight/session/processes.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace foresight::session {

namespace {
using Clock = std::chrono::steady_clock;
}  // namespace

std::string executable_dir() { return std::filesystem::read_symlink("/proc/self/exe").parent_path().string(); }

std::string read_log(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

pid_t spawn(const std::vector<std::string>& args, const std::string& out_path, const std::string& err_path) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    ::setpgid(0, 0);
    if (!out_path.empty()) {
      const int fd = ::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 1);
    }
    if (!err_path.empty()) {
      const int fd = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 2);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

int wait_for(pid_t pid, double timeout_s, const std::function<bool()>& interrupted,
             const std::function<void()>& on_interrupt) {
  const auto t0 = Clock::now();
  int status = 0;
  bool forwarded = false;
  while (since(t0) < timeout_s) {
    const pid_t w = ::waitpid(pid, &status, WNOHANG);
    if (w == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
    if (w < 0) return -2;
    if (!forwarded && on_interrupt && interrupted && interrupted()) {
      on_interrupt();
      forwarded = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return -1;
}

int stop_child(pid_t pid, double grace_s) {
  if (pid <= 0) return 0;
  ::kill(pid, SIGTERM);
  int rc = wait_for(pid, grace_s);
  if (rc == -1) {
    ::kill(pid, SIGKILL);
    rc = wait_for(pid, 5.0);
  }
  return rc;
}

bool wait_for_line(const std::string& path, const std::string& needle, pid_t pid, double timeout_s, int* exit_code,
                   std::string* line_found, const std::function<bool()>& interrupted) {
  const auto t0 = Clock::now();
  *exit_code = -1;
  while (since(t0) < timeout_s && !(interrupted && interrupted())) {
    std::istringstream in(read_log(path));
    for (std::string line; std::getline(in, line);)
      if (line.find(needle) != std::string::npos) {
        if (line_found) *line_found = line;
        return true;
      }
    int status = 0;
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      *exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -2;
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

}  // namespace foresight::session
