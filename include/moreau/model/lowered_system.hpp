#pragma once
/// @file
/// LoweredSystem: a scene lowered to an autonomous dynamic complementarity system (DCS)
///
///   y' = F(y, z),   0 = G(y, z),   0 <= A_k(y, z) ⟂ B_k(y, z) >= 0  (k = 1..n_pairs),
///
/// in the state y = (x, internal states, clock) and the algebraic unknowns z, with
/// n_z = n_G + n_pairs so that every collocation stage is square. The clock is the last
/// state; it carries physical time (clock' = 1, or 0 while time is frozen), so F, G, A and B
/// never depend on the integration variable explicitly. Parameters p and the current input
/// values u are set on the object; integrators keep u fixed between control breakpoints.
///
/// Only the effects a scene declares are lowered; a scene without effects gives n_z = 0.
/// The lowering of each effect (gradient form for moving sets, Stewart or Heaviside step
/// form for switching surfaces, time-freezing for hysteresis relays) is documented with its
/// equations in docs/lowering.md.
///
/// Time-freezing: with hysteresis relays the integration variable is *numerical time* tau,
/// the internal states are the relay memories w_i, and the clock runs at rate P(z) in {0, 1}
/// along solutions: 1 while the relays evolve in their modes, 0 while a relay's memory
/// travels between 0 and 1 (its jump, frozen in physical time). The physical-time dynamics
/// (smooth f and switching modes) are multiplied by P; moving-set multipliers are not.
///
/// Every complementarity pair has a *continuous side*: the quantity that is continuous in
/// time along solutions (e.g. c(x, t) for a moving set, lambda_i = g_i - min g in Stewart's
/// form). Integrators use it for cross complementarity at element boundaries.

#include <memory>
#include <string>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/linalg/derivative_matrix.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/events.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// How switching surfaces are lowered.
enum class SwitchingForm {
  kStewart,    ///< Stewart's convex-multiplier form (theta, lambda, mu)
  kHeaviside,  ///< Heaviside step form (alpha, lambda_n, lambda_p)
};
/// "stewart" or "heaviside".
std::string ToString(SwitchingForm form);
/// Parses "stewart" or "heaviside"; throws std::invalid_argument otherwise.
SwitchingForm ParseSwitchingForm(const std::string& name);

/// How hysteresis relays are lowered.
enum class RelayForm {
  /// Time-freezing: a Stewart subsystem per relay in numerical time (FESD, time-stepping).
  kTimeFreezing,
  /// Discrete memory: w_i is a state with w_i' = 0 that event-driven integrators flip when the
  /// relay's switching function (MemorySwitchingFunctions) reaches zero (IDA).
  kDiscreteMemory,
};

/// How the derivatives of a lowered system are stored (DerivativeMatrix).
enum class DerivativeStorage {
  /// Sparse if n_y + n_z > kSparseStorageThreshold or the dynamics have a hand-written sparse
  /// Jacobian (MakeSparseStateFunction), dense otherwise.
  kAutomatic,
  kDense,   ///< dense matrices, dense forward-mode AD (small systems: fastest)
  kSparse,  ///< compressed sparse matrices from sparse AD (large systems: cost ~ nonzeros)
};
/// "auto", "dense" or "sparse".
std::string ToString(DerivativeStorage storage);

/// The storage an integrator asks for given its linear solver option: sparse with the sparse
/// LU, otherwise automatic (a dense LU also accepts sparse blocks).
inline DerivativeStorage StorageForLinearSolver(LinearSolverKind kind) {
  return kind == LinearSolverKind::kSparseLu || kind == LinearSolverKind::kKlu
             ? DerivativeStorage::kSparse
             : DerivativeStorage::kAutomatic;
}

/// The near-active constraint filter of the integrators (docs/sparse-systems.md): moving-set
/// constraints far from zero are left out of the element systems and checked afterwards.
enum class ConstraintFilter {
  kAutomatic,  ///< on when the scene declares more than kFilterThreshold moving-set constraints
  kOff,        ///< every constraint in every element system
  kOn,         ///< the filter on whatever the number of constraints
};
/// "auto", "off" or "on".
std::string ToString(ConstraintFilter filter);
/// Parses "auto", "off" or "on"; throws std::invalid_argument otherwise.
ConstraintFilter ParseConstraintFilter(const std::string& name);
/// ConstraintFilter::kAutomatic turns the filter on above this many moving-set constraints.
inline constexpr int kFilterThreshold = 64;

