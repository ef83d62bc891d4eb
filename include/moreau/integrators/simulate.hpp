#pragma once
/// @file
/// One way to run a simulation: `Simulate(scene, settings)` with any integrator.
///
/// Every integrator is declared once (IntegratorSpec): its name, which effects it supports,
/// its options (name, meaning, type, default, allowed choices) and its statistics (name,
/// meaning). The declarations bind to the integrator's own XxxOptions and XxxStats structs, so
/// defaults stay at their declarations and XxxOptions::Validate() stays the validation; the
/// command-line flags, summary.json, the work-precision report and the Python keywords are all
/// generated from these declarations, and every front end goes through Simulate(). Refusals of
/// unsupported effects are derived from the declared support (RequireSupportedEffects), both
/// here and inside each SimulateXxx function.
///
/// Option names are lower-case with underscores (`rank_tol`); the command line spells them
/// with dashes (`--rank-tol`). Values arrive as SettingValue: a number, an integer, a bool, a
/// name or a list of numbers; strings are parsed (the command line passes every value as
/// text), integers are accepted where reals are expected, and anything else is refused with a
/// message naming the option, what it expects and what it got.

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/integrators/simulation.hpp"
#include "moreau/model/events.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// A setting as given by a front end.
using SettingValue = std::variant<bool, long, double, std::string, std::vector<double>>;

/// "true", "3", "0.5", "stewart", "[0.1, 0.2]": for messages and summary.json-like output.
std::string FormatSetting(const SettingValue& value);

/// One option of an integrator, declared once.
struct OptionSpec {
  /// The value type of an option.
  enum class Type { kBool, kInteger, kReal, kChoice, kRealList };
  std::string name;     ///< keyword (Python) and flag (command line, with '-' for '_')
  std::string meaning;  ///< one line: what it does, unit, valid range
  /// The value type (what SettingValue alternatives it accepts).
  Type type = Type::kReal;
  std::vector<std::string> choices;  ///< kChoice: the accepted names
  SettingValue default_value;        ///< read off a default-constructed XxxOptions
};
/// "bool", "integer", "real", "choice" or "list of reals".
std::string ToString(OptionSpec::Type type);

/// One statistic of an integrator's run, declared once.
struct StatSpec {
  /// Name as in summary.json, Python's Result.stats and SimulationResult::Stat.
  std::string name;
  /// One line: what it counts or measures.
  std::string meaning;
  bool count = false;  ///< an integer counter (num_*), else a real value
};

/// An integrator as front ends see it.
struct IntegratorSpec {
  std::string name;         ///< "fesd", "ida", ...
  std::string title;        ///< "the FESD integrator" (used in messages)
  std::string description;  ///< one line for listings
  /// EffectKind() names of the effects it simulates ("moving set", ...).
  std::vector<std::string> supported_effects;
  /// Whether it supports a speed of time (Scene::time_scale_input).
  bool supports_time_scale = false;
  /// Its options, in declaration order.
  std::vector<OptionSpec> options;
  /// Its statistics, in declaration order.
  std::vector<StatSpec> stats;
  /// What a "step" and an "iteration" count in the common result (SimulationResult).
  std::string step_unit;
  /// What SimulationResult::num_iterations counts ("Newton", "SQP", ...).
  std::string iteration_unit;

  /// The option with this name, or nullptr.
  const OptionSpec* FindOption(const std::string& option) const;
};

/// All integrators, in the order listings show them (radau, timestepping, fesd, ida, alpha).
const std::vector<IntegratorSpec>& Integrators();
/// The integrator with this name; throws std::invalid_argument listing the valid names.
const IntegratorSpec& FindIntegrator(const std::string& name);
/// The integrator "auto" picks: radau without effects, alpha for path constraints, and
/// otherwise the first declared integrator (fesd) that supports every effect of the scene.
std::string AutomaticIntegrator(const Scene& scene);
/// The names of the integrators that support every effect (and the speed of time) of `scene`.
std::vector<std::string> IntegratorsSupporting(const Scene& scene);
/// Throws std::invalid_argument if integrator `name` does not support an effect of the scene
/// (or its speed of time); the message names the effect and the integrators that support it.
void RequireSupportedEffects(const Scene& scene, const std::string& name);

