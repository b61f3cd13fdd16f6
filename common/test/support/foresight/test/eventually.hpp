#pragma once
// Waiting for a condition in a test: with a deadline, never a fixed sleep
// (CI machines are loaded and slow).

#include <chrono>
#include <thread>

namespace foresight::test {

/// Polls `condition` every 10 ms until it holds or `timeout` passes; returns
/// the last answer.
template <class F>
bool eventually(F condition, std::chrono::nanoseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return condition();
}

}  // namespace foresight::test
