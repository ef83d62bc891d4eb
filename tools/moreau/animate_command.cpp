#include "animate_command.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "moreau/core/error.hpp"
#include "render/trajectory_source.hpp"
#include "render/view_geometry.hpp"

namespace moreau::tool {

namespace fs = std::filesystem;

void AddAnimateOptions(CLI::App* command, AnimateSettings* settings) {
  render::AnimationOptions& o = settings->options;
  command->add_option("--fps", o.fps, "animation: frames per second of video (default 25)");
  command->add_option("--duration", o.duration,
                      "animation: seconds of video for the whole horizon (default 10)");
  command->add_option("--speed", o.speed,
                      "animation: simulation time per second of video (overrides --duration)");
  command->add_option("--width", o.width, "animation: frame width in pixels (default 720)");
  command->add_option("--gif-width", o.gif_width, "animation: GIF width in pixels (default 360)");
  command->add_option("--snapshots", o.max_snapshots,
                      "animation: most PNG snapshots at event times (default 12; 0: none)");
  command->add_option("--frames", o.frame_directory,
                      "animation: also write every frame as PNG into this directory");
  command->add_flag(
      "--no-mp4", [settings](std::int64_t) { settings->mp4 = false; },
      "animation: do not write animation.mp4");
  command->add_flag(
      "--no-gif", [settings](std::int64_t) { settings->gif = false; },
      "animation: do not write animation.gif");
}

namespace {

void SetPaths(const std::string& directory, AnimateSettings* settings) {
  render::AnimationOptions& o = settings->options;
  o.mp4_path = settings->mp4 ? directory + "/animation.mp4" : "";
  o.gif_path = settings->gif ? directory + "/animation.gif" : "";
  o.snapshot_directory = o.max_snapshots > 0 ? directory + "/snapshots" : "";
  if (!o.snapshot_directory.empty()) {
    // Snapshots of an earlier animation would mix with these.
    std::error_code error;
    for (const auto& entry : fs::directory_iterator(o.snapshot_directory, error)) {
      if (entry.path().filename().string().rfind("snapshot_", 0) == 0) fs::remove(entry.path());
    }
  }
}

void Report(const render::AnimationStats& stats, bool quiet) {
  if (quiet) return;
  std::printf("animation   %ld frames, %d snapshots in %.3g s\n", stats.frames, stats.snapshots,
              stats.seconds);
  for (const std::string& file : stats.files) {
    if (file.find("/snapshot_") == std::string::npos) std::printf("  %s\n", file.c_str());
  }
  if (stats.snapshots > 0) {
    std::printf("  %d snapshots at event times in %s\n", stats.snapshots,
                fs::path(stats.files.front()).parent_path().c_str());
  }
}

}  // namespace

int RunAnimateCommand(const std::string& run_directory, AnimateSettings settings) {
  const std::string view_path = run_directory + "/view.json";
  RequireArgument(fs::is_regular_file(view_path), "'", run_directory,
                  "' is not a run directory of `moreau run` (no view.json)");
  nlohmann::json view_json, summary;
  try {
    view_json = nlohmann::json::parse(std::ifstream(view_path));
  } catch (const nlohmann::json::exception& error) {
    ThrowInvalidArgument(view_path, ": not valid JSON (", error.what(), ")");
  }
  Scene scene = render::SceneFromViewJson(view_json, view_path);
  std::vector<Event> events;
  const std::string summary_path = run_directory + "/summary.json";
  if (fs::is_regular_file(summary_path)) {
    try {
      summary = nlohmann::json::parse(std::ifstream(summary_path));
      // Runs have events; optimal control solutions (moreau ocp) may not.
      for (const auto& e : summary.value("events", nlohmann::json::array())) {
        Event event;
        event.t = e.at("t").get<double>();
        event.what = e.at("what").get<std::string>();
        events.push_back(event);
      }
      // A run that stopped early is drawn up to where it stopped.
      const double t_final = summary.value("t_final", scene.final_time);
      if (t_final < scene.final_time && t_final > scene.initial_time) {
        scene.final_time = t_final;
      }
    } catch (const nlohmann::json::exception& error) {
      ThrowInvalidArgument(summary_path, ": not a summary written by `moreau run` (", error.what(),
                           ")");
    }
  }
  const render::CompiledView view(scene);
  // Stage points (FESD) are the densest record of the run; else the trajectory.
  std::string csv = run_directory + "/stages.csv";
  if (!fs::is_regular_file(csv)) csv = run_directory + "/trajectory.csv";
  std::vector<double> window;
  {
    render::CsvSource first_pass(csv, scene.state_names);
    window = render::FitWindow(view, &first_pass);
  }
  render::CsvSource source(csv, scene.state_names);
  SetPaths(run_directory, &settings);
  Report(render::Animate(view, &source, window, events, settings.options), settings.quiet);
  return 0;
}

void AnimateResult(const Scene& scene, const SimulationResult& result, const std::string& directory,
                   AnimateSettings settings) {
  SetPaths(directory, &settings);
  const Trajectory& trajectory =
      result.stage_trajectory.size() > 0 ? result.stage_trajectory : result.trajectory;
  Report(render::AnimateTrajectory(scene, trajectory, result.final_time, result.events,
                                   settings.options),
         settings.quiet);
}

}  // namespace moreau::tool
