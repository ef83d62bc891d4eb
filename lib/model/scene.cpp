#include "moreau/model/scene.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>
#include <utility>

#include "moreau/core/error.hpp"

namespace moreau {

double PiecewiseConstantSignal::ValueAt(double t) const {
  // Interval k = number of breakpoints <= t (right-continuous signal).
  const auto k = std::upper_bound(breakpoints.begin(), breakpoints.end(), t) - breakpoints.begin();
  return values[static_cast<std::size_t>(k)];
}

std::string EffectKind(const Effect& effect) {
  struct Visitor {
    std::string operator()(const MovingSet&) const { return "moving set"; }
    std::string operator()(const SwitchingSurfaces&) const { return "switching surfaces"; }
    std::string operator()(const HysteresisRelay&) const { return "hysteresis relay"; }
    std::string operator()(const PathConstraints&) const { return "path constraints"; }
    std::string operator()(const Complementarity&) const { return "complementarity system"; }
  };
  return std::visit(Visitor{}, effect);
}

const std::string& EffectName(const Effect& effect) {
  return std::visit([](const auto& e) -> const std::string& { return e.name; }, effect);
}

int Scene::AddParameter(const std::string& parameter_name, double value,
                        const std::string& parameter_description) {
  parameters.push_back({parameter_name, value, parameter_description});
  return static_cast<int>(parameters.size()) - 1;
}

int Scene::FindParameter(const std::string& parameter_name) const {
  for (std::size_t i = 0; i < parameters.size(); ++i) {
    if (parameters[i].name == parameter_name) return static_cast<int>(i);
  }
  return -1;
}

Vector Scene::ParameterValues() const {
  Vector p(num_parameters());
  for (int i = 0; i < num_parameters(); ++i) p[i] = parameters[static_cast<std::size_t>(i)].value;
  return p;
}

Vector Scene::InputValues(double t) const {
  Vector u(num_inputs());
  for (int i = 0; i < num_inputs(); ++i) {
    const InputSpec& input = inputs[static_cast<std::size_t>(i)];
    u[i] = input.kind == InputSpec::Kind::kControl ? input.signal.ValueAt(t) : input.initial_guess;
  }
  return u;
}

std::vector<double> Scene::ControlBreakpoints() const {
  std::vector<double> points;
  for (const InputSpec& input : inputs) {
    if (input.kind != InputSpec::Kind::kControl) continue;
    for (double b : input.signal.breakpoints) {
      if (b > initial_time && b < final_time) points.push_back(b);
    }
  }
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  return points;
}

namespace {

void RequireUniqueNames(const std::vector<std::string>& names, const std::string& what) {
  std::set<std::string> seen;
  for (const std::string& name : names) {
    RequireArgument(!name.empty(), what, ": names must not be empty");
    RequireArgument(seen.insert(name).second, what, ": duplicate name '", name, "'");
  }
}

bool AllFinite(const Vector& v) { return v.allFinite(); }

// Evaluates `f` at the initial point and checks its output size and finiteness; out-of-range
// argument accesses surface here as std::invalid_argument from the argument views.
Vector EvaluateAtStart(const Scene& scene, const SmoothFunction& f, const std::string& what,
                       int expected_outputs) {
  RequireArgument(!f.empty(), scene.name, ": ", what, " is missing");
  RequireArgument(f.num_outputs() == expected_outputs, scene.name, ": ", what, " ('", f.name(),
                  "') must have ", expected_outputs, " outputs, got ", f.num_outputs());
  Vector out;
  try {
    f.Evaluate(scene.initial_state, scene.InputValues(scene.initial_time), scene.initial_time,
               scene.ParameterValues(), &out);
  } catch (const std::invalid_argument& error) {
    ThrowInvalidArgument(scene.name, ": ", what, ": ", error.what());
  }
  RequireArgument(AllFinite(out), scene.name, ": ", what, " ('", f.name(),
                  "') is not finite at the initial state");
  return out;
}

void ValidateMovingSet(const Scene& scene, const MovingSet& set, bool check_feasibility) {
  const std::string what = "moving set '" + set.name + "'";
  RequireArgument(!set.constraint_names.empty(), scene.name, ": ", what, " has no constraints");
  RequireUniqueNames(set.constraint_names, scene.name + ": " + what + " constraints");
  const Vector c = EvaluateAtStart(scene, set.constraints, what + " constraints",
                                   static_cast<int>(set.constraint_names.size()));
  const double tolerance =
      kInitialFeasibilityTolerance * std::max(1.0, scene.initial_state.lpNorm<Eigen::Infinity>());
  for (Eigen::Index k = 0; check_feasibility && k < c.size(); ++k) {
    RequireArgument(c[k] >= -tolerance, scene.name, ": infeasible initial state: constraint '",
                    set.constraint_names[static_cast<std::size_t>(k)], "' of ", what,
                    " is c = ", c[k], " < 0 at t0 = ", scene.initial_time,
                    " (expected x0 in C(t0), i.e. c(x0, t0) >= 0)");
  }
  const Matrix& e = set.projection_basis;
  if (e.size() != 0) {
    RequireArgument(e.rows() == scene.num_states(), scene.name, ": ", what,
                    ": projection basis E must have ", scene.num_states(), " rows, got ", e.rows());
    RequireArgument(e.cols() >= 1 && e.cols() <= e.rows(), scene.name, ": ", what,
                    ": projection basis E must have between 1 and ", e.rows(), " columns, got ",
                    e.cols());
    RequireArgument(e.allFinite(), scene.name, ": ", what, ": projection basis E is not finite");
    const double orthonormality =
        (e.transpose() * e - Matrix::Identity(e.cols(), e.cols())).lpNorm<Eigen::Infinity>();
    RequireArgument(
        orthonormality <= 1e-12, scene.name, ": ", what,
        ": projection basis E must have orthonormal columns (|E^T E - I| = ", orthonormality, ")");
  }
}

void ValidateSwitching(const Scene& scene, const SwitchingSurfaces& switching) {
  const std::string what = "switching surfaces '" + switching.name + "'";
  const auto nc = switching.surface_names.size();
  RequireArgument(nc >= 1 && nc <= 8, scene.name, ": ", what,
                  " needs between 1 and 8 surfaces, got ", nc);
  RequireUniqueNames(switching.surface_names, scene.name + ": " + what + " surfaces");
  EvaluateAtStart(scene, switching.surfaces, what + " surfaces", static_cast<int>(nc));
  const std::size_t num_modes = std::size_t{1} << nc;
  RequireArgument(switching.modes.size() == num_modes, scene.name, ": ", what, " with ", nc,
                  " surface", nc == 1 ? "" : "s", " needs ", num_modes,
                  " modes (one per sign pattern), got ", switching.modes.size());
  RequireArgument(switching.mode_names.size() == num_modes, scene.name, ": ", what, " needs ",
                  num_modes, " mode names, got ", switching.mode_names.size());
  RequireUniqueNames(switching.mode_names, scene.name + ": " + what + " modes");
  for (std::size_t k = 0; k < num_modes; ++k) {
    EvaluateAtStart(scene, switching.modes[k], what + " mode '" + switching.mode_names[k] + "'",
                    scene.num_states());
  }
}

void ValidateRelay(const Scene& scene, const HysteresisRelay& relay) {
  const std::string what = "hysteresis relay '" + relay.name + "'";
  EvaluateAtStart(scene, relay.input, what + " input", 1);
  EvaluateAtStart(scene, relay.mode_a, what + " mode A", scene.num_states());
  EvaluateAtStart(scene, relay.mode_b, what + " mode B", scene.num_states());
  const int np = scene.num_parameters();
  RequireArgument(relay.lower_threshold >= 0 && relay.lower_threshold < np, scene.name, ": ", what,
                  ": lower threshold must be a parameter index in [0, ", np, "), got ",
                  relay.lower_threshold);
  RequireArgument(relay.upper_threshold >= 0 && relay.upper_threshold < np, scene.name, ": ", what,
                  ": upper threshold must be a parameter index in [0, ", np, "), got ",
                  relay.upper_threshold);
  const double lower = scene.parameters[static_cast<std::size_t>(relay.lower_threshold)].value;
  const double upper = scene.parameters[static_cast<std::size_t>(relay.upper_threshold)].value;
  RequireArgument(upper > lower, scene.name, ": ", what,
                  ": upper threshold must exceed the lower one, got lower = ", lower,
                  ", upper = ", upper);
  RequireArgument(relay.initial_memory == 0 || relay.initial_memory == 1, scene.name, ": ", what,
                  ": initial memory must be 0 (mode A) or 1 (mode B), got ", relay.initial_memory);
  RequireArgument(std::isfinite(relay.auxiliary_gain) && relay.auxiliary_gain > 0.0, scene.name,
                  ": ", what, ": auxiliary gain must be positive and finite, got ",
                  relay.auxiliary_gain);
}

void ValidatePathConstraints(const Scene& scene, const PathConstraints& dai) {
  const std::string what = "path constraints '" + dai.name + "'";
  RequireUniqueNames(dai.constraint_names, scene.name + ": " + what);
  if (!dai.constraint_names.empty()) {
    EvaluateAtStart(scene, dai.constraints, what, static_cast<int>(dai.constraint_names.size()));
  }
  for (const Vector* bound : {&dai.state_lower, &dai.state_upper}) {
    RequireArgument(bound->size() == 0 || bound->size() == scene.num_states(), scene.name, ": ",
                    what, ": state bounds need 0 or ", scene.num_states(), " entries, got ",
                    bound->size());
    for (Eigen::Index i = 0; i < bound->size(); ++i) {
      RequireArgument(!std::isnan((*bound)[i]), scene.name, ": ", what, ": state bound is NaN");
    }
  }
}

// Principal minors of D whose determinant is below this fraction of Hadamard's bound (the
// product of the row norms) count as zero: round-off of an exactly singular minor.
constexpr double kMinorRelativeTolerance = 1e-12;

void ValidateComplementarity(const Scene& scene, const Complementarity& effect,
                             bool check_feasibility) {
  const std::string what = "complementarity system '" + effect.name + "'";
  RequireArgument(!effect.pair_names.empty(), scene.name, ": ", what,
                  " has no pairs (pair_names is empty)");
  RequireUniqueNames(effect.pair_names, scene.name + ": " + what + " pairs");
  const int m = static_cast<int>(effect.pair_names.size());
  const int nx = scene.num_states();
  RequireArgument(m <= kMaxComplementarityPairs, scene.name, ": ", what, " has ", m,
                  " pairs; at most ", kMaxComplementarityPairs, " per effect");
  const Vector g = EvaluateAtStart(scene, effect.output, what + " output g", m);
  RequireArgument(!effect.input_matrix.empty(), scene.name, ": ", what,
                  " input matrix B is missing");
  RequireArgument(effect.input_matrix.num_outputs() == nx * m, scene.name, ": ", what,
                  " input matrix B ('", effect.input_matrix.name(), "') must have n_x * m = ", nx,
                  " * ", m, " = ", nx * m, " outputs (row-major), got ",
                  effect.input_matrix.num_outputs());
  EvaluateAtStart(scene, effect.input_matrix, what + " input matrix B", nx * m);
  if (effect.feedthrough.empty()) {
    // D = 0 (index 2): w = g(x, t) must start nonnegative, as a moving set's c.
    const double tolerance =
        kInitialFeasibilityTolerance * std::max(1.0, scene.initial_state.lpNorm<Eigen::Infinity>());
    for (int k = 0; check_feasibility && k < m; ++k) {
      RequireArgument(g[k] >= -tolerance, scene.name, ": infeasible initial state: pair '",
                      effect.pair_names[static_cast<std::size_t>(k)], "' of ", what,
                      " has w = g = ", g[k], " < 0 at t0 = ", scene.initial_time,
                      " (without D, w = g(x0, t0) must be >= 0)");
    }
    return;
  }
  RequireArgument(effect.feedthrough.num_outputs() == m * m, scene.name, ": ", what,
                  " feedthrough D ('", effect.feedthrough.name(), "') must have m * m = ", m, " * ",
                  m, " = ", m * m, " outputs (row-major), got ", effect.feedthrough.num_outputs());
  const Vector values = EvaluateAtStart(scene, effect.feedthrough, what + " feedthrough D", m * m);
  const Matrix d =
      Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          values.data(), m, m);
  const std::string violation = PMatrixViolation(d);
  RequireArgument(violation.empty(), scene.name, ": ", what,
                  ": the feedthrough D must be a P-matrix (all principal minors positive) for "
                  "the complementarity problem to have a unique solution at every state; at "
                  "the initial point ",
                  violation, ". For D = 0 leave D out (index-2 form); see docs/complementarity.md");
}

}  // namespace

