// moreau: command-line tool.
//   moreau list
//   moreau show <scene>
//   moreau run [<scene>] [--integrator NAME] [--stages S] [--h H] [--tf T]
//              [--set name=value ...] [--out DIR] ...
//   moreau ocp <problem> [--N N] [--stages S] [--fe N_FE] [--single-shooting] ...
//   moreau crowd-file [KEY=VALUE ...] > crowd.toml
// Exit codes: 0 success; 1 the simulation ended with a non-success status; 2 bad usage or
// input (unknown scene, option or parameter, bad value).

#include <dlfcn.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <sstream>

#include "animate_command.hpp"
#include "check_command.hpp"
#include "integrator_flags.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"
#include "moreau/scenes/crowd.hpp"
#include "moreau/version.hpp"
#include "ocp_command.hpp"
#include "output.hpp"
#include "progress.hpp"
#include "sweep_command.hpp"

namespace {

using moreau::Scene;
namespace tool = moreau::tool;

double ParseNumber(const std::string& text, const std::string& what) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  moreau::RequireArgument(used == text.size() && !text.empty(), "bad value '", text, "' for ", what,
                          ": expected a number");
  return value;
}

void ApplySettings(Scene* scene, const std::vector<std::string>& assignments, double tf,
                   bool tf_given) {
  for (const std::string& assignment : assignments) {
    const auto equals = assignment.find('=');
    moreau::RequireArgument(equals != std::string::npos && equals > 0, "bad --set '", assignment,
                            "': expected name=value");
    const std::string name = assignment.substr(0, equals);
    moreau::SetSceneValue(scene, name, ParseNumber(assignment.substr(equals + 1), "--set " + name));
  }
  if (tf_given) moreau::SetSceneValue(scene, "tf", tf);
  moreau::ValidateScene(*scene);
}

std::string Join(const std::vector<std::string>& items, std::size_t limit) {
  std::string text;
  for (std::size_t i = 0; i < items.size() && i < limit; ++i) text += (i ? ", " : "") + items[i];
  if (items.size() > limit) text += ", ... (" + std::to_string(items.size()) + " in all)";
  return text;
}

void List() {
  for (const moreau::SceneDefinition& definition : moreau::SceneCatalog()) {
    std::printf("  %-12s %s\n", definition.name.c_str(), definition.summary.c_str());
  }
  std::printf("\nintegrators (moreau run --integrator NAME):\n");
  std::printf("  %-12s %s\n", "auto",
              "radau without effects, alpha for path constraints, fesd otherwise");
  for (const moreau::IntegratorSpec& spec : moreau::Integrators()) {
    std::string effects;
    for (const std::string& kind : spec.supported_effects) {
      effects += (effects.empty() ? "" : ", ") + kind;
    }
    std::printf("  %-12s %s (effects: %s)\n", spec.name.c_str(), spec.description.c_str(),
                effects.empty() ? "none" : effects.c_str());
  }
  std::printf("\noptimal control problems (moreau ocp PROBLEM):\n");
  tool::ListOcpProblems();
}

