#pragma once
// Private interface of one lowered effect inside LoweredSystem (namespace moreau::internal).

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "moreau/model/events.hpp"
#include "moreau/model/lowered_system.hpp"

namespace moreau::internal {

class ThreadPool;

// Where a block's unknowns and equations sit in the lowered system.
struct BlockLayout {
  int y_offset = 0;     // first internal state of the block in y (after x, before the clock)
  int z_offset = 0;     // first algebraic unknown of the block in z
  int g_offset = 0;     // first algebraic equation in G
  int pair_offset = 0;  // first complementarity pair
};

// Everything a block may read while evaluating: the point, inputs, parameters and the
// Jacobian column layout of the smooth model functions.
struct BlockContext {
  int num_scene_states = 0;
  int clock_index = 0;
  const Vector* inputs = nullptr;
  const Vector* parameters = nullptr;
  // Set only while EvaluateVelocityLevel evaluates (null at collocation points): the pair
  // roles and the velocity-level values v. Blocks whose contribution to F depends on
  // continuous algebraic unknowns (index-1 complementarity systems) evaluate F there at the
  // consistent values for these roles, because v holds the rates of such unknowns.
  const std::vector<PairRole>* velocity_roles = nullptr;
  const ConstVectorRef* velocity = nullptr;
  // Derivative storage of the system (LoweredSystem::sparse()): blocks differentiate their
  // model functions with sparse AD and add sparse blocks when set.
  bool sparse = false;
  // The system's threads (LoweredSystem::SetThreads), for sparse derivatives of functions made
  // of blocks; null: the calling thread only.
  ThreadPool* pool = nullptr;
  // Set by LoweredSystem::EvaluateField: only F and its derivatives are wanted; a block may
  // leave its G, A, B rows and their derivatives unwritten (they are not read).
  bool field_only = false;
  // With field_only, >= 0: the field of Stewart mode `switching_mode` alone (theta held at the
  // unit vector e_mode; LoweredSystem::EvaluateField).
  int switching_mode = -1;
};

}  // namespace moreau::internal

namespace moreau {
// Defined here, where BlockContext is complete, so that every evaluation inlines it.
inline internal::BlockContext LoweredSystem::MakeBlockContext() const {
  internal::BlockContext context{scene_.num_states(), clock_index(), &inputs_, &parameters_};
  context.sparse = sparse_;
  context.pool = pool_.get();
  return context;
}
}  // namespace moreau