/// Under DerivativeStorage::kAutomatic, systems with more than this many states and algebraic
/// unknowns (n_y + n_z) are stored sparse: a Radau IIA stage system of s >= 2 stages then has
/// more than kDenseSizeLimit = 256 unknowns, where the sparse LU takes over from the dense one.
inline constexpr int kSparseStorageThreshold = 128;

/// How a scene is lowered (defaults: Stewart's form, time-freezing, automatic storage).
struct LoweringOptions {
  /// Lowering of switching surfaces.
  SwitchingForm switching_form = SwitchingForm::kStewart;
  /// Lowering of hysteresis relays (time-freezing for FESD and time-stepping, discrete memory for
  /// IDA).
  RelayForm relay_form = RelayForm::kTimeFreezing;
  /// Require the scene's x0 to lie in its moving sets (ValidateScene); false for integrators
  /// that start from another state and project it (FesdOptions::initial_state).
  bool require_feasible_initial_state = true;
  /// Dense or sparse derivatives (docs/sparse-systems.md).
  DerivativeStorage storage = DerivativeStorage::kAutomatic;
};

/// Which derivatives LoweredSystem::Evaluate computes.
enum class Derivatives {
  kNone,    ///< values F, G, A, B only
  kStates,  ///< values and derivatives with respect to y and z
  kAll,     ///< also with respect to the inputs u and the parameters p
};

/// Values (and requested derivatives) of the lowered system at one point (y, z). The
/// derivatives are stored as the system says (LoweredSystem::sparse()).
struct PointEvaluation {
  Vector F;              ///< the dynamics y' = F (n_y)
  Vector G;              ///< the equations 0 = G (n_G)
  Vector A;              ///< first sides of the pairs, 0 <= A ⟂ B >= 0 (n_pairs)
  Vector B;              ///< second sides of the pairs (n_pairs)
  DerivativeMatrix F_y;  ///< dF/dy (Derivatives::kStates or kAll)
  DerivativeMatrix G_y;  ///< dG/dy (Derivatives::kStates or kAll)
  DerivativeMatrix A_y;  ///< dA/dy (Derivatives::kStates or kAll)
  DerivativeMatrix B_y;  ///< dB/dy (Derivatives::kStates or kAll)
  DerivativeMatrix F_z;  ///< dF/dz (Derivatives::kStates or kAll)
  DerivativeMatrix G_z;  ///< dG/dz (Derivatives::kStates or kAll)
  DerivativeMatrix A_z;  ///< dA/dz (Derivatives::kStates or kAll)
  DerivativeMatrix B_z;  ///< dB/dz (Derivatives::kStates or kAll)
  DerivativeMatrix F_u;  ///< dF/du (Derivatives::kAll)
  DerivativeMatrix G_u;  ///< dG/du (Derivatives::kAll)
  DerivativeMatrix A_u;  ///< dA/du (Derivatives::kAll)
  DerivativeMatrix B_u;  ///< dB/du (Derivatives::kAll)
  DerivativeMatrix F_p;  ///< dF/dp (Derivatives::kAll)
  DerivativeMatrix G_p;  ///< dG/dp (Derivatives::kAll)
  DerivativeMatrix A_p;  ///< dA/dp (Derivatives::kAll)
  DerivativeMatrix B_p;  ///< dB/dp (Derivatives::kAll)
};

/// Which side of a complementarity pair is continuous in time along solutions.
enum class ContinuousSide {
  kA,
  kB,
  /// Both sides (index-1 pairs: an index-1 complementarity system's lambda and w). b must be an
  /// algebraic unknown itself (b = z_j), so that its velocity-level slot is its rate: the pair
  /// then reads 0 <= b' ⟂ a' >= 0 at velocity level, and both free sides are functions of the
  /// state (event indicators, certificates, IDA's position-level conditions).
  kBoth,
};

/// Description of one complementarity pair (for events and cross complementarity).
struct PairInfo {
  std::string effect;  ///< name of the effect it comes from
  std::string name;    ///< e.g. "wall.c1" or "circle.theta[outside]"
  /// Which side of the pair is continuous in time along solutions.
  ContinuousSide continuous = ContinuousSide::kA;
  int block = 0;  ///< index of the lowered effect (see block_names())
  /// ContinuousSide::kBoth: the index in z of the algebraic unknown that b is; -1 otherwise.
  int b_unknown = -1;
};

