// The shooting NLP (include/moreau/ocp/ocp.hpp, docs/ocp.md): variables, constraints and their
// exact derivatives from FESD's sensitivities.

#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"
#include "moreau/core/error.hpp"

namespace moreau {

namespace {
constexpr double kInfinity = 1e20;  // IPOPT's default "no bound"
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
    BuildStructure();
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

  void BuildBounds() {
    const int nz = nf_ + intervals_ * nd_ + (multiple_ ? intervals_ * ny_ : 0);
    variable_lower_ = Vector::Constant(nz, -kInfinity);
    variable_upper_ = Vector::Constant(nz, kInfinity);
    for (int i = 0; i < nf_; ++i) {
      const auto& free = problem_.free_initial_states[static_cast<std::size_t>(i)];
      variable_lower_[i] = std::max(free.lower, -kInfinity);
      variable_upper_[i] = std::min(free.upper, kInfinity);
    }
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

  // Dense blocks of the Jacobian: continuity rows depend on the start node (or the free
  // initial states), the interval's decisions and the end node; functions at node k on that
  // node, its decisions and (single shooting) on everything before.
  void BuildStructure() {
    const int nz = num_variables();
    const int m = num_constraints();
    std::vector<std::vector<bool>> mask(static_cast<std::size_t>(m),
                                        std::vector<bool>(static_cast<std::size_t>(nz), false));
    auto block = [&](int row, int rows, int col, int cols) {
      for (int r = row; r < row + rows; ++r) {
        for (int c = col; c < col + cols; ++c) {
          mask[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)] = true;
        }
      }
    };
    // Everything node k depends on: in multiple shooting the node itself (k = 0: the free
    // initial states); in single shooting the free initial states and all earlier decisions.
    auto node = [&](int row, int rows, int k) {
      if (multiple_) {
        if (k == 0) {
          block(row, rows, 0, nf_);
        } else {
          block(row, rows, NodeOffset(k), ny_);
        }
      } else {
        block(row, rows, 0, nf_ + k * nd_);
      }
    };
    if (multiple_) {
      for (int k = 0; k < intervals_; ++k) {
        node(ContinuityRow(k), ny_, k);
        block(ContinuityRow(k), ny_, DecisionOffset(k), nd_);
        node(ContinuityRow(k), ny_, k + 1);
      }
    }
    const int last = std::max(0, intervals_ - 1);
    const int terminal = num_terminal_equalities_ + num_terminal_inequalities_;
    node(TerminalEqualityRow(), terminal, intervals_);
    block(TerminalEqualityRow(), terminal, DecisionOffset(last), nd_);
    for (int k = 0; k <= intervals_; ++k) {
      node(PathRow(k), num_path_, k);
      block(PathRow(k), num_path_, DecisionOffset(std::min(k, last)), nd_);
    }
    structure_.clear();
    for (int r = 0; r < m; ++r) {
      for (int c = 0; c < nz; ++c) {
        if (mask[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)]) {
          structure_.emplace_back(r, c);
        }
      }
    }
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

