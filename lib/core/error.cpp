#include "moreau/core/error.hpp"

#include <cstdio>
#include <cstdlib>

namespace moreau::internal {

void AssertionFailed(const char* condition, const char* file, int line,
                     const std::string& message) {
  std::fprintf(stderr, "moreau: internal error at %s:%d: %s (%s)\n", file, line, message.c_str(),
               condition);
  std::abort();
}

}  // namespace moreau::internal