/// Second-derivative terms of the velocity-level rows (see LoweredSystem::EvaluateVelocityLevel):
/// rows of d/d(y, u, p) [grad_y X(y) . d] for the continuous sides of pairs and for the
/// differentiated equation rows, for a fixed direction d.
struct CurvatureTerms {
  DerivativeMatrix pair_y;      ///< continuous sides of the pairs, by y (n_pairs rows)
  DerivativeMatrix pair_u;      ///< continuous sides of the pairs, by u (n_pairs rows)
  DerivativeMatrix pair_p;      ///< continuous sides of the pairs, by p (n_pairs rows)
  DerivativeMatrix equation_y;  ///< differentiated equation rows, by y (n_G rows)
  DerivativeMatrix equation_u;  ///< differentiated equation rows, by u (n_G rows)
  DerivativeMatrix equation_p;  ///< differentiated equation rows, by p (n_G rows)
};

/// Event indicators (free side of every pair) and their derivatives.
struct IndicatorEvaluation {
  Vector values;         ///< n_pairs
  DerivativeMatrix d_y;  ///< by the state y (n_pairs rows)
  DerivativeMatrix d_v;  ///< by the velocity-level unknowns v (n_pairs rows)
  DerivativeMatrix d_u;  ///< by the inputs u (n_pairs rows)
  DerivativeMatrix d_p;  ///< by the parameters p (n_pairs rows)
};

/// Role of a pair in the velocity-level problem.
enum class PairRole {
  kAZero,          ///< a = 0 is kept (continuous a: a' = 0; jump a: a = 0)
  kBZero,          ///< b = 0 is kept (continuous b: b' = 0; jump b: b = 0)
  kComplementary,  ///< 0 <= jump side ⟂ rate of the continuous side >= 0
};

/// Rows of the velocity-level problem and their derivatives (see EvaluateVelocityLevel).
struct VelocityLevelEvaluation {
  Vector equations;              ///< n_G rows, then one row per pair with a decided role
  Vector a;                      ///< complementary pairs: the jump side's value
  Vector b;                      ///< complementary pairs: the continuous side's rate
  DerivativeMatrix equations_v;  ///< d equations / dv (always)
  DerivativeMatrix a_v;          ///< d a / dv (always)
  DerivativeMatrix b_v;          ///< d b / dv (always)
  DerivativeMatrix equations_y;  ///< d equations / dy (Derivatives::kStates or kAll)
  DerivativeMatrix a_y;          ///< d a / dy (Derivatives::kStates or kAll)
  DerivativeMatrix b_y;          ///< d b / dy (Derivatives::kStates or kAll)
  DerivativeMatrix equations_u;  ///< d equations / du (Derivatives::kAll)
  DerivativeMatrix a_u;          ///< d a / du (Derivatives::kAll)
  DerivativeMatrix b_u;          ///< d b / du (Derivatives::kAll)
  DerivativeMatrix equations_p;  ///< d equations / dp (Derivatives::kAll)
  DerivativeMatrix a_p;          ///< d a / dp (Derivatives::kAll)
  DerivativeMatrix b_p;          ///< d b / dp (Derivatives::kAll)
};

/// Outcome of LoweredSystem::DecideStatuses.
struct StatusDecision {
  bool solved = false;       ///< a consistent assignment was found
  std::vector<bool> a_zero;  ///< per pair: true if a = 0 holds next, false if b = 0
  Vector v;                  ///< velocity-level values for that assignment
  bool ambiguous = false;    ///< several continuations with different velocities
  int candidates = 0;        ///< pairs that were zero on both sides at y
  std::string message;       ///< why not solved, or what was ambiguous
};

/// Which side of a pair is zero: a if a <= b (ties, both zero, count as a = 0).
inline bool PairStatusIsAZero(double a, double b) { return a <= b; }

namespace internal {
struct BlockContext;
class LoweredBlock;
class ArgumentMatrix;
class VelocitySolver;
class ThreadPool;
}  // namespace internal

/// A scene lowered to a DCS (see file comment).
class LoweredSystem {
 public:
  /// Lowers every effect of `scene` (validated first; throws std::invalid_argument naming the
  /// problem).
  explicit LoweredSystem(const Scene& scene, const LoweringOptions& options = {});
  ~LoweredSystem();
  /// A copy with its own workspaces.
  LoweredSystem(const LoweredSystem& other);
  /// A copy with its own workspaces.
  LoweredSystem& operator=(const LoweredSystem& other);