std::string PMatrixViolation(const Matrix& d) {
  RequireArgument(d.rows() == d.cols(), "PMatrixViolation: D must be square, got ", d.rows(), " x ",
                  d.cols());
  const int m = static_cast<int>(d.rows());
  if (!d.allFinite()) return "D is not finite";
  if (m == 0) return "";
  // A positive definite symmetric part is sufficient (and cheap).
  const Matrix symmetric = 0.5 * (d + d.transpose());
  const double smallest =
      Eigen::SelfAdjointEigenSolver<Matrix>(symmetric, Eigen::EigenvaluesOnly).eigenvalues()[0];
  if (smallest > kMinorRelativeTolerance * symmetric.lpNorm<Eigen::Infinity>()) return "";
  RequireArgument(m <= kMaxEnumeratedPMatrixSize, "PMatrixViolation: D is ", m, " x ", m,
                  " and its symmetric part is not positive definite; checking all principal "
                  "minors is limited to ",
                  kMaxEnumeratedPMatrixSize, " x ", kMaxEnumeratedPMatrixSize);
  // Every principal minor, smallest index sets first (the first failure is the simplest).
  std::vector<unsigned> subsets;
  for (unsigned mask = 1; mask < (1u << m); ++mask) subsets.push_back(mask);
  std::stable_sort(subsets.begin(), subsets.end(),
                   [](unsigned a, unsigned b) { return std::popcount(a) < std::popcount(b); });
  for (unsigned mask : subsets) {
    std::vector<int> rows;
    for (int i = 0; i < m; ++i) {
      if ((mask >> i) & 1u) rows.push_back(i);
    }
    const int k = static_cast<int>(rows.size());
    Matrix minor(k, k);
    double hadamard = 1.0;
    for (int i = 0; i < k; ++i) {
      for (int j = 0; j < k; ++j) minor(i, j) = d(rows[i], rows[j]);
      hadamard *= std::max(minor.row(i).norm(), std::numeric_limits<double>::min());
    }
    const double det = minor.fullPivLu().determinant();
    if (det > kMinorRelativeTolerance * hadamard) continue;
    std::ostringstream s;
    s << "the principal minor of rows and columns {";
    for (int i = 0; i < k; ++i) s << (i ? ", " : "") << rows[i] + 1;
    s << "} is " << det << " (must be > 0)";
    return s.str();
  }
  return "";
}

