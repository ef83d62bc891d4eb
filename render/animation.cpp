#include "render/animation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "moreau/core/error.hpp"

namespace moreau::render {

namespace fs = std::filesystem;

namespace {

// The encoder runs without LD_PRELOAD: a host that preloads sanitizer runtimes (the Python
// tests under the dev preset) must not impose them on ffmpeg.
constexpr const char* kFfmpeg = "env -u LD_PRELOAD ffmpeg";

std::string Quote(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

void RunOrThrow(const std::string& command, const std::string& what) {
  const int code = std::system(command.c_str());
  if (code != 0) {
    throw std::runtime_error("ffmpeg failed while " + what + " (exit status " +
                             std::to_string(code) + "): " + command);
  }
}

// The events of which snapshots are taken: all, or max_snapshots spread evenly.
std::vector<Event> SnapshotEvents(const std::vector<Event>& events, int max_snapshots, double t0,
                                  double tf) {
  std::vector<Event> inside;
  for (const Event& e : events) {
    if (e.t >= t0 && e.t <= tf) inside.push_back(e);
  }
  if (static_cast<int>(inside.size()) <= max_snapshots) return inside;
  std::vector<Event> chosen;
  for (int k = 0; k < max_snapshots; ++k) {
    const double position =
        max_snapshots == 1 ? 0.0 : k * (inside.size() - 1.0) / (max_snapshots - 1.0);
    chosen.push_back(inside[static_cast<std::size_t>(std::lround(position))]);
  }
  return chosen;
}

}  // namespace

void AnimationOptions::Validate() const {
  RequireArgument(std::isfinite(fps) && fps >= 1.0 && fps <= 120.0, "fps must be in [1, 120], got ",
                  fps);
  RequireArgument(std::isfinite(duration) && duration > 0.0, "duration must be > 0 seconds, got ",
                  duration);
  RequireArgument(std::isfinite(speed) && speed >= 0.0,
                  "speed must be >= 0 (simulation time per second of video; 0: use duration), got ",
                  speed);
  RequireArgument(width >= 16 && width <= 8192, "width must be in [16, 8192] pixels, got ", width);
  RequireArgument(gif_width >= 16 && gif_width <= 8192,
                  "GIF width must be in [16, 8192] pixels, got ", gif_width);
  RequireArgument(std::isfinite(gif_fps) && gif_fps >= 1.0 && gif_fps <= 50.0,
                  "GIF rate must be in [1, 50] frames per second, got ", gif_fps);
  RequireArgument(max_snapshots >= 0, "snapshots must be >= 0, got ", max_snapshots);
}

bool FfmpegAvailable() {
  return std::system((std::string(kFfmpeg) + " -version > /dev/null 2>&1").c_str()) == 0;
}

AnimationStats Animate(const CompiledView& view, TrajectorySource* source,
                       const std::vector<double>& window, const std::vector<Event>& events,
                       const AnimationOptions& options) {
  options.Validate();
  const auto start = std::chrono::steady_clock::now();
  const bool video = !options.mp4_path.empty() || !options.gif_path.empty();
  if (video && !FfmpegAvailable()) {
    throw std::runtime_error(
        "writing MP4 or GIF needs ffmpeg, which was not found: install the Debian package "
        "ffmpeg (scripts/bootstrap does), or ask for PNG snapshots and frames only");
  }
  const double t0 = view.initial_time(), tf = view.final_time();
  const double seconds = options.speed > 0.0 ? (tf - t0) / options.speed : options.duration;
  const long num_frames = std::max(2L, std::lround(seconds * options.fps) + 1);
  RequireArgument(num_frames <= 1'000'000, "animation would have ", num_frames,
                  " frames; lower fps or duration, or raise speed");

  FrameRenderer renderer(view, window, options.width);
  AnimationStats stats;
  // The MP4 is the master: the GIF is made from it (one encoding pass over the frames).
  std::string mp4 = options.mp4_path;
  if (mp4.empty() && !options.gif_path.empty()) mp4 = options.gif_path + ".tmp.mp4";
  FILE* pipe = nullptr;
  if (!mp4.empty()) {
    char rate[32];
    std::snprintf(rate, sizeof rate, "%.6g", options.fps);
    const std::string command =
        std::string(kFfmpeg) + " -y -loglevel error -f rawvideo -pixel_format bgra -video_size " +
        std::to_string(renderer.width()) + "x" + std::to_string(renderer.height()) +
        " -framerate " + rate +
        " -i - -c:v libx264 -pix_fmt yuv420p -crf 23 -movflags +faststart " + Quote(mp4);
    pipe = popen(command.c_str(), "w");
    if (pipe == nullptr) throw std::runtime_error("cannot start ffmpeg: " + command);
  }
  if (!options.snapshot_directory.empty()) fs::create_directories(options.snapshot_directory);
  if (!options.frame_directory.empty()) fs::create_directories(options.frame_directory);

  const std::vector<Event> snapshots = options.snapshot_directory.empty()
                                           ? std::vector<Event>()
                                           : SnapshotEvents(events, options.max_snapshots, t0, tf);
  std::size_t next_snapshot = 0;
  Sampler sampler(source);
  Vector x;
  const int row_bytes = 4 * renderer.width();
  bool write_failed = false;
  for (long k = 0; k < num_frames; ++k) {
    const double t = k + 1 == num_frames ? tf : t0 + (tf - t0) * k / (num_frames - 1.0);
    // Snapshots at event times up to this frame's time, in order (the sampler only advances).
    while (next_snapshot < snapshots.size() && snapshots[next_snapshot].t <= t) {
      const Event& e = snapshots[next_snapshot];
      if (!sampler.At(e.t, &x)) break;
      renderer.Draw(e.t, x, false);
      char name[96];
      std::snprintf(name, sizeof name, "/snapshot_%02zu_t%.6g.png", next_snapshot, e.t);
      const std::string path = options.snapshot_directory + name;
      renderer.WritePng(path);
      stats.files.push_back(path);
      ++stats.snapshots;
      ++next_snapshot;
    }
    RequireArgument(sampler.At(t, &x), "nothing to animate: the trajectory is empty");
    renderer.Draw(t, x);
    ++stats.frames;
    if (!options.frame_directory.empty()) {
      char name[32];
      std::snprintf(name, sizeof name, "/frame_%05ld.png", k);
      renderer.WritePng(options.frame_directory + name);
    }
    if (pipe != nullptr && !write_failed) {
      for (int row = 0; row < renderer.height(); ++row) {
        const unsigned char* data = renderer.data() + row * renderer.stride();
        if (std::fwrite(data, 1, static_cast<std::size_t>(row_bytes), pipe) !=
            static_cast<std::size_t>(row_bytes)) {
          write_failed = true;
          break;
        }
      }
    }
  }
  if (pipe != nullptr) {
    const int code = pclose(pipe);
    if (code != 0 || write_failed) {
      throw std::runtime_error("ffmpeg failed to encode '" + mp4 + "' (exit status " +
                               std::to_string(code) + ")");
    }
    if (!options.mp4_path.empty()) stats.files.push_back(mp4);
  }
  if (!options.gif_path.empty()) {
    const std::string palette = options.gif_path + ".palette.png";
    char filters[160];
    std::snprintf(filters, sizeof filters, "fps=%.6g,scale=%d:-2:flags=lanczos",
                  std::min(options.fps, options.gif_fps), options.gif_width);
    RunOrThrow(std::string(kFfmpeg) + " -y -loglevel error -i " + Quote(mp4) + " -vf '" + filters +
                   ",palettegen=max_colors=32:stats_mode=diff' " + Quote(palette),
               "making the GIF palette");
    RunOrThrow(std::string(kFfmpeg) + " -y -loglevel error -i " + Quote(mp4) + " -i " +
                   Quote(palette) + " -lavfi '" + filters +
                   " [v]; [v][1:v] paletteuse=dither=none:diff_mode=rectangle' " +
                   Quote(options.gif_path),
               "writing the GIF");
    fs::remove(palette);
    if (options.mp4_path.empty()) fs::remove(mp4);
    stats.files.push_back(options.gif_path);
  }
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

AnimationStats AnimateTrajectory(const Scene& scene, const Trajectory& trajectory,
                                 double final_time, const std::vector<Event>& events,
                                 const AnimationOptions& options) {
  Scene drawn = scene;
  drawn.final_time = final_time;
  const CompiledView view(drawn);
  std::vector<double> window;
  {
    MemorySource first_pass(trajectory);
    window = FitWindow(view, &first_pass);
  }
  MemorySource source(trajectory);
  return Animate(view, &source, window, events, options);
}

}  // namespace moreau::render
