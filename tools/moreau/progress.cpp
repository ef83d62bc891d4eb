#include "progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <utility>

namespace moreau::tool {

ProgressBar::ProgressBar(std::string label, bool enabled)
    : label_(std::move(label)),
      enabled_(enabled),
      tty_(isatty(STDERR_FILENO) != 0),
      start_(Clock::now()),
      last_(start_) {}

bool ProgressBar::Due(double* elapsed) {
  const auto now = Clock::now();
  *elapsed = std::chrono::duration<double>(now - start_).count();
  const double since_last = std::chrono::duration<double>(now - last_).count();
  if (*elapsed < kProgressDelaySeconds || since_last < (tty_ ? 0.2 : 5.0)) return false;
  last_ = now;
  return true;
}

void ProgressBar::Draw(double fraction, double elapsed, const std::string& detail) {
  fraction = std::clamp(fraction, 0.0, 1.0);
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(kWidth * fraction);
  std::string eta;
  if (fraction > 0.0 && fraction < 1.0) {
    char text[32];
    std::snprintf(text, sizeof text, ", ETA %.0f s", elapsed * (1.0 - fraction) / fraction);
    eta = text;
  }
  std::fprintf(stderr, "%s[%s] [%s%s] %5.1f%%  %s%s%s", tty_ ? "\r" : "", label_.c_str(),
               std::string(static_cast<std::size_t>(filled), '#').c_str(),
               std::string(static_cast<std::size_t>(kWidth - filled), '.').c_str(),
               100.0 * fraction, detail.c_str(), eta.c_str(), tty_ ? "   " : "\n");
  printed_ = true;
}

void ProgressBar::Finish(double fraction, const std::string& detail) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!printed_) return;
  Draw(fraction, std::chrono::duration<double>(Clock::now() - start_).count(), detail);
  if (tty_) std::fprintf(stderr, "\n");
  printed_ = false;
}

}  // namespace moreau::tool