void Show(const Scene& scene) {
  constexpr std::size_t kLimit = 12;
  std::printf("%s: %s\n\n", scene.name.c_str(), scene.description.c_str());
  std::printf("states (%d), initial value (override with --set x0.<state>=v):\n",
              scene.num_states());
  for (int i = 0; i < scene.num_states() && static_cast<std::size_t>(i) < kLimit; ++i) {
    std::printf("  %-10s x0 = %.17g\n", scene.state_names[static_cast<std::size_t>(i)].c_str(),
                scene.initial_state[i]);
  }
  if (static_cast<std::size_t>(scene.num_states()) > kLimit) {
    std::printf("  ... (%d states in all)\n", scene.num_states());
  }
  std::printf("\nhorizon: t0 = %.17g, tf = %.17g (override with --tf or --set tf=v)\n",
              scene.initial_time, scene.final_time);
  std::printf("\nparameters (override with --set name=v):\n");
  if (scene.parameters.empty()) std::printf("  none\n");
  for (const moreau::ParameterSpec& p : scene.parameters) {
    std::printf("  %-12s = %-12.10g %s\n", p.name.c_str(), p.value, p.description.c_str());
  }
  std::printf("\ninputs:\n");
  if (scene.inputs.empty()) std::printf("  none\n");
  for (const moreau::InputSpec& input : scene.inputs) {
    std::printf("  %-12s %s %s\n", input.name.c_str(),
                input.kind == moreau::InputSpec::Kind::kControl ? "control" : "algebraic",
                input.description.c_str());
  }
  std::printf("\neffects:\n");
  if (scene.effects.empty()) std::printf("  none (smooth dynamics only)\n");
  for (const moreau::Effect& effect : scene.effects) {
    std::printf("  %s '%s'", moreau::EffectKind(effect).c_str(),
                moreau::EffectName(effect).c_str());
    if (const auto* set = std::get_if<moreau::MovingSet>(&effect)) {
      std::printf(": constraints %s >= 0%s", Join(set->constraint_names, kLimit).c_str(),
                  set->projection_basis.size() ? ", projection subspace E given" : "");
    } else if (const auto* sw = std::get_if<moreau::SwitchingSurfaces>(&effect)) {
      std::printf(": surfaces %s; modes %s", Join(sw->surface_names, kLimit).c_str(),
                  Join(sw->mode_names, kLimit).c_str());
    } else if (const auto* relay = std::get_if<moreau::HysteresisRelay>(&effect)) {
      std::printf(": A -> B at %s, B -> A at %s, initial memory w0 = %d",
                  scene.parameters[static_cast<std::size_t>(relay->upper_threshold)].name.c_str(),
                  scene.parameters[static_cast<std::size_t>(relay->lower_threshold)].name.c_str(),
                  relay->initial_memory);
    } else if (const auto* dai = std::get_if<moreau::PathConstraints>(&effect)) {
      std::printf(": %s <= 0", Join(dai->constraint_names, kLimit).c_str());
    } else if (const auto* lcs = std::get_if<moreau::Complementarity>(&effect)) {
      std::printf(": pairs %s; %s", Join(lcs->pair_names, kLimit).c_str(),
                  lcs->feedthrough.empty() ? "D = 0 (index 2: lambda jumps)"
                                           : "D given (index 1: lambda continuous)");
    }
    std::printf("\n");
  }
}

