// The shooting NLP (include/moreau/ocp/ocp.hpp, docs/ocp.md): variables, constraints, their
// exact first derivatives from the integrators' sensitivities as a sparse Jacobian, and the
// block-structured Hessian approximation.

#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"
#include "moreau/core/error.hpp"
#include "quasi_newton.hpp"

namespace moreau {

namespace {
constexpr double kInfinity = ocp_internal::kNoBound;
using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
}  // namespace

class ShootingNlp::Impl {
 public:
  Impl(const OcpProblem& problem, const OcpOptions& options)
      : problem_(problem), options_(options), augmented_(ocp_internal::Augment(problem)) {
    const Scene& scene = augmented_.scene;
    const LoweredSystem lowered(scene);
    intervals_ = problem.intervals;
    nx_ = augmented_.num_states;
    ny_ = lowered.num_states();
    nu_ = scene.num_inputs();
    np_ = scene.num_parameters();
    nd_ = static_cast<int>(augmented_.decisions.size());
    nf_ = static_cast<int>(problem.free_initial_states.size());
    clock_ = lowered.clock_index();
    multiple_ = options.transcription == OcpTranscription::kMultipleShooting;
    y0_ = lowered.InitialState();
    parameters_ = scene.ParameterValues();
    const double t0 = scene.initial_time, tf = scene.final_time;
    for (int k = 0; k <= intervals_; ++k) tau_.push_back(t0 + (tf - t0) * k / intervals_);
    tau_.back() = tf;
    for (int k = 0; k < intervals_; ++k) {
      Scene interval = scene;
      interval.initial_time = tau_[static_cast<std::size_t>(k)];
      interval.final_time = tau_[static_cast<std::size_t>(k) + 1];
      interval_scenes_.push_back(std::move(interval));
    }
    num_terminal_equalities_ = problem.terminal_equalities.num_outputs();
    num_terminal_inequalities_ = problem.terminal_inequalities.num_outputs();
    num_path_ = problem.path_constraints.num_outputs();
    BuildBounds();
    BuildJacobianStructure();
    if (options.hessian != OcpHessian::kLimitedMemory) BuildHessianStructure();
  }

  int num_variables() const { return static_cast<int>(variable_lower_.size()); }
  int num_constraints() const { return static_cast<int>(constraint_lower_.size()); }

  // --- layout ---------------------------------------------------------------------------
  int DecisionOffset(int k) const { return nf_ + k * nd_; }
  int NodeOffset(int k) const { return nf_ + intervals_ * nd_ + (k - 1) * ny_; }  // k >= 1
  int ContinuityRow(int k) const { return k * ny_; }
  int TerminalEqualityRow() const { return multiple_ ? intervals_ * ny_ : 0; }
  int TerminalInequalityRow() const { return TerminalEqualityRow() + num_terminal_equalities_; }
  int PathRow(int k) const {
    return TerminalInequalityRow() + num_terminal_inequalities_ + k * num_path_;
  }
  int Last() const { return intervals_ - 1; }

  void BuildBounds() {
    const int nz = nf_ + intervals_ * nd_ + (multiple_ ? intervals_ * ny_ : 0);
    variable_lower_ = Vector::Constant(nz, -kInfinity);
    variable_upper_ = Vector::Constant(nz, kInfinity);
    ocp_internal::BoundFreeInitialStates(problem_, &variable_lower_, &variable_upper_);
    for (int k = 0; k < intervals_; ++k) {
      for (int j = 0; j < nd_; ++j) {
        const InputSpec& input =
            augmented_.scene.inputs[static_cast<std::size_t>(augmented_.decisions[j])];
        variable_lower_[DecisionOffset(k) + j] = std::max(input.lower, -kInfinity);
        variable_upper_[DecisionOffset(k) + j] = std::min(input.upper, kInfinity);
      }
    }
    const int m = PathRow(intervals_ + 1);
    constraint_lower_ = Vector::Zero(m);
    constraint_upper_ = Vector::Zero(m);
    for (int r = TerminalInequalityRow(); r < m; ++r) constraint_lower_[r] = -kInfinity;
  }

  void SetLevel(const OcpHomotopyLevel& level) {
    RequireArgument(std::isfinite(level.smoothing) && level.smoothing >= 0.0 &&
                        std::isfinite(level.relaxation) && level.relaxation >= 0.0,
                    problem_.name, ": homotopy smoothing and relaxation must be >= 0, got ",
                    level.smoothing, " and ", level.relaxation);
    if (level.smoothing > 0.0) {
      RequireArgument(!problem_.speed.enabled, problem_.name,
                      ": homotopy smoothing integrates with the time-stepping scheme, which "
                      "does not support a free final time (speed of time)");
      for (const Effect& effect : problem_.scene.effects) {
        RequireArgument(std::holds_alternative<MovingSet>(effect) ||
                            std::holds_alternative<SwitchingSurfaces>(effect),
                        problem_.name,
                        ": homotopy smoothing integrates with the time-stepping scheme, which "
                        "does not support the ",
                        EffectKind(effect), " '", EffectName(effect), "'");
      }
    }
    // Parameter values of the level (the problem's for the others and on the exact level).
    Scene values = augmented_.scene;
    for (const auto& [name, value] : level.parameters) {
      RequireArgument(values.FindParameter(name) >= 0, problem_.name, ": homotopy parameter '",
                      name, "' is not a scene parameter");
      SetSceneValue(&values, name, value);
    }
    parameters_ = values.ParameterValues();
    for (Scene& interval : interval_scenes_) interval.parameters = values.parameters;
    level_ = level;
    for (int r = 0; r < num_terminal_equalities_; ++r) {
      constraint_lower_[TerminalEqualityRow() + r] = -level.relaxation;
      constraint_upper_[TerminalEqualityRow() + r] = level.relaxation;
    }
    // The quasi-Newton pairs must come from one function: no update across levels (the
    // matrices are kept as the next level's starting approximation).
    has_previous_ = false;
  }

