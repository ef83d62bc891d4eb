#pragma once
/// @file
/// The three error tiers of moreau:
///  1. broken internal invariants: MOREAU_ASSERT (always on; aborts with file and line);
///  2. invalid user input at the API boundary: std::invalid_argument thrown through
///     ThrowInvalidArgument / RequireArgument with a message "what, expected, got";
///  3. numerical outcomes: enum class statuses in result structs (never exceptions).

#include <sstream>
#include <stdexcept>
#include <string>

namespace moreau {
namespace internal {
[[noreturn]] void AssertionFailed(const char* condition, const char* file, int line,
                                  const std::string& message);

template <class... Args>
std::string Concat(const Args&... args) {
  std::ostringstream stream;
  stream.precision(17);
  (stream << ... << args);
  return stream.str();
}
}  // namespace internal

/// Throws std::invalid_argument whose message is the concatenation of `args`.
template <class... Args>
[[noreturn]] void ThrowInvalidArgument(const Args&... args) {
  throw std::invalid_argument(internal::Concat(args...));
}

/// Throws std::invalid_argument with the concatenated message unless `condition` holds.
template <class... Args>
void RequireArgument(bool condition, const Args&... args) {
  if (!condition) ThrowInvalidArgument(args...);
}

}  // namespace moreau

/// Checks an internal invariant in every build type; a failure is a bug in moreau.
#define MOREAU_ASSERT(condition, message)                                           \
  do {                                                                              \
    if (!(condition)) {                                                             \
      ::moreau::internal::AssertionFailed(#condition, __FILE__, __LINE__, message); \
    }                                                                               \
  } while (false)
