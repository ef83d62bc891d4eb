// The complementarity-constrained collocation transcription (collocation.hpp, docs/ocp.md,
// "Collocation transcription"): variables, constraints and their exact first derivatives as a
// sparse Jacobian; relaxed and exact levels; the initial guess from a FESD simulation.

#include "collocation.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/radau_tableau.hpp"
#include "moreau/model/projection.hpp"

namespace moreau::ocp_internal {

namespace {
constexpr double kInfinity = 1e20;  // IPOPT's default "no bound"
using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
// Element lengths stay in [kMinElementFraction, kMaxElementFraction] times H / N_fe (FESD's
// elements may shrink to place a switch and grow to cover the rest of the interval).
constexpr double kMinElementFraction = 1e-3;
constexpr double kMaxElementFraction = 3.0;
// Element minima of a free constraint (OcpOptions::collocation_element_minima): samples per
// element before the search (the polynomial X has degree s, c of it a few times that: at most
// a few local minima per element, each between two of 16 samples), and the golden-section
// search's final bracket in theta (the Illinois iteration usually ends on a zero slope or a
// bracket at rounding level first). The row's gradient is that of v (LocateMinima) at fixed
// theta*, exact where dv/dtheta(theta*) = 0: a bracket of 1e-10 leaves |dv/dtheta| <=
// |v''| 1e-10.
constexpr int kMinimumSamples = 16;
constexpr double kMinimumBracket = 1e-10;
// Illinois converges superlinearly (order about 1.44): from a bracket of 1/16 to 1e-10 in
// well under 100 slope evaluations; the cap only guards against a non-terminating loop.
constexpr int kMinimumIterations = 100;
// Pinned ends (LocateMinima): the search starts this far inside (c_m at the end is zero only
// to the solver's tolerance, and c_m / theta magnifies that residual by 1 / theta). A dip
// inside the margin is at most |c''| kPinnedMargin^2 / 8 (the slope at the margin is
// nonnegative). Measured on the doorway: with 1e-3 IPOPT stopped at
// Solved_To_Acceptable_Level with a pinned end 8e-8 off the wall; with 1e-2 Solve_Succeeded
// with x(T) within 2.5e-8 of it.
constexpr double kPinnedMargin = 1e-2;
// OpposedToActivePiece: normals at least this close to opposite (the doorway's two discs at
// their touching point: -1; a pusher constraint against a slider constraint: |cosine| <=
// 1/sqrt(2), the pusher-slider gradient has both bodies' components). -0.99 is reached by the
// slider on one disc within |x2| < 0.57 of the doorway (discs of radius 8).
constexpr double kOpposedNormalCosine = 0.99;
}  // namespace

class CollocationNlp::Impl {
 public:
  Impl(const OcpProblem& problem, const OcpOptions& options)
      : problem_(problem), options_(options), augmented_(Augment(problem)) {
    const Scene& scene = augmented_.scene;
    RequireArgument(!problem.speed.enabled, problem.name,
                    ": the collocation transcription does not support a free final time "
                    "(speed of time); use multiple shooting");
    for (const Effect& effect : scene.effects) {
      RequireArgument(std::holds_alternative<MovingSet>(effect), problem.name,
                      ": the collocation transcription supports moving sets only, not the ",
                      EffectKind(effect), " '", EffectName(effect), "'; use multiple shooting");
    }
    intervals_ = problem.intervals;
    elements_ = options.finite_elements;
    stages_ = options.stages;
    n_ = scene.num_states();
    nu_ = scene.num_inputs();
    nd_ = static_cast<int>(augmented_.decisions.size());
    nf_ = static_cast<int>(problem.free_initial_states.size());
    tableau_ = RadauIIA(stages_);
    // Check points: midway between consecutive collocation nodes {0, c_1, ..., c_s}.
    for (int q = 0; q < (options.collocation_check_points ? stages_ : 0); ++q) {
      const double left = q == 0 ? 0.0 : tableau_.c[q - 1];
      const double theta = 0.5 * (left + tableau_.c[q]);
      check_theta_.push_back(theta);
      check_weights_.push_back(tableau_.InterpolationWeights(theta));
    }
    for (const Effect& effect : scene.effects) {
      const auto& set = std::get<MovingSet>(effect);
      Set entry;
      entry.constraints = set.constraints;
      entry.offset = nc_;
      entry.size = set.constraints.num_outputs();
      entry.projection = set.projection_basis.size() == 0
                             ? Matrix(Matrix::Identity(n_, n_))
                             : Matrix(set.projection_basis * set.projection_basis.transpose());
      entry.identity = entry.projection.isIdentity(0.0);
      for (const std::string& name : set.constraint_names) {
        constraint_names_.push_back(set.name + "." + name);
      }
      nc_ += entry.size;
      sets_.push_back(std::move(entry));
    }
    parameters_ = scene.ParameterValues();
    const double t0 = scene.initial_time, tf = scene.final_time;
    interval_length_ = (tf - t0) / intervals_;
    for (int k = 0; k <= intervals_; ++k) tau_.push_back(t0 + interval_length_ * k);
    tau_.back() = tf;
    x0_ = scene.initial_state;
    num_terminal_equalities_ = problem.terminal_equalities.num_outputs();
    num_terminal_inequalities_ = problem.terminal_inequalities.num_outputs();
    num_path_ = problem.path_constraints.num_outputs();
    BuildLayout();
    BuildBounds();
    BuildJacobianStructure();
    if (options.hessian == OcpHessian::kSecondOrder) BuildHessianStructure();
    SetRelaxedLevel(OcpHomotopyLevel{0.0, 0.0, {}, 1.0});
  }

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
                             bool with_lambda) const {
    ElementColumns out;
    auto& c = out.columns;
    out.start = 0;
    if (with_start) {
      if (StartIsInitial(k, e)) {
        for (int i = 0; i < nf_; ++i) c.push_back(i);
      } else {
        for (int i = 0; i < n_; ++i) c.push_back(StartOffset(k, e) + i);
      }
    }
    out.start_count = static_cast<int>(c.size());
    if (with_previous && e > 0) {
      out.previous = static_cast<int>(c.size());
      for (int m = 0; m < nc_; ++m) c.push_back(LambdaOffset(k, e - 1, stages_ - 1) + m);
    }
    out.lengths = static_cast<int>(c.size());
    for (int m = 0; m <= e; ++m) c.push_back(LengthIndex(k, m));
    out.decisions = static_cast<int>(c.size());
    if (with_decisions) {
      for (int j = 0; j < nd_; ++j) c.push_back(ControlOffset(k) + j);
    }
    out.stages = static_cast<int>(c.size());
    for (int i = 0; i < stages_; ++i) {
      for (int j = 0; j < n_; ++j) c.push_back(StateOffset(k, e, i) + j);
      if (with_lambda) {
        for (int m = 0; m < nc_; ++m) c.push_back(LambdaOffset(k, e, i) + m);
      }
    }
    return out;
  }