  // --- which variables a function at a node depends on ----------------------------------
  // A problem function at node k with the decisions of interval kd: in multiple shooting the
  // node (k = 0: the free initial states) and the decisions; in single shooting every variable
  // up to the decisions of interval kd (node k depends on all earlier decisions).
  std::vector<int> NodeColumns(int k, int kd) const {
    std::vector<int> columns;
    if (multiple_) {
      if (k == 0) {
        for (int i = 0; i < nf_; ++i) columns.push_back(i);
      } else {
        for (int i = 0; i < ny_; ++i) columns.push_back(NodeOffset(k) + i);
      }
      for (int j = 0; j < nd_; ++j) columns.push_back(DecisionOffset(kd) + j);
    } else {
      for (int i = 0; i < DecisionOffset(kd) + nd_; ++i) columns.push_back(i);
    }
    return columns;
  }

  // Multiple shooting: the position in NodeColumns(k, kd) of every argument (x, u, t) of a
  // problem function, -1 for arguments that are constants (fixed initial states, the initial
  // clock, inputs that are not decisions).
  std::vector<int> ArgumentColumns(int k) const {
    std::vector<int> position(static_cast<std::size_t>(nx_ + nu_ + 1), -1);
    int node_size = 0;
    if (k == 0) {
      for (int i = 0; i < nf_; ++i) {
        position[static_cast<std::size_t>(
            problem_.free_initial_states[static_cast<std::size_t>(i)].state)] = i;
      }
      node_size = nf_;
    } else {
      for (int i = 0; i < nx_; ++i) position[static_cast<std::size_t>(i)] = i;
      position[static_cast<std::size_t>(nx_ + nu_)] = clock_;
      node_size = ny_;
    }
    for (int j = 0; j < nd_; ++j) {
      position[static_cast<std::size_t>(nx_ + augmented_.decisions[j])] = node_size + j;
    }
    return position;
  }

  // --- sparse Jacobian --------------------------------------------------------------------
  // A block of rows [row, row + rows): dense over `columns` (values row-major), or -I on them.
  struct JacobianBlock {
    int row = 0, rows = 0;
    std::vector<int> columns;
    bool negative_identity = false;
    long offset = 0;
    long size() const {
      return negative_identity ? rows : static_cast<long>(rows) * static_cast<long>(columns.size());
    }
  };

  int AddBlock(int row, int rows, std::vector<int> columns, bool negative_identity = false) {
    if (rows == 0 || columns.empty()) return -1;
    JacobianBlock block;
    block.row = row;
    block.rows = rows;
    block.columns = std::move(columns);
    block.negative_identity = negative_identity;
    block.offset = blocks_.empty() ? 0 : blocks_.back().offset + blocks_.back().size();
    blocks_.push_back(std::move(block));
    return static_cast<int>(blocks_.size()) - 1;
  }

  // Multiple shooting: per interval the continuity rows' block over (node k or the free
  // initial states, decisions k) and -I on node k + 1; then the terminal rows and the path
  // rows of every node over NodeColumns. Single shooting: the terminal and path rows over
  // every variable they depend on (lower block-triangular: this transcription's Jacobian is
  // dense in the decisions).
  void BuildJacobianStructure() {
    const int last = Last();
    if (multiple_) {
      for (int k = 0; k < intervals_; ++k) {
        continuity_block_.push_back(AddBlock(ContinuityRow(k), ny_, NodeColumns(k, k)));
        std::vector<int> next(static_cast<std::size_t>(ny_));
        for (int i = 0; i < ny_; ++i) next[static_cast<std::size_t>(i)] = NodeOffset(k + 1) + i;
        AddBlock(ContinuityRow(k), ny_, next, true);
      }
    }
    terminal_block_ =
        AddBlock(TerminalEqualityRow(), num_terminal_equalities_ + num_terminal_inequalities_,
                 NodeColumns(intervals_, last));
    for (int k = 0; k <= intervals_; ++k) {
      path_block_.push_back(AddBlock(PathRow(k), num_path_, NodeColumns(k, std::min(k, last))));
    }
    structure_.clear();
    for (const JacobianBlock& block : blocks_) {
      for (int r = 0; r < block.rows; ++r) {
        if (block.negative_identity) {
          structure_.emplace_back(block.row + r, block.columns[static_cast<std::size_t>(r)]);
          continue;
        }
        for (int c : block.columns) structure_.emplace_back(block.row + r, c);
      }
    }
  }

  SparseMatrix JacobianMatrix(const Vector& values) const {
    RequireArgument(values.size() == static_cast<Eigen::Index>(structure_.size()),
                    "shooting NLP: expected ", structure_.size(), " Jacobian values, got ",
                    values.size());
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(structure_.size());
    for (std::size_t i = 0; i < structure_.size(); ++i) {
      triplets.emplace_back(structure_[i].first, structure_[i].second,
                            values[static_cast<Eigen::Index>(i)]);
    }
    SparseMatrix jacobian(num_constraints(), num_variables());
    jacobian.setFromTriplets(triplets.begin(), triplets.end());
    return jacobian;
  }

