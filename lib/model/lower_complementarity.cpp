// Complementarity systems (docs/complementarity.md, docs/lowering.md "Complementarity systems"):
//
//   x' += B(x, u, t, p) lambda,   0 <= lambda ⟂ w = g(x, u, t, p) + D(x, u, t, p) lambda >= 0.
//
// z = lambda (m), no equations G, pairs (a, b) = (w_k, lambda_k).
//  - Index 2 (no D): a = g_k(x, t) is the continuous side and lambda a jump variable, exactly
//    as a moving set's multiplier; the velocity level is 0 <= lambda ⟂ g_x (f + B lambda) + g_t.
//  - Index 1 (D a P-matrix): lambda(x, t) solves an LCP with a P-matrix, so it is a Lipschitz
//    function of the state and both sides are continuous (ContinuousSide::kBoth). Their
//    velocity-level slots hold rates: 0 <= lambda' ⟂ w' = g_x F + g_t + (D_x F + D_t) lambda
//    + D lambda' >= 0, where F = f + B lambda needs the *value* of lambda. v holds lambda', so
//    at velocity level (BlockContext::velocity_roles set) this block evaluates F at the
//    consistent value lambda_bar(y) of the roles: lambda_S = -D_SS^{-1} g_S on the pairs S
//    kept at w = 0, lambda = 0 on the others.
// Every derivative is exact (automatic differentiation of B, g, D, second order in the
// velocity-level rows), compared with central differences in tests/model/.

#include <Eigen/Dense>
#include <cmath>
#include <limits>

#include "lowered_block.hpp"
#include "moreau/complementarity/lcp.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

// Row-major m x m (or n x m) matrix from a function's outputs.
// A view (no copy): callers that need a Matrix construct one from it.
Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> RowMajor(
    const Vector& values, int rows, int cols) {
  return Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      values.data(), rows, cols);
}

// dst = A^{-1} rhs for an invertible square A from its FullPivLU: the steps of Eigen 3.4's
// FullPivLU::_solve_impl (c = P rhs, unit-lower then upper triangular solves in place, rows
// placed by Q), in the caller's kept scratch c (of rhs's plain type, as Eigen's, so that the
// same triangular solver runs), where Eigen allocates c and a temporary for P rhs at each
// solve. The same arithmetic in the same order: the same bits.
template <class Rhs, class Dst>
void SolveInvertible(const Eigen::FullPivLU<Matrix>& lu, const Rhs& rhs,
                     typename Rhs::PlainObject* c, Dst* dst) {
  const Eigen::Index n = lu.rows();
  MOREAU_ASSERT(lu.cols() == n && lu.rank() == n, "SolveInvertible: a singular factorization");
  c->noalias() = lu.permutationP() * rhs;
  lu.matrixLU().template triangularView<Eigen::UnitLower>().solveInPlace(*c);
  lu.matrixLU().template triangularView<Eigen::Upper>().solveInPlace(*c);
  dst->resize(n, rhs.cols());
  for (Eigen::Index i = 0; i < n; ++i) dst->row(lu.permutationQ().indices().coeff(i)) = c->row(i);
}

