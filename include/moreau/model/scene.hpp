#pragma once
/// @file
/// Scenes: named, self-describing problems that integrators simulate.
///
/// A scene declares its states, initial state, horizon, named parameters, inputs, smooth
/// dynamics f(x, u, t, p) and a list of **effects**. Each effect is its own type:
///  - MovingSet:          x' in f - N_{C(t)}(x), C(t) = {x : c(x, t) >= 0} (sweeping process),
///                        optionally with a projection subspace E (extended PDS);
///  - SwitchingSurfaces:  Filippov system x' = f + f_mode(x), the mode given by the signs
///                        of switching functions c(x, t);
///  - HysteresisRelay:    delayed relay with memory w in {0, 1}: x' = f + f_A (w = 0) or
///                        f + f_B (w = 1), A -> B when psi reaches its upper threshold,
///                        B -> A when psi falls to its lower threshold;
///  - PathConstraints:    differential-algebraic inequalities phi(x, u, t) <= 0 with
///                        algebraic inputs u and bounds (alpha-method DAI stepper);
///  - Complementarity:    complementarity system x' = f + B(x, t) lambda,
///                        0 <= lambda ⟂ w = g(x, t) + D lambda >= 0 (circuits with ideal
///                        diodes, linear and nonlinear complementarity systems).
/// Effects compose additively: x' = f(x, u, t, p) + (sum of effect contributions). An effect
/// reaches an integrator's equations only if the scene declares it: a scene without effects
/// adds no complementarity unknowns or equations. An integrator handed an effect it does
/// not support refuses with std::invalid_argument naming the effect.
///
/// Every overridable number is named: parameters (the vector p passed to every model
/// function, so derivatives with respect to them are exact), the initial state entries
/// ("x0.<state>") and the horizon ("tf"); see SetSceneValue.

#include <limits>
#include <string>
#include <variant>
#include <vector>

#include "moreau/core/smooth_function.hpp"
#include "moreau/core/types.hpp"
#include "moreau/model/view.hpp"