  // Row-major view of a dense block's values.
  Eigen::Map<RowMajorMatrix> BlockValues(int index, Vector* values) const {
    const JacobianBlock& block = blocks_[static_cast<std::size_t>(index)];
    return Eigen::Map<RowMajorMatrix>(values->data() + block.offset, block.rows,
                                      static_cast<Eigen::Index>(block.columns.size()));
  }
  Eigen::Map<const RowMajorMatrix> BlockValues(int index, const Vector& values) const {
    const JacobianBlock& block = blocks_[static_cast<std::size_t>(index)];
    return Eigen::Map<const RowMajorMatrix>(values.data() + block.offset, block.rows,
                                            static_cast<Eigen::Index>(block.columns.size()));
  }

  // --- one interval -----------------------------------------------------------------------
  struct Interval {
    bool ok = false;
    std::string message;
    Vector y_end;
    Matrix d_start;      // ny x ny: d y_end / d y_start
    Matrix d_decisions;  // ny x nd
    // The interval's run, kept when recording (the time-stepping discretization fills its
    // trajectory and events in the same type).
    FesdResult recorded;
  };

  // Integrates interval k: with the time-stepping scheme and smoothed complementarity on a
  // smoothed homotopy level (unless `exact`), else with the transcription's integrator.
  Interval Simulate(int k, const Vector& y_start, const ConstVectorRef& decisions, bool derivatives,
                    bool record, bool exact = false) {
    Scene& scene = interval_scenes_[static_cast<std::size_t>(k)];
    for (int j = 0; j < nd_; ++j) {
      scene.inputs[static_cast<std::size_t>(augmented_.decisions[j])].signal.values[0] =
          decisions[j];
    }
    const double smoothing = exact ? 0.0 : level_.smoothing;
    if (smoothing > 0.0 || options_.integrator == OcpIntegrator::kTimeStepping) {
      return SimulateTimeSteppingInterval(k, scene, y_start, derivatives, record, smoothing);
    }
    FesdOptions fesd;
    fesd.stages = options_.stages;
    fesd.finite_elements = options_.finite_elements;
    fesd.step_size = scene.final_time - scene.initial_time;
    // One fixed step per interval, integrated many times: the NLP's own discretization,
    // whose accuracy the verification re-simulation checks (no error estimate per step).
    fesd.estimate_error = false;
    fesd.sensitivities = derivatives;
    fesd.initial_state = y_start;
    fesd.record_trajectory = record;
    // Node states on active constraint boundaries: keep the map continuous (fesd.hpp).
    fesd.keep_elements_after_early_switch = true;
    Interval out;
    try {
      out.recorded = SimulateFesd(scene, fesd);
    } catch (const std::invalid_argument& error) {
      out.message = error.what();
      return out;
    }
    ++simulations_;
    elements_ += out.recorded.stats.num_elements;
    if (out.recorded.status != FesdStatus::kSuccess) {
      std::ostringstream s;
      s << "interval " << k << ": " << out.recorded.message;
      out.message = s.str();
      return out;
    }
    out.ok = true;
    out.y_end = out.recorded.final_lowered_state;
    if (derivatives) {
      ExtractDerivatives(out.recorded.sensitivities.lowered,
                         static_cast<int>(out.recorded.sensitivities.segment_starts.size()), &out);
    }
    if (!record) out.recorded = FesdResult();
    return out;
  }

  // d y_end / d y_start and d y_end / d decisions from a lowered sensitivity matrix (columns
  // y0, p, u per segment; a decision input acts on every segment of the interval).
  void ExtractDerivatives(const Matrix& lowered, int segments, Interval* out) const {
    out->d_start = lowered.leftCols(ny_);
    out->d_decisions.setZero(ny_, nd_);
    for (int j = 0; j < nd_; ++j) {
      const int input = augmented_.decisions[j];
      for (int s = 0; s < segments; ++s) {
        out->d_decisions.col(j) += lowered.col(ny_ + np_ + s * nu_ + input);
      }
    }
  }

  // The standard time-stepping discretization of interval k (N_fe fixed steps of Radau IIA
  // with stage complementarity, no switch detection): for comparisons with FESD, and with
  // smoothing > 0 (a b = smoothing^2 at every stage) for the smoothed homotopy levels.
  Interval SimulateTimeSteppingInterval(int k, const Scene& scene, const Vector& y_start,
                                        bool derivatives, bool record, double smoothing) {
    TimeSteppingOptions stepping;
    stepping.stages = options_.stages;
    stepping.step_size = (scene.final_time - scene.initial_time) / options_.finite_elements;
    stepping.sensitivities = derivatives;
    stepping.initial_state = y_start;
    stepping.record_trajectory = record;
    stepping.newton.smoothing = smoothing;
    Interval out;
    TimeSteppingResult result;
    try {
      result = SimulateTimeStepping(scene, stepping);
    } catch (const std::invalid_argument& error) {
      out.message = error.what();
      return out;
    }
    ++simulations_;
    elements_ += result.stats.num_steps;
    if (result.status != TimeSteppingStatus::kSuccess) {
      std::ostringstream s;
      s << "interval " << k << ": " << result.message;
      out.message = s.str();
      return out;
    }
    out.ok = true;
    out.y_end = result.final_lowered_state;
    if (derivatives) {
      ExtractDerivatives(result.sensitivities, static_cast<int>(result.segment_starts.size()),
                         &out);
    }
    if (record) {
      out.recorded.trajectory = std::move(result.trajectory);
      out.recorded.events = std::move(result.events);
      out.recorded.final_state = result.final_state;
      out.recorded.final_lowered_state = out.y_end;
    }
    return out;
  }