/// What to run: an integrator ("auto" or a name) and option values by name. Options left out
/// keep their declared defaults.
struct SimulationSettings {
  /// "auto" (AutomaticIntegrator) or an integrator's name.
  std::string integrator = "auto";
  /// Option values by name (as the integrator declares them); others keep their defaults.
  std::map<std::string, SettingValue> options;
};

/// Derivatives of the final scene state, for shooting codes (integrators with a
/// `sensitivities` option): rows are the scene's states. theta = (x0, p, u_1, ..., u_S) orders
/// the data: initial state, parameters, then the inputs of every control segment.
struct SimulationSensitivities {
  Matrix initial_state;                ///< dx(T)/dx(0), n_x x n_x (option `sensitivities`)
  Matrix parameters;                   ///< dx(T)/dp, n_x x n_p
  Matrix inputs;                       ///< dx(T)/du, n_x x (n_u * segments)
  std::vector<double> segment_starts;  ///< start of each control segment
  /// Option `directions` (V, n_theta x k): dx(T)/dtheta V (n_x x k).
  Matrix directional;
  /// Option `directions` with `sample_times`: dx(t_j)/dtheta V (n_x x k) at every sample time.
  std::vector<Matrix> sample_directional;
  /// Options `adjoint_weights` (W, n_x x q) and `adjoint_sample_weights`: the q x n_theta
  /// gradient rows W^T dx(T)/dtheta + sum_j W_j^T dx(t_j)/dtheta.
  Matrix adjoint;
};

/// Gradients from a reverse sweep (AdjointSweep::Gradient).
struct AdjointGradient {
  bool success = true;       ///< false: a Jacobian was singular at its checkpoint (message)
  std::string message;       ///< why the sweep failed (empty on success)
  Matrix theta;              ///< q x n_theta: with respect to (x0, p, u_1..u_S)
  double cpu_seconds = 0.0;  ///< thread CPU time of the sweep
};

/// The reverse sweep of a finished run (option `keep_adjoint`): gradients for weights chosen
/// after the run, e.g. of a scalar function of the final and sample states, each for the cost
/// of one sweep. Not thread-safe (it re-evaluates the run's systems).
class AdjointSweep {
 public:
  virtual ~AdjointSweep() = default;
  /// final_weights: n_x x q (empty: zero); sample_weights: n_x x (q K) for the K sample
  /// times, sample j in columns j q .. (j + 1) q - 1 (empty: zero). Throws
  /// std::invalid_argument for other shapes.
  virtual AdjointGradient Gradient(const Matrix& final_weights,
                                   const Matrix& sample_weights) const = 0;
};