  /// The scene it was lowered from (with the values last set by UpdateValues).
  const Scene& scene() const { return scene_; }
  /// The options it was lowered with.
  const LoweringOptions& options() const { return options_; }
  int num_states() const { return num_states_; }                ///< n_y
  int num_scene_states() const { return scene_.num_states(); }  ///< n_x (y[0..n_x))
  /// Hysteresis relays, in the order of their memory states y[n_x + i] (time-freezing).
  const std::vector<std::string>& relay_names() const { return relay_names_; }
  /// True if relays are lowered by time-freezing: the clock is then not the integration
  /// variable.
  bool time_freezing() const { return time_freezing_; }
  /// Discrete-memory relays (RelayForm::kDiscreteMemory): per relay a switching function of y
  /// that is positive until the relay switches, 1 - psi while w = 0 and psi while w = 1.
  Vector MemorySwitchingFunctions(const Vector& y) const;
  /// Flips relay i's memory in y (w -> 1 - w) after its switching function reached zero.
  void SwitchMemory(int relay, Vector* y) const;
  /// Per relay under the pair statuses a_zero: -1 while it evolves in a mode, otherwise the
  /// memory value (0 or 1) it travels to while physical time is frozen (an auxiliary region).
  std::vector<int> MemoryTargets(const std::vector<bool>& a_zero) const;
  /// True if physical time is frozen under the pair statuses a_zero (some relay is jumping).
  bool TimeFrozen(const std::vector<bool>& a_zero) const;
  /// Events implied by the statuses decided at the initial state y: relays whose memory w0 is
  /// inconsistent with psi(x0) and are re-initialized while time is frozen (or that start
  /// inside a jump, 0 < w0 < 1).
  std::vector<Event> InitialEvents(double t, const Vector& y,
                                   const std::vector<bool>& a_zero) const;
  /// Index of the clock in y (the last state).
  int clock_index() const { return num_states_ - 1; }
  int num_algebraic() const { return num_algebraic_; }  ///< n_z
  int num_equations() const { return num_equations_; }  ///< n_G
  /// Number of complementarity pairs n_pairs.
  int num_pairs() const { return num_pairs_; }
  /// Number of scene inputs n_u.
  int num_inputs() const { return scene_.num_inputs(); }
  /// Number of scene parameters n_p.
  int num_parameters() const { return scene_.num_parameters(); }
  /// Names of the lowered states y.
  const std::vector<std::string>& state_names() const { return state_names_; }
  /// Names of the algebraic unknowns z.
  const std::vector<std::string>& algebraic_names() const { return algebraic_names_; }
  /// Every complementarity pair of the working set, in order.
  const std::vector<PairInfo>& pairs() const { return pairs_; }

  /// y0 = (x0, internal initial states (relay memories w0), t0).
  Vector InitialState() const;
  /// A guess of the algebraic unknowns at state y, for Newton's first iterate: Stewart's
  /// theta selects the region containing y, Heaviside's alpha follows the signs of c, and
  /// multipliers come from `previous` (or are 0). Where y does not decide (y on a switching
  /// surface), the values in `previous` are kept.
  Vector InitialAlgebraicGuess(const Vector& y, const Vector* previous = nullptr) const;
  /// The same into *z (resized; no allocation when it has the size already). previous must
  /// not be z.
  void InitialAlgebraicGuess(const Vector& y, const Vector* previous, Vector* z) const;
  /// Sets the input values u used by Evaluate (held constant by integrators within a step).
  void SetInputs(const Vector& u);
  /// The input values u set last.
  const Vector& inputs() const { return inputs_; }
  /// Sets the parameter values p (defaults: the scene's).
  void SetParameters(const Vector& p);
  /// Takes the values of `scene` — initial state and time, final time, parameter values and
  /// input signals — without lowering again: `scene` must be this system's scene with other
  /// values (the same states, parameters, inputs and effects; the model functions are not
  /// compared). Used by integrators that run one lowered system many times (shooting).
  /// Throws std::invalid_argument if the structure differs.
  void UpdateValues(const Scene& scene);
  /// The parameter values p set last.
  const Vector& parameters() const { return parameters_; }