// `implicit`: options the command line sets itself (shown only where they differ from that).
int Run(Scene scene, const moreau::SimulationSettings& settings,
        const std::map<std::string, moreau::SettingValue>& implicit, bool numerical_time,
        const std::string& out_directory, bool plot, bool plot_internal, bool quiet,
        const tool::AnimateSettings* animate) {
  tool::ProgressBar progress("run", !quiet);
  const double t0 = scene.initial_time, tf = scene.final_time;
  auto time_text = [tf](double t) {
    char text[64];
    std::snprintf(text, sizeof text, "t = %.6g of %.6g", t, tf);
    return std::string(text);
  };
  const moreau::SimulationResult report = moreau::Simulate(scene, settings, [&](double t) {
    progress.Update((t - t0) / (tf - t0), [&] { return time_text(t); });
  });
  progress.Finish((report.final_time - t0) / (tf - t0), time_text(report.final_time));
  // What the user should know although the run may have succeeded (also in summary.json;
  // --quiet leaves errors only).
  if (!quiet) {
    for (const std::string& warning : report.warnings) {
      std::fprintf(stderr, "moreau: warning: %s\n", warning.c_str());
    }
  }
  const moreau::Trajectory& trajectory =
      numerical_time ? report.numerical_trajectory : report.trajectory;

  std::filesystem::create_directories(out_directory);
  tool::WriteTrajectoryCsv(trajectory, out_directory + "/trajectory.csv");
  std::string extra_files;
  if (report.stage_trajectory.size() > 0) {
    tool::WriteTrajectoryCsv(report.stage_trajectory, out_directory + "/stages.csv");
    extra_files += ", " + out_directory + "/stages.csv";
  }
  if (!report.record_columns.empty()) {
    tool::WriteElementsCsv(report, out_directory + "/elements.csv");
    extra_files += ", " + out_directory + "/elements.csv";
  }
  if (!report.relays.empty()) {
    tool::WriteRelaysCsv(report, out_directory + "/relays.csv");
    extra_files += ", " + out_directory + "/relays.csv";
  }
  if (report.numerical_trajectory.size() > 0 && !numerical_time) {
    tool::WriteTrajectoryCsv(report.numerical_trajectory, out_directory + "/numerical.csv");
    extra_files += ", " + out_directory + "/numerical.csv";
  }
  tool::WriteSummaryJson(report, out_directory + "/summary.json");
  tool::WriteViewJson(scene, out_directory + "/view.json");
  const std::string image = plot ? tool::WritePlot(scene, report, trajectory, out_directory,
                                                   numerical_time, plot_internal)
                                 : "";
  if (quiet) {  // errors only: a run that did not succeed says why, on stderr
    if (animate != nullptr) {
      tool::AnimateSettings silent = *animate;
      silent.quiet = true;
      tool::AnimateResult(scene, report, out_directory, silent);
    }
    if (!report.success) {
      std::fprintf(stderr, "moreau: %s: %s: %s\n", report.scene.c_str(), report.status.c_str(),
                   report.message.c_str());
    }
    return report.success ? 0 : 1;
  }

  const auto& names = report.state_names;
  std::ostringstream state;
  state.precision(12);
  for (std::size_t i = 0; i < names.size() && i < 8; ++i) {
    state << (i ? ", " : "") << names[i] << " = " << report.final_state[static_cast<long>(i)];
  }
  if (names.size() > 8) state << ", ... (" << names.size() << " states, all in summary.json)";
  std::printf("scene       %s\n", report.scene.c_str());
  std::printf("integrator  %s\n", tool::IntegratorLine(report, implicit).c_str());
  std::printf("status      %s%s%s\n", report.status.c_str(), report.message.empty() ? "" : ": ",
              report.message.c_str());
  std::printf("t_final     %.17g\n", report.final_time);
  std::printf("x_final     %s\n", state.str().c_str());
  if (report.events.empty()) {
    std::printf("events      none\n");
  } else {
    std::printf("events      %zu\n", report.events.size());
    for (std::size_t k = 0; k < report.events.size() && k < 10; ++k) {
      const moreau::Event& e = report.events[k];
      std::printf("  t = %-22.17g %-12s %s %s\n", e.t, moreau::ToString(e.kind).c_str(),
                  e.what.c_str(), e.detail.c_str());
    }
    if (report.events.size() > 10) std::printf("  ... (all in summary.json)\n");
  }
  for (const moreau::RelaySignal& relay : report.relays) {
    std::printf("relay       %s: w = %d at t0, %zu jumps, w = %d at t_final\n", relay.relay.c_str(),
                relay.initial_value, relay.jump_times.size(), relay.FinalValue());
  }
  const moreau::IntegratorSpec& spec = moreau::FindIntegrator(report.integrator);
  std::printf("steps       %ld (%ss)\n", report.num_steps, spec.step_unit.c_str());
  std::printf("iterations  %ld (%s)\n", report.num_iterations, spec.iteration_unit.c_str());
  std::printf("cpu time    %.3g s (wall %.3g s)\n", report.cpu_seconds, report.wall_seconds);
  std::printf("stats       %s\n", report.stats_summary.c_str());
  if (report.error_estimate) {
    std::printf("error       %.3g estimated, relative to the solution's scale\n",
                *report.error_estimate);
  }
  std::printf("output      %s/trajectory.csv, %s/summary.json%s%s%s\n", out_directory.c_str(),
              out_directory.c_str(), extra_files.c_str(), image.empty() ? "" : ", ", image.c_str());
  if (plot && image.empty()) {
    std::fprintf(stderr, "moreau: warning: no plot written (is gnuplot installed?)\n");
  }
  if (animate != nullptr) tool::AnimateResult(scene, report, out_directory, *animate);
  return report.success ? 0 : 1;
}

}  // namespace

namespace {

// OpenBLAS (Debian's libblas.so.3 alternative, called by UMFPACK on its frontal matrices)
// keeps its idle threads spinning on sched_yield after each call: the crowd's default run
// took 244 s of CPU with the default threads and 150 to 163 s with one, in the same wall time.
// The BLAS calls of a run are small, so the command line runs OpenBLAS on one thread unless
// the user set OPENBLAS_NUM_THREADS (docs/cli.md). Looked up at run time: another BLAS is
// left as it is.
void UseSingleThreadedOpenBlas() {
  if (std::getenv("OPENBLAS_NUM_THREADS") != nullptr) return;
  if (void* symbol = dlsym(RTLD_DEFAULT, "openblas_set_num_threads")) {
    reinterpret_cast<void (*)(int)>(symbol)(1);
  }
}

}  // namespace