class ComplementarityBlock final : public LoweredBlock {
 public:
  ComplementarityBlock(const Scene& scene, const Complementarity& effect)
      : effect_(effect),
        nx_(scene.num_states()),
        m_(static_cast<int>(effect.pair_names.size())),
        index_one_(!effect.feedthrough.empty()) {
    for (const SmoothFunction* f : {&effect.output, &effect.input_matrix, &effect.feedthrough}) {
      RequireArgument(!f->has_sparse_state_jacobian(), "complementarity system '", effect.name,
                      "': its functions need second derivatives; write them as generic lambdas "
                      "(MakeSmoothFunction), not with a hand-written Jacobian");
    }
  }
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<ComplementarityBlock>(*this);
  }
  int num_algebraic() const override { return m_; }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return m_; }
  std::vector<std::string> AlgebraicNames() const override {
    std::vector<std::string> names;
    for (const std::string& k : effect_.pair_names) names.push_back(effect_.name + ".lambda_" + k);
    return names;
  }
  std::vector<PairInfo> Pairs() const override {
    std::vector<PairInfo> pairs;
    for (int k = 0; k < m_; ++k) {
      const std::string& name = effect_.pair_names[static_cast<std::size_t>(k)];
      pairs.push_back({effect_.name, effect_.name + "." + name,
                       index_one_ ? ContinuousSide::kBoth : ContinuousSide::kA, 0,
                       index_one_ ? layout.z_offset + k : -1});
    }
    return pairs;
  }
  // Index 1: lambda is a function of the state, part of the physical dynamics (time-freezing
  // and the speed of time scale it). Index 2: a multiplier that adapts, as a moving set's.
  bool ScaledByClockRate() const override { return index_one_; }
  // F += B(y) lambda and w = g(y) + D(y) lambda are affine in z = lambda. At velocity level,
  // index 2 reads z itself; index 1 evaluates F at the consistent multipliers lambda_bar(y) of
  // the roles (fixed for decided roles) and its rows are then affine in the rates v through
  // D(y) v. The roles enter index 1's coefficients, so AffineInAlgebraic stays false.
  bool AffineInAlgebraicForDecidedRoles() const override { return true; }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef& z,
                Derivatives derivatives, PointEvaluation* out) override {
    const int z0 = layout.z_offset;
    const int k0 = layout.pair_offset;
    const bool with_states = derivatives != Derivatives::kNone;
    const bool all = derivatives == Derivatives::kAll;
    EvaluateFunctions(context, y, derivatives);
    // Multipliers in F: the stage values, or at velocity level (index 1) the consistent
    // values, since v holds their rates there.
    const bool consistent = index_one_ && context.velocity_roles != nullptr;
    if (consistent) {
      ConsistentValues(Roles(*context.velocity_roles), derivatives);
      lambda_ = lambda_bar_;
    } else {
      lambda_ = z.segment(z0, m_);
    }
    const auto b = RowMajor(b_values_, nx_, m_);
    // Each product is evaluated into storage of its own (kept, never resized between uses) and
    // then added: the order Eigen follows for `+=` of a product through a temporary.
    // x' += B lambda.
    state_product_.noalias() = b * lambda_;
    out->F.head(nx_) += state_product_;
    // pair k: a = w_k = g_k + (D lambda)_k, b = lambda_k (the stage unknown, or its rate).
    out->A.segment(k0, m_) = g_;
    if (index_one_) {
      pair_product_.noalias() = RowMajor(d_values_, m_, m_) * lambda_;
      out->A.segment(k0, m_) += pair_product_;
    }
    out->B.segment(k0, m_) = z.segment(z0, m_);
    if (!with_states) return;

    // d(B lambda) with lambda held, plus B dlambda_bar through the consistent values.
    Matrix& f_jacobian = f_jacobian_;  // n_x x columns
    ContractRows(jac_b_, lambda_, &f_jacobian);
    if (consistent) {
      state_rows_product_.noalias() = b * d_lambda_bar_;
      f_jacobian += state_rows_product_;
    }
    if (!consistent) {
      b_column_major_ = b;  // AddBlock reads a column-major matrix
      out->F_z.AddBlock(0, z0, b_column_major_);
    }
    Scatter(context, f_jacobian, 0, all, &out->F_y, &out->F_u, &out->F_p);
    // dw with lambda held (the partial derivative; the velocity level adds the rest).
    Matrix& a_jacobian = a_jacobian_;
    a_jacobian = jac_g_;
    if (index_one_) {
      ContractRows(jac_d_, lambda_, &contracted_);
      a_jacobian += contracted_;
      d_column_major_ = RowMajor(d_values_, m_, m_);
      out->A_z.AddBlock(k0, z0, d_column_major_);
    }
    Scatter(context, a_jacobian, k0, all, &out->A_y, &out->A_u, &out->A_p);
    for (int k = 0; k < m_; ++k) out->B_z.Add(k0 + k, z0 + k, 1.0);
  }

  // Index 2: lambda from `previous` (not determined by the state), else 0. Index 1: the
  // solution of the LCP 0 <= lambda ⟂ g + D lambda >= 0 at y (unique: D is a P-matrix),
  // starting from the previous active set when given.
  void InitialGuess(const BlockContext& context, const ConstVectorRef& y, const Vector* previous,
                    VectorRef z) override {
    const int z0 = layout.z_offset;
    if (!index_one_) {
      if (previous != nullptr) {
        z.segment(z0, m_) = previous->segment(z0, m_);
      } else {
        z.segment(z0, m_).setZero();
      }
      return;
    }
    EvaluateFunctions(context, y, Derivatives::kNone, /*input_matrix=*/false);
    Matrix& d = d_matrix_;  // kept (a guess per element and output point)
    d = RowMajor(d_values_, m_, m_);
    // The active set to try first: the previous values' when given, else the set of this
    // block's last guess (consecutive guesses, e.g. dense output along an element, mostly keep
    // their set). A guess only saves the LCP solve: a set is accepted only if its solution is
    // complementary, and the LCP solution is unique (D is a P-matrix).
    std::vector<bool>& active = guess_active_;
    if (previous != nullptr) {
      active.assign(static_cast<std::size_t>(m_), false);
      for (int k = 0; k < m_; ++k) active[static_cast<std::size_t>(k)] = (*previous)[z0 + k] > 0.0;
    } else if (active.size() != static_cast<std::size_t>(m_)) {
      active.assign(static_cast<std::size_t>(m_), false);
    }
    Vector& lambda = guess_lambda_;
    int failing = -1;
    if (!SolveOnActiveSet(d, active, &lambda, &failing) &&
        !PivotToSolution(d, failing, &active, &lambda)) {
      const LcpResult lcp = SolveLcp(d, g_, LcpOptions());
      lambda = lcp.z;
      // Polish on the active set the LCP identified (exact to round-off when it is right).
      for (int k = 0; k < m_; ++k) active[static_cast<std::size_t>(k)] = lcp.z[k] > lcp.w[k];
      Vector polished;
      if (lcp.converged() && SolveOnActiveSet(d, active, &polished)) lambda = polished;
    }
    z.segment(z0, m_) = lambda;
  }

  std::vector<bool> ContinuousAlgebraic() const override {
    return std::vector<bool>(static_cast<std::size_t>(m_), index_one_);
  }
  std::vector<bool> DifferentiatedEquations() const override { return {}; }

  // Rows of d/d(y, u, p) [grad_y w_k . d] (d = F fixed) plus, for index 1, the terms the
  // framework's rate X_y F + X_z v does not see: X_y depends on y also through lambda_bar(y),
  // and X_z = D(y) multiplies the rates v_lambda.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    const int k0 = layout.pair_offset;
    const bool all = derivatives == Derivatives::kAll;
    directions_.HessianDirections(context, effect_.output, y, direction, derivatives);
    directions_.AddRows(0, m_, 1.0, k0, &out->pair_y, &out->pair_u, &out->pair_p);
    if (!index_one_) return;
    MOREAU_ASSERT(context.velocity_roles != nullptr && context.velocity != nullptr,
                  "complementarity curvature terms need the velocity-level roles and values");
    EvaluateFunctions(context, y, derivatives, /*input_matrix=*/false);
    ConsistentValues(Roles(*context.velocity_roles), derivatives);
    // (a) second derivatives of (D(y) l)_k along d, l = lambda_bar held.
    Vector& weights = weights_;
    weights.setZero(m_ * m_);
    for (int k = 0; k < m_; ++k) {
      weights.setZero();
      weights.segment(k * m_, m_) = lambda_bar_;
      AddWeightedHessianDirection(context, effect_.feedthrough, weights, y, direction, derivatives,
                                  k0 + k, &out->pair_y, &out->pair_u, &out->pair_p);
    }
    // (b) d/dl [grad_y (D l)_k . d] dlambda_bar = M dlambda_bar, M_kj = grad D_kj . d.
    const int t_col = TimeColumn(context, all);
    Vector& d_cols = argument_direction_;
    d_cols.setZero(jac_d_.cols());
    d_cols.head(nx_) = direction.head(nx_);
    d_cols[t_col] = direction[context.clock_index];
    feedthrough_direction_.noalias() = jac_d_ * d_cols;
    Matrix& m_matrix = d_column_major_;
    m_matrix = RowMajor(feedthrough_direction_, m_, m_);
    pair_rows_product_.noalias() = m_matrix * d_lambda_bar_;
    Scatter(context, pair_rows_product_, k0, all, &out->pair_y, &out->pair_u, &out->pair_p);
    // (c) d/d(y, u, p) of D(y) v_lambda.
    rates_ = context.velocity->segment(layout.z_offset, m_);
    ContractRows(jac_d_, rates_, &contracted_);
    Scatter(context, contracted_, k0, all, &out->pair_y, &out->pair_u, &out->pair_p);
  }

  // Free side of each pair. Index 2: the multiplier of an active pair (velocity level), g of
  // an inactive one. Index 1: the consistent values at y for the statuses: lambda_k of a pair
  // kept at w = 0, w_k of a pair kept at lambda = 0 (both functions of the state).
  // Index 2, inactive pair (lambda = 0): w = g(x, t) over the box. Index 1: the free sides
  // involve the consistent multipliers (an LCP in the state), which have no enclosure here.
  void IndicatorBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                       const ConstVectorRef& y_upper, const std::vector<bool>& a_zero,
                       VectorRef lower, VectorRef upper) override {
    if (index_one_) return;
    if (!FunctionBounds(context, effect_.output, y_lower, y_upper, &bound_lower_, &bound_upper_)) {
      return;
    }
    const int k0 = layout.pair_offset;
    for (int k = 0; k < m_; ++k) {
      if (a_zero[static_cast<std::size_t>(k0 + k)]) continue;
      lower[k0 + k] = bound_lower_[k];
      upper[k0 + k] = bound_upper_[k];
    }
  }

  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    const bool with_states = derivatives != Derivatives::kNone;
    const bool all = derivatives == Derivatives::kAll;
    EvaluateFunctions(context, y, derivatives, /*input_matrix=*/false);
    if (!index_one_) {
      for (int k = 0; k < m_; ++k) {
        if (a_zero[static_cast<std::size_t>(k0 + k)]) {
          out->values[k0 + k] = v[z0 + k];
          if (with_states) out->d_v.Add(k0 + k, z0 + k, 1.0);
          continue;
        }
        out->values[k0 + k] = g_[k];
        if (with_states) {
          Scatter(context, jac_g_.middleRows(k, 1), k0 + k, all, &out->d_y, &out->d_u, &out->d_p);
        }
      }
      return;
    }
    const Vector& w = IndexOneFreeSides(a_zero, derivatives);
    const auto d = RowMajor(d_values_, m_, m_);
    Matrix& w_jacobian = w_jacobian_;
    if (with_states) {
      // jac_g + contraction + product, summed in that order (as Eigen's expression did).
      ContractRows(jac_d_, lambda_bar_, &contracted_);
      pair_rows_product_.noalias() = d * d_lambda_bar_;
      w_jacobian = jac_g_ + contracted_ + pair_rows_product_;
    }
    for (int k = 0; k < m_; ++k) {
      const bool conducting = a_zero[static_cast<std::size_t>(k0 + k)];
      out->values[k0 + k] = conducting ? lambda_bar_[k] : w[k];
      if (!with_states) continue;
      const Matrix& source = conducting ? d_lambda_bar_ : w_jacobian;
      Scatter(context, source.middleRows(k, 1), k0 + k, all, &out->d_y, &out->d_u, &out->d_p);
    }
  }

  // Values as EventIndicators with kStates (the same evaluations and operations: the same
  // bits) and slopes along dy from the same Jacobians applied to the direction d = (dy_x, dy_t):
  // dg = J_g d, dD = J_D d, and for index 1 the consistent multipliers' rates from their
  // equations on the active set s, D_ss dlambda_s = -(dg + dD lambda)_s (the same LU), so that
  // dw = dg + dD lambda + D dlambda. The matrix d_lambda_bar and the rows scattered into d_y
  // are not formed (on the circuits, most of the cost of an evaluation with derivatives).
  bool EventIndicatorSlopes(const BlockContext& context, const ConstVectorRef& y,
                            const ConstVectorRef& v, const std::vector<bool>& a_zero,
                            const ConstVectorRef& dy, VectorRef values, VectorRef slopes) override {
    if (context.sparse) return false;  // (the dense Jacobians below)
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    EvaluateFunctions(context, y, Derivatives::kStates, /*input_matrix=*/false);
    // d in the Jacobians' columns: x, then t (Wrt::XT).
    Vector& d = argument_direction_;
    d.setZero(jac_g_.cols());
    d.head(nx_) = dy.head(nx_);
    d[TimeColumn(context, false)] = dy[context.clock_index];
    Vector& dg = slope_g_;
    dg.noalias() = jac_g_ * d;
    if (!index_one_) {
      for (int k = 0; k < m_; ++k) {
        const bool active = a_zero[static_cast<std::size_t>(k0 + k)];
        values[k0 + k] = active ? v[z0 + k] : g_[k];
        slopes[k0 + k] = active ? 0.0 : dg[k];  // a jump side: held with v
      }
      return true;
    }
    const Vector& w = IndexOneFreeSides(a_zero, Derivatives::kNone);
    const auto dmat = RowMajor(d_values_, m_, m_);
    // dD lambda: (J_D d) reshaped row-major, times lambda.
    Vector& dd = slope_d_;
    dd.noalias() = jac_d_ * d;
    Vector& partial = slope_partial_;  // dg + dD lambda
    partial = dg;
    for (int k = 0; k < m_; ++k) {
      for (int j = 0; j < m_; ++j) partial[k] += dd[k * m_ + j] * lambda_bar_[j];
    }
    Vector& dlambda = slope_lambda_;
    dlambda.setZero(m_);
    const std::vector<int>& s = active_indices_;  // (ConsistentValues' active set)
    const int n = static_cast<int>(s.size());
    if (n > 0) {
      if (!lu_.isInvertible()) return false;  // (the values are NaN then as well)
      Vector& rhs = rhs_;
      rhs.resize(n);
      for (int i = 0; i < n; ++i) rhs[i] = -partial[s[static_cast<std::size_t>(i)]];
      SolveInvertible(lu_, rhs, &solve_scratch_, &solved_);
      for (int i = 0; i < n; ++i) dlambda[s[static_cast<std::size_t>(i)]] = solved_[i];
    }
    for (int k = 0; k < m_; ++k) {
      const bool conducting = a_zero[static_cast<std::size_t>(k0 + k)];
      values[k0 + k] = conducting ? lambda_bar_[k] : w[k];
      if (conducting) {
        slopes[k0 + k] = dlambda[k];
      } else {
        double dw = partial[k];
        for (int j = 0; j < m_; ++j) dw += dmat(k, j) * dlambda[j];
        slopes[k0 + k] = dw;
      }
    }
    return true;
  }

  // Index 1, after EvaluateFunctions: the consistent multipliers lambda_bar_ for the statuses
  // a_zero (of the whole system; conducting pairs keep w = 0) with derivatives as asked, and w =
  // g + D lambda_bar, returned (w_). The free side of a conducting pair is lambda_bar_k, of a
  // blocking one w_k (EventIndicators, EventIndicatorSlopes).
  const Vector& IndexOneFreeSides(const std::vector<bool>& a_zero, Derivatives derivatives) {
    const int k0 = layout.pair_offset;
    std::vector<PairRole>& roles = roles_;
    roles.resize(static_cast<std::size_t>(m_));
    for (int k = 0; k < m_; ++k) {
      roles[static_cast<std::size_t>(k)] =
          a_zero[static_cast<std::size_t>(k0 + k)] ? PairRole::kAZero : PairRole::kBZero;
    }
    ConsistentValues(roles, derivatives);
    w_.noalias() = RowMajor(d_values_, m_, m_) * lambda_bar_;
    w_ += g_;
    return w_;
  }

  // a = w = 0 kept: the pair is active (a diode conducts); b = lambda = 0: inactive (blocks).
  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const override {
    std::vector<Event> events;
    for (int k = 0; k < m_; ++k) {
      const auto i = static_cast<std::size_t>(k);
      if (before[i] == after[i]) continue;
      events.push_back(
          {t, after[i] ? EventKind::kEnter : EventKind::kLeave,
           effect_.name + "." + effect_.pair_names[i],
           after[i] ? "w = 0, lambda >= 0 (pair active)" : "lambda = 0, w >= 0 (pair inactive)"});
    }
    return events;
  }

 private:
  static SemismoothNewtonOptions LcpOptions() {
    SemismoothNewtonOptions options;
    options.tolerance = 1e-14;
    options.max_iterations = 50;
    options.linear_solver = LinearSolverKind::kDenseLu;
    return options;
  }

  int TimeColumn(const BlockContext& context, bool all) const {
    return all ? nx_ + static_cast<int>(context.inputs->size()) : nx_;
  }

  // The block's slice of the system's pair roles.
  const std::vector<PairRole>& Roles(const std::vector<PairRole>& roles) {
    const auto first = roles.begin() + layout.pair_offset;
    roles_.assign(first, first + m_);
    return roles_;
  }

  // g, B, D at (x, u, t, p), with Jacobians (columns x, [u], t, [p]) unless kNone. Without
  // input_matrix, B is not evaluated (b_values_, jac_b_ keep older values): the pair sides and
  // consistent multipliers need g and D only (EventIndicators, InitialGuess), and every reader
  // of B evaluates it first (Evaluate, AddCurvature).
  void EvaluateFunctions(const BlockContext& context, const ConstVectorRef& y,
                         Derivatives derivatives, bool input_matrix = true) {
    x_ = y.head(nx_);
    const double t = y[context.clock_index];
    const Vector& u = *context.inputs;
    const Vector& p = *context.parameters;
    if (derivatives == Derivatives::kNone) {
      effect_.output.Evaluate(x_, u, t, p, &g_);
      if (input_matrix) effect_.input_matrix.Evaluate(x_, u, t, p, &b_values_);
      if (index_one_) effect_.feedthrough.Evaluate(x_, u, t, p, &d_values_);
      return;
    }
    const Wrt wrt = derivatives == Derivatives::kAll ? Wrt::All() : Wrt::XT();
    effect_.output.Jacobian(x_, u, t, p, wrt, &g_, &jac_g_);
    if (input_matrix) effect_.input_matrix.Jacobian(x_, u, t, p, wrt, &b_values_, &jac_b_);
    if (index_one_) effect_.feedthrough.Jacobian(x_, u, t, p, wrt, &d_values_, &jac_d_);
  }

  // Rows r of the contraction sum_j l_j J.row(r * m + j): the Jacobian of M(.) l for a
  // row-major matrix function M with m columns and l held fixed, into *out (its storage kept).
  void ContractRows(const Matrix& jacobian, const Vector& l, Matrix* out) const {
    const auto rows = static_cast<int>(jacobian.rows()) / m_;
    out->setZero(rows, jacobian.cols());
    for (int r = 0; r < rows; ++r) {
      for (int j = 0; j < m_; ++j) {
        if (l[j] != 0.0) out->row(r) += l[j] * jacobian.row(r * m_ + j);
      }
    }
  }

  // Adds J (columns x, [u], t, [p]) into rows [row, row + J.rows()) of (dy, du, dp): x
  // columns and the clock column of dy. (Each row of the block's pairs is written once.)
  void Scatter(const BlockContext& context, const ConstMatrixRef& j, int row, bool all,
               DerivativeMatrix* dy, DerivativeMatrix* du, DerivativeMatrix* dp) const {
    const int nu = static_cast<int>(context.inputs->size());
    const int np = static_cast<int>(context.parameters->size());
    const int t_col = TimeColumn(context, all);
    dy->AddBlock(row, 0, j.leftCols(nx_));
    dy->AddBlock(row, context.clock_index, j.col(t_col));
    if (!all) return;
    du->AddBlock(row, 0, j.middleCols(nx_, nu));
    dp->AddBlock(row, 0, j.rightCols(np));
  }

  // Adds d/d(y, u, p) [grad_y (sum_o weights_o f_o) . direction] into row `row`.
  void AddWeightedHessianDirection(const BlockContext& context, const SmoothFunction& function,
                                   const Vector& weights, const ConstVectorRef& y,
                                   const ConstVectorRef& direction, Derivatives derivatives,
                                   int row, DerivativeMatrix* dy, DerivativeMatrix* du,
                                   DerivativeMatrix* dp) {
    const bool all = derivatives == Derivatives::kAll;
    function.WeightedHessian(y.head(nx_), *context.inputs, y[context.clock_index],
                             *context.parameters, all ? Wrt::All() : Wrt::XT(), weights, &hessian_);
    const int t_col = TimeColumn(context, all);
    Vector& d = argument_direction_;
    d.setZero(hessian_.cols());
    d.head(nx_) = direction.head(nx_);
    d[t_col] = direction[context.clock_index];
    hessian_direction_.noalias() = hessian_ * d;
    row_ = hessian_direction_.transpose();
    Scatter(context, row_, row, all, dy, du, dp);
  }

  // lambda on the active set S: D_SS lambda_S = -g_S, lambda = 0 elsewhere; true if the result
  // is complementary (lambda_S >= 0, w >= 0 off S) up to round-off.
  // *failing (if given): the first pair whose free side is negative where the set's solution
  // is not complementary, -1 otherwise (also for a singular D_SS).
  bool SolveOnActiveSet(const Matrix& d, const std::vector<bool>& active, Vector* lambda,
                        int* failing = nullptr) const {
    if (failing != nullptr) *failing = -1;
    std::vector<int>& s = active_indices_;
    s.clear();
    for (int k = 0; k < m_; ++k) {
      if (active[static_cast<std::size_t>(k)]) s.push_back(k);
    }
    lambda->setZero(m_);
    const int n = static_cast<int>(s.size());
    if (n > 0) {
      Matrix& d_ss = d_ss_;
      Vector& rhs = rhs_;
      d_ss.resize(n, n);
      rhs.resize(n);
      for (int i = 0; i < n; ++i) {
        rhs[i] = -g_[s[static_cast<std::size_t>(i)]];
        for (int j = 0; j < n; ++j)
          d_ss(i, j) = d(s[static_cast<std::size_t>(i)], s[static_cast<std::size_t>(j)]);
      }
      Eigen::FullPivLU<Matrix>& lu = lu_;
      lu.compute(d_ss);
      if (!lu.isInvertible()) return false;
      SolveInvertible(lu, rhs, &solve_scratch_, &solved_);
      for (int i = 0; i < n; ++i) (*lambda)[s[static_cast<std::size_t>(i)]] = solved_[i];
    }
    Vector& w = w_;
    w.noalias() = d * *lambda;
    w += g_;
    const double scale = 1.0 + g_.lpNorm<Eigen::Infinity>();
    for (int k = 0; k < m_; ++k) {
      const double free = active[static_cast<std::size_t>(k)] ? (*lambda)[k] : w[k];
      if (!(free >= -kRoundOff * scale)) {
        if (failing != nullptr) *failing = k;
        return false;
      }
    }
    return true;
  }

  // From a set whose solution is not complementary, its first failing pair `failing`
  // (SolveOnActiveSet): Murty's least-index principal pivoting (K. G. Murty, "Note on a
  // Bard-type scheme for solving the complementarity problem", 1974): that pair changes sides
  // and the set is solved again. For a P-matrix D this reaches the LCP's unique solution in
  // finitely many pivots; a guess off by a pair or two (an element's stages across a diode's
  // switch) needs one or two, each an m x m solve, where the LCP solver iterates on the whole
  // problem. True with *active the solution's set and *lambda its multipliers (every set it
  // returns passed SolveOnActiveSet's test); false after 2 m pivots or at a singular D_SS (the
  // caller then solves the LCP).
  bool PivotToSolution(const Matrix& d, int failing, std::vector<bool>* active,
                       Vector* lambda) const {
    for (int pivot = 0; pivot < 2 * m_ && failing >= 0; ++pivot) {
      (*active)[static_cast<std::size_t>(failing)] = !(*active)[static_cast<std::size_t>(failing)];
      if (SolveOnActiveSet(d, *active, lambda, &failing)) return true;
    }
    return false;
  }

  // Index 1: lambda_bar for the block's roles (S = pairs kept at w = 0: lambda_S =
  // -D_SS^{-1} g_S; lambda = 0 on the others) and, unless kNone, d lambda_bar / d(x, [u], t,
  // [p]) = -D_SS^{-1} [J_g + J_(D l)]_S with l = lambda_bar held (implicit differentiation of
  // g_S + D_SS lambda_S = 0). A singular D_SS gives NaN (the solver then reports failure).
  // Expects EvaluateFunctions at the same point and derivative level.
  void ConsistentValues(const std::vector<PairRole>& roles, Derivatives derivatives) {
    std::vector<int>& s = active_indices_;
    s.clear();
    for (int k = 0; k < m_; ++k) {
      if (roles[static_cast<std::size_t>(k)] == PairRole::kAZero) s.push_back(k);
    }
    const int n = static_cast<int>(s.size());
    const auto d = RowMajor(d_values_, m_, m_);
    lambda_bar_.setZero(m_);
    const bool with_states = derivatives != Derivatives::kNone;
    if (with_states) d_lambda_bar_.setZero(m_, jac_g_.cols());
    if (n == 0) return;
    Matrix& d_ss = d_ss_;
    Vector& rhs = rhs_;
    d_ss.resize(n, n);
    rhs.resize(n);
    for (int i = 0; i < n; ++i) {
      rhs[i] = -g_[s[static_cast<std::size_t>(i)]];
      for (int j = 0; j < n; ++j)
        d_ss(i, j) = d(s[static_cast<std::size_t>(i)], s[static_cast<std::size_t>(j)]);
    }
    Eigen::FullPivLU<Matrix>& lu = lu_;
    lu.compute(d_ss);
    if (!lu.isInvertible()) {
      lambda_bar_.setConstant(std::numeric_limits<double>::quiet_NaN());
      if (with_states) d_lambda_bar_.setConstant(std::numeric_limits<double>::quiet_NaN());
      return;
    }
    SolveInvertible(lu, rhs, &solve_scratch_, &solved_);
    for (int i = 0; i < n; ++i) lambda_bar_[s[static_cast<std::size_t>(i)]] = solved_[i];
    if (!with_states) return;
    ContractRows(jac_d_, lambda_bar_, &contracted_);
    Matrix& partial = partial_;
    partial = jac_g_ + contracted_;
    Matrix& partial_s = partial_s_;
    partial_s.resize(n, partial.cols());
    for (int i = 0; i < n; ++i) partial_s.row(i) = partial.row(s[static_cast<std::size_t>(i)]);
    Matrix& d_solved = d_solved_;
    SolveInvertible(lu, partial_s, &solve_scratch_columns_, &d_solved);
    for (int i = 0; i < n; ++i) {
      d_lambda_bar_.row(s[static_cast<std::size_t>(i)]) = -d_solved.row(i);
    }
  }

  // Round-off allowance (relative to |g|) when checking a guessed active set.
  static constexpr double kRoundOff = 1e-13;

  Complementarity effect_;
  int nx_;
  int m_;
  bool index_one_;
  Vector x_, g_, b_values_, d_values_, lambda_, lambda_bar_;
  Vector bound_lower_, bound_upper_;  // IndicatorBounds' enclosures of g
  std::vector<bool> guess_active_;    // InitialGuess: the active set of the last guess
  Vector guess_lambda_;               // InitialGuess: its multipliers (storage kept)
  // Scratch kept across evaluations (every element evaluates the block many times): the
  // block's slice of the roles, and the indices of an active set.
  std::vector<PairRole> roles_;
  mutable std::vector<int> active_indices_;
  // The active-set solves' matrices and LU (FullPivLU::compute reuses its storage).
  Matrix d_matrix_;
  mutable Matrix d_ss_;
  mutable Vector rhs_, solved_, w_, solve_scratch_;
  mutable Matrix solve_scratch_columns_;
  mutable Eigen::FullPivLU<Matrix> lu_;
  Matrix jac_g_, jac_b_, jac_d_, d_lambda_bar_, hessian_;
  // EventIndicatorSlopes' rates along the direction (kept: one evaluation per search node).
  Vector slope_g_, slope_d_, slope_partial_, slope_lambda_;
  ArgumentMatrix directions_;
  // Kept scratch of the derivative rows (an element evaluates the block at every Newton
  // iteration; temporaries were most of its cost on small circuits): contractions, products,
  // column-major copies of row-major values, and the Jacobians assembled from them.
  Matrix f_jacobian_, a_jacobian_, w_jacobian_, contracted_, state_rows_product_,
      pair_rows_product_, row_;
  Matrix b_column_major_, d_column_major_;
  Matrix partial_, partial_s_, d_solved_;
  Vector state_product_, pair_product_, feedthrough_direction_, hessian_direction_, weights_,
      argument_direction_, rates_;
};

}  // namespace

std::unique_ptr<LoweredBlock> LowerComplementarity(const Scene& scene,
                                                   const Complementarity& effect) {
  return std::make_unique<ComplementarityBlock>(scene, effect);
}

}  // namespace moreau::internal