  /// Evaluates F, G, A, B (and derivatives) at (y, z). Not thread-safe (see SmoothFunction).
  void Evaluate(const ConstVectorRef& y, const ConstVectorRef& z, Derivatives derivatives,
                PointEvaluation* out) const {
    EvaluatePoint(y, z, derivatives, nullptr, out);
    NoteNonFinite(y, *out, false);
  }
  /// F and its derivatives (F_y, F_z; F_u, F_p with Derivatives::kAll) as Evaluate gives them;
  /// G, A, B and their derivatives are sized but unspecified (blocks may skip them). For
  /// integrators of the field with the algebraic unknowns held fixed (the smooth elements of
  /// FESD: Radau IIA steps of the field the statuses leave).
  ///
  /// switching_mode >= 0 (a scene whose only effect is one switching effect in Stewart's form,
  /// without other dynamics): F is the field f_mode of that mode alone, x' = f_mode(x), as if
  /// theta were the unit vector e_mode (z is not read). Bitwise the F and F_y of a system
  /// lowered from the dynamics f_mode, without lowering one per mode.
  void EvaluateField(const ConstVectorRef& y, const ConstVectorRef& z, Derivatives derivatives,
                     PointEvaluation* out, int switching_mode = -1) const {
    EvaluatePoint(y, z, derivatives, nullptr, out, /*field_only=*/true, switching_mode);
    NoteNonFinite(y, *out, true);
  }

  /// Non-finite witness: the first point y since ClearNonFinite() at which Evaluate or
  /// EvaluateField produced a non-finite F (or G, A, B), kept so that an integrator whose
  /// solve failed can say which model function was not finite where (DescribeNonFinite)
  /// instead of reporting the solver's failure alone. Not thread-safe (as Evaluate).
  void ClearNonFinite() const { non_finite_seen_ = false; }
  bool non_finite_seen() const { return non_finite_seen_; }  ///< a non-finite value since Clear
  const Vector& non_finite_state() const { return non_finite_state_; }  ///< y where it first was
  /// NonFiniteModelValue of the scene at the lowered state y (scene states, time from the
  /// clock) with the current inputs and parameters; empty if every model function is finite
  /// there.
  std::string DescribeNonFinite(const Vector& y) const;

  /// Velocity-level structure: continuous algebraic unknowns (rates at velocity level) and
  /// differentiated equations (see EvaluateVelocityLevel).
  const std::vector<bool>& continuous_algebraic() const { return continuous_algebraic_; }
  /// Per equation row of G: whether the velocity level differentiates it.
  const std::vector<bool>& differentiated_equations() const { return differentiated_; }

  /// Candidate sets larger than this are resolved by one semismooth Newton solve of the
  /// velocity-level complementarity problem instead of enumeration (no ambiguity check).
  static constexpr int kMaxEnumeratedCandidates = 10;

  // --- near-active constraint filter (docs/sparse-systems.md) ------------------------------
  // The pairs a scene declares are the "declared pairs" (every constraint of every effect);
  // the system holds a working set of them. Moving-set constraints may be left out (their
  // multiplier is zero and they have no pair, unknown or equation); every other pair is
  // always in. Integrators move their state between working sets with the Remap functions.

  /// Every pair the scene declares (num_pairs() when nothing is left out).
  int num_declared_pairs() const { return num_declared_pairs_; }
  /// The declared index of every pair of the system (increasing).
  const std::vector<int>& working_pairs() const { return working_pairs_; }
  /// True if the system has moving-set constraints (which may be left out).
  bool has_filterable_pairs() const;
  /// True if declared pair `declared` may be left out.
  bool PairFilterable(int declared) const;
  /// Keeps the declared pairs with keep[k] true (every pair that is not filterable must be
  /// kept) and lays the system out anew. Returns true if the working set changed.
  bool SetWorkingPairs(const std::vector<bool>& keep);
  /// Where the state of an integrator sits in a working set (for the Remap functions).
  struct WorkingLayout {
    std::vector<int> z_offset;              ///< per block: offset of its algebraic unknowns
    std::vector<int> pair_offset;           ///< per block: offset of its pairs
    std::vector<std::vector<int>> working;  ///< per block: its working pairs (block-local)
    int num_algebraic = 0;                  ///< algebraic unknowns in all
    int num_pairs = 0;                      ///< pairs in all
  };
  /// The current layout (for the Remap functions).
  WorkingLayout working_layout() const;
  /// z (laid out as in `from`) in the current layout; unknowns new to it get `fill`.
  Vector RemapAlgebraic(const Vector& z, const WorkingLayout& from, double fill) const;
  /// Per-pair values (laid out as in `from`) in the current layout; new pairs get `fill`.
  Vector RemapPairValues(const Vector& values, const WorkingLayout& from, double fill) const;
  /// Per-pair statuses (laid out as in `from`) in the current layout; new pairs get `fill`.
  std::vector<bool> RemapStatuses(const std::vector<bool>& a_zero, const WorkingLayout& from,
                                  bool fill) const;
  /// For every declared moving-set constraint (NaN for other declared pairs): its value
  /// c_k(y) and the bound |grad_x c_k(y)|_1 max_i |velocity_i| + |dc_k/dt(y)| on its rate
  /// (velocity: n_x scene-state rates).
  void FilterableConstraints(const Vector& y, const Vector& velocity, Vector* values,
                             Vector* rate_bounds) const;
  /// The smallest value at y of the constraints left out (infinity if none).
  double MinExcludedConstraint(const Vector& y) const;
  /// Sets include[declared] for every left-out constraint whose value at y is below threshold.
  void ExcludedViolations(const Vector& y, double threshold, std::vector<bool>* include) const;
  /// The algebraic unknowns of every declared pair: z with zeros for left-out multipliers.
  Vector DeclaredAlgebraic(const Vector& z) const;
  /// Number of algebraic unknowns of every declared pair (DeclaredAlgebraic's size).
  int num_declared_algebraic() const;
  /// Their names.
  std::vector<std::string> declared_algebraic_names() const;