  // Lowered initial state for the free initial states in z.
  Vector InitialNode(const Vector& z) const {
    Vector y = y0_;
    for (int i = 0; i < nf_; ++i) {
      y[problem_.free_initial_states[static_cast<std::size_t>(i)].state] = z[i];
    }
    return y;
  }

  // All scene inputs on interval k (decisions from z).
  Vector Inputs(const Vector& z, int k) const {
    Vector u = augmented_.scene.InputValues(tau_[static_cast<std::size_t>(k)]);
    for (int j = 0; j < nd_; ++j) u[augmented_.decisions[j]] = z[DecisionOffset(k) + j];
    return u;
  }

  // A problem function at node k (state y, decisions of interval kd): its value and, with
  // `local` non-null, its derivative with respect to NodeColumns(k, kd). d_node: single
  // shooting's d y_k / d z (all columns).
  void NodeFunction(const SmoothFunction& f, const Vector& z, const Vector& y, int k, int kd,
                    const Matrix* d_node, Vector* value, Matrix* local) {
    const Vector x = y.head(nx_);
    const Vector u = Inputs(z, kd);
    const double t = y[clock_];
    if (local == nullptr) {
      f.Evaluate(x, u, t, parameters_, value);
      return;
    }
    Matrix jacobian;  // columns x (nx), u (nu), t
    f.Jacobian(x, u, t, parameters_, Wrt::XUT(), value, &jacobian);
    const int columns = static_cast<int>(NodeColumns(k, kd).size());
    local->setZero(f.num_outputs(), columns);
    if (multiple_) {
      const std::vector<int> position = ArgumentColumns(k);
      for (int a = 0; a < nx_ + nu_ + 1; ++a) {
        const int c = position[static_cast<std::size_t>(a)];
        if (c >= 0) local->col(c) += jacobian.col(a);
      }
      return;
    }
    *local += jacobian.leftCols(nx_) * d_node->topLeftCorner(nx_, columns);
    *local += jacobian.col(nx_ + nu_) * d_node->row(clock_).head(columns);
    for (int j = 0; j < nd_; ++j) {
      local->col(DecisionOffset(kd) + j) += jacobian.col(nx_ + augmented_.decisions[j]);
    }
  }

  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Vector* jacobian_values, std::string* message) {
    const bool derivatives = gradient != nullptr || jacobian_values != nullptr;
    const int nz = num_variables();
    const int last = Last();
    Vector g = Vector::Zero(num_constraints());
    Vector values;
    if (derivatives) {
      values.setZero(static_cast<Eigen::Index>(structure_.size()));
      // -I blocks.
      for (const JacobianBlock& block : blocks_) {
        if (block.negative_identity) values.segment(block.offset, block.rows).setConstant(-1.0);
      }
    }
    Eigen::RowVectorXd df = Eigen::RowVectorXd::Zero(derivatives ? nz : 0);
    Vector value;
    Matrix local;
    // Path constraints at node k (state y; d_node: single shooting's dy/dz).
    auto path = [&](int k, const Vector& y, const Matrix* d_node) {
      if (num_path_ == 0) return;
      NodeFunction(problem_.path_constraints, z, y, k, std::min(k, last), d_node, &value,
                   derivatives ? &local : nullptr);
      g.segment(PathRow(k), num_path_) = value;
      if (derivatives) BlockValues(path_block_[static_cast<std::size_t>(k)], &values) = local;
    };
    Vector y = InitialNode(z);
    Matrix d_node;  // single shooting: d y_k / d z
    if (!multiple_ && derivatives) {
      d_node.setZero(ny_, nz);
      for (int i = 0; i < nf_; ++i) {
        d_node(problem_.free_initial_states[static_cast<std::size_t>(i)].state, i) = 1.0;
      }
    }
    path(0, y, &d_node);
    for (int k = 0; k < intervals_; ++k) {
      const Interval interval =
          Simulate(k, y, z.segment(DecisionOffset(k), nd_), derivatives, false);
      if (!interval.ok) {
        if (message != nullptr) *message = interval.message;
        return false;
      }
      if (multiple_) {
        const Vector next = z.segment(NodeOffset(k + 1), ny_);
        // Continuity: Phi_k(y_k, decisions_k) - y_{k+1} = 0.
        g.segment(ContinuityRow(k), ny_) = interval.y_end - next;
        if (derivatives) {
          auto block = BlockValues(continuity_block_[static_cast<std::size_t>(k)], &values);
          if (k == 0) {
            for (int i = 0; i < nf_; ++i) {
              block.col(i) = interval.d_start.col(
                  problem_.free_initial_states[static_cast<std::size_t>(i)].state);
            }
            block.rightCols(nd_) = interval.d_decisions;
          } else {
            block.leftCols(ny_) = interval.d_start;
            block.rightCols(nd_) = interval.d_decisions;
          }
        }
        y = next;
      } else {
        y = interval.y_end;
        if (derivatives) {
          d_node = interval.d_start * d_node;
          d_node.middleCols(DecisionOffset(k), nd_) += interval.d_decisions;
        }
      }
      path(k + 1, y, &d_node);
    }
    // Objective: Phi(x_N, u_{N-1}, T) + q_N.
    const std::vector<int> terminal_columns = NodeColumns(intervals_, last);
    double f = 0.0;
    if (!problem_.terminal_cost.empty()) {
      NodeFunction(problem_.terminal_cost, z, y, intervals_, last, &d_node, &value,
                   derivatives ? &local : nullptr);
      f += value[0];
      if (derivatives) {
        for (std::size_t c = 0; c < terminal_columns.size(); ++c) {
          df[terminal_columns[c]] += local(0, static_cast<Eigen::Index>(c));
        }
      }
    }
    if (augmented_.cost_state >= 0) {
      f += y[augmented_.cost_state];
      if (derivatives) {
        if (multiple_) {
          df[NodeOffset(intervals_) + augmented_.cost_state] += 1.0;
        } else {
          df += d_node.row(augmented_.cost_state);
        }
      }
    }
    // Terminal constraints.
    const int num_terminal = num_terminal_equalities_ + num_terminal_inequalities_;
    Matrix terminal_local(num_terminal, static_cast<Eigen::Index>(terminal_columns.size()));
    if (num_terminal_equalities_ > 0) {
      NodeFunction(problem_.terminal_equalities, z, y, intervals_, last, &d_node, &value,
                   derivatives ? &local : nullptr);
      g.segment(TerminalEqualityRow(), num_terminal_equalities_) = value;
      if (derivatives) terminal_local.topRows(num_terminal_equalities_) = local;
    }
    if (num_terminal_inequalities_ > 0) {
      NodeFunction(problem_.terminal_inequalities, z, y, intervals_, last, &d_node, &value,
                   derivatives ? &local : nullptr);
      g.segment(TerminalInequalityRow(), num_terminal_inequalities_) = value;
      if (derivatives) terminal_local.bottomRows(num_terminal_inequalities_) = local;
    }
    if (derivatives && terminal_block_ >= 0) BlockValues(terminal_block_, &values) = terminal_local;
    if (objective != nullptr) *objective = f;
    if (constraints != nullptr) *constraints = g;
    if (gradient != nullptr) *gradient = df.transpose();
    if (jacobian_values != nullptr) *jacobian_values = std::move(values);
    if (!std::isfinite(f) || !g.allFinite()) {
      if (message != nullptr) *message = "non-finite objective or constraints";
      return false;
    }
    return true;
  }