void ValidateScene(const Scene& scene, bool check_initial_feasibility) {
  RequireArgument(!scene.name.empty(), "scene name must not be empty");
  const std::string& s = scene.name;
  RequireArgument(!scene.state_names.empty(), s, ": a scene needs at least one state");
  RequireUniqueNames(scene.state_names, s + ": states");
  RequireArgument(scene.initial_state.size() == scene.num_states(), s, ": initial state has ",
                  scene.initial_state.size(), " entries, expected ", scene.num_states(),
                  " (one per state)");
  for (int i = 0; i < scene.num_states(); ++i) {
    RequireArgument(std::isfinite(scene.initial_state[i]), s, ": initial state x0.",
                    scene.state_names[static_cast<std::size_t>(i)], " is not finite (got ",
                    scene.initial_state[i], ")");
  }
  RequireArgument(std::isfinite(scene.initial_time), s, ": initial time is not finite");
  RequireArgument(std::isfinite(scene.final_time), s, ": final time tf is not finite");
  RequireArgument(scene.final_time > scene.initial_time, s,
                  ": horizon must be positive: expected tf > t0 = ", scene.initial_time,
                  ", got tf = ", scene.final_time);

  std::vector<std::string> names;
  for (const ParameterSpec& parameter : scene.parameters) {
    names.push_back(parameter.name);
    RequireArgument(std::isfinite(parameter.value), s, ": parameter '", parameter.name,
                    "' is not finite (got ", parameter.value, ")");
  }
  RequireUniqueNames(names, s + ": parameters");
  names.clear();
  for (const InputSpec& input : scene.inputs) {
    names.push_back(input.name);
    // The signal is the control's value, or an algebraic input's reference w(t).
    const char* kind = input.kind == InputSpec::Kind::kControl ? "control" : "algebraic input";
    const auto& sig = input.signal;
    RequireArgument(sig.values.size() == sig.breakpoints.size() + 1, s, ": ", kind, " '",
                    input.name, "' needs one value more than breakpoints, got ", sig.values.size(),
                    " values and ", sig.breakpoints.size(), " breakpoints");
    for (std::size_t k = 0; k < sig.breakpoints.size(); ++k) {
      RequireArgument(std::isfinite(sig.breakpoints[k]), s, ": ", kind, " '", input.name,
                      "' has a non-finite breakpoint");
      RequireArgument(k == 0 || sig.breakpoints[k] > sig.breakpoints[k - 1], s, ": ", kind, " '",
                      input.name, "' breakpoints must increase strictly");
    }
    for (double v : sig.values) {
      RequireArgument(std::isfinite(v), s, ": ", kind, " '", input.name,
                      "' has a non-finite value (got ", v, ")");
    }
    if (input.kind == InputSpec::Kind::kAlgebraic) {
      RequireArgument(
          !std::isnan(input.lower) && !std::isnan(input.upper) && input.lower <= input.upper, s,
          ": algebraic input '", input.name, "' has invalid bounds [", input.lower, ", ",
          input.upper, "]");
      RequireArgument(std::isfinite(input.initial_guess), s, ": algebraic input '", input.name,
                      "' initial guess is not finite");
    }
  }
  RequireUniqueNames(names, s + ": inputs");
  if (scene.time_scale_input >= 0) {
    RequireArgument(scene.time_scale_input < scene.num_inputs(), s,
                    ": the speed-of-time input index must be in [0, ", scene.num_inputs(),
                    "), got ", scene.time_scale_input);
    const InputSpec& speed = scene.inputs[static_cast<std::size_t>(scene.time_scale_input)];
    RequireArgument(speed.kind == InputSpec::Kind::kControl, s, ": the speed of time '", speed.name,
                    "' must be a control input");
    for (double v : speed.signal.values) {
      RequireArgument(v > 0.0, s, ": the speed of time '", speed.name, "' must be positive, got ",
                      v);
    }
  } else {
    RequireArgument(scene.time_scale_input == -1, s,
                    ": the speed-of-time input index must be -1 (none) or an input, got ",
                    scene.time_scale_input);
  }

  const SceneDefaults& defaults = scene.defaults;
  for (const auto& [value, key] : {std::pair{defaults.relative_tolerance, "rtol"},
                                   {defaults.absolute_tolerance, "atol"},
                                   {defaults.initial_step, "h0"},
                                   {defaults.max_step, "h_max"},
                                   {defaults.output_step, "output_dt"}}) {
    RequireArgument(std::isfinite(value) && value >= 0.0, s, ": default ", key,
                    " must be finite and >= 0 (0: the integrator's own), got ", value);
  }
  RequireArgument(defaults.relative_tolerance < 1.0, s, ": default rtol must be below 1, got ",
                  defaults.relative_tolerance);
  for (double t : defaults.output_times) {
    RequireArgument(std::isfinite(t) && t >= scene.initial_time, s,
                    ": default output times must be finite and >= t0 = ", scene.initial_time,
                    ", got ", t);
  }

  if (!scene.dynamics.empty()) {
    EvaluateAtStart(scene, scene.dynamics, "dynamics f", scene.num_states());
  }
  names.clear();
  for (const Effect& effect : scene.effects) {
    names.push_back(EffectName(effect));
    std::visit(
        [&](const auto& e) {
          using E = std::decay_t<decltype(e)>;
          if constexpr (std::is_same_v<E, MovingSet>) {
            ValidateMovingSet(scene, e, check_initial_feasibility);
          }
          if constexpr (std::is_same_v<E, SwitchingSurfaces>) ValidateSwitching(scene, e);
          if constexpr (std::is_same_v<E, HysteresisRelay>) ValidateRelay(scene, e);
          if constexpr (std::is_same_v<E, PathConstraints>) ValidatePathConstraints(scene, e);
          if constexpr (std::is_same_v<E, Complementarity>) {
            ValidateComplementarity(scene, e, check_initial_feasibility);
          }
        },
        effect);
  }
  RequireUniqueNames(names, s + ": effects");
  ValidateView(scene);
}