namespace moreau {

/// A named scalar parameter of a scene (an entry of p).
struct ParameterSpec {
  /// The name (a `--set` name, and the key in scene files).
  std::string name;
  /// The value.
  double value = 0.0;
  /// One line for `moreau show`.
  std::string description;
};

/// A piecewise-constant signal: value[k] on [breakpoints[k-1], breakpoints[k]) with
/// breakpoints strictly increasing (values.size() == breakpoints.size() + 1). A constant
/// signal has no breakpoints. Integrators never step across a breakpoint.
struct PiecewiseConstantSignal {
  /// Breakpoints t_1 < t_2 < ..., possibly none.
  std::vector<double> breakpoints;
  /// The values, one more than breakpoints.
  std::vector<double> values{0.0};
  /// The value at time t (right-continuous at breakpoints).
  double ValueAt(double t) const;
};

/// An input u_i of the dynamics: either a control signal given as a function of time, or an
/// algebraic variable determined by a PathConstraints effect (DAI), with bounds.
struct InputSpec {
  /// A control signal, or an algebraic variable of a DAI.
  enum class Kind { kControl, kAlgebraic };
  /// The input's name.
  std::string name;
  /// Control or algebraic.
  Kind kind = Kind::kControl;
  /// kControl: the input's value. kAlgebraic: the user input function w(t) that the variable
  /// follows where no active constraint needs it (alpha stepper, AlphaDaiObjective::kReference).
  PiecewiseConstantSignal signal;
  double lower = -std::numeric_limits<double>::infinity();  ///< bound (algebraic inputs)
  double upper = std::numeric_limits<double>::infinity();   ///< bound (algebraic inputs)
  double initial_guess = 0.0;                               ///< algebraic inputs at t0
  /// One line for `moreau show`.
  std::string description;
};

/// Sweeping process / (extended) projected dynamical system with the moving set
/// C(t) = {x : c(x, t) >= 0}: x' = f + E E^T grad_x c(x, t) lambda, 0 <= lambda ⟂ c >= 0.
struct MovingSet {
  /// The effect's name (unique among the scene's effects; prefixes events and multipliers).
  std::string name;
  std::vector<std::string> constraint_names;  ///< one name per component of c
  SmoothFunction constraints;                 ///< c(x, u, t, p), u is not used
  /// E: n_x-by-n' with orthonormal columns spanning the directions along which the state
  /// may be projected. Empty means E = I (ordinary PDS / sweeping process).
  Matrix projection_basis;
};

/// Filippov system with n_c switching functions c(x, t). The mode with sign pattern
/// sigma in {-1, +1}^{n_c} is active where sign(c_j) = sigma_j for all j; modes are indexed
/// by the bit pattern k = sum_j [sigma_j > 0] 2^j (mode 0: all c_j < 0). Its contribution
/// f_k(x, u, t, p) is added to the smooth dynamics; on switching surfaces the Filippov
/// convexification applies.
struct SwitchingSurfaces {
  /// The effect's name (unique among the scene's effects).
  std::string name;
  std::vector<std::string> surface_names;  ///< one per component of c
  SmoothFunction surfaces;                 ///< c(x, u, t, p)
  std::vector<std::string> mode_names;     ///< 2^{n_c} names
  std::vector<SmoothFunction> modes;       ///< 2^{n_c} vector fields with n_x outputs
};

/// Delayed relay (hysteresis) with memory w in {0 (mode A), 1 (mode B)}.
/// psi = (input - lower)/(upper - lower) is the normalized input: the relay switches A -> B
/// when psi reaches 1 and B -> A when psi falls to 0. Thresholds are scene parameters.
struct HysteresisRelay {
  /// The effect's name (unique among the scene's effects).
  std::string name;
  SmoothFunction input;      ///< scalar input(x, u, t, p) compared with the thresholds
  int lower_threshold = -1;  ///< index of the parameter at which B -> A
  int upper_threshold = -1;  ///< index of the parameter at which A -> B
  SmoothFunction mode_a;     ///< contribution f_A(x, u, t, p) while w = 0
  SmoothFunction mode_b;     ///< contribution f_B(x, u, t, p) while w = 1
  int initial_memory = 0;    ///< w(t0) in {0, 1}; inconsistent values are re-initialized
  /// Speed a > 0 of the auxiliary fields of the time-freezing reformulation: w travels
  /// between 0 and 1 at rate a in numerical time while physical time is frozen, so a jump
  /// lasts 1/a (docs/lowering.md, "Hysteresis relays", on the departure from the paper's
  /// gamma(s) = a s^2/(1 + s^2)).
  double auxiliary_gain = 1.0;
};

/// Differential-algebraic inequalities: phi(x, u, t, p) <= 0 and state bounds, where the
/// algebraic inputs (InputSpec::Kind::kAlgebraic) are determined at every time.
struct PathConstraints {
  /// The effect's name (unique among the scene's effects).
  std::string name;
  std::vector<std::string> constraint_names;  ///< one per component of phi
  SmoothFunction constraints;                 ///< phi(x, u, t, p) <= 0
  Vector state_lower;                         ///< empty or n_x entries (-inf allowed)
  Vector state_upper;                         ///< empty or n_x entries (+inf allowed)
};

/// Complementarity system (docs/complementarity.md): m pairs with multipliers lambda (e.g.
/// diode currents) and outputs w (e.g. diode reverse voltages),
///
///   x' = f + B(x, u, t, p) lambda,   0 <= lambda ⟂ w = g(x, u, t, p) + D(x, u, t, p) lambda >= 0.
///
/// Two forms, chosen by whether D is given:
///  - D given (index 1): D must be a P-matrix (checked at the initial point; ValidateScene).
///    Then lambda is the unique solution of an LCP at every state, a Lipschitz function of
///    (x, t): lambda and w are continuous in time and the system is an ODE with a piecewise
///    smooth right-hand side. Example: a resistor in series with an ideal diode (D = R).
///  - D absent (D = 0, index 2): w = g(x, t) is continuous and lambda jumps where the active
///    set changes (like a moving set's multiplier). Well posed where g_x B is a P-matrix on the
///    active pairs; where it is not, integrators report a status (no unique continuation).
/// Effects that couple through D must be one effect; pairs without D coupling may be split
/// into an index-1 and an index-2 effect.
struct Complementarity {
  /// The effect's name (unique among the scene's effects).
  std::string name;
  std::vector<std::string> pair_names;  ///< m names, one per pair (e.g. the diodes)
  /// B: n_x x m, row-major: out[i * m + j] = B_ij (state i, pair j).
  SmoothFunction input_matrix;
  /// g: m outputs.
  SmoothFunction output;
  /// D: m x m, row-major (out[k * m + j] = D_kj), or empty for D = 0 (index-2 form).
  SmoothFunction feedthrough;
};

/// One effect of a scene: a moving set, switching surfaces, a hysteresis relay, path constraints or
/// a complementarity system.
using Effect =
    std::variant<MovingSet, SwitchingSurfaces, HysteresisRelay, PathConstraints, Complementarity>;

/// The kind of an effect as used in messages ("moving set", "switching surfaces", ...).
std::string EffectKind(const Effect& effect);
/// The effect's name.
const std::string& EffectName(const Effect& effect);

/// What a scene's author knows of its scales (scene files: the [defaults] table,
/// docs/scene-files.md): integrator settings that moreau::Simulate uses where the user gives
/// none (docs/accuracy.md). Zero or empty: the integrator's own default.
struct SceneDefaults {
  double relative_tolerance = 0.0;  ///< rtol of error-controlled runs, >= 0
  double absolute_tolerance = 0.0;  ///< atol of error-controlled runs (one for every state), >= 0
  double initial_step = 0.0;        ///< initial step of error-controlled runs (h0), >= 0
  double max_step = 0.0;            ///< largest step of error-controlled runs (h_max), >= 0
  /// Output times: the trajectory at these times (dense output), in [t0, tf]; times beyond a
  /// horizon the user shortened are left out.
  std::vector<double> output_times;
  double output_step = 0.0;  ///< output every output_step from t0 (output_dt), >= 0