int main(int argc, char** argv) {
  UseSingleThreadedOpenBlas();
  CLI::App app{"moreau: simulate nonsmooth dynamical systems with measured accuracy"};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "help for all subcommands");
  app.set_version_flag("--version", std::string("moreau ") + MOREAU_VERSION,
                       "print the version (moreau/version.hpp) and exit");

  app.add_subcommand("list", "list the scenes and integrators");

  auto* show = app.add_subcommand("show", "show a scene: states, effects, parameters");
  std::string show_scene;
  show->add_option("scene", show_scene, "scene name or scene file (.toml)")->required();

  auto* check = app.add_subcommand(
      "check", "validate a scene or scene file and print its lowered sizes, without simulating");
  std::string check_scene;
  std::vector<std::string> check_assignments;
  int check_stages = 3;
  check->add_option("scene", check_scene, "scene name or scene file (.toml)")->required();
  check->add_option("--set", check_assignments, "override a scene value: name=value");
  check->add_option("--stages", check_stages, "Radau IIA stages for the FESD sizes (default 3)");

  auto* run = app.add_subcommand("run", "simulate a scene");
  std::string run_scene = moreau::DefaultSceneName();
  moreau::SimulationSettings settings;
  std::vector<std::string> assignments;
  std::string out_directory;
  double tf = 0.0;
  bool no_plot = false, quiet = false, numerical_time = false;
  run->add_option("scene", run_scene,
                  "scene name or scene file (.toml; default: " + run_scene + ")");
  run->add_option("--integrator", settings.integrator,
                  "integrator (see `moreau list`; default auto: radau without effects, alpha "
                  "for path constraints, fesd otherwise)");
  auto* tf_option = run->add_option("--tf", tf, "final time (overrides the scene's horizon)");
  run->add_option("--set", assignments, "override a scene value: name=value (repeatable)");
  run->add_option("--out", out_directory, "output directory (default: out/<scene>)");
  run->add_flag("--numerical-time", numerical_time,
                "hysteresis scenes (fesd): trajectory.csv in numerical time tau, with the relay "
                "memories and the clock (default: physical time)");
  run->add_flag("--no-plot", no_plot, "do not write trajectory.png");
  run->add_flag("--quiet", quiet, "print nothing but errors (the files are written as usual)");
  bool plot_internal = false;
  run->add_flag("--plot-internal", plot_internal,
                "trajectory.png also shows the lowering's internal variables (Filippov theta, "
                "lambda, mu; time-freezing variables)");
  bool run_animate = false;
  tool::AnimateSettings run_animate_settings;
  run->add_flag("--animate", run_animate,
                "also animate the run (scenes with a view: animation.mp4, animation.gif, "
                "snapshots/; see `moreau animate --help` for the animation options)");
  tool::AddAnimateOptions(run, &run_animate_settings);
  // Every integrator option, declared once in the library (moreau::Integrators()), becomes a
  // flag --name (dashes for underscores); its value goes to moreau::Simulate() as text, which
  // parses and validates it for the chosen integrator.
  tool::IntegratorFlags integrator_flags(run);
  auto* animate = app.add_subcommand(
      "animate",
      "animate a run of a planar scene: RUN_DIR/animation.mp4, animation.gif and snapshots at "
      "event times (needs ffmpeg)");
  std::string animate_directory;
  tool::AnimateSettings animate_settings;
  animate->add_option("run_dir", animate_directory, "a directory written by `moreau run`")
      ->required();
  animate->add_flag("--quiet", animate_settings.quiet, "print nothing");
  tool::AddAnimateOptions(animate, &animate_settings);
  auto* sweep = app.add_subcommand(
      "sweep", "run a scene over grids and samples of its named values on all cores");
  std::string sweep_scene;
  tool::SweepCommandSettings sweep_settings;
  std::vector<std::string> sweep_assignments;
  double sweep_tf = 0.0;
  sweep->add_option("scene", sweep_scene, "scene name or scene file (.toml)")->required();
  sweep->add_option("--grid", sweep_settings.grids,
                    "vary a named value over a grid: name=start:stop:count (several: product)");
  sweep->add_option("--sample", sweep_settings.samples,
                    "sample a named value: name=normal:mean:std or name=uniform:a:b");
  sweep->add_option("--samples", sweep_settings.num_samples,
                    "draws per grid point (with --sample)");
  sweep->add_option("--seed", sweep_settings.seed, "seed of the samples (default 0)");
  sweep->add_option("--jobs", sweep_settings.jobs, "worker threads (default 0: all cores)");
  sweep->add_option("--events", sweep_settings.event_times, "event times per row (default 5)");
  sweep->add_option("--integrator", sweep_settings.simulation.integrator,
                    "integrator (see `moreau list`; default auto)");
  sweep->add_option("--set", sweep_assignments, "fixed override: name=value (repeatable)");
  auto* sweep_tf_option = sweep->add_option("--tf", sweep_tf, "final time");
  sweep->add_option("--out", sweep_settings.out_directory,
                    "output directory (default: out/sweep/<scene>)");
  sweep->add_flag("--no-plot", no_plot, "do not write the summary plots");
  sweep->add_flag("--quiet", quiet, "print nothing but errors (the files are written as usual)");
  tool::IntegratorFlags sweep_flags(sweep);

  auto* ocp = app.add_subcommand("ocp", "solve an optimal control problem (see `moreau list`)");
  tool::OcpCommandSettings ocp_settings;
  bool single_shooting = false, no_verify = false;
  ocp->add_option("problem", ocp_settings.problem, "problem name")->required();
  auto* ocp_intervals =
      ocp->add_option("--N", ocp_settings.intervals,
                      "control intervals (default: the problem's; the problem's control guess is "
                      "then replaced by its constant signal)");
  // Flags override the problem's options (MakeOcpOptions): only the given ones are applied.
  int ocp_stages = 0, ocp_fe = 0, ocp_max_iterations = 0, ocp_print_level = 0;
  double ocp_tol = 0.0, ocp_level_tol = 0.0;
  std::string ocp_integrator, ocp_hessian, ocp_homotopy;
  auto* ocp_stages_option =
      ocp->add_option("--stages", ocp_stages, "FESD Radau IIA stages s (1..4)");
  auto* ocp_fe_option =
      ocp->add_option("--fe", ocp_fe, "FESD finite elements per control interval");
  auto* ocp_integrator_option = ocp->add_option(
      "--integrator", ocp_integrator,
      "discretization of the intervals: fesd (default) or timestepping (fixed steps, for "
      "comparisons)");
  ocp->add_flag("--single-shooting", single_shooting,
                "single shooting (default: multiple shooting)");
  std::string ocp_transcription;
  auto* ocp_transcription_option = ocp->add_option(
      "--transcription", ocp_transcription,
      "multiple_shooting (default), single_shooting or collocation (FESD equations as NLP "
      "constraints; homotopy levels need a complementarity relaxation SIGMA > 0)");
  auto* ocp_hessian_option = ocp->add_option(
      "--hessian", ocp_hessian,
      "second-order information: limited_memory (default), block_bfgs, block_sr1 or "
      "second_order (collocation only)");
  auto* ocp_homotopy_option = ocp->add_option(
      "--homotopy", ocp_homotopy,
      "levels before the exact problem, MU:EPS[:SIGMA][:NAME=VALUE...],... (smoothing mu, "
      "terminal relaxation eps, complementarity relaxation sigma of the collocation "
      "transcription, scene parameters of the level), or none (default: the problem's)");
  auto* ocp_tol_option = ocp->add_option("--tol", ocp_tol, "IPOPT tolerance (tol)");
  auto* ocp_level_tol_option =
      ocp->add_option("--level-tol", ocp_level_tol, "IPOPT tolerance of the homotopy levels");
  auto* ocp_max_iterations_option =
      ocp->add_option("--max-iterations", ocp_max_iterations, "IPOPT iteration limit per level");
  auto* ocp_print_level_option =
      ocp->add_option("--print-level", ocp_print_level, "IPOPT output level 0..12 (0: silent)");
  double ocp_equilibration = 0.0;
  auto* ocp_equilibration_option = ocp->add_option(
      "--step-equilibration", ocp_equilibration,
      "collocation transcription: weight of the element-length penalty on relaxed levels");
  std::string ocp_mesh;
  auto* ocp_mesh_option = ocp->add_option(
      "--mesh-continuation", ocp_mesh,
      "shooting: interval counts N1,N2,... solved first, coarsest first, each prolongated to "
      "the next (none: no continuation; default: the problem's)");
  ocp->add_flag("--no-verify", no_verify, "skip the IDA re-simulation of the optimal controls");
  bool ocp_no_regularization = false;
  ocp->add_flag("--no-constraint-regularization", ocp_no_regularization,
                "IPOPT regularizes the constraint block only after a wrong inertia (default: "
                "at every iteration, perturb_always_cd)");
  bool ocp_no_element_minima = false;
  ocp->add_flag("--no-element-minima", ocp_no_element_minima,
                "collocation transcription: stop after the exact level with c >= 0 at check "
                "points only (default: then re-solve it with every free constraint's minimum "
                "over each element >= 0)");
  int ocp_refine_stages = 0;
  auto* ocp_refine_stages_option = ocp->add_option(
      "--refine-stages", ocp_refine_stages,
      "collocation transcription: after the exact level, re-solve it once with this many Radau "
      "IIA stages (s < S <= 7) from the interpolated solution; 0: no refinement (default: the "
      "problem's)");
  ocp->add_option("--out", ocp_settings.out_directory,
                  "output directory (default: out/ocp/<problem>)");
  ocp->add_flag("--no-plot", no_plot, "do not write solution.png");
  ocp->add_flag("--quiet", quiet, "print nothing but errors (the files are written as usual)");

  auto* crowd_file = app.add_subcommand(
      "crowd-file",
      "write a crowd-motion scene as a scene file on stdout (the built-in crowd:KEY=VALUE,...)");
  std::vector<std::string> crowd_options;
  crowd_file->add_option("options", crowd_options,
                         "crowd options KEY=VALUE (N, radius, speed, spacing, jitter, seed, "
                         "cutoff, door, exit_distance, smoothing, tf; docs/crowd-motion.md)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    return app.exit(error) == 0 ? 0 : 2;
  }

  try {
    if (app.got_subcommand("list")) {
      List();
      return 0;
    }
    if (app.got_subcommand("crowd-file")) {
      std::string text;
      for (const std::string& option : crowd_options) text += (text.empty() ? "" : ",") + option;
      moreau::WriteCrowdSceneFile(moreau::ParseCrowdOptions(text), std::cout);
      return 0;
    }
    if (app.got_subcommand("show")) {
      Show(tool::ResolveScene(show_scene));
      return 0;
    }
    if (app.got_subcommand("check")) {
      Scene scene = tool::ResolveScene(check_scene);
      ApplySettings(&scene, check_assignments, 0.0, false);
      tool::CheckScene(scene, check_stages);
      return 0;
    }
    if (app.got_subcommand("animate")) {
      return tool::RunAnimateCommand(animate_directory, animate_settings);
    }
    if (app.got_subcommand("sweep")) {
      Scene scene = tool::ResolveScene(sweep_scene);
      ApplySettings(&scene, sweep_assignments, sweep_tf, sweep_tf_option->count() > 0);
      sweep_settings.simulation.options = sweep_flags.Given();
      sweep_settings.plot = !no_plot;
      sweep_settings.quiet = quiet;
      return tool::RunSweepCommand(scene, sweep_settings);
    }
    if (app.got_subcommand("ocp")) {
      auto& overrides = ocp_settings.overrides;
      using moreau::OcpOptions;
      if (ocp_stages_option->count() > 0) {
        overrides.push_back([=](OcpOptions* o) { o->stages = ocp_stages; });
      }
      if (ocp_fe_option->count() > 0) {
        overrides.push_back([=](OcpOptions* o) { o->finite_elements = ocp_fe; });
      }
      if (ocp_integrator_option->count() > 0) {
        const auto integrator = moreau::ParseOcpIntegrator(ocp_integrator);
        overrides.push_back([=](OcpOptions* o) { o->integrator = integrator; });
      }
      if (single_shooting) {
        overrides.push_back(
            [](OcpOptions* o) { o->transcription = moreau::OcpTranscription::kSingleShooting; });
      }
      if (ocp_transcription_option->count() > 0) {
        const auto transcription = moreau::ParseOcpTranscription(ocp_transcription);
        overrides.push_back([=](OcpOptions* o) { o->transcription = transcription; });
      }
      if (ocp_hessian_option->count() > 0) {
        const auto hessian = moreau::ParseOcpHessian(ocp_hessian);
        overrides.push_back([=](OcpOptions* o) { o->hessian = hessian; });
      }
      if (ocp_homotopy_option->count() > 0) {
        const auto levels = tool::ParseHomotopy(ocp_homotopy);
        overrides.push_back([=](OcpOptions* o) { o->homotopy = levels; });
      }
      if (ocp_tol_option->count() > 0) {
        overrides.push_back([=](OcpOptions* o) { o->tolerance = ocp_tol; });
      }
      if (ocp_level_tol_option->count() > 0) {
        overrides.push_back([=](OcpOptions* o) { o->level_tolerance = ocp_level_tol; });
      }
      if (ocp_max_iterations_option->count() > 0) {
        overrides.push_back([=](OcpOptions* o) { o->max_iterations = ocp_max_iterations; });
      }
      if (ocp_print_level_option->count() > 0) {
        overrides.push_back([=](OcpOptions* o) { o->print_level = ocp_print_level; });
      }
      if (ocp_equilibration_option->count() > 0) {
        overrides.push_back(
            [=](OcpOptions* o) { o->step_equilibration_weight = ocp_equilibration; });
      }
      if (ocp_mesh_option->count() > 0) {
        const std::vector<int> counts = tool::ParseIntervalCounts(ocp_mesh);
        overrides.push_back([=](OcpOptions* o) { o->mesh_continuation = counts; });
      }
      if (no_verify) overrides.push_back([](OcpOptions* o) { o->verify = false; });
      if (ocp_no_element_minima) {
        overrides.push_back([](OcpOptions* o) { o->collocation_element_minima = false; });
      }
      if (ocp_refine_stages_option->count() > 0) {
        overrides.push_back(
            [=](OcpOptions* o) { o->collocation_refinement_stages = ocp_refine_stages; });
      }
      if (ocp_no_regularization) {
        overrides.push_back([](OcpOptions* o) { o->regularize_constraints = false; });
      }
      ocp_settings.intervals_given = ocp_intervals->count() > 0;
      ocp_settings.plot = !no_plot;
      ocp_settings.quiet = quiet;
      return tool::RunOcpCommand(ocp_settings);
    }
    settings.options = integrator_flags.Given();
    Scene scene = tool::ResolveScene(run_scene);
    ApplySettings(&scene, assignments, tf, tf_option->count() > 0);
    if (out_directory.empty()) out_directory = "out/" + scene.name;
    // The command line records FESD's stage points (stages.csv) unless told otherwise.
    if (settings.integrator == "auto") settings.integrator = moreau::AutomaticIntegrator(scene);
    std::map<std::string, moreau::SettingValue> implicit;
    if (settings.integrator == "fesd") {
      settings.options.try_emplace("record_stages", true);
      implicit["record_stages"] = true;
    }
    moreau::RequireArgument(
        !numerical_time || (settings.integrator == "fesd" && scene.Has<moreau::HysteresisRelay>()),
        "--numerical-time applies to scenes with hysteresis relays simulated by the fesd "
        "integrator (elsewhere numerical and physical time coincide)");
    if (run_animate) {
      // Checked before simulating: a scene without bodies, or bad animation options.
      const moreau::render::CompiledView view(scene);
      run_animate_settings.options.Validate();
    }
    return Run(std::move(scene), settings, implicit, numerical_time, out_directory, !no_plot,
               plot_internal, quiet, run_animate ? &run_animate_settings : nullptr);
  } catch (const std::invalid_argument& error) {
    std::fprintf(stderr, "moreau: error: %s\n", error.what());
    return 2;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "moreau: error: %s\n", error.what());
    return 2;
  }
}
