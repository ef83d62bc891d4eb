#pragma once
// Private to moreau::ocp: the implementation of CollocationNlp (collocation.hpp; docs/ocp.md,
// "Collocation transcription"), one class whose methods are defined by topic in
//   collocation.cpp             construction, layout and bounds, the Jacobian structure, the
//                               relaxed and exact levels, the initial guess, results, and the
//                               public class's methods;
//   collocation_evaluation.cpp  points, constraints and their exact first derivatives;
//   element_minima.cpp          the element-minimum rows (collocation_element_minima);
//   collocation_hessian.cpp     the second-order Hessian (OcpHessian::kSecondOrder);
//   collocation_refinement.cpp  the refinement (collocation_refinement_stages).

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "collocation.hpp"
#include "internal.hpp"
#include "moreau/integrators/radau_tableau.hpp"

namespace moreau::ocp_internal {

class CollocationNlp::Impl {
 public:
  static constexpr double kInfinity = kNoBound;
  using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  // Pinned ends of the element minima (LocateMinima): the search starts this far inside (c_m
  // at the end is zero only to the solver's tolerance, and c_m / theta magnifies that residual
  // by 1 / theta). A dip inside the margin is at most |c''| kPinnedMargin^2 / 8 (the slope at
  // the margin is nonnegative). Measured on the doorway: with 1e-3 IPOPT stopped at
  // Solved_To_Acceptable_Level with a pinned end 8e-8 off the wall; with 1e-2 Solve_Succeeded
  // with x(T) within 2.5e-8 of it.
  static constexpr double kPinnedMargin = 1e-2;

  Impl(const OcpProblem& problem, const OcpOptions& options);

  // --- layout -----------------------------------------------------------------------------
  // Variables: the free initial states, then per interval k: the decisions u_k and per element
  // n its length h followed by its stages i, each (X, Lambda).
  int StageSize() const { return n_ + nc_; }
  int ElementSize() const { return 1 + stages_ * StageSize(); }
  int IntervalSize() const { return nd_ + elements_ * ElementSize(); }
  int ControlOffset(int k) const { return nf_ + k * IntervalSize(); }
  int LengthIndex(int k, int e) const { return ControlOffset(k) + nd_ + e * ElementSize(); }
  int StateOffset(int k, int e, int i) const { return LengthIndex(k, e) + 1 + i * StageSize(); }
  int LambdaOffset(int k, int e, int i) const { return StateOffset(k, e, i) + n_; }
  // Rows: per interval and element the collocation rows (s n), the stage feasibility rows
  // (s n_c) and the complementarity rows (n_c); per interval the length row and N_fe - 1
  // step-equilibration rows; then terminal and path rows.
  int NumCheckPoints() const { return options_.collocation_check_points ? stages_ : 0; }
  int ElementRows() const { return stages_ * n_ + stages_ * nc_ + nc_ + NumCheckPoints() * nc_; }
  int IntervalRows() const { return elements_ * ElementRows() + 1 + (elements_ - 1); }
  int CollocationRow(int k, int e) const { return k * IntervalRows() + e * ElementRows(); }
  int FeasibilityRow(int k, int e) const { return CollocationRow(k, e) + stages_ * n_; }
  int ComplementarityRow(int k, int e) const { return FeasibilityRow(k, e) + stages_ * nc_; }
  int CheckRow(int k, int e) const { return ComplementarityRow(k, e) + nc_; }
  int LengthRow(int k) const { return k * IntervalRows() + elements_ * ElementRows(); }
  int EquilibrationRow(int k, int e) const { return LengthRow(k) + e; }  // e = 1..N_fe-1
  int TerminalRow() const { return intervals_ * IntervalRows(); }
  int PathRow(int k) const {
    return TerminalRow() + num_terminal_equalities_ + num_terminal_inequalities_ + k * num_path_;
  }
  int NumRows() const { return PathRow(intervals_ + 1); }
  // The element-minimum rows (ImposeElementMinima): per element one per constraint, appended
  // after all other rows only while imposed, so that the NLP of the other levels is unchanged
  // (their IPOPT paths change at round-off level with any extra row, and they are sensitive to
  // it: with free extra rows the doorway's exact level did not converge).
  int NumMinimumRows() const { return options_.collocation_element_minima ? nc_ : 0; }
  int MinimumRow(int k, int e) const { return NumRows() + (k * elements_ + e) * nc_; }
  int NumRowsWithMinima() const { return NumRows() + intervals_ * elements_ * NumMinimumRows(); }