  void BuildLayout() {
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        collocation_columns_.push_back(MakeColumns(k, e, true, false, true, true));
        feasibility_columns_.push_back(MakeColumns(k, e, false, false, false, false));
        complementarity_columns_.push_back(MakeColumns(k, e, true, true, false, true));
        check_columns_.push_back(MakeColumns(k, e, true, false, false, false));
      }
    }
  }

  void BuildBounds() {
    const int nz = nf_ + intervals_ * IntervalSize();
    variable_lower_ = Vector::Constant(nz, -kInfinity);
    variable_upper_ = Vector::Constant(nz, kInfinity);
    for (int i = 0; i < nf_; ++i) {
      const auto& free = problem_.free_initial_states[static_cast<std::size_t>(i)];
      variable_lower_[i] = std::max(free.lower, -kInfinity);
      variable_upper_[i] = std::min(free.upper, kInfinity);
    }
    const double nominal = interval_length_ / elements_;
    for (int k = 0; k < intervals_; ++k) {
      for (int j = 0; j < nd_; ++j) {
        const InputSpec& input =
            augmented_.scene.inputs[static_cast<std::size_t>(augmented_.decisions[j])];
        variable_lower_[ControlOffset(k) + j] = std::max(input.lower, -kInfinity);
        variable_upper_[ControlOffset(k) + j] = std::min(input.upper, kInfinity);
      }
      for (int e = 0; e < elements_; ++e) {
        variable_lower_[LengthIndex(k, e)] = kMinElementFraction * nominal;
        variable_upper_[LengthIndex(k, e)] = kMaxElementFraction * nominal;
        for (int i = 0; i < stages_; ++i) {
          variable_lower_.segment(LambdaOffset(k, e, i), nc_).setZero();
        }
      }
    }
    base_variable_upper_ = variable_upper_;
    const int m = NumRows();
    constraint_lower_ = Vector::Zero(m);
    constraint_upper_ = Vector::Zero(m);
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        // c >= 0 at every stage; the complementarity rows' bounds are per level.
        constraint_upper_.segment(FeasibilityRow(k, e), stages_ * nc_).setConstant(kInfinity);
        constraint_lower_.segment(ComplementarityRow(k, e), nc_).setConstant(-kInfinity);
        // Check rows are imposed on the exact level only (on inactive pieces); on relaxed levels
        // contacts make c between the nodes slightly negative (interpolation error).
        constraint_lower_.segment(CheckRow(k, e), NumCheckPoints() * nc_).setConstant(-kInfinity);
        constraint_upper_.segment(CheckRow(k, e), NumCheckPoints() * nc_).setConstant(kInfinity);
        if (e > 0) {
          constraint_lower_[EquilibrationRow(k, e)] = -kInfinity;
          constraint_upper_[EquilibrationRow(k, e)] = kInfinity;
        }
      }
    }
    const int inequalities = TerminalRow() + num_terminal_equalities_;
    for (int r = inequalities; r < m; ++r) constraint_lower_[r] = -kInfinity;
    base_constraint_lower_ = constraint_lower_;
    base_constraint_upper_ = constraint_upper_;
  }

  // --- Jacobian structure -------------------------------------------------------------------
  struct Block {
    int row = 0, rows = 0;
    std::vector<int> columns;
    long offset = 0;
  };
  int AddBlock(int row, int rows, const std::vector<int>& columns) {
    if (rows == 0 || columns.empty()) return -1;
    Block block;
    block.row = row;
    block.rows = rows;
    block.columns = columns;
    block.offset = blocks_.empty() ? 0
                                   : blocks_.back().offset +
                                         static_cast<long>(blocks_.back().rows) *
                                             static_cast<long>(blocks_.back().columns.size());
    blocks_.push_back(std::move(block));
    return static_cast<int>(blocks_.size()) - 1;
  }

  // A node function's columns: node k's state (the start of interval k's first element, the
  // last stage at k = N; the free initial states at k = 0) and the decisions of interval kd.
  std::vector<int> NodeColumns(int k, int kd) const {
    std::vector<int> columns;
    if (k == 0) {
      for (int i = 0; i < nf_; ++i) columns.push_back(i);
    } else {
      const int offset = StateOffset(k - 1, elements_ - 1, stages_ - 1);
      for (int i = 0; i < n_; ++i) columns.push_back(offset + i);
    }
    for (int j = 0; j < nd_; ++j) columns.push_back(ControlOffset(kd) + j);
    return columns;
  }

  void BuildJacobianStructure() {
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        const int index = k * elements_ + e;
        collocation_block_.push_back(
            AddBlock(CollocationRow(k, e), stages_ * n_, collocation_columns_[index].columns));
        feasibility_block_.push_back(
            AddBlock(FeasibilityRow(k, e), stages_ * nc_, feasibility_columns_[index].columns));
        complementarity_block_.push_back(
            AddBlock(ComplementarityRow(k, e), nc_, complementarity_columns_[index].columns));
        check_block_.push_back(
            AddBlock(CheckRow(k, e), NumCheckPoints() * nc_, check_columns_[index].columns));
      }
      std::vector<int> lengths;
      for (int e = 0; e < elements_; ++e) lengths.push_back(LengthIndex(k, e));
      length_block_.push_back(AddBlock(LengthRow(k), 1, lengths));
      for (int e = 1; e < elements_; ++e) {
        equilibration_block_.push_back(
            AddBlock(EquilibrationRow(k, e), 1, {LengthIndex(k, e - 1), LengthIndex(k, e)}));
      }
    }
    terminal_block_ = AddBlock(TerminalRow(), num_terminal_equalities_ + num_terminal_inequalities_,
                               NodeColumns(intervals_, intervals_ - 1));
    for (int k = 0; k <= intervals_; ++k) {
      path_block_.push_back(
          AddBlock(PathRow(k), num_path_, NodeColumns(k, std::min(k, intervals_ - 1))));
    }
    structure_.clear();
    for (const Block& block : blocks_) {
      for (int r = 0; r < block.rows; ++r) {
        for (int c : block.columns) structure_.emplace_back(block.row + r, c);
      }
    }
    // The element minima's blocks last: their values follow all others.
    structure_with_minima_ = structure_;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        const int index =
            AddBlock(MinimumRow(k, e), NumMinimumRows(),
                     check_columns_[static_cast<std::size_t>(k * elements_ + e)].columns);
        minimum_block_.push_back(index);
        if (index < 0) continue;
        const Block& block = blocks_[static_cast<std::size_t>(index)];
        for (int r = 0; r < block.rows; ++r) {
          for (int c : block.columns) structure_with_minima_.emplace_back(block.row + r, c);
        }
      }
    }
  }

  Eigen::Map<RowMajorMatrix> BlockValues(int index, Vector* values) const {
    const Block& block = blocks_[static_cast<std::size_t>(index)];
    return Eigen::Map<RowMajorMatrix>(values->data() + block.offset, block.rows,
                                      static_cast<Eigen::Index>(block.columns.size()));
  }

  // --- levels -------------------------------------------------------------------------------
  void ApplyParameters(const OcpHomotopyLevel& level) {
    Scene values = augmented_.scene;
    for (const auto& [name, value] : level.parameters) {
      RequireArgument(values.FindParameter(name) >= 0, problem_.name, ": homotopy parameter '",
                      name, "' is not a scene parameter");
      SetSceneValue(&values, name, value);
    }
    parameters_ = values.ParameterValues();
    points_valid_ = false;
    level_ = level;
    for (int r = 0; r < num_terminal_equalities_; ++r) {
      constraint_lower_[TerminalRow() + r] = -level.relaxation;
      constraint_upper_[TerminalRow() + r] = level.relaxation;
    }
  }

  void SetRelaxedLevel(const OcpHomotopyLevel& level) {
    RequireArgument(level.smoothing == 0.0, problem_.name,
                    ": the collocation transcription relaxes complementarity instead of "
                    "smoothing the dynamics (homotopy smoothing must be 0)");
    RequireArgument(level.complementarity > 0.0, problem_.name,
                    ": a relaxed level of the collocation transcription needs a complementarity "
                    "relaxation > 0");
    variable_upper_ = base_variable_upper_;
    constraint_lower_ = base_constraint_lower_;
    constraint_upper_ = base_constraint_upper_;
    ApplyParameters(level);
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        constraint_upper_.segment(ComplementarityRow(k, e), nc_).setConstant(level.complementarity);
      }
    }
    exact_ = false;
    minima_imposed_ = false;
  }

  // On the exact level (same pieces): c_m's minimum over the element >= 0 for every inactive
  // piece instead of c_m >= 0 at the check points (the minimum bounds c there, and an active
  // check row next to an active minimum at almost the same theta would be an almost parallel
  // pair of active constraints). The check rows' multipliers move to the minimum's row: to
  // first order the same force, acting at the minimiser instead of at the check points.
  // Except where the minimum is opposed to an active piece (OpposedToActivePiece): there the
  // check points stay.
  void ImposeElementMinima(const Vector& z, Vector* multipliers) {
    MOREAU_ASSERT(exact_ && NumMinimumRows() > 0, "element minima need the exact level");
    std::vector<bool> rows(pieces_.size(), false);
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        for (int m = 0; m < nc_; ++m) {
          rows[Piece(k, e, m)] = !pieces_[Piece(k, e, m)] && !OpposedToActivePiece(z, k, e, m);
        }
      }
    }
    ImposeElementMinimumRows(rows, multipliers);
  }

  // An inactive constraint m whose normal, at its smallest sampled value on the element's
  // polynomial, is opposite to an active constraint's normal (cosine below
  // -kOpposedNormalCosine): the doorway's touching point, where the slider riding one disc
  // passes the other. There the true trajectory has c_m = 0 at one instant, and the
  // polynomial's c_m at the passage is minus the active constraint's interpolation error
  // between the nodes (c_1 + c_2 = 2 |x - (cos t, 0)|^2 for the two discs): the row's
  // gradient is almost minus those of the active piece's stage rows, the minimum's sign is
  // that of a discretization error, and IPOPT does not converge on it (measured with s = 4:
  // infeasibility stuck at 1.2e-8 at element (12, 1)). Such pairs keep c_m >= 0 at the nodes
  // and check points: a dip between them is of the size of the active piece's own deviation
  // from its wall.
  bool OpposedToActivePiece(const Vector& z, int k, int e, int m) {
    EvaluatePoints(z, false);
    const double start = StartTime(z, k, e), h = z[LengthIndex(k, e)];
    const Vector u = Inputs(z, k);
    Point lowest, p;
    double lowest_value = kInfinity;
    for (int q = 0; q <= kMinimumSamples; ++q) {
      const double theta = static_cast<double>(q) / kMinimumSamples;
      const Vector x = PolynomialState(k, e, tableau_.InterpolationWeights(theta));
      EvaluatePoint(x, start + theta * h, u, nullptr, true, &p);
      if (p.c[m] < lowest_value) {
        lowest_value = p.c[m];
        lowest = p;
      }
    }
    const double norm = lowest.c_x.row(m).norm();
    for (int a = 0; a < nc_; ++a) {
      if (!pieces_[Piece(k, e, a)] || norm == 0.0) continue;
      const double other = lowest.c_x.row(a).norm();
      if (other > 0.0 &&
          lowest.c_x.row(m).dot(lowest.c_x.row(a)) < -kOpposedNormalCosine * norm * other) {
        return true;
      }
    }
    return false;
  }

  // The element-minimum rows where rows[Piece(k, e, m)] (inactive pieces only).
  void ImposeElementMinimumRows(const std::vector<bool>& rows_present, Vector* multipliers) {
    const int rows = NumRows(), all = NumRowsWithMinima();
    constraint_lower_.conservativeResize(all);
    constraint_upper_.conservativeResize(all);
    constraint_lower_.tail(all - rows).setConstant(-kInfinity);
    constraint_upper_.tail(all - rows).setConstant(kInfinity);
    const bool move = multipliers != nullptr && multipliers->size() == rows;
    if (move) {
      multipliers->conservativeResize(all);
      multipliers->tail(all - rows).setZero();
    }
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        for (int m = 0; m < nc_; ++m) {
          if (!rows_present[Piece(k, e, m)]) continue;
          MOREAU_ASSERT(!pieces_[Piece(k, e, m)], "element minima on inactive pieces only");
          double sum = 0.0;
          for (int q = 0; q < NumCheckPoints(); ++q) {
            const int row = CheckRow(k, e) + q * nc_ + m;
            constraint_lower_[row] = -kInfinity;
            if (move) {
              sum += (*multipliers)[row];
              (*multipliers)[row] = 0.0;
            }
          }
          constraint_lower_[MinimumRow(k, e) + m] = 0.0;
          if (move) (*multipliers)[MinimumRow(k, e) + m] = sum;
        }
      }
    }
    minimum_rows_ = rows_present;
    minima_imposed_ = true;
    points_valid_ = false;
  }

  // Per element and constraint: is the constraint active (c = 0, Lambda >= 0) on the piece?
  // Decided from the relaxed solution by which side of the product is larger: c summed over
  // the element's stages against Lambda summed over them, scaled by the constraint's
  // gradient (so that both are rates of the same quantity: |grad c|^2 Lambda is the normal
  // speed the multiplier produces).
  std::vector<bool> Pieces(const Vector& z) {
    EvaluatePoints(z, true);
    std::vector<bool> active(static_cast<std::size_t>(intervals_ * elements_ * nc_), false);
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        for (int m = 0; m < nc_; ++m) {
          double lambda = 0.0, c = 0.0;
          for (int i = 0; i < stages_; ++i) {
            const Point& p = Stage(k, e, i);
            lambda += z[LambdaOffset(k, e, i) + m] * p.c_x.row(m).squaredNorm();
            c += std::max(0.0, p.c[m]);
          }
          // c is a distance-like quantity, |grad c|^2 Lambda a rate: compare c with the
          // distance the multiplier moves the state over the element.
          const double h = z[LengthIndex(k, e)];
          active[Piece(k, e, m)] = lambda * h > c;
        }
      }
    }
    return active;
  }
  std::size_t Piece(int k, int e, int m) const {
    return static_cast<std::size_t>((k * elements_ + e) * nc_ + m);
  }

  int SetExactLevel(const Vector& z) { return SetExactPieces(Pieces(z)); }

  int SetExactPieces(const std::vector<bool>& active) {
    MOREAU_ASSERT(active.size() == static_cast<std::size_t>(intervals_ * elements_ * nc_),
                  "one piece per element and constraint");
    variable_upper_ = base_variable_upper_;
    constraint_lower_ = base_constraint_lower_;
    constraint_upper_ = base_constraint_upper_;
    ApplyParameters(OcpHomotopyLevel{});
    int count = 0;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        constraint_lower_.segment(ComplementarityRow(k, e), nc_).setConstant(-kInfinity);
        constraint_upper_.segment(ComplementarityRow(k, e), nc_).setConstant(kInfinity);
        for (int m = 0; m < nc_; ++m) {
          if (active[Piece(k, e, m)]) {
            ++count;
            // c_m = 0 at every stage and at the element's start (the previous element's
            // last stage; at t0 the initial state, which must then lie on the boundary).
            for (int i = 0; i < stages_; ++i)
              constraint_upper_[FeasibilityRow(k, e) + i * nc_ + m] = 0.0;
            // Between the nodes of an active piece c deviates from 0 by the interpolation
            // error, either way: no sign condition at the check points.
            if (e > 0) {
              constraint_upper_[FeasibilityRow(k, e - 1) + (stages_ - 1) * nc_ + m] = 0.0;
            } else if (k > 0) {
              constraint_upper_[FeasibilityRow(k - 1, elements_ - 1) + (stages_ - 1) * nc_ + m] =
                  0.0;
            }
          } else {
            for (int i = 0; i < stages_; ++i) variable_upper_[LambdaOffset(k, e, i) + m] = 0.0;
            for (int q = 0; q < NumCheckPoints(); ++q) {
              constraint_lower_[CheckRow(k, e) + q * nc_ + m] = 0.0;
            }
            // An active piece followed by an inactive one in the same interval: the multiplier
            // at the switch is zero (cross complementarity with the next element's c > 0).
            if (e > 0 && active[Piece(k, e - 1, m)]) {
              variable_upper_[LambdaOffset(k, e - 1, stages_ - 1) + m] = 0.0;
            }
          }
        }
        // Step equilibration: elements of one interval whose boundary carries no change of
        // the active set have equal lengths.
        if (e > 0) {
          bool change = false;
          for (int m = 0; m < nc_; ++m)
            change |= active[Piece(k, e, m)] != active[Piece(k, e - 1, m)];
          if (!change) {
            constraint_lower_[EquilibrationRow(k, e)] = 0.0;
            constraint_upper_[EquilibrationRow(k, e)] = 0.0;
          }
        }
      }
    }
    exact_ = true;
    minima_imposed_ = false;
    pieces_ = active;
    return count;
  }

  // --- refinement (OcpOptions::collocation_refinement_stages) ---------------------------------
  // The exact level with the pieces of `coarse` (same N and N_fe, fewer stages), and its
  // element minima if they are imposed there.
  void SetRefinedLevel(const Impl& coarse) {
    MOREAU_ASSERT(coarse.exact_ && coarse.intervals_ == intervals_ &&
                      coarse.elements_ == elements_ && coarse.n_ == n_ && coarse.nc_ == nc_ &&
                      coarse.nd_ == nd_ && coarse.nf_ == nf_,
                  "a refinement needs the coarse transcription's exact level on the same mesh");
    SetExactPieces(coarse.pieces_);
    if (coarse.minima_imposed_) ImposeElementMinimumRows(coarse.minimum_rows_, nullptr);
  }

  // The coarse solution zc on this transcription: decisions and element lengths as they are;
  // the stage states on the coarse collocation polynomial at this tableau's nodes (element
  // ends unchanged); the multipliers Lambda by the polynomial through the coarse stages
  // (clamped to >= 0, zero on inactive pieces). IPOPT's multipliers (mc, if not empty) go to
  // *mf: rows and bounds of decisions, lengths, the interval, terminal, path and element-minimum
  // rows as they are; per element the collocation rows' mu as a density: nu = A^T mu
  // approximates b_i p(t_i) (p the costate: with f = 0 only the last stage's mu = p is
  // nonzero, and the last row of A is b), so p_i = nu_i / b_i is interpolated to the new
  // nodes and mapped back by mu = A^-T (b p); the stage feasibility rows' and the Lambda
  // bounds' multipliers as densities over the weights b. The check and complementarity rows
  // are free on the exact level (zero multipliers).
  Vector Interpolate(const Impl& coarse, const Vector& zc, const OcpMultipliers& mc,
                     OcpMultipliers* mf) const {
    const RadauTableau& tc = coarse.tableau_;
    const int sc = coarse.stages_;
    // Per new stage i: the coarse polynomial's weights at c_i (over the start and the coarse
    // stages) and the Lagrange weights over the coarse nodes c_1..c_sc (Lambda has no start
    // value).
    std::vector<Vector> polynomial(static_cast<std::size_t>(stages_));
    Matrix lagrange(stages_, sc);
    for (int i = 0; i < stages_; ++i) {
      polynomial[static_cast<std::size_t>(i)] = tc.InterpolationWeights(tableau_.c[i]);
      for (int j = 0; j < sc; ++j) {
        double w = 1.0;
        for (int l = 0; l < sc; ++l) {
          if (l != j) w *= (tableau_.c[i] - tc.c[l]) / (tc.c[j] - tc.c[l]);
        }
        lagrange(i, j) = w;
      }
    }
    // Densities over the quadrature weights: values at the coarse nodes -> this tableau's.
    const Vector b_coarse_inverse = tc.b.cwiseInverse();
    auto density = [&](const Matrix& coarse_values) -> Matrix {  // sc x cols -> stages_ x cols
      return tableau_.b.asDiagonal() * (lagrange * (b_coarse_inverse.asDiagonal() * coarse_values));
    };
    Vector z = Vector::Zero(variable_lower_.size());
    z.head(nf_) = zc.head(nf_);
    const bool duals = !mc.empty() && mf != nullptr;
    if (duals) {
      mf->constraints = Vector::Zero(constraint_lower_.size());
      mf->lower_bounds = Vector::Zero(z.size());
      mf->upper_bounds = Vector::Zero(z.size());
      mf->lower_bounds.head(nf_) = mc.lower_bounds.head(nf_);
      mf->upper_bounds.head(nf_) = mc.upper_bounds.head(nf_);
    }
    auto copy = [&](int fine, int from, int size) {
      z.segment(fine, size) = zc.segment(from, size);
      if (!duals) return;
      mf->lower_bounds.segment(fine, size) = mc.lower_bounds.segment(from, size);
      mf->upper_bounds.segment(fine, size) = mc.upper_bounds.segment(from, size);
    };
    Matrix states(sc, n_), lambdas(sc, nc_), rows(sc, n_);
    for (int k = 0; k < intervals_; ++k) {
      copy(ControlOffset(k), coarse.ControlOffset(k), nd_);
      for (int e = 0; e < elements_; ++e) {
        copy(LengthIndex(k, e), coarse.LengthIndex(k, e), 1);
        const Vector x_start = coarse.StartIsInitial(k, e)
                                   ? coarse.InitialState(zc)
                                   : Vector(zc.segment(coarse.StartOffset(k, e), n_));
        for (int j = 0; j < sc; ++j) {
          states.row(j) = zc.segment(coarse.StateOffset(k, e, j), n_).transpose();
          lambdas.row(j) = zc.segment(coarse.LambdaOffset(k, e, j), nc_).transpose();
        }
        const Matrix lambda = lagrange * lambdas;
        for (int i = 0; i < stages_; ++i) {
          Vector x = x_start;
          for (int j = 0; j < sc; ++j) {
            x += polynomial[static_cast<std::size_t>(i)][j] * (states.row(j).transpose() - x_start);
          }
          z.segment(StateOffset(k, e, i), n_) = x;
          for (int m = 0; m < nc_; ++m) {
            z[LambdaOffset(k, e, i) + m] =
                pieces_[Piece(k, e, m)] ? std::max(0.0, lambda(i, m)) : 0.0;
          }
        }
        if (!duals) continue;
        // (9a) collocation rows: mu -> nu = A^T mu ~ b p -> p at the new nodes -> mu.
        for (int j = 0; j < sc; ++j) {
          rows.row(j) =
              mc.constraints.segment(coarse.CollocationRow(k, e) + j * n_, n_).transpose();
        }
        const Matrix mu = tableau_.a_inverse.transpose() * density(tc.a.transpose() * rows);
        Matrix feasibility(sc, nc_), lower(sc, nc_), upper(sc, nc_);
        for (int j = 0; j < sc; ++j) {
          feasibility.row(j) =
              mc.constraints.segment(coarse.FeasibilityRow(k, e) + j * nc_, nc_).transpose();
          lower.row(j) = mc.lower_bounds.segment(coarse.LambdaOffset(k, e, j), nc_).transpose();
          upper.row(j) = mc.upper_bounds.segment(coarse.LambdaOffset(k, e, j), nc_).transpose();
        }
        const Matrix feasibility_fine = density(feasibility);
        const Matrix lower_fine = density(lower).cwiseMax(0.0);
        const Matrix upper_fine = density(upper).cwiseMax(0.0);
        for (int i = 0; i < stages_; ++i) {
          mf->constraints.segment(CollocationRow(k, e) + i * n_, n_) = mu.row(i).transpose();
          mf->constraints.segment(FeasibilityRow(k, e) + i * nc_, nc_) =
              feasibility_fine.row(i).transpose();
          mf->lower_bounds.segment(LambdaOffset(k, e, i), nc_) = lower_fine.row(i).transpose();
          mf->upper_bounds.segment(LambdaOffset(k, e, i), nc_) = upper_fine.row(i).transpose();
        }
        if (minima_imposed_ && coarse.minima_imposed_ && mc.constraints.size() > coarse.NumRows()) {
          mf->constraints.segment(MinimumRow(k, e), NumMinimumRows()) =
              mc.constraints.segment(coarse.MinimumRow(k, e), coarse.NumMinimumRows());
        }
      }
      if (duals) {
        mf->constraints.segment(LengthRow(k), elements_) =
            mc.constraints.segment(coarse.LengthRow(k), elements_);
      }
    }
    if (duals) {
      const int tail = NumRows() - TerminalRow();
      mf->constraints.segment(TerminalRow(), tail) =
          mc.constraints.segment(coarse.TerminalRow(), tail);
    }
    return z;
  }

  // --- evaluation ---------------------------------------------------------------------------
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
                     bool derivatives, Point* p) {
    p->x = x;
    p->t = t;
    p->c.resize(nc_);
    Vector value;
    Matrix jacobian;
    if (derivatives) {
      p->c_x.resize(nc_, n_);
      p->c_t.resize(nc_);
    }
    for (const Set& set : sets_) {
      if (derivatives) {
        set.constraints.Jacobian(x, u, t, parameters_, Wrt::XT(), &value, &jacobian);
        p->c_x.middleRows(set.offset, set.size) = jacobian.leftCols(n_);
        p->c_t.segment(set.offset, set.size) = jacobian.col(n_);
      } else {
        set.constraints.Evaluate(x, u, t, parameters_, &value);
      }
      p->c.segment(set.offset, set.size) = value;
    }
    // Per-constraint Hessians (second-order mode): the Lambda-weighted sums below, the
    // constraint Hessians and the Lambda-(x, t) cross terms of the Lagrangian's Hessian come
    // from them without further evaluations.
    const bool second_order = derivatives && options_.hessian == OcpHessian::kSecondOrder;
    if (second_order) {
      p->c_hessians.resize(static_cast<std::size_t>(nc_));
      SparseMatrix sparse;
      for (const Set& set : sets_) {
        for (int m = 0; m < set.size; ++m) {
          Vector unit = Vector::Zero(set.size);
          unit[m] = 1.0;
          const std::vector<int> rows{m};
          set.constraints.SparseWeightedHessian(x, u, t, parameters_, Wrt::XT(), unit, &sparse,
                                                &rows);
          p->c_hessians[static_cast<std::size_t>(set.offset + m)] = Matrix(sparse);
        }
      }
    }
    if (lambda == nullptr) return;
    // V = f + sum P grad_x c^T Lambda.
    const SmoothFunction& f = augmented_.scene.dynamics;
    p->v.setZero(n_);
    if (derivatives) {
      p->v_x.setZero(n_, n_);
      p->v_t.setZero(n_);
      p->v_u.setZero(n_, nd_);
      p->v_lambda.setZero(n_, nc_);
    }
    if (!f.empty()) {
      if (derivatives) {
        f.Jacobian(x, u, t, parameters_, Wrt::XUT(), &value, &jacobian);
        p->v_x = jacobian.leftCols(n_);
        for (int j = 0; j < nd_; ++j) p->v_u.col(j) = jacobian.col(n_ + augmented_.decisions[j]);
        p->v_t = jacobian.col(n_ + nu_);
      } else {
        f.Evaluate(x, u, t, parameters_, &value);
      }
      p->v = value;
    }
    Matrix c_x_local;
    Matrix hessian;
    for (const Set& set : sets_) {
      const Vector weights = lambda->segment(set.offset, set.size);
      if (derivatives) {
        c_x_local = p->c_x.middleRows(set.offset, set.size);
      } else {
        set.constraints.Jacobian(x, u, t, parameters_, Wrt::X(), &value, &c_x_local);
      }
      const Vector push = c_x_local.transpose() * weights;
      p->v += set.identity ? push : Vector(set.projection * push);
      if (!derivatives) continue;
      if (set.identity) {
        p->v_lambda.middleCols(set.offset, set.size) = c_x_local.transpose();
      } else {
        p->v_lambda.middleCols(set.offset, set.size) = set.projection * c_x_local.transpose();
      }
      if (weights.lpNorm<Eigen::Infinity>() == 0.0) continue;
      // d/d(x, t) of grad_x c^T Lambda: the Lambda-weighted Hessian's x rows.
      if (second_order) {
        hessian.setZero(n_ + 1, n_ + 1);
        for (int m = 0; m < set.size; ++m) {
          hessian += weights[m] * p->c_hessians[static_cast<std::size_t>(set.offset + m)];
        }
      } else {
        set.constraints.WeightedHessian(x, u, t, parameters_, Wrt::XT(), weights, &hessian);
      }
      if (set.identity) {
        p->v_x += hessian.topLeftCorner(n_, n_);
        p->v_t += hessian.topRightCorner(n_, 1);
      } else {
        p->v_x += set.projection * hessian.topLeftCorner(n_, n_);
        p->v_t += set.projection * hessian.topRightCorner(n_, 1);
      }
    }
  }

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
  Weight MinimumWeight(int k, int e, int m) const {
    Weight w;
    if (e > 0) {
      w.start = pieces_[Piece(k, e - 1, m)];
    } else if (k > 0) {
      w.start = pieces_[Piece(k - 1, elements_ - 1, m)];
    }
    if (e + 1 < elements_) {
      w.end = pieces_[Piece(k, e + 1, m)];
    } else if (k + 1 < intervals_) {
      w.end = pieces_[Piece(k + 1, 0, m)];
    }
    return w;
  }

  // The minimiser theta* of v for every inactive constraint m of element (k, e), and the point
  // there. Samples locate the smallest sampled value; the minimiser is that sample where the
  // slope dv/dtheta points out of the search interval (an end, taken exactly), else the root
  // of the slope between the sample and the neighbour it descends to, by the Illinois method
  // (the global minimiser unless two minima within 1/16 of an element compete). A root of the
  // slope, not a search on values: near a flat minimum the values stop deciding at rounding
  // level while theta* still moves, and the row's gradient at fixed theta* is exact only where
  // the slope is 0. Without a sign change of the slope, golden-section search on the values.
  void LocateMinima(int k, int e, double start, double h, const Vector& u, bool derivatives) {
    const Vector& x_start = Start(k, e).x;
    Vector value;
    Matrix jacobian;
    // (c_m, dc_m/dtheta) at theta.
    auto constraint_at = [&](double theta, int m) -> std::pair<double, double> {
      const Vector x = PolynomialState(k, e, tableau_.InterpolationWeights(theta));
      const Vector w = tableau_.InterpolationDerivativeWeights(theta);
      Vector dx = Vector::Zero(n_);  // dX/dtheta
      for (int j = 0; j < stages_; ++j) dx += w[j] * (Stage(k, e, j).x - x_start);
      for (const Set& set : sets_) {
        if (m < set.offset || m >= set.offset + set.size) continue;
        set.constraints.Jacobian(x, u, start + theta * h, parameters_, Wrt::XT(), &value,
                                 &jacobian);
        const int row = m - set.offset;
        return {value[row], jacobian.row(row).head(n_).dot(dx) + jacobian(row, n_) * h};
      }
      return {0.0, 0.0};
    };
    const double ratio = 0.5 * (std::sqrt(5.0) - 1.0);
    for (int m = 0; m < nc_; ++m) {
      if (!HasMinimumRow(k, e, m)) continue;
      const Weight weight = MinimumWeight(k, e, m);
      // v and dv/dtheta = (c' phi - c phi') / phi^2.
      auto v_at = [&](double theta) {
        const auto [c, dc] = constraint_at(theta, m);
        const double phi = weight.Value(theta);
        return std::pair<double, double>{c / phi,
                                         (dc * phi - c * weight.Slope(theta)) / (phi * phi)};
      };
      const double first = weight.start ? kPinnedMargin : 0.0;
      const double last = weight.end ? 1.0 - kPinnedMargin : 1.0;
      auto sample_theta = [&](Eigen::Index i) {
        return first + (last - first) * static_cast<double>(i) / kMinimumSamples;
      };
      Vector samples(kMinimumSamples + 1);
      for (int i = 0; i <= kMinimumSamples; ++i) samples[i] = v_at(sample_theta(i)).first;
      Eigen::Index best = 0;
      samples.minCoeff(&best);
      double theta = sample_theta(best);
      const double slope = v_at(theta).second;
      // The neighbour the slope descends to (none: theta is an end with an outward slope).
      const int toward = slope > 0.0 ? -1 : (slope < 0.0 ? 1 : 0);
      const Eigen::Index neighbour = best + toward;
      if (toward != 0 && neighbour >= 0 && neighbour <= kMinimumSamples) {
        const double other = sample_theta(neighbour);
        double lo = std::min(theta, other), hi = std::max(theta, other);
        double slope_lo = toward < 0 ? v_at(lo).second : slope;
        double slope_hi = toward < 0 ? slope : v_at(hi).second;
        if (slope_lo < 0.0 && slope_hi > 0.0) {
          // Illinois: regula falsi, halving the weight of an end kept twice.
          int kept = 0;
          for (int iteration = 0; iteration < kMinimumIterations && hi - lo > kMinimumBracket;
               ++iteration) {
            double mid = (lo * slope_hi - hi * slope_lo) / (slope_hi - slope_lo);
            // A secant point on an end (one slope negligible next to the other): bisect.
            if (!(mid > lo && mid < hi)) mid = 0.5 * (lo + hi);
            if (!(mid > lo && mid < hi)) break;  // the bracket at rounding level
            const double slope_mid = v_at(mid).second;
            if (slope_mid == 0.0) {
              lo = hi = mid;
              break;
            }
            if (slope_mid < 0.0) {
              lo = mid;
              slope_lo = slope_mid;
              if (kept == -1) slope_hi *= 0.5;
              kept = -1;
            } else {
              hi = mid;
              slope_hi = slope_mid;
              if (kept == 1) slope_lo *= 0.5;
              kept = 1;
            }
          }
          theta = 0.5 * (lo + hi);
        } else {
          lo = sample_theta(std::max<Eigen::Index>(best - 1, 0));
          hi = sample_theta(std::min<Eigen::Index>(best + 1, kMinimumSamples));
          double a = hi - ratio * (hi - lo), b = lo + ratio * (hi - lo);
          double fa = v_at(a).first, fb = v_at(b).first;
          while (hi - lo > kMinimumBracket) {
            if (fa <= fb) {
              hi = b;
              b = a;
              fb = fa;
              a = hi - ratio * (hi - lo);
              fa = v_at(a).first;
            } else {
              lo = a;
              a = b;
              fa = fb;
              b = lo + ratio * (hi - lo);
              fb = v_at(b).first;
            }
          }
          if (std::min(fa, fb) < samples[best]) theta = fa <= fb ? a : b;
        }
      }
      const std::size_t piece = Piece(k, e, m);
      minimum_theta_[piece] = theta;
      EvaluatePoint(PolynomialState(k, e, tableau_.InterpolationWeights(theta)), start + theta * h,
                    u, nullptr, derivatives, &minimum_points_[piece]);
    }
  }

  void EvaluatePoints(const Vector& z, bool derivatives) {
    // Evaluate and Hessian are called at the same point (IPOPT): evaluate once.
    if (points_valid_ && (points_derivatives_ || !derivatives) && z.size() == points_z_.size() &&
        z == points_z_) {
      return;
    }
    points_valid_ = false;
    points_.resize(static_cast<std::size_t>(intervals_ * elements_ * stages_));
    check_points_.resize(static_cast<std::size_t>(intervals_ * elements_ * NumCheckPoints()));
    minimum_points_.resize(static_cast<std::size_t>(intervals_ * elements_ * nc_));
    minimum_theta_.assign(static_cast<std::size_t>(intervals_ * elements_ * nc_), 0.0);
    const Vector u0 = Inputs(z, 0);
    EvaluatePoint(InitialState(z), tau_[0], u0, nullptr, derivatives, &initial_point_);
    interval_start_points_.resize(static_cast<std::size_t>(intervals_));
    for (int k = 0; k < intervals_; ++k) {
      const Vector u = Inputs(z, k);
      if (k > 0) {
        EvaluatePoint(z.segment(StateOffset(k - 1, elements_ - 1, stages_ - 1), n_),
                      tau_[static_cast<std::size_t>(k)], u, nullptr, derivatives,
                      &interval_start_points_[static_cast<std::size_t>(k)]);
      }
      for (int e = 0; e < elements_; ++e) {
        const double start = StartTime(z, k, e);
        const double h = z[LengthIndex(k, e)];
        for (int i = 0; i < stages_; ++i) {
          const Vector x = z.segment(StateOffset(k, e, i), n_);
          const Vector lambda = z.segment(LambdaOffset(k, e, i), nc_);
          EvaluatePoint(x, start + tableau_.c[i] * h, u, &lambda, derivatives, &Stage(k, e, i));
        }
        // Check points on the collocation polynomial.
        const Vector& x_start = Start(k, e).x;
        for (int q = 0; q < NumCheckPoints(); ++q) {
          Vector x = x_start;
          for (int j = 0; j < stages_; ++j) {
            x += check_weights_[static_cast<std::size_t>(q)][j] * (Stage(k, e, j).x - x_start);
          }
          EvaluatePoint(x, start + check_theta_[static_cast<std::size_t>(q)] * h, u, nullptr,
                        derivatives, &Check(k, e, q));
        }
        if (minima_imposed_) LocateMinima(k, e, start, h, u, derivatives);
      }
    }
    points_z_ = z;
    points_derivatives_ = derivatives;
    points_valid_ = true;
  }

  // A problem function at node k with the decisions of interval kd (columns NodeColumns).
  void NodeFunction(const SmoothFunction& f, const Vector& z, int k, int kd, Vector* value,
                    Matrix* local) const {
    const Vector x = k == 0 ? InitialState(z)
                            : Vector(z.segment(StateOffset(k - 1, elements_ - 1, stages_ - 1), n_));
    const Vector u = Inputs(z, kd);
    const double t = tau_[static_cast<std::size_t>(k)];
    if (local == nullptr) {
      f.Evaluate(x, u, t, parameters_, value);
      return;
    }
    Matrix jacobian;
    f.Jacobian(x, u, t, parameters_, Wrt::XUT(), value, &jacobian);
    const int node = k == 0 ? nf_ : n_;
    local->setZero(f.num_outputs(), node + nd_);
    if (k == 0) {
      for (int i = 0; i < nf_; ++i) {
        local->col(i) =
            jacobian.col(problem_.free_initial_states[static_cast<std::size_t>(i)].state);
      }
    } else {
      local->leftCols(n_) = jacobian.leftCols(n_);
    }
    for (int j = 0; j < nd_; ++j) local->col(node + j) = jacobian.col(n_ + augmented_.decisions[j]);
  }

  double EquilibrationPenalty(const Vector& z, Vector* gradient) const {
    if (exact_ || options_.step_equilibration_weight == 0.0) return 0.0;
    const double nominal = interval_length_ / elements_;
    double penalty = 0.0;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        const double d = (z[LengthIndex(k, e)] - nominal) / nominal;
        penalty += options_.step_equilibration_weight * d * d / intervals_;
        if (gradient != nullptr) {
          (*gradient)[LengthIndex(k, e)] +=
              2.0 * options_.step_equilibration_weight * d / nominal / intervals_;
        }
      }
    }
    return penalty;
  }

  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Vector* jacobian_values, std::string* message) {
    const bool derivatives = gradient != nullptr || jacobian_values != nullptr;
    EvaluatePoints(z, derivatives);
    Vector g = Vector::Zero(constraint_lower_.size());
    Vector values;
    if (derivatives) values.setZero(static_cast<Eigen::Index>(Structure().size()));
    const Matrix& a = tableau_.a;
    const Vector& cc = tableau_.c;
    for (int k = 0; k < intervals_; ++k) {
      double length_sum = 0.0;
      for (int e = 0; e < elements_; ++e) {
        const int index = k * elements_ + e;
        const double h = z[LengthIndex(k, e)];
        length_sum += h;
        const Point& start = Start(k, e);
        // (9a, 9b) Radau IIA collocation: R_i = X_i - X_0 - h sum_j a_ij V_j.
        for (int i = 0; i < stages_; ++i) {
          Vector r = Stage(k, e, i).x - start.x;
          for (int j = 0; j < stages_; ++j) r -= h * a(i, j) * Stage(k, e, j).v;
          g.segment(CollocationRow(k, e) + i * n_, n_) = r;
        }
        // Stage feasibility c(X_i, t_i) >= 0 and (9c-9f) cross complementarity.
        for (int i = 0; i < stages_; ++i) {
          g.segment(FeasibilityRow(k, e) + i * nc_, nc_) = Stage(k, e, i).c;
        }
        Vector c_sum = start.c;
        Vector lambda_sum = Vector::Zero(nc_);
        for (int i = 0; i < stages_; ++i) {
          c_sum += Stage(k, e, i).c;
          lambda_sum += z.segment(LambdaOffset(k, e, i), nc_);
        }
        if (e > 0) lambda_sum += z.segment(LambdaOffset(k, e - 1, stages_ - 1), nc_);
        g.segment(ComplementarityRow(k, e), nc_) = c_sum.cwiseProduct(lambda_sum);
        for (int q = 0; q < NumCheckPoints(); ++q) {
          g.segment(CheckRow(k, e) + q * nc_, nc_) = Check(k, e, q).c;
        }
        // Element minima of the inactive constraints (the other rows are free and stay 0).
        for (int m = 0; minima_imposed_ && m < nc_; ++m) {
          if (!HasMinimumRow(k, e, m)) continue;
          g[MinimumRow(k, e) + m] = MinimumPoint(k, e, m).c[m] /
                                    MinimumWeight(k, e, m).Value(minimum_theta_[Piece(k, e, m)]);
        }
        if (e > 0) g[EquilibrationRow(k, e)] = h - z[LengthIndex(k, e - 1)];
        if (!derivatives) continue;
        // Collocation block.
        {
          const ElementColumns& layout = collocation_columns_[static_cast<std::size_t>(index)];
          auto block = BlockValues(collocation_block_[static_cast<std::size_t>(index)], &values);
          for (int i = 0; i < stages_; ++i) {
            auto rows = block.middleRows(i * n_, n_);
            // Start state.
            if (StartIsInitial(k, e)) {
              for (int f = 0; f < nf_; ++f) {
                rows(problem_.free_initial_states[static_cast<std::size_t>(f)].state, f) -= 1.0;
              }
            } else {
              rows.middleCols(layout.start, n_) -= Matrix::Identity(n_, n_);
            }
            Vector d_h = Vector::Zero(n_);        // d/dh_e
            Vector d_earlier = Vector::Zero(n_);  // d/dh_m, m < e (through the stage times)
            for (int j = 0; j < stages_; ++j) {
              const Point& p = Stage(k, e, j);
              const double w = h * a(i, j);
              d_h -= a(i, j) * p.v + w * cc[j] * p.v_t;
              d_earlier -= w * p.v_t;
              const int column = layout.stages + j * StageSize();
              rows.middleCols(column, n_) -= w * p.v_x;
              if (i == j) rows.middleCols(column, n_) += Matrix::Identity(n_, n_);
              rows.middleCols(column + n_, nc_) -= w * p.v_lambda;
              rows.middleCols(layout.decisions, nd_) -= w * p.v_u;
            }
            for (int m = 0; m < e; ++m) rows.col(layout.lengths + m) = d_earlier;
            rows.col(layout.lengths + e) = d_h;
          }
        }
        // Feasibility block: columns h_0..h_e, stage states.
        {
          const ElementColumns& layout = feasibility_columns_[static_cast<std::size_t>(index)];
          auto block = BlockValues(feasibility_block_[static_cast<std::size_t>(index)], &values);
          for (int i = 0; i < stages_; ++i) {
            const Point& p = Stage(k, e, i);
            auto rows = block.middleRows(i * nc_, nc_);
            rows.middleCols(layout.stages + i * n_, n_) = p.c_x;
            for (int m = 0; m < e; ++m) rows.col(layout.lengths + m) = p.c_t;
            rows.col(layout.lengths + e) = cc[i] * p.c_t;
          }
        }
        // Complementarity block: d (c_sum .* lambda_sum).
        {
          const ElementColumns& layout = complementarity_columns_[static_cast<std::size_t>(index)];
          auto block =
              BlockValues(complementarity_block_[static_cast<std::size_t>(index)], &values);
          // The start point: state columns and time (earlier lengths).
          const Matrix start_x = lambda_sum.asDiagonal() * start.c_x;
          if (StartIsInitial(k, e)) {
            for (int f = 0; f < nf_; ++f) {
              block.col(f) +=
                  start_x.col(problem_.free_initial_states[static_cast<std::size_t>(f)].state);
            }
          } else {
            block.middleCols(layout.start, n_) += start_x;
          }
          const Vector start_t = lambda_sum.cwiseProduct(start.c_t);
          for (int m = 0; m < e; ++m) block.col(layout.lengths + m) += start_t;
          if (e > 0) {
            block.middleCols(layout.previous, nc_) += Matrix(c_sum.asDiagonal());
          }
          for (int i = 0; i < stages_; ++i) {
            const Point& p = Stage(k, e, i);
            const int column = layout.stages + i * StageSize();
            block.middleCols(column, n_) += lambda_sum.asDiagonal() * p.c_x;
            block.middleCols(column + n_, nc_) += Matrix(c_sum.asDiagonal());
            const Vector d_t = lambda_sum.cwiseProduct(p.c_t);
            for (int m = 0; m < e; ++m) block.col(layout.lengths + m) += d_t;
            block.col(layout.lengths + e) += cc[i] * d_t;
          }
        }
        // Check points: X(theta) = (1 - sum w) X_0 + sum_j w_j X_j at t_start + theta h_e.
        if (NumCheckPoints() > 0) {
          const ElementColumns& layout = check_columns_[static_cast<std::size_t>(index)];
          auto block = BlockValues(check_block_[static_cast<std::size_t>(index)], &values);
          for (int q = 0; q < NumCheckPoints(); ++q) {
            const Point& p = Check(k, e, q);
            const Vector& w = check_weights_[static_cast<std::size_t>(q)];
            auto rows = block.middleRows(q * nc_, nc_);
            const double start_weight = 1.0 - w.sum();
            if (StartIsInitial(k, e)) {
              for (int f = 0; f < nf_; ++f) {
                rows.col(f) +=
                    start_weight *
                    p.c_x.col(problem_.free_initial_states[static_cast<std::size_t>(f)].state);
              }
            } else {
              rows.middleCols(layout.start, n_) += start_weight * p.c_x;
            }
            for (int j = 0; j < stages_; ++j)
              rows.middleCols(layout.stages + j * n_, n_) += w[j] * p.c_x;
            for (int m = 0; m < e; ++m) rows.col(layout.lengths + m) += p.c_t;
            rows.col(layout.lengths + e) += check_theta_[static_cast<std::size_t>(q)] * p.c_t;
          }
        }
        // Element minima: c_m(X(theta*), t_start + theta* h) at fixed theta* (envelope theorem:
        // dc_m/dtheta = 0 at an interior minimiser, and theta* = 0 or 1 is fixed at an end).
        if (minima_imposed_) {
          const ElementColumns& layout = check_columns_[static_cast<std::size_t>(index)];
          auto block = BlockValues(minimum_block_[static_cast<std::size_t>(index)], &values);
          for (int m = 0; m < nc_; ++m) {
            if (!HasMinimumRow(k, e, m)) continue;
            const Point& p = MinimumPoint(k, e, m);
            const double theta = minimum_theta_[Piece(k, e, m)];
            const Vector w = tableau_.InterpolationWeights(theta) /
                             MinimumWeight(k, e, m).Value(theta);  // over phi(theta*)
            auto row = block.row(m);
            const double start_weight = 1.0 / MinimumWeight(k, e, m).Value(theta) - w.sum();
            if (StartIsInitial(k, e)) {
              for (int f = 0; f < nf_; ++f) {
                row[f] += start_weight *
                          p.c_x(m, problem_.free_initial_states[static_cast<std::size_t>(f)].state);
              }
            } else {
              row.segment(layout.start, n_) += start_weight * p.c_x.row(m);
            }
            for (int j = 0; j < stages_; ++j) {
              row.segment(layout.stages + j * n_, n_) += w[j] * p.c_x.row(m);
            }
            const double c_t = p.c_t[m] / MinimumWeight(k, e, m).Value(theta);
            for (int l = 0; l < e; ++l) row[layout.lengths + l] += c_t;
            row[layout.lengths + e] += theta * c_t;
          }
        }
        if (e > 0) {
          auto block = BlockValues(
              equilibration_block_[static_cast<std::size_t>(k * (elements_ - 1) + e - 1)], &values);
          block(0, 0) = -1.0;
          block(0, 1) = 1.0;
        }
      }
      g[LengthRow(k)] = length_sum - interval_length_;
      if (derivatives) {
        BlockValues(length_block_[static_cast<std::size_t>(k)], &values).setConstant(1.0);
      }
    }
    // Objective: the cost state at T, the terminal cost, the step-equilibration penalty.
    Vector df = Vector::Zero(derivatives ? variable_lower_.size() : 0);
    const int last = intervals_ - 1;
    const std::vector<int> terminal_columns = NodeColumns(intervals_, last);
    Vector value;
    Matrix local;
    double f = 0.0;
    if (augmented_.cost_state >= 0) {
      f += z[StateOffset(last, elements_ - 1, stages_ - 1) + augmented_.cost_state];
      if (derivatives)
        df[StateOffset(last, elements_ - 1, stages_ - 1) + augmented_.cost_state] += 1.0;
    }
    if (!problem_.terminal_cost.empty()) {
      NodeFunction(problem_.terminal_cost, z, intervals_, last, &value,
                   derivatives ? &local : nullptr);
      f += value[0];
      if (derivatives) {
        for (std::size_t c = 0; c < terminal_columns.size(); ++c) {
          df[terminal_columns[c]] += local(0, static_cast<Eigen::Index>(c));
        }
      }
    }
    f += EquilibrationPenalty(z, derivatives ? &df : nullptr);
    const int num_terminal = num_terminal_equalities_ + num_terminal_inequalities_;
    Matrix terminal_local(num_terminal, static_cast<Eigen::Index>(terminal_columns.size()));
    if (num_terminal_equalities_ > 0) {
      NodeFunction(problem_.terminal_equalities, z, intervals_, last, &value,
                   derivatives ? &local : nullptr);
      g.segment(TerminalRow(), num_terminal_equalities_) = value;
      if (derivatives) terminal_local.topRows(num_terminal_equalities_) = local;
    }
    if (num_terminal_inequalities_ > 0) {
      NodeFunction(problem_.terminal_inequalities, z, intervals_, last, &value,
                   derivatives ? &local : nullptr);
      g.segment(TerminalRow() + num_terminal_equalities_, num_terminal_inequalities_) = value;
      if (derivatives) terminal_local.bottomRows(num_terminal_inequalities_) = local;
    }
    if (derivatives && terminal_block_ >= 0) BlockValues(terminal_block_, &values) = terminal_local;
    for (int k = 0; num_path_ > 0 && k <= intervals_; ++k) {
      NodeFunction(problem_.path_constraints, z, k, std::min(k, last), &value,
                   derivatives ? &local : nullptr);
      g.segment(PathRow(k), num_path_) = value;
      if (derivatives) BlockValues(path_block_[static_cast<std::size_t>(k)], &values) = local;
    }
    if (objective != nullptr) *objective = f;
    if (constraints != nullptr) *constraints = g;
    if (gradient != nullptr) *gradient = df;
    if (jacobian_values != nullptr) *jacobian_values = std::move(values);
    if (!std::isfinite(f) || !g.allFinite()) {
      if (message != nullptr) *message = "non-finite objective or constraints";
      return false;
    }
    return true;
  }

  double ComplementarityResidual(const Vector& z) {
    Vector g;
    Evaluate(z, nullptr, &g, nullptr, nullptr, nullptr);
    double worst = 0.0;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        worst = std::max(worst, g.segment(ComplementarityRow(k, e), nc_).cwiseAbs().maxCoeff());
      }
    }
    return worst;
  }

  std::vector<int> InteriorMinimumRows(const Vector& z, double margin) {
    EvaluatePoints(z, false);
    std::vector<int> rows;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        for (int m = 0; m < nc_; ++m) {
          if (!HasMinimumRow(k, e, m)) continue;
          const double theta = minimum_theta_[Piece(k, e, m)];
          const Weight phi = MinimumWeight(k, e, m);
          const double first = phi.start ? kPinnedMargin : 0.0;
          const double last = phi.end ? 1.0 - kPinnedMargin : 1.0;
          if (theta > first + margin && theta < last - margin) {
            rows.push_back(MinimumRow(k, e) + m);
          }
        }
      }
    }
    return rows;
  }

  // --- Hessian (OcpHessian::kSecondOrder) ----------------------------------------------------
  // Dense blocks over a set of columns, scattered into the union of their lower triangles.
  struct HessianBlock {
    std::vector<int> columns;
    std::vector<int>
        position;  // n * n entries (i, j) -> index in the values (-1 above the diagonal)
  };

  void BuildHessianStructure() {
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        hessian_columns_.push_back(MakeColumns(k, e, true, true, true, true));
        HessianBlock block;
        block.columns = hessian_columns_.back().columns;
        element_hessian_.push_back(std::move(block));
      }
    }
    for (int k = 0; k <= intervals_; ++k) {
      HessianBlock block;
      block.columns = NodeColumns(k, std::min(k, intervals_ - 1));
      node_hessian_.push_back(std::move(block));
    }
    ocp_internal::BuildHessianPattern({&element_hessian_, &node_hessian_}, &hessian_structure_);
  }

  static void Scatter(const HessianBlock& block, const Matrix& local, Vector* values) {
    const int n = static_cast<int>(block.columns.size());
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        const int position = block.position[static_cast<std::size_t>(i * n + j)];
        if (position >= 0) (*values)[position] += local(i, j);
      }
    }
  }

  // How the arguments y = (x, t, u_decisions, Lambda) of a function at a point map to the
  // element block's local columns: each coordinate is a list of (column, coefficient).
  using Map = std::vector<std::vector<std::pair<int, double>>>;
  // y = (x, t[, u, Lambda]) of stage i (i = -1: the element's start) of element (k, e).
  Map PointMap(int k, int e, int i, bool with_u_lambda) const {
    const ElementColumns& layout = hessian_columns_[static_cast<std::size_t>(k * elements_ + e)];
    Map map(static_cast<std::size_t>(n_ + 1 + (with_u_lambda ? nd_ + nc_ : 0)));
    if (i < 0) {
      if (StartIsInitial(k, e)) {
        for (int f = 0; f < nf_; ++f) {
          map[static_cast<std::size_t>(
                  problem_.free_initial_states[static_cast<std::size_t>(f)].state)]
              .emplace_back(layout.start + f, 1.0);
        }
      } else {
        for (int a = 0; a < n_; ++a)
          map[static_cast<std::size_t>(a)].emplace_back(layout.start + a, 1.0);
      }
      for (int m = 0; m < e; ++m)
        map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + m, 1.0);
      return map;
    }
    const int column = layout.stages + i * StageSize();
    for (int a = 0; a < n_; ++a) map[static_cast<std::size_t>(a)].emplace_back(column + a, 1.0);
    for (int m = 0; m < e; ++m)
      map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + m, 1.0);
    map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + e, tableau_.c[i]);
    if (with_u_lambda) {
      for (int j = 0; j < nd_; ++j) {
        map[static_cast<std::size_t>(n_ + 1 + j)].emplace_back(layout.decisions + j, 1.0);
      }
      for (int m = 0; m < nc_; ++m) {
        map[static_cast<std::size_t>(n_ + 1 + nd_ + m)].emplace_back(column + n_ + m, 1.0);
      }
    }
    return map;
  }

  // y = (X(theta), t(theta)) of the collocation polynomial of element (k, e) at theta in
  // [0, 1], with interpolation weights w of the stages: X = (1 - sum w) x_start + sum_j w_j
  // X_j, t = t_start + theta h_e (linear in the element's columns at fixed theta).
  Map InterpolatedPointMap(int k, int e, const Vector& w, double theta) const {
    const ElementColumns& layout = hessian_columns_[static_cast<std::size_t>(k * elements_ + e)];
    Map map(static_cast<std::size_t>(n_ + 1));
    const Map start_map = PointMap(k, e, -1, false);
    for (int c = 0; c < n_; ++c) {
      for (const auto& [column, coefficient] : start_map[static_cast<std::size_t>(c)]) {
        map[static_cast<std::size_t>(c)].emplace_back(column, coefficient * (1.0 - w.sum()));
      }
      for (int j = 0; j < stages_; ++j) {
        map[static_cast<std::size_t>(c)].emplace_back(layout.stages + j * StageSize() + c, w[j]);
      }
    }
    map[static_cast<std::size_t>(n_)] = start_map[static_cast<std::size_t>(n_)];
    map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + e, theta);
    return map;
  }

  // local += D^T M D (M symmetric over y) and gradient-outer terms are the caller's.
  static void AddMapped(const Map& map, const Matrix& m, Matrix* local) {
    const int size = static_cast<int>(map.size());
    for (int a = 0; a < size; ++a) {
      for (const auto& [ca, wa] : map[static_cast<std::size_t>(a)]) {
        for (int b = 0; b < size; ++b) {
          const double value = m(a, b);
          if (value == 0.0) continue;
          for (const auto& [cb, wb] : map[static_cast<std::size_t>(b)]) {
            (*local)(ca, cb) += wa * wb * value;
          }
        }
      }
    }
  }
  // D^T g for a gradient g over y.
  static Vector MappedGradient(const Map& map, const Vector& g, int columns) {
    Vector out = Vector::Zero(columns);
    for (std::size_t a = 0; a < map.size(); ++a) {
      for (const auto& [c, w] : map[a]) out[c] += w * g[static_cast<Eigen::Index>(a)];
    }
    return out;
  }

  // Hessian over (x, t) of the moving-set constraints weighted by `weights` (n_c).
  static Matrix ConstraintHessian(const Point& p, const Vector& weights) {
    Matrix total = Matrix::Zero(p.x.size() + 1, p.x.size() + 1);
    for (std::size_t m = 0; m < p.c_hessians.size(); ++m) {
      if (weights[static_cast<Eigen::Index>(m)] != 0.0) {
        total += weights[static_cast<Eigen::Index>(m)] * p.c_hessians[m];
      }
    }
    return total;
  }

  bool Hessian(const Vector& z, double objective_factor, const Vector& lambda, Vector* values) {
    EvaluatePoints(z, true);
    values->setZero(static_cast<Eigen::Index>(hessian_structure_.size()));
    const Matrix& a = tableau_.a;
    const int y_size = n_ + 1 + nd_ + nc_;
    Matrix hessian;
    for (int k = 0; k < intervals_; ++k) {
      const Vector u = Inputs(z, k);
      for (int e = 0; e < elements_; ++e) {
        const int index = k * elements_ + e;
        const ElementColumns& layout = hessian_columns_[static_cast<std::size_t>(index)];
        const int size = static_cast<int>(layout.columns.size());
        Matrix local = Matrix::Zero(size, size);
        const double h = z[LengthIndex(k, e)];
        // (a) Collocation: mu^T R = ... - h sum_j w_j^T V_j, w_j = sum_i a_ij mu_i.
        const Vector mu = lambda.segment(CollocationRow(k, e), stages_ * n_);
        Vector d_h = Vector::Zero(size);  // gradient of -sum_j w_j^T V_j (times h: the term)
        for (int j = 0; j < stages_; ++j) {
          Vector w = Vector::Zero(n_);
          for (int i = 0; i < stages_; ++i) w += a(i, j) * mu.segment(i * n_, n_);
          if (w.lpNorm<Eigen::Infinity>() == 0.0) continue;
          const Point& p = Stage(k, e, j);
          const Map map = PointMap(k, e, j, true);
          // First derivatives of phi = w^T V over y = (x, t, u, Lambda).
          Vector g(y_size);
          g.head(n_) = p.v_x.transpose() * w;
          g[n_] = p.v_t.dot(w);
          g.segment(n_ + 1, nd_) = p.v_u.transpose() * w;
          g.tail(nc_) = p.v_lambda.transpose() * w;
          d_h -= MappedGradient(map, g, size);
          // Second derivatives of phi: f part (x, u, t) and the Lambda-(x, t) cross terms of
          // Lambda^T (grad_x c P w); the (x, t) curvature of grad_x c (third derivatives of c)
          // is left out.
          Matrix q = Matrix::Zero(y_size, y_size);
          const SmoothFunction& f = augmented_.scene.dynamics;
          if (!f.empty()) {
            f.WeightedHessian(p.x, u, p.t, parameters_, Wrt::XUT(), w, &hessian);
            // hessian over (x, u_all, t): reorder to (x, t, u_decisions).
            std::vector<int> from(static_cast<std::size_t>(n_ + 1 + nd_));
            for (int i = 0; i < n_; ++i) from[static_cast<std::size_t>(i)] = i;
            from[static_cast<std::size_t>(n_)] = n_ + nu_;
            for (int jd = 0; jd < nd_; ++jd) {
              from[static_cast<std::size_t>(n_ + 1 + jd)] = n_ + augmented_.decisions[jd];
            }
            for (int r = 0; r < n_ + 1 + nd_; ++r) {
              for (int c = 0; c < n_ + 1 + nd_; ++c) {
                q(r, c) =
                    hessian(from[static_cast<std::size_t>(r)], from[static_cast<std::size_t>(c)]);
              }
            }
          }
          for (const Set& set : sets_) {
            const Vector v = set.identity ? w : Vector(set.projection * w);
            for (int m = 0; m < set.size; ++m) {
              // d/d(x, t) of grad_x c_m . v.
              const Vector cross =
                  p.c_hessians[static_cast<std::size_t>(set.offset + m)].leftCols(n_) * v;
              const int lambda_row = n_ + 1 + nd_ + set.offset + m;
              q.block(0, lambda_row, n_ + 1, 1) += cross;
              q.block(lambda_row, 0, 1, n_ + 1) += cross.transpose();
            }
          }
          AddMapped(map, -h * q, &local);
        }
        // The h_e cross terms of -h sum_j phi_j: -(e_h d^T + d e_h^T) with d = sum_j D^T g_j.
        {
          const int hc = layout.lengths + e;
          local.col(hc) += d_h;
          local.row(hc) += d_h.transpose();
        }
        // (b) Stage feasibility mu_c^T c(X_i, t_i) and (c) complementarity
        // nu_m (A_m B_m): nu_m B_m grad^2 A_m + nu_m (grad A_m grad B_m^T + transpose).
        const Vector nu = lambda.segment(ComplementarityRow(k, e), nc_);
        Vector b_sum = Vector::Zero(nc_);
        for (int i = 0; i < stages_; ++i) b_sum += z.segment(LambdaOffset(k, e, i), nc_);
        if (e > 0) b_sum += z.segment(LambdaOffset(k, e - 1, stages_ - 1), nc_);
        const Vector nu_b = nu.cwiseProduct(b_sum);
        Matrix grad_a = Matrix::Zero(size, nc_);  // columns: gradient of A_m over the block
        for (int i = -1; i < stages_; ++i) {
          const Point& p = i < 0 ? Start(k, e) : Stage(k, e, i);
          const Map map = PointMap(k, e, i, false);
          Vector weights = nu_b;
          if (i >= 0) weights += lambda.segment(FeasibilityRow(k, e) + i * nc_, nc_);
          AddMapped(map, ConstraintHessian(p, weights), &local);
          for (int m = 0; m < nc_; ++m) {
            Vector g(n_ + 1);
            g.head(n_) = p.c_x.row(m).transpose();
            g[n_] = p.c_t[m];
            grad_a.col(m) += MappedGradient(map, g, size);
          }
        }
        for (int m = 0; m < nc_; ++m) {
          if (nu[m] == 0.0) continue;
          Vector grad_b = Vector::Zero(size);
          for (int i = 0; i < stages_; ++i) grad_b[layout.stages + i * StageSize() + n_ + m] = 1.0;
          if (e > 0) grad_b[layout.previous + m] = 1.0;
          local +=
              nu[m] * (grad_a.col(m) * grad_b.transpose() + grad_b * grad_a.col(m).transpose());
        }
        // Check points: mu_q^T c(X(theta_q), t_q), X(theta) linear in the start and the stages.
        for (int q = 0; q < NumCheckPoints(); ++q) {
          const Vector weights = lambda.segment(CheckRow(k, e) + q * nc_, nc_);
          if (weights.lpNorm<Eigen::Infinity>() == 0.0) continue;
          const Map map = InterpolatedPointMap(k, e, check_weights_[static_cast<std::size_t>(q)],
                                               check_theta_[static_cast<std::size_t>(q)]);
          AddMapped(map, ConstraintHessian(Check(k, e, q), weights), &local);
        }
        // Element minima: mu_m r with r(z) = v(theta*(z), z), v = c_m(y) / phi(theta),
        // y = (X, t) linear in z at fixed theta. r'' = y_z^T c_yy y_z / phi + g g^T
        // d theta*/dz, g = d^2 v / dtheta dz, and d theta*/dz = -g / v'' from dv/dtheta = 0
        // (interior minima; at an end of the search interval theta* is fixed). Near a flat
        // minimum the second term is large (a curvature of -1.3e4 measured at the doorway's
        // plan): without it IPOPT's model of the row is poor.
        for (int m = 0; minima_imposed_ && m < nc_; ++m) {
          if (!HasMinimumRow(k, e, m)) continue;
          const double weight = lambda[MinimumRow(k, e) + m];
          if (weight == 0.0) continue;
          const double theta = minimum_theta_[Piece(k, e, m)];
          const Vector w = tableau_.InterpolationWeights(theta);
          const Map map = InterpolatedPointMap(k, e, w, theta);
          const Point& p = MinimumPoint(k, e, m);
          const Matrix& c_yy = p.c_hessians[static_cast<std::size_t>(m)];
          const Weight phi = MinimumWeight(k, e, m);
          const double phi_value = phi.Value(theta), phi_slope = phi.Slope(theta);
          AddMapped(map, (weight / phi_value) * c_yy, &local);
          const double first = phi.start ? kPinnedMargin : 0.0;
          const double last = phi.end ? 1.0 - kPinnedMargin : 1.0;
          if (theta <= first || theta >= last) continue;
          // y' = dy/dtheta = (sum_j w'_j Z_j, h) and y''; w'' by central differences of w'
          // (exact for s <= 3, where w' is quadratic; O(1e-8) relative otherwise).
          constexpr double kDelta = 1e-4;
          const Vector dw = tableau_.InterpolationDerivativeWeights(theta);
          const Vector ddw = (tableau_.InterpolationDerivativeWeights(theta + kDelta) -
                              tableau_.InterpolationDerivativeWeights(theta - kDelta)) /
                             (2.0 * kDelta);
          const Vector& x_start = Start(k, e).x;
          Vector dy = Vector::Zero(n_ + 1), ddy = Vector::Zero(n_ + 1);
          for (int j = 0; j < stages_; ++j) {
            dy.head(n_) += dw[j] * (Stage(k, e, j).x - x_start);
            ddy.head(n_) += ddw[j] * (Stage(k, e, j).x - x_start);
          }
          dy[n_] = h;
          Vector c_y(n_ + 1);
          c_y.head(n_) = p.c_x.row(m).transpose();
          c_y[n_] = p.c_t[m];
          // v'' from c, c' and c'' (phi is at most quadratic).
          const double c_value = p.c[m], dc = c_y.dot(dy), ddc = dy.dot(c_yy * dy) + c_y.dot(ddy);
          const double curvature =
              ddc / phi_value - 2.0 * dc * phi_slope / (phi_value * phi_value) -
              c_value * phi.Curvature() / (phi_value * phi_value) +
              2.0 * c_value * phi_slope * phi_slope / (phi_value * phi_value * phi_value);
          if (!(curvature > 0.0)) continue;  // not a strict minimum: no theta* derivative
          // d y' / dz: the start with -sum_j w'_j, stage j with w'_j, t' = h_e.
          const Map start_map = PointMap(k, e, -1, false);
          Map derivative_map(static_cast<std::size_t>(n_ + 1));
          for (int c = 0; c < n_; ++c) {
            for (const auto& [column, coefficient] : start_map[static_cast<std::size_t>(c)]) {
              derivative_map[static_cast<std::size_t>(c)].emplace_back(column,
                                                                       -coefficient * dw.sum());
            }
            for (int j = 0; j < stages_; ++j) {
              derivative_map[static_cast<std::size_t>(c)].emplace_back(
                  layout.stages + j * StageSize() + c, dw[j]);
            }
          }
          derivative_map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + e, 1.0);
          // d/dz of v' = c'/phi - c phi'/phi^2.
          const Vector g =
              (MappedGradient(map, c_yy * dy, size) + MappedGradient(derivative_map, c_y, size)) /
                  phi_value -
              MappedGradient(map, c_y, size) * (phi_slope / (phi_value * phi_value));
          local -= (weight / curvature) * g * g.transpose();
        }
        // (d) The step-equilibration penalty.
        if (!exact_ && options_.step_equilibration_weight > 0.0) {
          const double nominal = interval_length_ / elements_;
          local(layout.lengths + e, layout.lengths + e) += objective_factor * 2.0 *
                                                           options_.step_equilibration_weight /
                                                           (nominal * nominal) / intervals_;
        }
        Scatter(element_hessian_[static_cast<std::size_t>(index)], local, values);
      }
    }
    // (e) Terminal and path functions at the nodes.
    const int last = intervals_ - 1;
    for (int k = 0; k <= intervals_; ++k) {
      const int kd = std::min(k, last);
      const Vector x = k == 0
                           ? InitialState(z)
                           : Vector(z.segment(StateOffset(k - 1, elements_ - 1, stages_ - 1), n_));
      const Vector u = Inputs(z, kd);
      const double t = tau_[static_cast<std::size_t>(k)];
      Matrix total = Matrix::Zero(n_ + nu_, n_ + nu_);
      auto add = [&](const SmoothFunction& f, const Vector& weights) {
        if (f.empty() || weights.lpNorm<Eigen::Infinity>() == 0.0) return;
        Wrt wrt;
        wrt.x = true;
        wrt.u = true;
        f.WeightedHessian(x, u, t, parameters_, wrt, weights, &hessian);
        total += hessian;
      };
      if (k == intervals_) {
        add(problem_.terminal_cost, Vector::Constant(1, objective_factor));
        if (num_terminal_equalities_ > 0) {
          add(problem_.terminal_equalities,
              lambda.segment(TerminalRow(), num_terminal_equalities_));
        }
        if (num_terminal_inequalities_ > 0) {
          add(problem_.terminal_inequalities,
              lambda.segment(TerminalRow() + num_terminal_equalities_, num_terminal_inequalities_));
        }
      }
      if (num_path_ > 0) add(problem_.path_constraints, lambda.segment(PathRow(k), num_path_));
      const HessianBlock& block = node_hessian_[static_cast<std::size_t>(k)];
      const int node = k == 0 ? nf_ : n_;
      std::vector<int> position(static_cast<std::size_t>(n_ + nu_), -1);
      if (k == 0) {
        for (int f = 0; f < nf_; ++f) {
          position[static_cast<std::size_t>(
              problem_.free_initial_states[static_cast<std::size_t>(f)].state)] = f;
        }
      } else {
        for (int i = 0; i < n_; ++i) position[static_cast<std::size_t>(i)] = i;
      }
      for (int j = 0; j < nd_; ++j)
        position[static_cast<std::size_t>(n_ + augmented_.decisions[j])] = node + j;
      Matrix local = Matrix::Zero(static_cast<Eigen::Index>(block.columns.size()),
                                  static_cast<Eigen::Index>(block.columns.size()));
      for (int r = 0; r < n_ + nu_; ++r) {
        const int i = position[static_cast<std::size_t>(r)];
        if (i < 0) continue;
        for (int c = 0; c < n_ + nu_; ++c) {
          const int j = position[static_cast<std::size_t>(c)];
          if (j >= 0) local(i, j) += total(r, c);
        }
      }
      Scatter(block, local, values);
    }
    return values->allFinite();
  }

  // --- initial guess --------------------------------------------------------------------------
  Vector InitialGuess() {
    Vector z = Vector::Zero(variable_lower_.size());
    for (int i = 0; i < nf_; ++i) {
      const auto& free = problem_.free_initial_states[static_cast<std::size_t>(i)];
      z[i] = std::clamp(problem_.scene.initial_state[free.state], free.lower, free.upper);
    }
    const int nc = static_cast<int>(problem_.controls.size());
    Scene scene = augmented_.scene;
    scene.initial_state = InitialState(z);
    // The decisions as piecewise-constant signals on the grid.
    const std::vector<double> breakpoints(tau_.begin() + 1, tau_.end() - 1);
    for (int j = 0; j < nd_; ++j) {
      const int input_index = augmented_.decisions[j];
      const InputSpec& input = augmented_.scene.inputs[static_cast<std::size_t>(input_index)];
      PiecewiseConstantSignal& signal = scene.inputs[static_cast<std::size_t>(input_index)].signal;
      signal.breakpoints = breakpoints;
      signal.values.clear();
      for (int k = 0; k < intervals_; ++k) {
        const double guess = j < nc && problem_.initial_controls.size() > 0
                                 ? problem_.initial_controls(k, j)
                                 : input.signal.values.front();
        z[ControlOffset(k) + j] = std::clamp(guess, input.lower, input.upper);
        signal.values.push_back(z[ControlOffset(k) + j]);
      }
    }
    const double nominal = interval_length_ / elements_;
    std::vector<double> times;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        z[LengthIndex(k, e)] = nominal;
        for (int i = 0; i < stages_; ++i) {
          times.push_back(tau_[static_cast<std::size_t>(k)] + (e + tableau_.c[i]) * nominal);
        }
      }
    }
    times.back() = tau_.back();
    FesdOptions fesd;
    fesd.stages = stages_;
    fesd.finite_elements = elements_;
    fesd.step_size = interval_length_;
    fesd.output_times = times;
    FesdResult run;
    bool ok = false;
    try {
      run = SimulateFesd(scene, fesd);
      ok = run.status == FesdStatus::kSuccess;
    } catch (const std::invalid_argument&) {
      ok = false;
    }
    // The dense output holds t0, the requested times and tf (in order): match by time.
    std::vector<std::size_t> row(times.size(), 0);
    if (ok) {
      std::size_t next = 0;
      for (std::size_t r = 0; r < run.trajectory.size() && next < times.size(); ++r) {
        if (std::abs(run.trajectory.t[r] - times[next]) <= 1e-12 * (1.0 + std::abs(times[next]))) {
          row[next++] = r;
        }
      }
      ok = next == times.size();
    }
    std::size_t point = 0;
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        for (int i = 0; i < stages_; ++i, ++point) {
          if (!ok) {
            z.segment(StateOffset(k, e, i), n_) = scene.initial_state;
            continue;
          }
          z.segment(StateOffset(k, e, i), n_) = run.trajectory.x[row[point]].head(n_);
          const Vector& algebraic = run.trajectory.algebraic[row[point]];
          if (algebraic.size() == nc_) {
            z.segment(LambdaOffset(k, e, i), nc_) = algebraic.cwiseMax(0.0);
          }
        }
      }
    }
    return z;
  }

  // --- results --------------------------------------------------------------------------------
  void Describe(const Vector& z, OcpResult* result) {
    const int nc = static_cast<int>(problem_.controls.size());
    const int nx = problem_.scene.num_states();
    result->decision = z;
    result->controls.resize(intervals_, nc);
    result->speeds.resize(0);
    for (int k = 0; k < intervals_; ++k) {
      for (int j = 0; j < nc; ++j) result->controls(k, j) = z[ControlOffset(k) + j];
    }
    const Vector x0 = InitialState(z);
    result->initial_state = x0.head(nx);
    result->grid.assign(tau_.begin(), tau_.end());
    result->node_states.assign(1, x0.head(nx));
    result->trajectory = Trajectory();
    result->trajectory.state_names = problem_.scene.state_names;
    result->trajectory.Append(tau_[0], x0.head(nx), Vector(), 0.0);
    result->events.clear();
    EvaluatePoints(z, false);
    std::vector<bool> previous(static_cast<std::size_t>(nc_), false);
    for (int m = 0; m < nc_; ++m)
      previous[static_cast<std::size_t>(m)] = initial_point_.c[m] <= 0.0;
    const std::vector<bool> active = exact_ ? pieces_ : Pieces(z);
    for (int k = 0; k < intervals_; ++k) {
      for (int e = 0; e < elements_; ++e) {
        const double start = StartTime(z, k, e);
        for (int m = 0; m < nc_; ++m) {
          const bool now = active[Piece(k, e, m)];
          if (now != previous[static_cast<std::size_t>(m)]) {
            Event event;
            event.t = start;
            event.kind = now ? EventKind::kEnter : EventKind::kLeave;
            event.what = constraint_names_[static_cast<std::size_t>(m)];
            event.detail = now ? "constraint becomes active" : "constraint becomes inactive";
            result->events.push_back(event);
          }
          previous[static_cast<std::size_t>(m)] = now;
        }
        const Point& end = Stage(k, e, stages_ - 1);
        result->trajectory.Append(end.t, end.x.head(nx),
                                  z.segment(LambdaOffset(k, e, stages_ - 1), nc_),
                                  z[LengthIndex(k, e)]);
      }
      result->node_states.push_back(Stage(k, elements_ - 1, stages_ - 1).x.head(nx));
    }
    const Vector& y = Stage(intervals_ - 1, elements_ - 1, stages_ - 1).x;
    result->final_time = tau_.back();
    result->final_state = y.head(nx);
    result->running_cost = augmented_.cost_state >= 0 ? y[augmented_.cost_state] : 0.0;
    if (num_terminal_equalities_ > 0) {
      Vector value;
      problem_.terminal_equalities.Evaluate(y.head(nx), Inputs(z, intervals_ - 1), tau_.back(),
                                            parameters_, &value);
      result->terminal_equality_error = value.lpNorm<Eigen::Infinity>();
    }
  }

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

