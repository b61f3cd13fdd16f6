#pragma once
// Running the built `foresight` executable from a test: its exit status,
// stdout and stderr, and scratch files under /tmp. One copy for every CLI test.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

namespace foresight::test {

struct CliRun {
  int status = -1;  ///< exit status; -1 when killed by a signal or not started
  std::string out;
  std::string err;
};

/// A fresh path "/tmp/foresight_test_XXXXXX<suffix>" (nothing created there).
inline std::string temp_path(const std::string& suffix) {
  char name[] = "/tmp/foresight_test_XXXXXX";
  const int fd = mkstemp(name);
  EXPECT_GE(fd, 0);
  ::close(fd);
  std::remove(name);
  return std::string(name) + suffix;
}

/// Writes `text` to a fresh temporary file; returns its path.
inline std::string write_temp_file(const std::string& text, const std::string& suffix = ".csv") {
  const std::string p = temp_path(suffix);
  std::ofstream(p) << text;
  return p;
}

inline std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Runs the shell command `cmd` to its end: its exit status, stdout, and
/// stderr (what `cmd` does not redirect itself).
inline CliRun run_shell(const std::string& cmd) {
  const std::string err_path = temp_path(".err");
  CliRun r;
  FILE* p = popen(("{ " + cmd + "\n} 2>" + err_path).c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  r.err = read_file(err_path);
  std::remove(err_path.c_str());
  return r;
}

/// Runs the built executable `program` (foresight, foresight-remote) with
/// `args` (through the shell) under a 300 s limit.
inline CliRun run_program(const std::string& program, const std::string& args) {
  return run_shell("timeout 300 " + std::string(FORESIGHT_BIN_DIR) + "/" + program + " " + args);
}

/// Runs `foresight <args>` (args go through the shell) with a 300 s limit.
inline CliRun run_foresight(const std::string& args) { return run_program("foresight", args); }

}  // namespace foresight::test