/// The common result of every integrator.
struct SimulationResult {
  /// The scene's name.
  std::string scene;
  std::string integrator;  ///< the integrator that ran ("auto" resolved)
  /// Every declared option of that integrator with the value used, in declaration order.
  std::vector<std::pair<std::string, SettingValue>> options;
  /// True if the integrator reached the final time.
  bool success = false;
  std::string status;  ///< the integrator's status name (ToString of its enum)
  /// The time and reason when success is false.
  std::string message;
  /// Time reached (physical time).
  double final_time = 0.0;
  /// The scene's state names.
  std::vector<std::string> state_names;
  /// Scene states at final_time.
  Vector final_state;
  Vector final_inputs;  ///< algebraic inputs at T (alpha), else empty
  /// The recorded trajectory in physical time.
  Trajectory trajectory;
  /// Every collocation stage point (FESD with record_stages), else empty.
  Trajectory stage_trajectory;
  /// Time-freezing scenes: the numerical-time trajectory (x, memories, clock), else empty.
  Trajectory numerical_trajectory;
  /// Switch and contact events in time order.
  std::vector<Event> events;
  /// Hysteresis relays: each memory w(t) in physical time.
  std::vector<RelaySignal> relays;
  /// The integrator's statistics, named as declared (IntegratorSpec::stats), in order.
  std::vector<std::pair<std::string, double>> stats;
  std::string stats_summary;  ///< the integrator's one-line Summary()
  long num_steps = 0;         ///< IntegratorSpec::step_unit
  long num_iterations = 0;    ///< IntegratorSpec::iteration_unit
  /// CPU time of the integrator's run (its cpu_seconds statistic: the thread's CPU time, not
  /// elapsed time).
  double cpu_seconds = 0.0;
  /// Elapsed (wall-clock) time of the whole Simulate call, lowering and set-up included: on a
  /// loaded machine larger than cpu_seconds by the time other work held the cores.
  double wall_seconds = 0.0;
  /// Per-element (FESD) or per-step (alpha) certificates: column names and rows.
  std::vector<std::string> record_columns;
  /// One row per element or step, values in record_columns order.
  std::vector<std::vector<double>> records;
  /// With the `sensitivities` option.
  std::optional<SimulationSensitivities> sensitivities;
  /// Adaptive FESD: the accepted steps, in the form its option `step_sequence` replays them.
  std::vector<double> step_sequence;
  /// The run's estimated error relative to the solution's scale (docs/accuracy.md): local
  /// error estimates accumulated over the steps (FESD, smooth Radau IIA), else empty.
  std::optional<double> error_estimate;
  /// What the user should know although the run may have succeeded (an estimated error far
  /// above the tolerance, a suspected unresolved crossing, ...), one sentence each. Front ends
  /// show them: the command line on stderr and in summary.json, Python by warnings.warn.
  std::vector<std::string> warnings;
  /// Option `sample_times`: the scene states at those times.
  std::vector<Vector> sample_states;
  /// Option `keep_adjoint`: the run's reverse sweep (shared by copies of the result).
  std::shared_ptr<const AdjointSweep> adjoint;

  /// The statistic with this name (std::invalid_argument if the integrator has none).
  double Stat(const std::string& name) const;
};

/// The options `given` for `integrator` with the scene's defaults (Scene::defaults) added
/// where the user gave none: rtol, atol, h0 and h_max (IDA: max_step) only where the steps are
/// error-controlled (no h given, or h with adaptive, rtol, atol or h0), output times (those
/// inside [t0, tf]) and output_dt unless either is given; each only where the integrator
/// declares the option. Simulate, Simulator and ValidateSimulationSettings apply it.
std::map<std::string, SettingValue> WithSceneDefaults(
    const Scene& scene, const std::string& integrator,
    const std::map<std::string, SettingValue>& given);

/// Checks the settings for `scene` without simulating: the integrator exists ("auto" is
/// resolved for the scene) and supports the scene's effects, every option is declared, of the
/// right type and in range. Throws std::invalid_argument as Simulate would.
void ValidateSimulationSettings(const Scene& scene, const SimulationSettings& settings);

/// Simulates `scene` with the settings' integrator. Throws std::invalid_argument for an
/// unknown integrator or option, a value of the wrong type or out of range, an invalid scene
/// or an unsupported effect; a numerical failure is a result with success = false and the
/// integrator's status and message.
SimulationResult Simulate(const Scene& scene, const SimulationSettings& settings,
                          const ProgressCallback& progress = {});

/// One scene and one set of settings simulated many times with other named values (shooting
/// codes, Python's moreau.Integrator): the integrator and options are resolved and checked
/// once, and integrators that can (FESD) lower the scene once and reuse it. Each Run gives
/// the result Simulate would give for the scene with the values set (SetSceneValue names:
/// "x0.<state>", parameters, "tf"); values not given keep the scene's own. Not thread-safe.
class Simulator {
 public:
  /// Resolves and checks the settings for `scene` (throws std::invalid_argument as Simulate).
  Simulator(const Scene& scene, const SimulationSettings& settings);
  ~Simulator();
  Simulator(const Simulator&) = delete;
  Simulator& operator=(const Simulator&) = delete;
  /// Simulates with `values` set on the scene (SetSceneValue names); the result equals Simulate's
  /// on that scene.
  SimulationResult Run(const std::vector<std::pair<std::string, double>>& values = {},
                       const ProgressCallback& progress = {});
  /// The integrator that runs ("auto" resolved).
  const std::string& integrator() const;
  /// The scene the simulator was made for.
  const Scene& scene() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace moreau