  /// True if derivatives are stored sparse (LoweringOptions::storage resolved).
  bool sparse() const { return sparse_; }
  /// Threads that evaluate the sparse derivatives and the interval enclosures (event
  /// indicators' bounds) of model functions made of blocks (MakeBlockFunction) in parallel:
  /// `threads` > 0 threads (the calling one included), or every hardware thread for `threads`
  /// <= 0. Only systems stored sparse use them (small systems stay on the calling thread, where
  /// their evaluations take microseconds); calls over fewer than 1024 blocks (8192 for
  /// enclosures) run on the calling thread. Results are bitwise the same for any number of threads:
  /// each block's derivatives and enclosures are computed alone and written to their own places,
  /// second derivatives in block order. A copy of the system starts without threads.
  void SetThreads(int threads);
  /// The threads in use (1: the calling thread only).
  int threads() const;
  /// CPU time the worker threads spent for this system since SetThreads (RunClock).
  double worker_cpu_seconds() const;
  /// Structurally nonzero entries of each derivative block with respect to y and z at the
  /// initial point (sparse storage; dense storage counts every entry), for sizing linear
  /// solvers before the first evaluation.
  struct Nonzeros {
    double F_y = 0;  ///< structural nonzeros of F_y
    double F_z = 0;  ///< structural nonzeros of F_z
    double G_y = 0;  ///< structural nonzeros of G_y
    double G_z = 0;  ///< structural nonzeros of G_z
    double A_y = 0;  ///< structural nonzeros of A_y
    double A_z = 0;  ///< structural nonzeros of A_z
    double B_y = 0;  ///< structural nonzeros of B_y
    double B_z = 0;  ///< structural nonzeros of B_z
  };
  /// The nonzero counts at the initial point.
  const Nonzeros& nonzeros() const;
  /// Number of structurally nonzero entries of F_y (for choosing dense or sparse LU).
  double EstimatedNonzerosFy() const { return nonzeros().F_y; }