  bool empty() const {  ///< whether the scene declares nothing (every field zero or empty)
    return relative_tolerance == 0.0 && absolute_tolerance == 0.0 && initial_step == 0.0 &&
           max_step == 0.0 && output_times.empty() && output_step == 0.0;
  }
};

/// A complete problem description (see file comment).
struct Scene {
  /// The scene's name (messages, output directories).
  std::string name;
  /// One line for `moreau list` and `moreau show`.
  std::string description;
  /// The names of the states x, in order.
  std::vector<std::string> state_names;
  /// Initial state x0.
  Vector initial_state;
  /// Initial time t0.
  double initial_time = 0.0;
  /// Final time tf.
  double final_time = 1.0;
  /// The parameters p, in order.
  std::vector<ParameterSpec> parameters;
  /// The inputs u, in order.
  std::vector<InputSpec> inputs;
  SmoothFunction dynamics;  ///< f(x, u, t, p) with n_x outputs; empty means f = 0
  /// The effects, in order.
  std::vector<Effect> effects;
  /// Speed of time (time transformation for free final times), -1 for none. Otherwise the
  /// index of a control input s > 0: the scene's time axis (initial_time, final_time, control
  /// breakpoints) is then *numerical* time tau, physical time t (the clock, the t argument of
  /// every model function) advances as dt/dtau = s, and every physical rate is multiplied by s
  /// (smooth dynamics, switching modes, relay fields; moving-set multipliers adapt). Supported
  /// by the FESD integrator.
  int time_scale_input = -1;
  /// Integrator settings the scene's author chose for its scales (see SceneDefaults).
  SceneDefaults defaults;
  /// How figures and animations show the scene (names, units, planar geometry); never
  /// changes the dynamics (moreau/model/view.hpp).
  SceneView view;