  // The element's start: the previous element's last stage, or the initial state.
  bool StartIsInitial(int k, int e) const { return k == 0 && e == 0; }
  int StartOffset(int k, int e) const {
    if (e > 0) return StateOffset(k, e - 1, stages_ - 1);
    return StateOffset(k - 1, elements_ - 1, stages_ - 1);
  }

  // Columns of an element's blocks, in the order of ElementColumns: the start state (n
  // columns, or the free initial states), the previous element's last multipliers (n_c, only
  // e > 0 and complementarity rows), the lengths h_0..h_e, the decisions, the stages.
  struct ElementColumns {
    std::vector<int> columns;
    int start = 0, start_count = 0, previous = -1, lengths = 0, decisions = 0, stages = 0;
  };
  ElementColumns MakeColumns(int k, int e, bool with_start, bool with_previous, bool with_decisions,
                             bool with_lambda) const;
  void BuildLayout();
  void BuildBounds();

  // --- Jacobian structure -------------------------------------------------------------------
  struct Block {
    int row = 0, rows = 0;
    std::vector<int> columns;
    long offset = 0;
  };
  int AddBlock(int row, int rows, const std::vector<int>& columns);
  std::vector<int> NodeColumns(int k, int kd) const;
  void BuildJacobianStructure();

  Eigen::Map<RowMajorMatrix> BlockValues(int index, Vector* values) const {
    const Block& block = blocks_[static_cast<std::size_t>(index)];
    return Eigen::Map<RowMajorMatrix>(values->data() + block.offset, block.rows,
                                      static_cast<Eigen::Index>(block.columns.size()));
  }

  // --- levels, initial guess, results (collocation.cpp) -------------------------------------
  void ApplyParameters(const OcpHomotopyLevel& level);
  void SetRelaxedLevel(const OcpHomotopyLevel& level);
  std::vector<bool> Pieces(const Vector& z);
  std::size_t Piece(int k, int e, int m) const {
    return static_cast<std::size_t>((k * elements_ + e) * nc_ + m);
  }
  int SetExactLevel(const Vector& z) { return SetExactPieces(Pieces(z)); }
  int SetExactPieces(const std::vector<bool>& active);
  Vector InitialGuess();
  void Describe(const Vector& z, OcpResult* result);

  // --- element minima: rows (element_minima.cpp) ---------------------------------------------
  void ImposeElementMinima(const Vector& z, Vector* multipliers);
  bool OpposedToActivePiece(const Vector& z, int k, int e, int m);
  void ImposeElementMinimumRows(const std::vector<bool>& rows_present, Vector* multipliers);

  // --- refinement (collocation_refinement.cpp) -----------------------------------------------
  void SetRefinedLevel(const Impl& coarse);
  Vector Interpolate(const Impl& coarse, const Vector& zc, const OcpMultipliers& mc,
                     OcpMultipliers* mf) const;

  // --- evaluation (collocation_evaluation.cpp) ----------------------------------------------
  // One collocation point: dynamics V = f + sum_sets P grad_x c^T Lambda and c with their
  // derivatives.
  struct Point {
    Vector x;
    double t = 0.0;
    Vector c;         // n_c
    Matrix c_x;       // n_c x n
    Vector c_t;       // n_c
    Vector v;         // n
    Matrix v_x;       // n x n
    Vector v_t;       // n
    Matrix v_u;       // n x n_d
    Matrix v_lambda;  // n x n_c
    // With OcpHessian::kSecondOrder: per constraint m its Hessian over (x, t).
    std::vector<Matrix> c_hessians;
  };