  // --- velocity level -------------------------------------------------------------------
  /// The velocity-level problem at state y (docs/fesd-formulation.md): unknowns v in the
  /// layout of z, jump variables (theta, alpha, moving-set lambda) as values and continuous
  /// variables (Stewart's lambda and mu, Heaviside's lambda_n, lambda_p) as rates. Rows:
  /// the equations G (differentiated along the flow, G_y F + G_z v_c, or on values), then for
  /// each pair with a decided role one equation (the kept side's rate if it is continuous,
  /// its value if it is a jump variable); pairs with kComplementary give (a, b) =
  /// (jump side, rate of the continuous side). Derivatives with respect to v always; with
  /// respect to y (and u, p) per `derivatives`, including the second-derivative terms.
  void EvaluateVelocityLevel(const ConstVectorRef& y, const ConstVectorRef& v,
                             const std::vector<PairRole>& roles, Derivatives derivatives,
                             VelocityLevelEvaluation* out) const;
  /// Event indicators at y: the free side of every pair for statuses a_zero (continuous
  /// sides from y, jump sides from the velocity-level values v).
  void EvaluateEventIndicators(const ConstVectorRef& y, const ConstVectorRef& v,
                               const std::vector<bool>& a_zero, Derivatives derivatives,
                               IndicatorEvaluation* out) const;
  /// Event indicators at y (the values of EvaluateEventIndicators with derivatives, bit for
  /// bit) and their slopes along the state direction dy, slopes_k = d_y.row(k) . dy up to
  /// round-off (v, u, p held): what a search along a path needs at a node, without the full
  /// Jacobian d_y. Returns false, with *values and *slopes unspecified, if a block with pairs
  /// does not provide them (today only complementarity blocks in dense storage do, whose
  /// index-1 free sides have no interval bounds; the caller then takes d_y from
  /// EvaluateEventIndicators).
  bool EvaluateEventIndicatorSlopes(const ConstVectorRef& y, const ConstVectorRef& v,
                                    const std::vector<bool>& a_zero, const ConstVectorRef& dy,
                                    Vector* values, Vector* slopes) const;
  /// Enclosures of the event indicators over a box of states: for statuses a_zero, lower_k <=
  /// (free side of pair k at y) <= upper_k for every y with y_lower <= y <= y_upper (the clock's
  /// entries bound the time), by interval arithmetic on the model functions (core/interval.hpp).
  /// Available for the free sides that are functions of the state through model functions:
  /// inactive moving-set constraints c, Stewart's lambda and Heaviside's lambda_n, lambda_p
  /// (switching functions), index-2 complementarity outputs g of inactive pairs, and the Voronoi
  /// indicators of hysteresis relays (relay inputs). Every other entry is (-inf, +inf): jump free
  /// sides (multipliers, theta, alpha), index-1 complementarity free sides (which involve the
  /// consistent multipliers), and functions without interval evaluation (hand-written
  /// Jacobians, comparisons that the box does not decide).
  void BoundEventIndicators(const ConstVectorRef& y_lower, const ConstVectorRef& y_upper,
                            const std::vector<bool>& a_zero, Vector* lower, Vector* upper) const;
  /// Enclosures of MemorySwitchingFunctions over a box of states (as BoundEventIndicators).
  void BoundMemorySwitchingFunctions(const ConstVectorRef& y_lower, const ConstVectorRef& y_upper,
                                     Vector* lower, Vector* upper) const;
  /// Roles for fixed statuses (every pair decided).
  static std::vector<PairRole> RolesFor(const std::vector<bool>& a_zero);
  /// Solves the velocity-level problem for fixed statuses (smooth, square) from v0. Returns
  /// false if Newton does not converge.
  bool SolveVelocityLevel(const Vector& y, const std::vector<bool>& a_zero, const Vector& v0,
                          Vector* v) const;
  /// The same, given `point`: this system's Evaluate at (y, z) with derivatives (kStates or
  /// kAll), e.g. a collocation stage. Where the velocity level is linear (every effect affine
  /// in the algebraic unknowns; with time-freezing, one relay and no switching surfaces, see
  /// VelocityLevelIsLinear) that evaluation is the velocity-level
  /// evaluation at z, the solve starts there and evaluates nothing more; otherwise `point` and
  /// z are not used.
  bool SolveVelocityLevel(const Vector& y, const std::vector<bool>& a_zero, const Vector& v0,
                          const Vector& z, const PointEvaluation& point, Vector* v) const;
  /// Decides the statuses that continue from state y (the slow solution): pairs whose
  /// continuous side is not zero keep their jump side at zero; candidate pairs (continuous
  /// side within candidate_tolerance of zero) are resolved by the velocity-level
  /// complementarity problem, all assignments of up to kMaxEnumeratedCandidates candidates
  /// being checked. Several valid assignments with different velocities are ambiguous: the
  /// one of least velocity norm is taken (slow solution). Valid assignments with equal
  /// velocities (degenerate pairs, zero on both sides at velocity level) are broken in favour
  /// of the continuous side being free, i.e. the pair leaves zero (second-order departure).
  /// Candidates of moving sets are not enumerated: their velocity-level problem is a monotone
  /// LCP (matrix J P J^T) whose solutions share one velocity, so one semismooth Newton solve
  /// decides them inside every enumerated assignment of the other candidates (a crowd's
  /// active contacts are all candidates at every switch: enumeration would cost 2^contacts).
  StatusDecision DecideStatuses(const Vector& y, double candidate_tolerance) const;

  /// Events implied by a change of pair statuses: a_zero[k] is true when pair k has its
  /// first side a_k = 0, false when b_k = 0 (see PairStatusIsAZero).
  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const;