  /// Number of states n_x.
  int num_states() const { return static_cast<int>(state_names.size()); }
  /// Number of inputs n_u.
  int num_inputs() const { return static_cast<int>(inputs.size()); }
  /// Number of parameters n_p.
  int num_parameters() const { return static_cast<int>(parameters.size()); }
  /// Adds a parameter and returns its index in p.
  int AddParameter(const std::string& name, double value, const std::string& description);
  /// Index of a parameter by name, or -1.
  int FindParameter(const std::string& name) const;
  /// Current parameter values p.
  Vector ParameterValues() const;
  /// Input values at time t (controls from their signals; algebraic inputs from the guess).
  Vector InputValues(double t) const;
  /// Sorted control breakpoints in (initial_time, final_time): integrators stop there.
  std::vector<double> ControlBreakpoints() const;
  /// True if any effect is of the given alternative type.
  template <class E>
  bool Has() const {
    for (const Effect& effect : effects) {
      if (std::holds_alternative<E>(effect)) return true;
    }
    return false;
  }
};

/// Tolerance on c(x0, t0) >= 0 for the initial state of a moving set: values down to
/// -kInitialFeasibilityTolerance * max(1, |x0|_inf) count as feasible (round-off in x0).
inline constexpr double kInitialFeasibilityTolerance = 1e-12;

/// Throws std::invalid_argument naming the first problem found: empty or duplicate names,
/// dimension mismatches (initial state, function outputs, projection basis, number of
/// modes, complementarity matrices), a complementarity feedthrough D that is not a P-matrix at
/// the initial point, non-finite values, a non-positive horizon, out-of-range function arguments,
/// non-finite function values at the initial point, and initial states outside the moving
/// sets (x0 not in C(t0)). `check_initial_feasibility = false` skips the last check, for
/// integrators that start elsewhere and project (FesdOptions::initial_state).
void ValidateScene(const Scene& scene, bool check_initial_feasibility = true);

/// Most pairs one Complementarity effect may have (validation; the status decision enumerates
/// the pairs that are zero on both sides at a switch).
inline constexpr int kMaxComplementarityPairs = 64;
/// Largest D whose principal minors PMatrixViolation enumerates (2^m - 1 determinants) when
/// its symmetric part is not positive definite.
inline constexpr int kMaxEnumeratedPMatrixSize = 16;

/// Empty if D is a P-matrix (every principal minor positive: a positive definite symmetric
/// part suffices, otherwise all 2^m - 1 minors are checked, m <= kMaxEnumeratedPMatrixSize),
/// else the first failing principal minor ("the principal minor of rows and columns {1, 3} is
/// 0 (must be > 0)", 1-based). A P-matrix is exactly what makes LCP(q, D) uniquely solvable for
/// every q (Cottle, Pang, Stone, The Linear Complementarity Problem, Thm. 3.3.7). Throws
/// std::invalid_argument for a non-square D or an m too large to enumerate.
std::string PMatrixViolation(const Matrix& d);

/// Empty if every model function of the scene (dynamics and every effect's functions) is
/// finite at the state x, inputs u, time t and parameters p; otherwise names the first that is
/// not: which function, which output, its value, and the point, e.g. "the dynamics f, output
/// 'y' (the rate of state y), is nan at t = 0.1276, x = (x = -1e-17, y = 0.03)". Integrators put
/// it into their non-finite statuses (a runaway named, never an unexplained solver failure).
std::string NonFiniteModelValue(const Scene& scene, const Vector& x, const Vector& u, double t,
                                const Vector& p);

/// Names accepted by SetSceneValue: "tf", "x0.<state>" and every parameter name.
std::vector<std::string> OverridableNames(const Scene& scene);

/// Sets a named value ("tf", "x0.<state>" or a parameter). Throws std::invalid_argument for
/// unknown names (listing the valid ones) and for non-finite values.
void SetSceneValue(Scene* scene, const std::string& name, double value);

}  // namespace moreau