std::string NonFiniteModelValue(const Scene& scene, const Vector& x, const Vector& u, double t,
                                const Vector& p) {
  std::string found;
  // Evaluates f and names its first non-finite output (output_name(k) says what output k is).
  auto check = [&](const SmoothFunction& f, const std::string& what, const auto& output_name) {
    if (!found.empty() || f.empty()) return;
    Vector out;
    try {
      f.Evaluate(x, u, t, p, &out);
    } catch (const std::exception&) {
      return;  // out-of-range arguments are refused at validation, not here
    }
    for (Eigen::Index k = 0; k < out.size(); ++k) {
      if (std::isfinite(out[k])) continue;
      std::ostringstream text;
      text.precision(17);
      text << what << " ('" << f.name() << "'), output " << output_name(k) << ", is " << out[k]
           << " at t = " << t << ", x = (";
      for (int i = 0; i < scene.num_states(); ++i) {
        text << (i ? ", " : "") << scene.state_names[static_cast<std::size_t>(i)] << " = " << x[i];
      }
      text << ")";
      found = text.str();
      return;
    }
  };
  auto named = [](const std::vector<std::string>& names, const std::string& kind) {
    return [&names, kind](Eigen::Index k) {
      const auto i = static_cast<std::size_t>(k);
      return i < names.size() ? "'" + names[i] + "' (" + kind + ")" : std::to_string(k);
    };
  };
  const auto rate = named(scene.state_names, "its rate");
  check(scene.dynamics, "the dynamics f", rate);
  for (const Effect& effect : scene.effects) {
    const std::string what = EffectKind(effect) + " '" + EffectName(effect) + "'";
    std::visit(
        [&](const auto& e) {
          using E = std::decay_t<decltype(e)>;
          if constexpr (std::is_same_v<E, MovingSet>) {
            check(e.constraints, what + " constraints c", named(e.constraint_names, "c"));
          } else if constexpr (std::is_same_v<E, SwitchingSurfaces>) {
            check(e.surfaces, what + " surfaces c", named(e.surface_names, "c"));
            for (std::size_t m = 0; m < e.modes.size(); ++m) {
              check(e.modes[m], what + " mode '" + e.mode_names[m] + "'", rate);
            }
          } else if constexpr (std::is_same_v<E, HysteresisRelay>) {
            check(e.input, what + " input", [](Eigen::Index) { return std::string("0"); });
            check(e.mode_a, what + " mode A", rate);
            check(e.mode_b, what + " mode B", rate);
          } else if constexpr (std::is_same_v<E, PathConstraints>) {
            check(e.constraints, what + " phi", named(e.constraint_names, "phi"));
          } else if constexpr (std::is_same_v<E, Complementarity>) {
            check(e.output, what + " output g", named(e.pair_names, "w"));
            const auto entry = [](Eigen::Index k) { return "entry " + std::to_string(k); };
            check(e.input_matrix, what + " input matrix B", entry);
            check(e.feedthrough, what + " feedthrough D", entry);
          }
        },
        effect);
  }
  return found;
}

