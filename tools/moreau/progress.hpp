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
  // `fraction` of the work is done (clamped to [0, 1]); detail() returns the text after the
  // percentage. It is called only when the bar is drawn: runs update the bar at every step,
  // and formatting a text each time cost a small run a few percent of its time.
  template <class Detail>
  void Update(double fraction, Detail&& detail) {
    if (!enabled_) return;
    std::lock_guard<std::mutex> lock(mutex_);
    double elapsed = 0.0;
    if (Due(&elapsed)) Draw(fraction, elapsed, detail());
  }
  // If the bar was shown: draws it at `fraction` with `detail` (the final state) and ends its
  // line.
  void Finish(double fraction, const std::string& detail);

 private:
  // (With mutex_ held.) Whether the bar is to be drawn now (kProgressDelaySeconds after the
  // start, then every 0.2 s on a terminal, 5 s otherwise); if so, notes the time and sets
  // *elapsed.
  bool Due(double* elapsed);
  void Draw(double fraction, double elapsed, const std::string& detail);
  using Clock = std::chrono::steady_clock;
  std::string label_;
  bool enabled_, tty_, printed_ = false;
  Clock::time_point start_, last_;
  std::mutex mutex_;
};

}  // namespace moreau::tool