  Vector Inputs(const Vector& z, int k) const {
    Vector u = augmented_.scene.InputValues(tau_[static_cast<std::size_t>(k)]);
    for (int j = 0; j < nd_; ++j) u[augmented_.decisions[j]] = z[ControlOffset(k) + j];
    return u;
  }

  Vector InitialState(const Vector& z) const {
    Vector x = x0_;
    for (int i = 0; i < nf_; ++i) {
      x[problem_.free_initial_states[static_cast<std::size_t>(i)].state] = z[i];
    }
    return x;
  }

  double StartTime(const Vector& z, int k, int e) const {
    double t = tau_[static_cast<std::size_t>(k)];
    for (int m = 0; m < e; ++m) t += z[LengthIndex(k, m)];
    return t;
  }

  void EvaluatePoint(const Vector& x, double t, const Vector& u, const Vector* lambda,
                     bool derivatives, Point* p);

  Point& Check(int k, int e, int q) {
    return check_points_[static_cast<std::size_t>((k * elements_ + e) * NumCheckPoints() + q)];
  }
  Point& MinimumPoint(int k, int e, int m) { return minimum_points_[Piece(k, e, m)]; }
  Point& Stage(int k, int e, int i) {
    return points_[static_cast<std::size_t>((k * elements_ + e) * stages_ + i)];
  }
  // The element's start point: the initial state, the previous element's last stage, or (at
  // an interval's first element) the previous interval's last state at the grid time tau_k
  // (so that the point's time does not depend on the previous interval's lengths).
  const Point& Start(int k, int e) {
    if (StartIsInitial(k, e)) return initial_point_;
    if (e > 0) return Stage(k, e - 1, stages_ - 1);
    return interval_start_points_[static_cast<std::size_t>(k)];
  }

  // The collocation polynomial of element (k, e) at theta in [0, 1]:
  // X(theta) = X_0 + sum_j w_j(theta) (X_j - X_0).
  Vector PolynomialState(int k, int e, const Vector& weights) {
    const Vector& x_start = Start(k, e).x;
    Vector x = x_start;
    for (int j = 0; j < stages_; ++j) x += weights[j] * (Stage(k, e, j).x - x_start);
    return x;
  }

  bool HasMinimumRow(int k, int e, int m) const {
    return minima_imposed_ && minimum_rows_[Piece(k, e, m)];
  }

  // Element minima, per inactive constraint m of element (k, e): the row is the minimum over
  // theta of v(theta) = c_m(X(theta), t_start + theta h) / phi(theta). phi = 1, except at an
  // end that a neighbouring active piece pins to c_m = 0: there c_m(theta) vanishes like the
  // distance to the end, and min c_m >= 0 would have a zero gradient exactly where the
  // trajectory leaves the wall tangentially (IPOPT then crawls: measured 1000 iterations at
  // infeasibility 1e-7 on the doorway). Dividing by theta (start pinned), 1 - theta (end
  // pinned) or both keeps the row's gradient away from zero there (v -> dc_m/dtheta at the
  // pinned end) and c_m >= 0 on the element is still v >= 0. Pinned ends are searched from
  // kPinnedMargin inside (c_m at the end is only zero to the solver's tolerance).
  struct Weight {
    bool start = false, end = false;
    double Value(double theta) const { return (start ? theta : 1.0) * (end ? 1.0 - theta : 1.0); }
    double Slope(double theta) const {
      if (start && end) return 1.0 - 2.0 * theta;
      return start ? 1.0 : (end ? -1.0 : 0.0);
    }
    double Curvature() const { return start && end ? -2.0 : 0.0; }
  };
  // element_minima.cpp:
  Weight MinimumWeight(int k, int e, int m) const;
  void LocateMinima(int k, int e, double start, double h, const Vector& u, bool derivatives);
  std::vector<int> InteriorMinimumRows(const Vector& z, double margin);
  // collocation_evaluation.cpp:
  void EvaluatePoints(const Vector& z, bool derivatives);
  void NodeFunction(const SmoothFunction& f, const Vector& z, int k, int kd, Vector* value,
                    Matrix* local) const;
  double EquilibrationPenalty(const Vector& z, Vector* gradient) const;
  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Vector* jacobian_values, std::string* message);
  double ComplementarityResidual(const Vector& z);