CollocationNlp::CollocationNlp(const OcpProblem& problem, const OcpOptions& options) {
  ValidateOcp(problem);
  options.Validate();
  impl_ = std::make_unique<Impl>(problem, options);
}
CollocationNlp::~CollocationNlp() = default;
int CollocationNlp::num_variables() const {
  return static_cast<int>(impl_->variable_lower_.size());
}
int CollocationNlp::num_constraints() const {
  return static_cast<int>(impl_->constraint_lower_.size());
}
const Vector& CollocationNlp::variable_lower() const { return impl_->variable_lower_; }
const Vector& CollocationNlp::variable_upper() const { return impl_->variable_upper_; }
const Vector& CollocationNlp::constraint_lower() const { return impl_->constraint_lower_; }
const Vector& CollocationNlp::constraint_upper() const { return impl_->constraint_upper_; }
bool CollocationNlp::Evaluate(const Vector& z, double* objective, Vector* constraints,
                              Vector* gradient, Vector* jacobian_values, std::string* message) {
  return impl_->Evaluate(z, objective, constraints, gradient, jacobian_values, message);
}
const std::vector<std::pair<int, int>>& CollocationNlp::JacobianStructure() const {
  return impl_->Structure();
}
const std::vector<std::pair<int, int>>& CollocationNlp::HessianStructure() const {
  return impl_->hessian_structure_;
}
bool CollocationNlp::Hessian(const Vector& z, double objective_factor, const Vector& lambda,
                             const Vector&, const Vector&, Vector* hessian_values) {
  return impl_->Hessian(z, objective_factor, lambda, hessian_values);
}
void CollocationNlp::SetRelaxedLevel(const OcpHomotopyLevel& level) {
  impl_->SetRelaxedLevel(level);
}
int CollocationNlp::SetExactLevel(const Vector& z) { return impl_->SetExactLevel(z); }
void CollocationNlp::ImposeElementMinima(const Vector& z, Vector* multipliers) {
  impl_->ImposeElementMinima(z, multipliers);
}
double CollocationNlp::ComplementarityResidual(const Vector& z) {
  return impl_->ComplementarityResidual(z);
}
std::vector<int> CollocationNlp::InteriorMinimumRows(const Vector& z, double margin) {
  return impl_->InteriorMinimumRows(z, margin);
}
void CollocationNlp::SetRefinedLevel(const CollocationNlp& coarse) {
  impl_->SetRefinedLevel(*coarse.impl_);
}
Vector CollocationNlp::Interpolate(const CollocationNlp& coarse, const Vector& z,
                                   const OcpMultipliers& multipliers,
                                   OcpMultipliers* fine_multipliers) const {
  return impl_->Interpolate(*coarse.impl_, z, multipliers, fine_multipliers);
}
Vector CollocationNlp::InitialGuess() { return impl_->InitialGuess(); }
void CollocationNlp::Describe(const Vector& z, OcpResult* result) { impl_->Describe(z, result); }

}  // namespace moreau::ocp_internal