  // --- Hessian approximation (docs/ocp.md, "Second-order information") ---------------------
  // A dense block of the Hessian over `columns`: a quasi-Newton block, or the exact Hessian
  // of the functions at a node. `position` maps every local entry (i, j) with
  // columns[i] >= columns[j] to its place in the lower-triangular values
  // (ocp_internal::BuildHessianPattern; -1 above the diagonal).
  struct HessianBlock {
    std::vector<int> columns;
    std::vector<int> position;  // size n * n, entry i * n + j
    int node = 0;               // exact blocks: the node and the interval of its decisions
    int decisions = 0;
    bool terminal = false;  // exact block of the terminal functions (else path constraints)
  };

  void BuildHessianStructure() {
    const int last = Last();
    const auto kind = options_.hessian == OcpHessian::kBlockSr1
                          ? ocp_internal::QuasiNewtonBlock::Kind::kSr1
                          : ocp_internal::QuasiNewtonBlock::Kind::kDampedBfgs;
    if (multiple_) {
      for (int k = 0; k < intervals_; ++k) {
        HessianBlock block;
        block.columns = NodeColumns(k, k);
        if (block.columns.empty()) continue;
        quasi_newton_.emplace_back(static_cast<int>(block.columns.size()), kind,
                                   options_.lbfgs_memory);
        quasi_newton_interval_.push_back(k);
        quasi_newton_blocks_.push_back(std::move(block));
      }
      const bool terminal = !problem_.terminal_cost.empty() || num_terminal_equalities_ > 0 ||
                            num_terminal_inequalities_ > 0;
      if (terminal) {
        HessianBlock block;
        block.columns = NodeColumns(intervals_, last);
        block.node = intervals_;
        block.decisions = last;
        block.terminal = true;
        exact_blocks_.push_back(std::move(block));
      }
      for (int k = 0; num_path_ > 0 && k <= intervals_; ++k) {
        HessianBlock block;
        block.columns = NodeColumns(k, std::min(k, last));
        block.node = k;
        block.decisions = std::min(k, last);
        exact_blocks_.push_back(std::move(block));
      }
    } else {
      // Single shooting: every function depends on (nearly) every variable; one block.
      HessianBlock block;
      for (int i = 0; i < num_variables(); ++i) block.columns.push_back(i);
      quasi_newton_.emplace_back(num_variables(), kind, options_.lbfgs_memory);
      quasi_newton_interval_.push_back(-1);
      quasi_newton_blocks_.push_back(std::move(block));
    }
    ocp_internal::BuildHessianPattern({&quasi_newton_blocks_, &exact_blocks_}, &hessian_structure_);
  }