 private:
  void Build();
  // What every call of a block receives (lowered_block.hpp): the scene's state count and the
  // clock's index, the inputs and parameters, the derivative storage and the system's threads.
  // Made in one place so that no call leaves one out (the enclosures of the event indicators
  // once ran without the threads); callers add what their call sets (velocity-level roles, a
  // field-only evaluation). Defined in lib/model/lowered_block.hpp.
  internal::BlockContext MakeBlockContext() const;
  // Offsets, names and pair descriptions of the blocks' current working sets.
  void Layout();
  // The block that declares pair `declared`.
  int DeclaredBlock(int declared) const;
  // True if every block is affine in the algebraic unknowns (the time-freezing block's clock
  // rate included) and the clock rate multiplies no block with algebraic unknowns: the
  // velocity-level rows are then affine in v (velocity_level.cpp).
  bool VelocityLevelIsLinear() const;
  // Weaker: for roles that decide every pair (no complementary pair) the velocity-level rows
  // are affine in v, with coefficients that may depend on the roles (every block
  // AffineInAlgebraicForDecidedRoles, the same clock-rate condition). A solve for fixed
  // statuses, and a status decision's trial, is then a linear system (velocity_level.cpp).
  bool VelocityLevelIsAffineForDecidedRoles() const;
  // The test of both: every block affine (for decided roles, or for all), the clock-rate
  // condition.
  bool VelocityLevelIsAffine(bool for_decided_roles) const;
  // Evaluate; with `velocity_roles` (EvaluateVelocityLevel, z = v) blocks see the roles and v
  // in their context (BlockContext::velocity_roles).
  // field_only, switching_mode: EvaluateField (BlockContext::field_only, switching_mode).
  void EvaluatePoint(const ConstVectorRef& y, const ConstVectorRef& z, Derivatives derivatives,
                     const std::vector<PairRole>* velocity_roles, PointEvaluation* out,
                     bool field_only = false, int switching_mode = -1) const;
  // Completes sparse accumulation (DerivativeMatrix::Finalize) of the requested blocks.
  void FinalizeEvaluation(Derivatives derivatives, PointEvaluation* out) const;
  // Records y as the non-finite witness if none is kept and the evaluation is not finite.
  void NoteNonFinite(const ConstVectorRef& y, const PointEvaluation& out, bool field_only) const {
    if (non_finite_seen_ ||
        (out.F.allFinite() &&
         (field_only || (out.G.allFinite() && out.A.allFinite() && out.B.allFinite())))) {
      return;
    }
    non_finite_seen_ = true;
    non_finite_state_ = y;
  }

  Scene scene_;
  LoweringOptions options_;
  int num_states_ = 0;
  int num_algebraic_ = 0;
  int num_equations_ = 0;
  int num_pairs_ = 0;
  int num_declared_pairs_ = 0;
  std::vector<int> declared_pair_offset_;  // per block: its first declared pair
  std::vector<int> working_pairs_;         // per pair: its declared index
  std::vector<std::string> state_names_;
  std::vector<std::string> relay_names_;
  std::vector<std::string> algebraic_names_;
  std::vector<PairInfo> pairs_;
  std::vector<bool> continuous_algebraic_;
  std::vector<bool> differentiated_;
  Vector inputs_;
  Vector parameters_;
  std::vector<std::unique_ptr<internal::LoweredBlock>> blocks_;
  int clock_rate_block_ = -1;  // the time-freezing block (hysteresis relays), or -1
  int memory_block_ = -1;      // the discrete-memory relay block, or -1
  bool time_freezing_ = false;
  bool sparse_dynamics_ = false;  // dynamics with a hand-written sparse Jacobian
  bool sparse_ = false;           // sparse derivative storage
  mutable Nonzeros nonzeros_;     // counted on first use after a layout (nonzeros())
  mutable bool nonzeros_valid_ = false;
  mutable Vector f_scratch_;
  mutable Eigen::RowVectorXd rate_gradient_;
  mutable PointEvaluation velocity_point_;  // EvaluateVelocityLevel's workspace
  mutable bool non_finite_seen_ = false;    // the non-finite witness (NoteNonFinite)
  mutable Vector non_finite_state_;
  mutable CurvatureTerms curvature_;
  mutable std::unique_ptr<internal::ArgumentMatrix> dynamics_jacobian_holder_;
  // SolveVelocityLevel's solver and its last solutions (velocity_level.cpp); not copied.
  // Made at its first use (VelocitySolverOf).
  mutable std::shared_ptr<internal::VelocitySolver> velocity_solver_;
  internal::VelocitySolver& VelocitySolverOf() const;
  std::unique_ptr<internal::ThreadPool> pool_;  // SetThreads; not copied
};

}  // namespace moreau
