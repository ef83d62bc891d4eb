#pragma once
// Animations of planar scenes: frames at a fixed rate in simulation time, streamed one at a
// time as raw BGRA to an ffmpeg process that encodes the MP4 (H.264), then a GIF made from the
// MP4 in two passes (palettegen, paletteuse: neither holds the whole clip), and PNG snapshots
// at event times. Memory: one frame, two trajectory points and the trails.

#include <string>
#include <vector>

#include "moreau/model/events.hpp"
#include "render/frame.hpp"

namespace moreau::render {

struct AnimationOptions {
  /// Frames per second of video, in [1, 120].
  double fps = 25.0;
  /// Seconds of video for the whole horizon (> 0); ignored when `speed` > 0.
  double duration = 10.0;
  /// Simulation time per second of video; 0: the horizon lasts `duration` seconds.
  double speed = 0.0;
  /// Frame width in pixels (the height follows the window's aspect ratio).
  int width = 720;
  /// GIF width in pixels (smaller: GIFs are large); its rate is min(fps, gif_fps).
  int gif_width = 360;
  double gif_fps = 12.0;
  /// Output paths; empty: not written.
  std::string mp4_path;
  std::string gif_path;
  /// Directory for snapshot_<k>_t<time>.png at event times; empty: none.
  std::string snapshot_directory;
  /// Most snapshots (events spread evenly when there are more), >= 0.
  int max_snapshots = 12;
  /// Also write every frame as frame_<k>.png into this directory (tests, slides); empty: no.
  std::string frame_directory;
  /// Throws std::invalid_argument for out-of-range values.
  void Validate() const;
};

struct AnimationStats {
  long frames = 0;
  int snapshots = 0;
  std::vector<std::string> files;  // everything written
  double seconds = 0.0;            // wall time
};

// Renders [t0, tf] of the trajectory (t0, tf from the view). Throws std::invalid_argument for
// bad options, and std::runtime_error if ffmpeg is needed (an MP4 or GIF asked for) but missing
// or fails, with what to do.
AnimationStats Animate(const CompiledView& view, TrajectorySource* source,
                       const std::vector<double>& window, const std::vector<Event>& events,
                       const AnimationOptions& options);

// Animates a simulation in memory: the scene's view over [t0, final_time] (where the run got),
// drawn from `trajectory` (the stage points where recorded: the densest record) in the window
// FitWindow chooses.
AnimationStats AnimateTrajectory(const Scene& scene, const Trajectory& trajectory,
                                 double final_time, const std::vector<Event>& events,
                                 const AnimationOptions& options);

// True if an `ffmpeg` executable runs.
bool FfmpegAvailable();

}  // namespace moreau::render