  // Adds a symmetric local matrix over block.columns into the lower-triangular values.
  static void AddToHessian(const HessianBlock& block, const Matrix& local, Vector* values) {
    const int n = static_cast<int>(block.columns.size());
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        // Each unordered pair of variables once: the local pair whose global row is larger
        // (the diagonal once).
        const int a = block.columns[static_cast<std::size_t>(i)];
        const int b = block.columns[static_cast<std::size_t>(j)];
        if (a < b) continue;
        (*values)[block.position[static_cast<std::size_t>(i * n + j)]] += local(i, j);
      }
    }
  }

  // Gradient over the block's columns of its part of the Lagrangian: multiple shooting,
  // lambda_k^T Phi_k (the continuity rows' block); single shooting, the whole Lagrangian
  // objective_factor f + lambda^T c.
  Vector QuasiNewtonGradient(std::size_t b, const Vector& lambda, double objective_factor,
                             const Vector& gradient, const Vector& jacobian_values) const {
    const int k = quasi_newton_interval_[b];
    if (k >= 0) {
      const auto block =
          BlockValues(continuity_block_[static_cast<std::size_t>(k)], jacobian_values);
      return block.transpose() * lambda.segment(ContinuityRow(k), ny_);
    }
    Vector total = objective_factor * gradient;
    for (const JacobianBlock& block : blocks_) {
      for (int r = 0; r < block.rows; ++r) {
        const double weight = lambda[block.row + r];
        if (block.negative_identity) {
          total[block.columns[static_cast<std::size_t>(r)]] -= weight;
          continue;
        }
        const long row_offset = block.offset + static_cast<long>(r) * block.columns.size();
        for (std::size_t c = 0; c < block.columns.size(); ++c) {
          total[block.columns[c]] += weight * jacobian_values[row_offset + static_cast<long>(c)];
        }
      }
    }
    return total;
  }

  // Exact Hessian of the functions at an exact block's node, weighted by their multipliers
  // (the terminal cost by objective_factor), over the block's columns.
  Matrix ExactBlock(const HessianBlock& block, const Vector& z, double objective_factor,
                    const Vector& lambda) const {
    const Vector y = block.node == 0 ? InitialNode(z) : z.segment(NodeOffset(block.node), ny_);
    const Vector x = y.head(nx_);
    const Vector u = Inputs(z, block.decisions);
    const double t = y[clock_];
    const int arguments = nx_ + nu_ + 1;
    Matrix total = Matrix::Zero(arguments, arguments);
    Matrix hessian;
    auto add = [&](const SmoothFunction& f, const Vector& weights) {
      if (f.empty() || weights.lpNorm<Eigen::Infinity>() == 0.0) return;
      f.WeightedHessian(x, u, t, parameters_, Wrt::XUT(), weights, &hessian);
      total += hessian;
    };
    if (block.terminal) {
      add(problem_.terminal_cost, Vector::Constant(1, objective_factor));
      if (num_terminal_equalities_ > 0) {
        add(problem_.terminal_equalities,
            lambda.segment(TerminalEqualityRow(), num_terminal_equalities_));
      }
      if (num_terminal_inequalities_ > 0) {
        add(problem_.terminal_inequalities,
            lambda.segment(TerminalInequalityRow(), num_terminal_inequalities_));
      }
    } else {
      add(problem_.path_constraints, lambda.segment(PathRow(block.node), num_path_));
    }
    const std::vector<int> position = ArgumentColumns(block.node);
    const auto n = static_cast<Eigen::Index>(block.columns.size());
    Matrix local = Matrix::Zero(n, n);
    for (int a = 0; a < arguments; ++a) {
      const int i = position[static_cast<std::size_t>(a)];
      if (i < 0) continue;
      for (int b = 0; b < arguments; ++b) {
        const int j = position[static_cast<std::size_t>(b)];
        if (j >= 0) local(i, j) += total(a, b);
      }
    }
    return local;
  }

  bool HessianApproximation(const Vector& z, double objective_factor, const Vector& lambda,
                            const Vector& gradient, const Vector& jacobian_values,
                            Vector* hessian_values) {
    MOREAU_ASSERT(options_.hessian != OcpHessian::kLimitedMemory,
                  "no Hessian approximation with limited memory");
    if (has_previous_ && z != previous_z_) {
      // y = grad L_b(z, lambda) - grad L_b(z_previous, lambda): both at the new multipliers.
      for (std::size_t b = 0; b < quasi_newton_.size(); ++b) {
        const HessianBlock& block = quasi_newton_blocks_[b];
        Vector s(static_cast<Eigen::Index>(block.columns.size()));
        for (std::size_t i = 0; i < block.columns.size(); ++i) {
          s[static_cast<Eigen::Index>(i)] = z[block.columns[i]] - previous_z_[block.columns[i]];
        }
        const Vector change =
            QuasiNewtonGradient(b, lambda, objective_factor, gradient, jacobian_values) -
            QuasiNewtonGradient(b, lambda, objective_factor, previous_gradient_,
                                previous_jacobian_);
        quasi_newton_[b].Update(s, change);
      }
    }
    previous_z_ = z;
    previous_gradient_ = gradient;
    previous_jacobian_ = jacobian_values;
    has_previous_ = true;
    hessian_values->setZero(static_cast<Eigen::Index>(hessian_structure_.size()));
    for (std::size_t b = 0; b < quasi_newton_.size(); ++b) {
      AddToHessian(quasi_newton_blocks_[b], quasi_newton_[b].matrix(), hessian_values);
    }
    for (const HessianBlock& block : exact_blocks_) {
      AddToHessian(block, ExactBlock(block, z, objective_factor, lambda), hessian_values);
    }
    return hessian_values->allFinite();
  }

  void ResetHessian() {
    for (auto& block : quasi_newton_) block.Reset();
    has_previous_ = false;
  }

  Vector InitialGuess() {
    Vector z = Vector::Zero(num_variables());
    ocp_internal::GuessFreeInitialStates(problem_, &z);
    const int nc = static_cast<int>(problem_.controls.size());
    for (int k = 0; k < intervals_; ++k) {
      for (int j = 0; j < nd_; ++j) {
        const InputSpec& input =
            augmented_.scene.inputs[static_cast<std::size_t>(augmented_.decisions[j])];
        const double guess = j < nc && problem_.initial_controls.size() > 0
                                 ? problem_.initial_controls(k, j)
                                 : input.signal.values.front();
        z[DecisionOffset(k) + j] = std::clamp(guess, input.lower, input.upper);
      }
    }
    if (!multiple_) return z;
    // Node states from a forward simulation with the initial controls (where it succeeds).
    Vector y = InitialNode(z);
    for (int k = 0; k < intervals_; ++k) {
      const Interval interval = Simulate(k, y, z.segment(DecisionOffset(k), nd_), false, false);
      if (interval.ok) y = interval.y_end;
      z.segment(NodeOffset(k + 1), ny_) = y;
    }
    return z;
  }

  Vector PointFromDecisions(const Matrix& decisions, const Vector& free_initial) {
    RequireArgument(decisions.rows() == intervals_ && decisions.cols() == nd_,
                    "shooting NLP: expected ", intervals_, " x ", nd_, " decisions, got ",
                    decisions.rows(), " x ", decisions.cols());
    RequireArgument(free_initial.size() == nf_, "shooting NLP: expected ", nf_,
                    " free initial states, got ", free_initial.size());
    Vector z = Vector::Zero(num_variables());
    z.head(nf_) = free_initial;
    for (int k = 0; k < intervals_; ++k) {
      for (int j = 0; j < nd_; ++j) {
        z[DecisionOffset(k) + j] =
            std::clamp(decisions(k, j), variable_lower_[DecisionOffset(k) + j],
                       variable_upper_[DecisionOffset(k) + j]);
      }
    }
    if (!multiple_) return z;
    Vector y = InitialNode(z);
    for (int k = 0; k < intervals_; ++k) {
      const Interval interval = Simulate(k, y, z.segment(DecisionOffset(k), nd_), false, false);
      if (interval.ok) y = interval.y_end;
      z.segment(NodeOffset(k + 1), ny_) = y;
    }
    return z;
  }

  void Describe(const Vector& z, OcpResult* result) {
    const int nc = static_cast<int>(problem_.controls.size());
    result->decision = z;
    result->controls.resize(intervals_, nc);
    result->speeds.resize(augmented_.speed_input >= 0 ? intervals_ : 0);
    for (int k = 0; k < intervals_; ++k) {
      for (int j = 0; j < nc; ++j) result->controls(k, j) = z[DecisionOffset(k) + j];
      if (augmented_.speed_input >= 0) result->speeds[k] = z[DecisionOffset(k) + nc];
    }
    const Vector y0 = InitialNode(z);
    result->initial_state = y0.head(problem_.scene.num_states());
    result->grid.assign(1, y0[clock_]);
    result->node_states.assign(1, y0.head(problem_.scene.num_states()));
    result->trajectory = Trajectory();
    result->trajectory.state_names = problem_.scene.state_names;
    result->events.clear();
    result->relays.clear();
    Vector y = y0;
    for (int k = 0; k < intervals_; ++k) {
      // Multiple shooting integrates every interval from its node (what the NLP constrains).
      if (multiple_ && k > 0) y = z.segment(NodeOffset(k), ny_);
      const Interval interval =
          Simulate(k, y, z.segment(DecisionOffset(k), nd_), false, true, /*exact=*/true);
      if (!interval.ok) {
        result->message += " (re-integration at the solution failed: " + interval.message + ")";
        break;
      }
      const FesdResult& fesd = interval.recorded;
      const Trajectory& piece = fesd.trajectory;
      for (std::size_t i = (k == 0 ? 0 : 1); i < piece.size(); ++i) {
        result->trajectory.Append(piece.t[i], piece.x[i].head(problem_.scene.num_states()),
                                  Vector(), piece.step[i]);
      }
      // An interval that starts inside a jump continues the previous interval's jump: not a
      // new event, and not a new value of the memory.
      for (const Event& event : fesd.events) {
        const bool continued = k > 0 && event.kind == EventKind::kRelaySwitch &&
                               event.detail.rfind("starts inside a jump", 0) == 0;
        if (!continued) result->events.push_back(event);
      }
      if (result->relays.empty()) {
        result->relays = fesd.relays;
      } else {
        for (std::size_t r = 0; r < fesd.relays.size(); ++r) {
          auto& relay = result->relays[r];
          const RelaySignal& signal = fesd.relays[r];
          for (std::size_t j = 0; j < signal.jump_times.size(); ++j) {
            if (signal.values[j] == relay.FinalValue()) continue;
            relay.jump_times.push_back(signal.jump_times[j]);
            relay.values.push_back(signal.values[j]);
          }
        }
      }
      y = interval.y_end;
      result->grid.push_back(y[clock_]);
      result->node_states.push_back(y.head(problem_.scene.num_states()));
    }
    result->final_time = y[clock_];
    result->final_state = y.head(problem_.scene.num_states());
    result->running_cost = augmented_.cost_state >= 0 ? y[augmented_.cost_state] : 0.0;
    if (num_terminal_equalities_ > 0) {
      Vector value;
      problem_.terminal_equalities.Evaluate(y.head(nx_), Inputs(z, intervals_ - 1), y[clock_],
                                            parameters_, &value);
      result->terminal_equality_error = value.lpNorm<Eigen::Infinity>();
    }
  }

  OcpProblem problem_;
  OcpOptions options_;
  ocp_internal::AugmentedScene augmented_;
  int intervals_ = 0, nx_ = 0, ny_ = 0, nu_ = 0, np_ = 0, nd_ = 0, nf_ = 0, clock_ = 0;
  int num_terminal_equalities_ = 0, num_terminal_inequalities_ = 0, num_path_ = 0;
  bool multiple_ = true;
  OcpHomotopyLevel level_;
  Vector y0_, parameters_;
  std::vector<double> tau_;
  std::vector<Scene> interval_scenes_;
  Vector variable_lower_, variable_upper_, constraint_lower_, constraint_upper_;
  // Jacobian: blocks, their (row, column) pairs, and which block is which.
  std::vector<JacobianBlock> blocks_;
  std::vector<std::pair<int, int>> structure_;
  std::vector<int> continuity_block_;  // per interval (multiple shooting)
  int terminal_block_ = -1;
  std::vector<int> path_block_;  // per node
  // Hessian: quasi-Newton blocks (with their interval, -1 for single shooting's one block),
  // exact blocks, the union structure, and the previous point's first derivatives.
  std::vector<HessianBlock> quasi_newton_blocks_, exact_blocks_;
  std::vector<ocp_internal::QuasiNewtonBlock> quasi_newton_;
  std::vector<int> quasi_newton_interval_;
  std::vector<std::pair<int, int>> hessian_structure_;
  bool has_previous_ = false;
  Vector previous_z_, previous_gradient_, previous_jacobian_;
  long simulations_ = 0, elements_ = 0;
};

