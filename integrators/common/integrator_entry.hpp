#pragma once
// Declarations of an integrator for Simulate() (include/moreau/integrators/simulate.hpp):
// options bound to the members of its XxxOptions struct, statistics bound to its XxxStats, and
// the conversion of its XxxResult into the common SimulationResult. Each integrator folder
// declares its entry once (<name>/<name>_entry.cpp); simulate.cpp collects them.

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau::internal {

// Throws std::invalid_argument for an option `name` that `spec` does not declare: "option
// 'h' does not apply to integrator 'ida' (an option of fesd, radau, timestepping)" if another
// integrator declares it, else "unknown option 'stage'; did you mean 'stages'?".
[[noreturn]] void ThrowUnknownOption(const IntegratorSpec& spec, const std::string& name);

// The step options of the error-controlled integrators (FESD, smooth Radau IIA), as their
// entries' adjust step: without h the steps are error-controlled; with h they are fixed unless
// an error-control option (adaptive, rtol, atol, h0) is given too, which makes h the initial
// step. A given h = 0 (the structs' "no fixed step") is refused like any non-positive step,
// never read as "choose for me"; adaptive = false without h and the controller's bounds
// (h_min, h_max) with fixed steps are refused (they would be silently ignored).
template <typename Options>
void AdjustStepControl(const std::map<std::string, SettingValue>& given, Options* built) {
  RequireArgument(given.count("h") == 0 || built->step_size > 0.0,
                  "step size h must be positive and finite (leave h out for error-controlled "
                  "steps), got ",
                  built->step_size);
  for (const char* control : {"rtol", "atol", "h0"}) {
    if (given.count(control) > 0) built->adaptive = true;
  }
  RequireArgument(given.count("adaptive") == 0 || built->adaptive || given.count("h") > 0,
                  "adaptive = false needs a fixed step h (without h the steps are "
                  "error-controlled)");
  for (const char* controller_option : {"h_min", "h_max"}) {
    RequireArgument(built->ErrorControlled() || given.count(controller_option) == 0, "option '",
                    controller_option,
                    "' applies to error-controlled steps only (leave h out, or give adaptive, "
                    "rtol or atol with it)");
  }
}

// Converts a front end's value to the option's type; throws std::invalid_argument naming the
// option, what it expects and what it got.
bool SettingToBool(const OptionSpec& spec, const SettingValue& value);
long SettingToInteger(const OptionSpec& spec, const SettingValue& value);
double SettingToReal(const OptionSpec& spec, const SettingValue& value);
std::string SettingToChoice(const OptionSpec& spec, const SettingValue& value);
std::vector<double> SettingToRealList(const OptionSpec& spec, const SettingValue& value);

// An option bound to a field of Options (through get/set, so nested fields such as
// newton.tolerance bind as well).
template <class Options>
struct OptionBinding {
  OptionSpec spec;
  std::function<void(Options*, const SettingValue&)> set;
  std::function<SettingValue(const Options&)> get;
};

template <class Options, class Field>
OptionBinding<Options> BindReal(std::string name, Field Options::*member, std::string meaning) {
  OptionBinding<Options> binding;
  binding.spec = {std::move(name), std::move(meaning), OptionSpec::Type::kReal, {}, {}};
  binding.set = [member, spec = binding.spec](Options* o, const SettingValue& v) {
    o->*member = SettingToReal(spec, v);
  };
  binding.get = [member](const Options& o) { return SettingValue(static_cast<double>(o.*member)); };
  return binding;
}

template <class Options, class Field>
OptionBinding<Options> BindInteger(std::string name, Field Options::*member, std::string meaning) {
  OptionBinding<Options> binding;
  binding.spec = {std::move(name), std::move(meaning), OptionSpec::Type::kInteger, {}, {}};
  binding.set = [member, spec = binding.spec](Options* o, const SettingValue& v) {
    const long value = SettingToInteger(spec, v);
    RequireArgument(static_cast<long>(static_cast<Field>(value)) == value, "option '", spec.name,
                    "': ", value, " is out of range");
    o->*member = static_cast<Field>(value);
  };
  binding.get = [member](const Options& o) { return SettingValue(static_cast<long>(o.*member)); };
  return binding;
}

template <class Options>
OptionBinding<Options> BindBool(std::string name, bool Options::*member, std::string meaning) {
  OptionBinding<Options> binding;
  binding.spec = {std::move(name), std::move(meaning), OptionSpec::Type::kBool, {}, {}};
  binding.set = [member, spec = binding.spec](Options* o, const SettingValue& v) {
    o->*member = SettingToBool(spec, v);
  };
  binding.get = [member](const Options& o) { return SettingValue(o.*member); };
  return binding;
}

template <class Options>
OptionBinding<Options> BindRealList(std::string name, std::vector<double> Options::*member,
                                    std::string meaning) {
  OptionBinding<Options> binding;
  binding.spec = {std::move(name), std::move(meaning), OptionSpec::Type::kRealList, {}, {}};
  binding.set = [member, spec = binding.spec](Options* o, const SettingValue& v) {
    o->*member = SettingToRealList(spec, v);
  };
  binding.get = [member](const Options& o) { return SettingValue(o.*member); };
  return binding;
}

// A Matrix field given as a list of numbers: a single column, which the integrator reads
// column by column into its documented shape (FesdOptions::sensitivity_directions).
template <class Options>
OptionBinding<Options> BindMatrixList(std::string name, Matrix Options::*member,
                                      std::string meaning) {
  OptionBinding<Options> binding;
  binding.spec = {std::move(name), std::move(meaning), OptionSpec::Type::kRealList, {}, {}};
  binding.set = [member, spec = binding.spec](Options* o, const SettingValue& v) {
    const std::vector<double> list = SettingToRealList(spec, v);
    o->*member = Eigen::Map<const Vector>(list.data(), static_cast<Eigen::Index>(list.size()));
  };
  binding.get = [member](const Options& o) {
    const Matrix& m = o.*member;
    return SettingValue(std::vector<double>(m.data(), m.data() + m.size()));
  };
  return binding;
}

// An enum field with named values: `parse` maps a name to the enum (throwing for others),
// `format` the enum to its name.
template <class Options, class Enum>
OptionBinding<Options> BindChoice(std::string name, Enum Options::*member,
                                  std::vector<std::string> choices,
                                  Enum (*parse)(const std::string&), std::string (*format)(Enum),
                                  std::string meaning) {
  OptionBinding<Options> binding;
  binding.spec = {
      std::move(name), std::move(meaning), OptionSpec::Type::kChoice, std::move(choices), {}};
  binding.set = [member, parse, spec = binding.spec](Options* o, const SettingValue& v) {
    o->*member = parse(SettingToChoice(spec, v));
  };
  binding.get = [member, format](const Options& o) { return SettingValue(format(o.*member)); };
  return binding;
}

// A nested field: the binding of `inner` applied to (outer.*member).
template <class Options, class Inner>
OptionBinding<Options> Nested(Inner Options::*member, OptionBinding<Inner> inner) {
  OptionBinding<Options> binding;
  binding.spec = inner.spec;
  binding.set = [member, set = inner.set](Options* o, const SettingValue& v) {
    set(&(o->*member), v);
  };
  binding.get = [member, get = inner.get](const Options& o) { return get(o.*member); };
  return binding;
}

// Options several integrators share, declared once.
template <class Options>
OptionBinding<Options> BindSwitching(SwitchingForm Options::*member) {
  return BindChoice("switching", member, {"stewart", "heaviside"}, ParseSwitchingForm, ToString,
                    "lowering of switching surfaces");
}
template <class Options>
OptionBinding<Options> BindLinearSolver(LinearSolverKind Options::*member) {
  return BindChoice("linear_solver", member, {"auto", "dense", "sparse", "klu"},
                    ParseLinearSolverKind, ToString,
                    "LU backend (auto: dense up to 256 unknowns, KLU above, handing over to "
                    "UMFPACK where KLU fills in; sparse: SuiteSparse UMFPACK; klu: KLU alone)");
}
// Stop times of FESD, time-stepping, Radau and IDA: the user's breakpoints.
template <class Options>
OptionBinding<Options> BindStopTimes(std::vector<double> Options::*member) {
  return BindRealList("tstops", member,
                      "breakpoints: steps end at these times in (t0, tf) and never cross them (a "
                      "switch the steps cannot see, at a time you know)");
}
// The near-active constraint filter of FESD and time-stepping (docs/sparse-systems.md).
template <class Options>
std::vector<OptionBinding<Options>> BindConstraintFilter(ConstraintFilter Options::*filter,
                                                         double Options::*safety) {
  return {BindChoice("constraint_filter", filter, {"auto", "off", "on"}, ParseConstraintFilter,
                     ToString,
                     "leave moving-set constraints far from contact out of the element systems "
                     "(auto: on above 64 constraints)"),
          BindReal("filter_safety", safety,
                   "safety factor of the filter's margin (times H and the rate bound), >= 1")};
}
// Threads for large scenes (LoweredSystem::SetThreads), declared once for the integrators that
// run them (FESD, time-stepping).
template <class Options>
OptionBinding<Options> BindThreads(int Options::*member) {
  return BindInteger("threads", member,
                     "threads evaluating model functions made of blocks in large (sparse) scenes, "
                     ">= 0 (0: every hardware thread); results are the same for any value");
}
// The semismooth Newton settings of the complementarity integrators (FESD, time-stepping).
template <class Options>
std::vector<OptionBinding<Options>> BindNewton(SemismoothNewtonOptions Options::*member) {
  using N = SemismoothNewtonOptions;
  return {Nested(member, BindReal("newton_tol", &N::tolerance,
                                  "Newton tolerance on the scaled residual ||S Phi||_inf, > 0")),
          Nested(member, BindInteger("max_newton_iterations", &N::max_iterations,
                                     "Newton iterations per solve, >= 1")),
          Nested(member, BindLinearSolver(&N::linear_solver))};
}

// A statistic bound to a field of Stats.
template <class Stats>
struct StatBinding {
  StatSpec spec;
  std::function<double(const Stats&)> get;
};
template <class Stats, class Field>
StatBinding<Stats> BindStat(std::string name, Field Stats::*member, std::string meaning) {
  return {{std::move(name), std::move(meaning), std::is_integral_v<Field>},
          [member](const Stats& s) { return static_cast<double>(s.*member); }};
}

// A kept reverse sweep (FesdAdjoint, TimeSteppingAdjoint) as Simulate()'s results offer it:
// its Sweep's gradient over theta, its time, and (where the sweep can fail) its status.
template <class Adjoint>
class KeptAdjointSweep final : public AdjointSweep {
 public:
  explicit KeptAdjointSweep(std::shared_ptr<Adjoint> adjoint) : adjoint_(std::move(adjoint)) {}
  AdjointGradient Gradient(const Matrix& final_weights,
                           const Matrix& sample_weights) const override {
    auto gradient = adjoint_->Sweep(final_weights, sample_weights);
    AdjointGradient out;
    if constexpr (requires { gradient.success; }) {
      out.success = gradient.success;
      out.message = std::move(gradient.message);
    }
    out.theta = std::move(gradient.theta);
    out.cpu_seconds = gradient.cpu_seconds;
    return out;
  }

 private:
  std::shared_ptr<Adjoint> adjoint_;
};

// Directional and adjoint sensitivities of FESD and time-stepping (docs/sensitivities.md): the
// options of the same names in both, `sample_times` described by the integrator (where its
// sample times may lie).
template <class Options>
std::vector<OptionBinding<Options>> BindDirectionalAndAdjoint(std::string sample_times_meaning) {
  using O = Options;
  return {
      BindMatrixList("directions", &O::sensitivity_directions,
                     "directional sensitivities dx(T)/dtheta V: V column by column, n_theta = "
                     "n_x + n_p + n_u S entries per direction (theta = x0, p, u per segment)"),
      BindMatrixList("adjoint_weights", &O::adjoint_weights,
                     "adjoint sensitivities W^T dx(T)/dtheta by a reverse sweep: W (n_x x q) "
                     "column by column"),
      BindRealList("sample_times", &O::sample_times, std::move(sample_times_meaning)),
      BindMatrixList("adjoint_sample_weights", &O::adjoint_sample_weights,
                     "adjoint weights of the sample states: n_x x q per sample time, column by "
                     "column"),
      BindReal("adjoint_memory_limit_mb", &O::adjoint_memory_limit_mb,
               "memory bound of the adjoint's checkpoints in MB (0: none); beyond it they go to "
               "a temporary file"),
      BindBool("keep_adjoint", &O::keep_adjoint,
               "keep the reverse sweep in the result: gradients for weights chosen after the "
               "run"),
  };
}
// The adjoint's statistics (FESD and time-stepping).
template <class Stats>
std::vector<StatBinding<Stats>> BindAdjointStats() {
  using S = Stats;
  return {BindStat("adjoint_memory_bytes", &S::adjoint_memory_bytes,
                   "bytes kept in memory for the adjoint sweep"),
          BindStat("adjoint_file_bytes", &S::adjoint_file_bytes,
                   "bytes of adjoint checkpoints written to a file (beyond the memory limit)"),
          BindStat("adjoint_cpu_seconds", &S::adjoint_cpu_seconds, "time of the adjoint sweep")};
}

// The type-erased entry Simulate() dispatches to; `check` builds and validates the options
// without running.
struct IntegratorEntry {
  IntegratorSpec spec;
  std::function<SimulationResult(const Scene&, const std::map<std::string, SettingValue>&,
                                 const ProgressCallback&)>
      run;
  std::function<void(const std::map<std::string, SettingValue>&)> check;
  // Settings checked and (where the integrator can) the scene prepared once; the returned
  // function runs the scene with other values (Simulator).
  using Prepared = std::function<SimulationResult(const Scene& values, const ProgressCallback&)>;
  std::function<Prepared(const Scene&, const std::map<std::string, SettingValue>&)> prepare;
};

// Builds an entry from an integrator's bindings. `simulate` runs the integrator on the
// options built from the settings (defaults, then the given values, then Validate());
// `convert` fills the integrator-specific parts of the common result (records, relays, ...)
// after the shared fields (status, message, final time and state, trajectory, events, stats)
// are copied.
template <class Options, class Result>
IntegratorEntry MakeEntry(
    IntegratorSpec spec, std::vector<OptionBinding<Options>> options,
    std::vector<StatBinding<decltype(Result::stats)>> stats,
    std::function<Result(const Scene&, const Options&, const ProgressCallback&)> simulate,
    std::function<void(const Scene&, const Result&, SimulationResult*)> convert,
    std::function<void(const std::map<std::string, SettingValue>&, Options*)> adjust = {},
    // Optional reuse: given the scene and options once, a function that runs other values of
    // the scene (FESD: lowered once). Absent: each run simulates the values from scratch.
    std::function<std::function<Result(const Scene&, const ProgressCallback&)>(const Scene&,
                                                                               const Options&)>
        reuse = {}) {
  const Options defaults;
  for (OptionBinding<Options>& binding : options) {
    binding.spec.default_value = binding.get(defaults);
    spec.options.push_back(binding.spec);
  }
  for (const auto& stat : stats) spec.stats.push_back(stat.spec);
  // Defaults, then the given values, then the integrator's adjustments and Validate().
  auto build = [spec, options, adjust](const std::map<std::string, SettingValue>& given) {
    Options built;
    for (const auto& [name, value] : given) {
      const OptionBinding<Options>* found = nullptr;
      for (const auto& binding : options) {
        if (binding.spec.name == name) found = &binding;
      }
      if (found == nullptr) ThrowUnknownOption(spec, name);
      found->set(&built, value);
    }
    if (adjust) adjust(given, &built);
    built.Validate();
    return built;
  };
  IntegratorEntry entry;
  entry.spec = spec;
  entry.check = [build](const std::map<std::string, SettingValue>& given) { build(given); };
  // The common result of a run with options `built`.
  auto common = [spec, options, stats, convert](const Scene& scene, const Options& built,
                                                const Result& result) {
    SimulationResult out;
    out.integrator = spec.name;
    for (const auto& binding : options) {
      out.options.emplace_back(binding.spec.name, binding.get(built));
    }
    out.status = ToString(result.status);
    out.success = result.status == decltype(result.status)::kSuccess;
    out.message = result.message;
    out.final_time = result.final_time;
    out.final_state = result.final_state;
    out.trajectory = result.trajectory;
    if constexpr (requires { result.events; }) out.events = result.events;
    if constexpr (requires { result.warnings; }) out.warnings = result.warnings;
    if constexpr (requires { result.stats.error_estimate; }) {
      if (result.stats.error_estimate >= 0.0) out.error_estimate = result.stats.error_estimate;
    }
    for (const auto& stat : stats) out.stats.emplace_back(stat.spec.name, stat.get(result.stats));
    out.stats_summary = result.stats.Summary();
    out.cpu_seconds = result.stats.cpu_seconds;
    convert(scene, result, &out);
    out.scene = scene.name;
    out.state_names = scene.state_names;
    return out;
  };
  entry.run = [simulate, build, common](const Scene& scene,
                                        const std::map<std::string, SettingValue>& given,
                                        const ProgressCallback& progress) {
    const Options built = build(given);
    return common(scene, built, simulate(scene, built, progress));
  };
  entry.prepare = [simulate, build, common, reuse](
                      const Scene& scene, const std::map<std::string, SettingValue>& given) {
    const Options built = build(given);
    if (reuse) {
      auto run = reuse(scene, built);
      return IntegratorEntry::Prepared(
          [run, built, common](const Scene& values, const ProgressCallback& progress) mutable {
            return common(values, built, run(values, progress));
          });
    }
    return IntegratorEntry::Prepared(
        [simulate, built, common](const Scene& values, const ProgressCallback& progress) {
          return common(values, built, simulate(values, built, progress));
        });
  };
  return entry;
}

// Each integrator's entry (defined in its folder).
IntegratorEntry RadauEntry();
IntegratorEntry TimeSteppingEntry();
IntegratorEntry FesdEntry();
IntegratorEntry IdaEntry();
IntegratorEntry AlphaDaiEntry();

}  // namespace moreau::internal
