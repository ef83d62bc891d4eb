#pragma once
// The progress bar of `moreau run` and `moreau sweep` on stderr.

#include <chrono>
#include <mutex>
#include <string>

namespace moreau::tool {

// Nothing is shown before a run has lasted this long: short runs print no progress at all.
inline constexpr double kProgressDelaySeconds = 2.0;

// "[run] [##########....................]  33.4%  t = 3.34 of 10, ETA 4 s" on stderr, in
// place on a terminal (every 0.2 s), one line every 5 s otherwise, from kProgressDelaySeconds
// on; a bar that was shown is drawn complete by Finish(). Thread-safe (sweeps update it from
// their worker threads). Disabled bars print nothing (--quiet).
class ProgressBar {
 public:
  ProgressBar(std::string label, bool enabled);
  // `fraction` of the work is done (clamped to [0, 1]); `detail` follows the percentage.
  void Update(double fraction, const std::string& detail);
  // If the bar was shown: draws it at `fraction` with `detail` (the final state) and ends its
  // line.
  void Finish(double fraction, const std::string& detail);

 private:
  void Draw(double fraction, double elapsed, const std::string& detail);
  using Clock = std::chrono::steady_clock;
  std::string label_;
  bool enabled_, tty_, printed_ = false;
  Clock::time_point start_, last_;
  std::mutex mutex_;
};

}  // namespace moreau::tool