std::vector<std::string> OverridableNames(const Scene& scene) {
  std::vector<std::string> names{"tf"};
  for (const std::string& state : scene.state_names) names.push_back("x0." + state);
  for (const ParameterSpec& parameter : scene.parameters) names.push_back(parameter.name);
  return names;
}

void SetSceneValue(Scene* scene, const std::string& name, double value) {
  RequireArgument(std::isfinite(value), "value of '", name, "' must be finite, got ", value);
  if (name == "tf") {
    scene->final_time = value;
    return;
  }
  if (name.rfind("x0.", 0) == 0) {
    const std::string state = name.substr(3);
    for (std::size_t i = 0; i < scene->state_names.size(); ++i) {
      if (scene->state_names[i] == state) {
        scene->initial_state[static_cast<Eigen::Index>(i)] = value;
        return;
      }
    }
  }
  const int index = scene->FindParameter(name);
  if (index >= 0) {
    scene->parameters[static_cast<std::size_t>(index)].value = value;
    return;
  }
  std::string valid;
  for (const std::string& candidate : OverridableNames(*scene)) {
    valid += (valid.empty() ? "" : ", ") + candidate;
  }
  ThrowInvalidArgument("scene '", scene->name, "' has no value named '", name,
                       "'; valid names: ", valid);
}

}  // namespace moreau