  // --- Hessian (OcpHessian::kSecondOrder; collocation_hessian.cpp) ---------------------------
  // Dense blocks over a set of columns, scattered into the union of their lower triangles.
  struct HessianBlock {
    std::vector<int> columns;
    std::vector<int>
        position;  // n * n entries (i, j) -> index in the values (-1 above the diagonal)
  };
  void BuildHessianStructure();
  static void Scatter(const HessianBlock& block, const Matrix& local, Vector* values);

  // How the arguments y = (x, t, u_decisions, Lambda) of a function at a point map to the
  // element block's local columns: each coordinate is a list of (column, coefficient).
  using Map = std::vector<std::vector<std::pair<int, double>>>;
  Map PointMap(int k, int e, int i, bool with_u_lambda) const;
  Map InterpolatedPointMap(int k, int e, const Vector& w, double theta) const;
  static void AddMapped(const Map& map, const Matrix& m, Matrix* local);
  static Vector MappedGradient(const Map& map, const Vector& g, int columns);
  static Matrix ConstraintHessian(const Point& p, const Vector& weights);
  bool Hessian(const Vector& z, double objective_factor, const Vector& lambda, Vector* values);

  struct Set {
    SmoothFunction constraints;
    int offset = 0, size = 0;
    Matrix projection;
    bool identity = true;  // P = I: products skipped
  };

  OcpProblem problem_;
  OcpOptions options_;
  AugmentedScene augmented_;
  int intervals_ = 0, elements_ = 0, stages_ = 0, n_ = 0, nu_ = 0, nd_ = 0, nf_ = 0, nc_ = 0;
  int num_terminal_equalities_ = 0, num_terminal_inequalities_ = 0, num_path_ = 0;
  RadauTableau tableau_;
  std::vector<double> check_theta_;
  std::vector<Vector> check_weights_;  // X(theta) = X_0 + sum_j w_j (X_j - X_0)
  std::vector<Set> sets_;
  std::vector<std::string> constraint_names_;
  Vector parameters_, x0_;
  double interval_length_ = 0.0;
  std::vector<double> tau_;
  OcpHomotopyLevel level_;
  bool exact_ = false;
  bool minima_imposed_ = false;  // ImposeElementMinima
  std::vector<bool> pieces_;
  std::vector<bool> minimum_rows_;  // per piece: its element-minimum row is imposed
  Vector variable_lower_, variable_upper_, constraint_lower_, constraint_upper_;
  Vector base_variable_upper_, base_constraint_lower_, base_constraint_upper_;
  std::vector<ElementColumns> collocation_columns_, feasibility_columns_, complementarity_columns_,
      check_columns_, hessian_columns_;
  std::vector<HessianBlock> element_hessian_, node_hessian_;
  std::vector<Block> blocks_;
  std::vector<std::pair<int, int>> structure_, structure_with_minima_, hessian_structure_;
  const std::vector<std::pair<int, int>>& Structure() const {
    return minima_imposed_ ? structure_with_minima_ : structure_;
  }
  std::vector<int> collocation_block_, feasibility_block_, complementarity_block_, check_block_,
      minimum_block_, length_block_, equilibration_block_, path_block_;
  int terminal_block_ = -1;
  std::vector<Point> points_, interval_start_points_, check_points_;
  // Element minima per (element, constraint) (Piece's index): theta* and the point there,
  // valid where HasMinimumRow.
  std::vector<Point> minimum_points_;
  std::vector<double> minimum_theta_;
  Point initial_point_;
  Vector points_z_;
  bool points_valid_ = false, points_derivatives_ = false;
};

}  // namespace moreau::ocp_internal