  Interval Simulate(int k, const Vector& y_start, const ConstVectorRef& decisions, bool derivatives,
                    bool record) {
    Scene& scene = interval_scenes_[static_cast<std::size_t>(k)];
    for (int j = 0; j < nd_; ++j) {
      scene.inputs[static_cast<std::size_t>(augmented_.decisions[j])].signal.values[0] =
          decisions[j];
    }
    if (options_.integrator == OcpIntegrator::kTimeStepping) {
      return SimulateTimeSteppingInterval(k, scene, y_start, derivatives, record);
    }
    FesdOptions fesd;
    fesd.stages = options_.stages;
    fesd.finite_elements = options_.finite_elements;
    fesd.step_size = scene.final_time - scene.initial_time;
    fesd.sensitivities = derivatives;
    fesd.initial_state = y_start;
    fesd.record_trajectory = record;
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
  // with stage complementarity, no switch detection), for comparisons with FESD.
  Interval SimulateTimeSteppingInterval(int k, const Scene& scene, const Vector& y_start,
                                        bool derivatives, bool record) {
    TimeSteppingOptions stepping;
    stepping.stages = options_.stages;
    stepping.step_size = (scene.final_time - scene.initial_time) / options_.finite_elements;
    stepping.sensitivities = derivatives;
    stepping.initial_state = y_start;
    stepping.record_trajectory = record;
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

  // A problem function at node k (state y, decisions of interval kd) and its gradient with
  // respect to z (rows), given D = dy/dz.
  void EvaluateFunction(const SmoothFunction& f, const Vector& z, const Vector& y,
                        const Matrix* d_y, int kd, Vector* value, Matrix* gradient) {
    const Vector x = y.head(nx_);
    const Vector u = Inputs(z, kd);
    const double t = y[clock_];
    if (gradient == nullptr) {
      f.Evaluate(x, u, t, parameters_, value);
      return;
    }
    Matrix jacobian;  // columns x (nx), u (nu), t
    f.Jacobian(x, u, t, parameters_, Wrt::XUT(), value, &jacobian);
    gradient->setZero(f.num_outputs(), num_variables());
    *gradient += jacobian.leftCols(nx_) * d_y->topRows(nx_);
    *gradient += jacobian.col(nx_ + nu_) * d_y->row(clock_);
    for (int j = 0; j < nd_; ++j) {
      gradient->col(DecisionOffset(kd) + j) += jacobian.col(nx_ + augmented_.decisions[j]);
    }
  }

  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Matrix* jacobian, std::string* message) {
    const bool derivatives = gradient != nullptr || jacobian != nullptr;
    const int nz = num_variables();
    Vector g = Vector::Zero(num_constraints());
    Matrix jac;
    if (derivatives) jac.setZero(num_constraints(), nz);
    // Node states and their derivatives with respect to z.
    std::vector<Vector> nodes(static_cast<std::size_t>(intervals_) + 1);
    std::vector<Matrix> d_nodes(static_cast<std::size_t>(intervals_) + 1);
    nodes[0] = InitialNode(z);
    if (derivatives) {
      d_nodes[0].setZero(ny_, nz);
      for (int i = 0; i < nf_; ++i) {
        d_nodes[0](problem_.free_initial_states[static_cast<std::size_t>(i)].state, i) = 1.0;
      }
    }
    for (int k = 0; k < intervals_; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      const Interval interval =
          Simulate(k, nodes[kk], z.segment(DecisionOffset(k), nd_), derivatives, false);
      if (!interval.ok) {
        if (message != nullptr) *message = interval.message;
        return false;
      }
      Matrix d_end;
      if (derivatives) {
        d_end = interval.d_start * d_nodes[kk];
        d_end.middleCols(DecisionOffset(k), nd_) += interval.d_decisions;
      }
      if (multiple_) {
        nodes[kk + 1] = z.segment(NodeOffset(k + 1), ny_);
        // Continuity: Phi_k(y_k, decisions_k) - y_{k+1} = 0.
        g.segment(ContinuityRow(k), ny_) = interval.y_end - nodes[kk + 1];
        if (derivatives) {
          d_nodes[kk + 1].setZero(ny_, nz);
          d_nodes[kk + 1].middleCols(NodeOffset(k + 1), ny_).setIdentity();
          jac.middleRows(ContinuityRow(k), ny_) = d_end - d_nodes[kk + 1];
        }
      } else {
        nodes[kk + 1] = interval.y_end;
        if (derivatives) d_nodes[kk + 1] = d_end;
      }
    }
    const int last = intervals_ - 1;
    const auto n = static_cast<std::size_t>(intervals_);
    const Matrix* d_final = derivatives ? &d_nodes[n] : nullptr;
    Vector value;
    Matrix grad;
    // Objective: Phi(x_N, u_{N-1}, T) + q_N.
    double f = 0.0;
    Eigen::RowVectorXd df = Eigen::RowVectorXd::Zero(nz);
    if (!problem_.terminal_cost.empty()) {
      EvaluateFunction(problem_.terminal_cost, z, nodes[n], d_final, last, &value,
                       derivatives ? &grad : nullptr);
      f += value[0];
      if (derivatives) df += grad.row(0);
    }
    if (augmented_.cost_state >= 0) {
      f += nodes[n][augmented_.cost_state];
      if (derivatives) df += d_nodes[n].row(augmented_.cost_state);
    }
    // Terminal constraints.
    if (num_terminal_equalities_ > 0) {
      EvaluateFunction(problem_.terminal_equalities, z, nodes[n], d_final, last, &value,
                       derivatives ? &grad : nullptr);
      g.segment(TerminalEqualityRow(), num_terminal_equalities_) = value;
      if (derivatives) jac.middleRows(TerminalEqualityRow(), num_terminal_equalities_) = grad;
    }
    if (num_terminal_inequalities_ > 0) {
      EvaluateFunction(problem_.terminal_inequalities, z, nodes[n], d_final, last, &value,
                       derivatives ? &grad : nullptr);
      g.segment(TerminalInequalityRow(), num_terminal_inequalities_) = value;
      if (derivatives) jac.middleRows(TerminalInequalityRow(), num_terminal_inequalities_) = grad;
    }
    // Path constraints at the grid points.
    for (int k = 0; num_path_ > 0 && k <= intervals_; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      EvaluateFunction(problem_.path_constraints, z, nodes[kk],
                       derivatives ? &d_nodes[kk] : nullptr, std::min(k, last), &value,
                       derivatives ? &grad : nullptr);
      g.segment(PathRow(k), num_path_) = value;
      if (derivatives) jac.middleRows(PathRow(k), num_path_) = grad;
    }
    if (objective != nullptr) *objective = f;
    if (constraints != nullptr) *constraints = g;
    if (gradient != nullptr) *gradient = df.transpose();
    if (jacobian != nullptr) *jacobian = std::move(jac);
    if (!std::isfinite(f) || !g.allFinite()) {
      if (message != nullptr) *message = "non-finite objective or constraints";
      return false;
    }
    return true;
  }

  Vector InitialGuess() {
    Vector z = Vector::Zero(num_variables());
    for (int i = 0; i < nf_; ++i) {
      const auto& free = problem_.free_initial_states[static_cast<std::size_t>(i)];
      z[i] = std::clamp(problem_.scene.initial_state[free.state], free.lower, free.upper);
    }
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
      const Interval interval = Simulate(k, y, z.segment(DecisionOffset(k), nd_), false, true);
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
  Vector y0_, parameters_;
  std::vector<double> tau_;
  std::vector<Scene> interval_scenes_;
  Vector variable_lower_, variable_upper_, constraint_lower_, constraint_upper_;
  std::vector<std::pair<int, int>> structure_;
  long simulations_ = 0, elements_ = 0;
};

ShootingNlp::ShootingNlp(const OcpProblem& problem, const OcpOptions& options) {
  ValidateOcp(problem);
  options.Validate();
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
}
ShootingNlp::~ShootingNlp() = default;
int ShootingNlp::num_variables() const { return impl_->num_variables(); }
int ShootingNlp::num_constraints() const { return impl_->num_constraints(); }
const Vector& ShootingNlp::variable_lower() const { return impl_->variable_lower_; }
const Vector& ShootingNlp::variable_upper() const { return impl_->variable_upper_; }
const Vector& ShootingNlp::constraint_lower() const { return impl_->constraint_lower_; }
const Vector& ShootingNlp::constraint_upper() const { return impl_->constraint_upper_; }
Vector ShootingNlp::InitialGuess() { return impl_->InitialGuess(); }
bool ShootingNlp::Evaluate(const Vector& z, double* objective, Vector* constraints,
                           Vector* gradient, Matrix* jacobian, std::string* message) {
  RequireArgument(z.size() == impl_->num_variables(), "shooting NLP: expected ",
                  impl_->num_variables(), " variables, got ", z.size());
  return impl_->Evaluate(z, objective, constraints, gradient, jacobian, message);
}
const std::vector<std::pair<int, int>>& ShootingNlp::JacobianStructure() const {
  return impl_->structure_;
}
void ShootingNlp::Describe(const Vector& z, OcpResult* result) { impl_->Describe(z, result); }
long ShootingNlp::simulations() const { return impl_->simulations_; }
long ShootingNlp::fesd_elements() const { return impl_->elements_; }

}  // namespace moreau
