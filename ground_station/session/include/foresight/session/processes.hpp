#pragma once
// Child processes for the ground's orchestration (`foresight demo`: the
// daemon, the link emulator, the ground half in its namespace). Each child
// runs in its own process group, so a terminal's Ctrl-C reaches only the
// parent, which stops its children in order. Set-up code, not real-time.

#include <sys/types.h>

#include <chrono>
#include <functional>
#include <string>
#include <vector>

namespace foresight::session {

/// Seconds since t0 on the steady clock (the orchestration's timings).
inline double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// Starts `args` (args[0] an executable path); stdout/stderr to the files
/// ("" = inherited). std::runtime_error when fork fails.
pid_t spawn(const std::vector<std::string>& args, const std::string& out_path, const std::string& err_path);

/// Waits for `pid` at most `timeout_s`: its exit status, -1 when it did not
/// end in time (still running), -2 when killed by a signal. `on_interrupt`
/// runs once, the first time `interrupted` returns true (e.g. to forward
/// the interrupt to the child).
int wait_for(pid_t pid, double timeout_s, const std::function<bool()>& interrupted = {},
             const std::function<void()>& on_interrupt = {});

/// SIGTERM, then SIGKILL after `grace_s`; the exit status (as wait_for).
int stop_child(pid_t pid, double grace_s);

/// Polls the file `path` for a line containing `needle` (the line in
/// *line_found); false when `pid` exits, `interrupted` returns true or the
/// deadline passes first (*exit_code: the exit status, or -1 when it is
/// still up).
bool wait_for_line(const std::string& path, const std::string& needle, pid_t pid, double timeout_s, int* exit_code,
                   std::string* line_found = nullptr, const std::function<bool()>& interrupted = {});

/// The directory of this executable: where its sibling programs
/// (foresight-remote, foresight-linkemu) are installed and built.
std::string executable_dir();

/// The whole file ("" when it cannot be read): for logs and the children's outputs.
std::string read_log(const std::string& path);

}  // namespace foresight::session
