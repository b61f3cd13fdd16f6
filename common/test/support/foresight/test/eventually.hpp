#pragma once
// Waiting for a condition in a test: with a deadline, never a fixed sleep
// (CI machines are loaded and slow).

#include <chrono>
#include <thread>
#include <utility>

namespace foresight::test {

/// Polls `condition` every `poll` (10 ms) until it holds or `timeout`
/// passes; returns the last answer.
template <class F>
bool eventually(F condition, std::chrono::nanoseconds timeout,
                std::chrono::nanoseconds poll = std::chrono::milliseconds(10)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(poll);
  }
  return condition();
}

/// The same with the timeout in seconds.
template <class F>
bool eventually(F condition, double timeout_s, std::chrono::nanoseconds poll = std::chrono::milliseconds(10)) {
  return eventually(std::move(condition),
                    std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(timeout_s)), poll);
}

}  // namespace foresight::test