namespace moreau::internal {

// A matrix whose columns follow a smooth model function's argument layout x, [u], t, [p]
// (Wrt::XT, or Wrt::All with Derivatives::kAll), dense or sparse, and whose rows the blocks
// scatter into the y (x columns and the clock column), u and p derivative blocks of the
// lowered system: a model function's Jacobian, or its second derivatives along a direction.
// Enclosure of a block's model function over a box of lowered states (x = the first n_x
// entries, t = the clock's entry; inputs and parameters from the context): false if the
// function has no interval evaluation there (SmoothFunction::Bounds). Only the rows in `rows`
// (sorted; nullptr: all) are needed; the others may be left unbounded.
bool FunctionBounds(const BlockContext& context, const SmoothFunction& function,
                    const ConstVectorRef& y_lower, const ConstVectorRef& y_upper, Vector* lower,
                    Vector* upper, const std::vector<int>* rows = nullptr);

class ArgumentMatrix {
 public:
  // Jacobian of `function` at the block's point x = y[0..n_x), t = y[clock] (values into
  // *values); with Derivatives::kNone only the values. Dense AD or sparse AD per context.
  void Jacobian(const BlockContext& context, const SmoothFunction& function,
                const ConstVectorRef& y, Derivatives derivatives, Vector* values,
                const std::vector<int>* rows = nullptr);
  // Row k of the x columns: its l1 norm (after Jacobian).
  double StateRowNorm1(int k) const;
  // The time column's entry of row k.
  double TimeEntry(int k) const;
  // Row k = (d^2 g_k / d(args)^2 . d)^T, d the direction in y-space (x and clock components
  // taken), for the outputs in `outputs` (nullptr: all; the other rows are zero).
  void HessianDirections(const BlockContext& context, const SmoothFunction& function,
                         const ConstVectorRef& y, const ConstVectorRef& direction,
                         Derivatives derivatives, const std::vector<int>* outputs = nullptr);
  int rows() const { return rows_; }
  // Adds weight * row k into row `row` of dy (x and clock columns) and, with kAll, of du, dp.
  void AddRow(int k, double weight, int row, DerivativeMatrix* dy, DerivativeMatrix* du,
              DerivativeMatrix* dp) const;
  // Rows [first, first + count) into rows [row0, row0 + count).
  void AddRows(int first, int count, double weight, int row0, DerivativeMatrix* dy,
               DerivativeMatrix* du, DerivativeMatrix* dp) const;
  // target += P (dg/dx)^T weights (moving sets: x' += P grad c lambda); P null: identity.
  // `rows` (sorted; nullptr: all) lists the rows whose weights may be nonzero.
  void AddStateGradientProduct(const ConstVectorRef& weights, const Matrix* projection,
                               VectorRef target, const std::vector<int>* rows = nullptr) const;
  // Column col of target (rows 0..n_x): P (dg_k/dx)^T (P null: identity).
  void AddStateGradient(int k, int col, const Matrix* projection, DerivativeMatrix* target) const;
  // The x columns transposed, premultiplied by P (null: identity) and weighted:
  // target(0..n_x, col0 + k) += weight * P (dg_k/dx)^T (moving sets: F_z = P grad c).
  void AddStateGradients(int col0, const Matrix* projection, double weight,
                         DerivativeMatrix* target) const;
  // x rows of a weighted Hessian (the matrix is then square over the arguments): F_y, F_u and
  // F_p of x' += P grad g w get P sum_k w_k Hess g_k (x rows; x, clock, u and p columns).
  void WeightedHessian(const BlockContext& context, const SmoothFunction& function,
                       const ConstVectorRef& y, const ConstVectorRef& weights,
                       Derivatives derivatives, const std::vector<int>* rows = nullptr);
  void AddStateRows(const Matrix* projection, double weight, DerivativeMatrix* dy,
                    DerivativeMatrix* du, DerivativeMatrix* dp) const;

 private:
  void Layout(const BlockContext& context, Derivatives derivatives);
  // Target of argument column j: 0 = y, 1 = u, 2 = p; *index its column there.
  int Target(int j, int* index) const;

  bool is_sparse_ = false, all_ = false;
  int rows_ = 0, nx_ = 0, nu_ = 0, np_ = 0, clock_ = 0;
  Matrix dense_;
  SparseMatrix columns_;                                           // sparse AD result
  Eigen::SparseMatrix<double, Eigen::RowMajor, int> rows_sparse_;  // the same, by rows
  // How rows_sparse_ was filled from columns_: the pattern of columns_ then (outer and inner
  // indices), and for each entry of rows_sparse_ the position of its value in columns_.
  // While the pattern repeats (most evaluations), only the values are gathered again.
  std::vector<int> copied_outer_, copied_inner_, row_entry_source_;
  Vector x_, direction_, weights_;
  mutable Vector gradient_;
  mutable Vector gradient_row_, projected_row_;  // AddStateGradient's scratch
};

class LoweredBlock {
 public:
  virtual ~LoweredBlock() = default;
  virtual std::unique_ptr<LoweredBlock> Clone() const = 0;

  virtual int num_algebraic() const = 0;
  virtual int num_equations() const = 0;
  virtual int num_pairs() const = 0;
  // Names of the block's algebraic unknowns (size num_algebraic()).
  virtual std::vector<std::string> AlgebraicNames() const = 0;
  // Descriptions of the block's pairs (size num_pairs()).
  virtual std::vector<PairInfo> Pairs() const = 0;