ShootingNlp::ShootingNlp(const OcpProblem& problem, const OcpOptions& options) {
  ValidateOcp(problem);
  options.Validate();
  RequireArgument(options.transcription != OcpTranscription::kCollocation, problem.name,
                  ": the shooting NLP needs multiple or single shooting, got the collocation "
                  "transcription");
  if (options.integrator == OcpIntegrator::kTimeStepping) {
    RequireArgument(!problem.speed.enabled, problem.name,
                    ": the time-stepping discretization does not support a free final time "
                    "(speed of time); use fesd");
    for (const Effect& effect : problem.scene.effects) {
      RequireArgument(std::holds_alternative<MovingSet>(effect) ||
                          std::holds_alternative<SwitchingSurfaces>(effect),
                      problem.name, ": the time-stepping discretization does not support the ",
                      EffectKind(effect), " '", EffectName(effect), "'; use fesd");
    }
  }
  impl_ = std::make_unique<Impl>(problem, options);
  // Smoothed homotopy levels need a scene the time-stepping scheme integrates.
  for (const OcpHomotopyLevel& level : options.homotopy) impl_->SetLevel(level);
  impl_->SetLevel(OcpHomotopyLevel{});
}
ShootingNlp::~ShootingNlp() = default;
int ShootingNlp::num_variables() const { return impl_->num_variables(); }
int ShootingNlp::num_constraints() const { return impl_->num_constraints(); }
const Vector& ShootingNlp::variable_lower() const { return impl_->variable_lower_; }
const Vector& ShootingNlp::variable_upper() const { return impl_->variable_upper_; }
const Vector& ShootingNlp::constraint_lower() const { return impl_->constraint_lower_; }
const Vector& ShootingNlp::constraint_upper() const { return impl_->constraint_upper_; }
void ShootingNlp::SetLevel(const OcpHomotopyLevel& level) { impl_->SetLevel(level); }
const OcpHomotopyLevel& ShootingNlp::level() const { return impl_->level_; }
Vector ShootingNlp::InitialGuess() { return impl_->InitialGuess(); }
bool ShootingNlp::Evaluate(const Vector& z, double* objective, Vector* constraints,
                           Vector* gradient, Vector* jacobian_values, std::string* message) {
  RequireArgument(z.size() == impl_->num_variables(), "shooting NLP: expected ",
                  impl_->num_variables(), " variables, got ", z.size());
  return impl_->Evaluate(z, objective, constraints, gradient, jacobian_values, message);
}
const std::vector<std::pair<int, int>>& ShootingNlp::JacobianStructure() const {
  return impl_->structure_;
}
SparseMatrix ShootingNlp::JacobianMatrix(const Vector& jacobian_values) const {
  return impl_->JacobianMatrix(jacobian_values);
}
const std::vector<std::pair<int, int>>& ShootingNlp::HessianStructure() const {
  return impl_->hessian_structure_;
}
bool ShootingNlp::HessianApproximation(const Vector& z, double objective_factor,
                                       const Vector& lambda, const Vector& gradient,
                                       const Vector& jacobian_values, Vector* hessian_values) {
  RequireArgument(impl_->options_.hessian != OcpHessian::kLimitedMemory,
                  "shooting NLP: no Hessian approximation with the limited-memory option");
  RequireArgument(z.size() == impl_->num_variables() && lambda.size() == impl_->num_constraints() &&
                      gradient.size() == impl_->num_variables() &&
                      jacobian_values.size() == static_cast<Eigen::Index>(impl_->structure_.size()),
                  "shooting NLP: Hessian approximation called with wrong sizes");
  return impl_->HessianApproximation(z, objective_factor, lambda, gradient, jacobian_values,
                                     hessian_values);
}
void ShootingNlp::ResetHessian() { impl_->ResetHessian(); }
void ShootingNlp::Describe(const Vector& z, OcpResult* result) { impl_->Describe(z, result); }
Vector ShootingNlp::PointFromDecisions(const Matrix& decisions, const Vector& free_initial) {
  return impl_->PointFromDecisions(decisions, free_initial);
}
long ShootingNlp::simulations() const { return impl_->simulations_; }
long ShootingNlp::fesd_elements() const { return impl_->elements_; }

}  // namespace moreau
