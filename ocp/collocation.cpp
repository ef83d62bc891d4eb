// The complementarity-constrained collocation transcription (collocation.hpp, docs/ocp.md,
// "Collocation transcription"): construction, the layout of variables and rows, bounds, the
// sparse Jacobian's structure, the relaxed and exact levels, the initial guess from a FESD
// simulation, results, and CollocationNlp's methods. The rest of CollocationNlp::Impl
// (collocation_impl.hpp) is in collocation_evaluation.cpp, element_minima.cpp,
// collocation_hessian.cpp and collocation_refinement.cpp.

#include <algorithm>
#include <cmath>
#include <variant>

#include "collocation_impl.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/fesd.hpp"

namespace moreau::ocp_internal {

namespace {
// Element lengths stay in [kMinElementFraction, kMaxElementFraction] times H / N_fe (FESD's
// elements may shrink to place a switch and grow to cover the rest of the interval).
constexpr double kMinElementFraction = 1e-3;
constexpr double kMaxElementFraction = 3.0;
}  // namespace

CollocationNlp::Impl::Impl(const OcpProblem& problem, const OcpOptions& options)
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

auto CollocationNlp::Impl::MakeColumns(int k, int e, bool with_start, bool with_previous,
                                       bool with_decisions, bool with_lambda) const
    -> ElementColumns {
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

void CollocationNlp::Impl::BuildLayout() {
  for (int k = 0; k < intervals_; ++k) {
    for (int e = 0; e < elements_; ++e) {
      collocation_columns_.push_back(MakeColumns(k, e, true, false, true, true));
      feasibility_columns_.push_back(MakeColumns(k, e, false, false, false, false));
      complementarity_columns_.push_back(MakeColumns(k, e, true, true, false, true));
      check_columns_.push_back(MakeColumns(k, e, true, false, false, false));
    }
  }
}

void CollocationNlp::Impl::BuildBounds() {
  const int nz = nf_ + intervals_ * IntervalSize();
  variable_lower_ = Vector::Constant(nz, -kInfinity);
  variable_upper_ = Vector::Constant(nz, kInfinity);
  BoundFreeInitialStates(problem_, &variable_lower_, &variable_upper_);
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

auto CollocationNlp::Impl::AddBlock(int row, int rows, const std::vector<int>& columns) -> int {
  if (rows == 0 || columns.empty()) return -1;
  Block block;
  block.row = row;
  block.rows = rows;
  block.columns = columns;
  block.offset = blocks_.empty()
                     ? 0
                     : blocks_.back().offset + static_cast<long>(blocks_.back().rows) *
                                                   static_cast<long>(blocks_.back().columns.size());
  blocks_.push_back(std::move(block));
  return static_cast<int>(blocks_.size()) - 1;
}

// A node function's columns: node k's state (the start of interval k's first element, the
// last stage at k = N; the free initial states at k = 0) and the decisions of interval kd.
auto CollocationNlp::Impl::NodeColumns(int k, int kd) const -> std::vector<int> {
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

void CollocationNlp::Impl::BuildJacobianStructure() {
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

// --- levels -------------------------------------------------------------------------------
void CollocationNlp::Impl::ApplyParameters(const OcpHomotopyLevel& level) {
  Scene values = augmented_.scene;
  for (const auto& [name, value] : level.parameters) {
    RequireArgument(values.FindParameter(name) >= 0, problem_.name, ": homotopy parameter '", name,
                    "' is not a scene parameter");
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

void CollocationNlp::Impl::SetRelaxedLevel(const OcpHomotopyLevel& level) {
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

// Per element and constraint: is the constraint active (c = 0, Lambda >= 0) on the piece?
// Decided from the relaxed solution by which side of the product is larger: c summed over
// the element's stages against Lambda summed over them, scaled by the constraint's
// gradient (so that both are rates of the same quantity: |grad c|^2 Lambda is the normal
// speed the multiplier produces).
auto CollocationNlp::Impl::Pieces(const Vector& z) -> std::vector<bool> {
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

auto CollocationNlp::Impl::SetExactPieces(const std::vector<bool>& active) -> int {
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
            constraint_upper_[FeasibilityRow(k - 1, elements_ - 1) + (stages_ - 1) * nc_ + m] = 0.0;
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

// --- initial guess --------------------------------------------------------------------------
auto CollocationNlp::Impl::InitialGuess() -> Vector {
  Vector z = Vector::Zero(variable_lower_.size());
  GuessFreeInitialStates(problem_, &z);
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
  fesd.estimate_error = false;  // a guess for the NLP, not a result
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
void CollocationNlp::Impl::Describe(const Vector& z, OcpResult* result) {
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
  for (int m = 0; m < nc_; ++m) previous[static_cast<std::size_t>(m)] = initial_point_.c[m] <= 0.0;
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