  // Adds the block's contributions to `out` at (y, z). The matrices of `out` are sized for
  // the whole system and zero-initialized by the caller for the block's rows; F rows are
  // accumulated (+=) because effects compose additively.
  virtual void Evaluate(const BlockContext& context, const ConstVectorRef& y,
                        const ConstVectorRef& z, Derivatives derivatives, PointEvaluation* out) = 0;

  // Writes a guess of the block's algebraic unknowns at state y into its slice of z,
  // consistent with the algebraic equations where possible (e.g. Stewart: the mode of the
  // region containing y). `previous` (may be null) holds earlier values of all algebraic
  // unknowns; blocks keep their slice of it where y does not decide (multipliers, y on a
  // switching surface).
  virtual void InitialGuess(const BlockContext& context, const ConstVectorRef& y,
                            const Vector* previous, VectorRef z) = 0;

  // --- velocity level (docs/fesd-formulation.md, "Velocity-level problem") ---------------
  // Per algebraic unknown of the block: true if it is continuous in time along solutions
  // (its velocity-level slot holds its rate), false for jump variables (slot holds a value).
  virtual std::vector<bool> ContinuousAlgebraic() const = 0;
  // Per equation row of the block: true if the row is differentiated along the flow at
  // velocity level (it involves the state and continuous unknowns only), false if it is
  // imposed on values (it involves jump variables only).
  virtual std::vector<bool> DifferentiatedEquations() const = 0;
  // Second-derivative terms of the velocity-level rows along `direction` (a vector in
  // y-space, in practice F): for every pair whose continuous side depends on y, and every
  // differentiated equation row r, adds d/d(y, u, p) of [grad_y X(y) . direction] with the
  // direction held fixed (rows at the block's pair and equation offsets of `out`).
  virtual void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                            const ConstVectorRef& direction, Derivatives derivatives,
                            CurvatureTerms* out) = 0;
  // Event indicators: the free side of every pair of the block (the side not enforced to
  // zero by its status a_zero) at state y, with jump variables taken from the velocity-level
  // values v; derivatives with respect to y and v (and u, p) when requested.
  virtual void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                               const ConstVectorRef& v, const std::vector<bool>& a_zero,
                               Derivatives derivatives, IndicatorEvaluation* out) = 0;
  // The block's event indicators with Derivatives::kStates (the same values, bit for bit) and
  // their slopes along dy, d_y.row(k) . dy up to round-off, into values and slopes at the
  // block's pair offset (LoweredSystem::EvaluateEventIndicatorSlopes). False if the block does
  // not provide them; a block without pairs has nothing to provide.
  virtual bool EventIndicatorSlopes(const BlockContext& /*context*/, const ConstVectorRef& /*y*/,
                                    const ConstVectorRef& /*v*/,
                                    const std::vector<bool>& /*a_zero*/,
                                    const ConstVectorRef& /*dy*/, VectorRef /*values*/,
                                    VectorRef /*slopes*/) {
    return num_pairs() == 0;
  }

  // Enclosures of the continuous free sides over a box of states (LoweredSystem::
  // BoundEventIndicators): for every pair of the block whose free side under a_zero is a
  // function of the state through the block's model functions, [lower, upper] (at the pair's
  // index) containing its value at every y in [y_lower, y_upper] (the clock's entries bound
  // the time), by interval evaluation of those functions. Other pairs (jump free sides, free
  // sides that depend on algebraic unknowns, functions without interval evaluation) are left
  // as the caller set them (-inf, +inf).
  virtual void IndicatorBounds(const BlockContext& /*context*/, const ConstVectorRef& /*y_lower*/,
                               const ConstVectorRef& /*y_upper*/,
                               const std::vector<bool>& /*a_zero*/, VectorRef /*lower*/,
                               VectorRef /*upper*/) {}

  // --- internal states and time-freezing (docs/lowering.md, "Hysteresis relays") ---------
  // Internal states of the block (hysteresis memories), stored in y from layout.y_offset.
  virtual int num_internal_states() const { return 0; }
  virtual std::vector<std::string> InternalStateNames() const { return {}; }
  // Writes the initial values of the internal states into their slots of y.
  virtual void InitialInternalStates(VectorRef /*y*/) const {}
  // True if the block's contribution to F belongs to the physical-time dynamics, which
  // time-freezing multiplies by the clock rate and the speed of time by s (mode fields of
  // switching surfaces, discrete relay fields). False for
  // multipliers (moving sets: lambda adapts, and scaling it would leave it undetermined while
  // time is frozen) and for the time-freezing block itself.
  virtual bool ScaledByClockRate() const { return false; }
  // Time-freezing blocks only: the clock rate P(z) (1 when physical time runs, 0 while it is
  // frozen) and dP/dz (a row of length n_z).
  virtual bool HasClockRate() const { return false; }
  virtual double ClockRate(const ConstVectorRef& /*z*/, Eigen::RowVectorXd* /*d_rate_dz*/) const {
    return 1.0;
  }
  // Per relay of the block: -1 while it is in a mode (physical time runs), otherwise the
  // memory value (0 or 1) it is travelling to while physical time is frozen.
  virtual std::vector<int> MemoryTargets(const std::vector<bool>& /*a_zero*/) const { return {}; }
  // True if some MemoryTargets entry is >= 0, read from the system's statuses `a_zero` at the
  // block's pair offset `offset` (LoweredSystem::TimeFrozen asks this every element: without
  // the block-local copy and the targets MemoryTargets allocates).
  virtual bool AnyMemoryTarget(const std::vector<bool>& /*a_zero*/, std::size_t /*offset*/) const {
    return false;
  }
  // Events implied by the statuses decided at the initial time (a relay whose memory is
  // inconsistent with its input and is re-initialized while time is frozen).
  virtual std::vector<Event> InitialEvents(double /*t*/, const ConstVectorRef& /*y*/,
                                           const std::vector<bool>& /*a_zero*/) const {
    return {};
  }

  // Discrete-memory relays: switching functions (positive until a switch) into `out`.
  virtual int num_memory_switches() const { return 0; }
  virtual void MemorySwitchingFunctions(const BlockContext& /*context*/,
                                        const ConstVectorRef& /*y*/, VectorRef /*out*/) {}
  // Their enclosures over a box of states (as IndicatorBounds; left as set where unavailable).
  virtual void MemorySwitchingBounds(const BlockContext& /*context*/,
                                     const ConstVectorRef& /*y_lower*/,
                                     const ConstVectorRef& /*y_upper*/, VectorRef /*lower*/,
                                     VectorRef /*upper*/) {}

  // False if the block-local pair roles of a velocity-level assignment are contradictory by
  // construction (e.g. every theta of a Stewart subsystem kept at zero although they sum to
  // one), so that DecideStatuses need not try it.
  virtual bool AdmitsRoles(const std::vector<PairRole>& /*roles*/) const { return true; }

  // --- near-active constraint filter (LoweredSystem::SetWorkingPairs) ------------------------
  // Pairs the block declares (its working pairs are a subset for filterable blocks).
  virtual int num_declared_pairs() const { return num_pairs(); }
  // True if constraints of the block may be left out of the system (moving sets).
  virtual bool Filterable() const { return false; }
  // Block-local declared indices of the pairs in the system, increasing.
  virtual std::vector<int> WorkingPairs() const {
    std::vector<int> all(static_cast<std::size_t>(num_pairs()));
    for (int k = 0; k < num_pairs(); ++k) all[static_cast<std::size_t>(k)] = k;
    return all;
  }
  virtual void SetWorkingPairs(const std::vector<int>& /*working*/) {}
  // Names of the algebraic unknowns of every declared pair (AlgebraicNames() when unfiltered).
  virtual std::vector<std::string> DeclaredAlgebraicNames() const { return AlgebraicNames(); }
  // Filterable blocks: value and rate bound of every declared constraint at y (see
  // LoweredSystem::FilterableConstraints).
  virtual void DeclaredConstraints(const BlockContext& /*context*/, const ConstVectorRef& /*y*/,
                                   const Vector& /*velocity*/, VectorRef /*values*/,
                                   VectorRef /*rate_bounds*/) {}
  // Filterable blocks: the smallest left-out constraint at y (infinity if none).
  virtual double MinExcluded(const BlockContext& /*context*/, const ConstVectorRef& /*y*/) {
    return std::numeric_limits<double>::infinity();
  }
  // Filterable blocks: include[offset + k] = true for left-out constraints k below threshold.
  virtual void ExcludedBelow(const BlockContext& /*context*/, const ConstVectorRef& /*y*/,
                             double /*threshold*/, int /*offset*/, std::vector<bool>* /*include*/) {
  }

  // True if the velocity-level problem in the block's jump variables is monotone: an LCP
  // whose matrix is symmetric positive semidefinite (moving sets: J P J^T), so that all its
  // solutions give the same velocity. DecideStatuses then solves for such candidates instead
  // of enumerating their assignments.
  virtual bool MonotoneVelocityLevel() const { return false; }

  // True if the block's contributions to F, G, A and B are affine in z with coefficients that
  // depend on y only, and do not depend on the velocity-level roles (BlockContext); for the
  // time-freezing block, its clock rate P(z) too. If every block says so (and the blocks that
  // P multiplies have no algebraic unknowns), the velocity-level rows are affine in v and
  // a velocity-level problem of fixed statuses is solved by one linear solve
  // (SolveVelocityLevel). False is always safe.
  virtual bool AffineInAlgebraic() const { return false; }
  // True if, at velocity level with roles that decide every pair (BlockContext::velocity_roles
  // without a complementary pair), the block's contributions to F, G, A and B are affine in z
  // with coefficients that depend on y and those roles only: the rows of a velocity-level
  // problem of fixed statuses are then affine in v, although they may change with the roles
  // (index-1 complementarity evaluates F at the roles' consistent multipliers). Implied by
  // AffineInAlgebraic. False is always safe.
  virtual bool AffineInAlgebraicForDecidedRoles() const { return AffineInAlgebraic(); }

  // Events implied by a change of the block's pair statuses between two times:
  // a_zero[k] is true when pair k has a_k = 0 (its first side vanishes), false when b_k = 0.
  virtual std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                          const std::vector<bool>& after) const = 0;

  BlockLayout layout;
};

// Factories, one per lowering (lower_*.cpp).
std::unique_ptr<LoweredBlock> LowerMovingSet(const Scene& scene, const MovingSet& set);
std::unique_ptr<LoweredBlock> LowerStewart(const Scene& scene, const SwitchingSurfaces& effect);
std::unique_ptr<LoweredBlock> LowerHeaviside(const Scene& scene, const SwitchingSurfaces& effect);
std::unique_ptr<LoweredBlock> LowerComplementarity(const Scene& scene,
                                                   const Complementarity& effect);
// All hysteresis relays of a scene in one time-freezing block (their clock rates multiply).
std::unique_ptr<LoweredBlock> LowerHysteresis(const Scene& scene,
                                              const std::vector<HysteresisRelay>& relays);
// All hysteresis relays of a scene as discrete memories (event-driven integrators).
std::unique_ptr<LoweredBlock> LowerDiscreteRelays(const Scene& scene,
                                                  const std::vector<HysteresisRelay>& relays);

}  // namespace moreau::internal
