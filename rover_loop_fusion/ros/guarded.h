// One way to run code that may throw where nothing may escape: the host's threads (inside
// loop_fusion), ROS callbacks, destructors. What was thrown is logged with ROS_ERROR naming
// what was being done, and the caller decides the safe outcome from the return value (the
// rule: a loop that cannot be verified is rejected).
#pragma once

#include <ros/console.h>

#include <exception>
#include <string>
#include <utility>

namespace rover_loop_fusion {

namespace detail {
inline void reportThrow(const std::string& what, const char* why, std::string* error) noexcept {
  try {
    ROS_ERROR("[rover] %s: %s", what.c_str(), why);
    if (error) *error = why;
  } catch (...) {
  }
}
}  // namespace detail

/// Runs f(). Returns true if it returned normally; false if it threw, after a ROS_ERROR
/// "[rover] <what>: <exception text>" (and the text in *error, if given). Never throws.
template <typename F>
bool guarded(const std::string& what, F&& f, std::string* error = nullptr) noexcept {
  try {
    std::forward<F>(f)();
    return true;
  } catch (const std::exception& e) {
    detail::reportThrow(what, e.what(), error);
  } catch (...) {
    detail::reportThrow(what, "unknown exception", error);
  }
  return false;
}

}  // namespace rover_loop_fusion
