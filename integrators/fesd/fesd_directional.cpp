// Directional and adjoint sensitivities of a FESD run (sensitivity_tape.hpp,
// docs/sensitivities.md): the run's derivative applied to a block of directions as the run
// goes, and its transpose applied to adjoint weights by a reverse sweep over a tape of the
// run's steps. Both use the same implicit-function-theorem blocks as the full matrices
// (fesd_sensitivities.cpp), as products (group_sensitivity.cpp).
#include <Eigen/Dense>
#include <cmath>
#include <sstream>
#include <type_traits>
#include <variant>

#include "../common/sensitivity_arguments.hpp"
#include "fesd_run.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

// A sample time counts as reached at an element end whose clock is within this relative
// distance of it: clocks at grid points carry the round-off of summed increments (far below),
// and distinct grid points are separated by whole elements (far above).
constexpr double kSampleTolerance = 1e-9;

// The sweep keeps a factorization per system size up to this many sizes (trial elements and
// switch groups of a few element counts alternate; more sizes, with the near-active filter,
// would keep every one's factors in memory).
constexpr std::size_t kReverseSolvers = 4;

}  // namespace

// The working set of the near-active filter as flags over the declared pairs.
static std::vector<bool> WorkingFlags(const LoweredSystem& system) {
  std::vector<bool> keep(static_cast<std::size_t>(system.num_declared_pairs()), false);
  for (int k : system.working_pairs()) keep[static_cast<std::size_t>(k)] = true;
  return keep;
}

FesdOptions FesdRun::Tracking(const FesdOptions& options) {
  FesdOptions tracking = options;
  tracking.sensitivities = options.sensitivities || options.sensitivity_directions.size() > 0 ||
                           options.adjoint_weights.size() > 0 ||
                           options.adjoint_sample_weights.size() > 0 || options.keep_adjoint;
  return tracking;
}

void FesdRun::InitializeTape() {
  const Scene& scene = system_.scene();
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  const int segments = static_cast<int>(control_starts_.size());
  const int n_theta = np + nu * segments;
  tape_ = SensitivityTape();
  tape_.sample_times = options_.sample_times;
  for (double t : tape_.sample_times) {
    RequireArgument(t > scene.initial_time && t <= scene.final_time, "sample time ", t,
                    " is outside (t0, tf] = (", scene.initial_time, ", ", scene.final_time, "]");
  }
  if (options_.sensitivity_directions.size() > 0) {
    bool lowered = false;
    const Matrix directions =
        ShapedSensitivityArgument(options_.sensitivity_directions, nx_ + n_theta, ny_ + n_theta, 1,
                                  "sensitivity directions", &lowered);
    const int state_rows = lowered ? ny_ : nx_;
    tape_.directional = true;
    tape_.d.setZero(ny_ + 2, directions.cols());
    tape_.d.topRows(state_rows) = directions.topRows(state_rows);
    tape_.theta = directions.bottomRows(n_theta);
  }
  tape_.adjoint = options_.adjoint_weights.size() > 0 ||
                  options_.adjoint_sample_weights.size() > 0 || options_.keep_adjoint;
  if (tape_.adjoint) {
    for (int k = 0; k < segments; ++k) {
      tape_.segment_inputs.push_back(
          scene.InputValues(control_starts_[static_cast<std::size_t>(k)]));
    }
    tape_.parameters = system_.parameters();
    tape_.layouts.push_back(WorkingFlags(system_));
    tape_.memory_limit =
        static_cast<std::size_t>(options_.adjoint_memory_limit_mb * 1024.0 * 1024.0);
  }
}

void FesdRun::TrackGroup(const Vector& w, int group_elements, int remaining, const Vector& a0,
                         SolveRecord* record) {
  if (full_) record->transfer = LocalTransfer(w, group_elements, remaining);
  if (tape_.directional) {
    const bool chained = pending_a_last_ == &a0 && pending_a_last_ != &record->a_last;
    const Matrix& start = chained ? *pending_directions_ : tape_.d;
    if (!full_) group_.EvaluateForSensitivities(w);  // (LocalTransfer evaluated it)
    Matrix end;
    GroupForward(w, group_elements, remaining, start, &end);
    record->directions_end = std::move(end);
    pending_a_last_ = &record->a_last;
    pending_directions_ = &record->directions_end;
  }
  if (tape_.adjoint) {
    GroupStep& step = record->step;
    step.setup = group_.setup();
    step.w = w;
    step.segment = segment_;
    step.remaining = remaining;
    // The working set only changes with the near-active filter.
    if (filter_.enabled()) {
      std::vector<bool> keep = WorkingFlags(system_);
      if (tape_.layouts.back() != keep) tape_.layouts.push_back(std::move(keep));
    }
    step.layout = static_cast<int>(tape_.layouts.size()) - 1;
  }
}

void FesdRun::CommitTracks(SolveRecord& record) {
  if (full_) ApplyTransfer(record.transfer);
  if (tape_.directional) tape_.d = record.directions_end;
  if (tape_.adjoint) {
    GroupStep& step = record.step;
    const std::size_t small =
        sizeof(GroupStep) +
        sizeof(double) * static_cast<std::size_t>(step.setup.indicator_weights.size()) +
        step.setup.a_zero.size() / 8 + sizeof(int) * step.setup.indicator_power.size();
    const std::size_t large =
        sizeof(double) * static_cast<std::size_t>(step.w.size() + step.setup.y_start.size());
    if (tape_.memory_limit > 0 && tape_.bytes + small + large > tape_.memory_limit) {
      // Beyond the bound: the large parts to the checkpoint file.
      if (!tape_.file) tape_.file = std::make_unique<CheckpointFile>();
      tape_.file_bytes = tape_.file->Write(tape_.file_bytes, &step);
      tape_.bytes += small;
    } else {
      step.file_offset = -1;
      tape_.bytes += small + large;
    }
    tape_.steps.emplace_back(std::move(step));
  }
  if (tape_.next_sample >= tape_.sample_times.size() || record.frozen) return;
  const double clock = y_[system_.clock_index()];
  const double t = tape_.sample_times[tape_.next_sample];
  if (std::fabs(clock - t) > kSampleTolerance * std::max(1.0, std::fabs(t))) return;
  const int sample = static_cast<int>(tape_.next_sample++);
  tape_.sample_states.push_back(y_);
  if (tape_.directional) tape_.sample_d.push_back(tape_.d.topRows(ny_));
  if (tape_.adjoint) tape_.steps.emplace_back(SampleStep{sample});
}

void FesdRun::TrackClock(int clock, double n) {
  if (full_) {
    if (n > 0.0) {
      sensitivity_.row(ny_) = sensitivity_.row(clock) / n;
    } else {
      sensitivity_.row(ny_).setZero();
    }
  }
  const ClockStep step{clock, n > 0.0 ? 1.0 / n : 0.0};
  if (tape_.directional) ApplyForward(step, &tape_.d);
  if (tape_.adjoint) tape_.steps.emplace_back(step);
}

void FesdRun::TrackStepStart(bool lands, bool clock_targets) {
  const int clock = system_.clock_index();
  if (full_) {
    const Eigen::RowVectorXd d_tau = sensitivity_.row(ny_) + d_step_end_;
    Eigen::RowVectorXd d_end = d_tau;
    if (lands) {
      d_end = clock_targets ? Eigen::RowVectorXd(d_tau - sensitivity_.row(clock))
                            : Eigen::RowVectorXd::Zero(d_tau.size());
    }
    sensitivity_.row(ny_) = d_tau - d_end;
    d_step_end_ = d_end;
  }
  const StepStart step{lands, clock_targets, clock};
  if (tape_.directional) ApplyForward(step, ny_, &tape_.d);
  if (tape_.adjoint) tape_.steps.emplace_back(step);
}

void FesdRun::TrackProjection(const Matrix& d_x0, const Vector& d_t, const Matrix& d_p,
                              const Matrix& d_u) {
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  const int clock = system_.clock_index();
  if (full_) {
    // New rows x: dx/dx0 (x columns), dx/dclock (clock column), dx/dp, dx/du (segment 0).
    Matrix rows = Matrix::Zero(nx_, sensitivity_.cols());
    rows.leftCols(nx_) = d_x0;
    rows.col(clock) = d_t;
    rows.middleCols(ny_, np) = d_p;
    rows.middleCols(ny_ + np, nu) = d_u;
    sensitivity_.topRows(nx_) = rows;
  }
  ProjectionStep step{d_x0, d_t, d_p, d_u, clock};
  if (tape_.directional) ApplyForward(step, np, tape_.theta, &tape_.d);
  if (tape_.adjoint) {
    tape_.bytes += sizeof(double) *
                   static_cast<std::size_t>(d_x0.size() + d_t.size() + d_p.size() + d_u.size());
    tape_.steps.emplace_back(std::move(step));
  }
}

void FesdRun::EventWeights(const Vector& w, double* da, double* db) const {
  const GroupSetup& setup = group_.setup();
  *da = *db = 0.0;
  if (!setup.with_event) return;
  // As LocalTransfer: the Fischer-Burmeister derivatives of the element-length pair.
  const NcpValue phi =
      FischerBurmeister((setup.h_max - group_.H(w)) / setup.h_max, group_.event_indicator());
  *da = phi.da;
  *db = phi.db;
}

// dw = -R_w^{-1} (B_y dy + b_tau dtau + B_p dp + B_u du) per direction (LocalTransfer's
// rhs as products), then y_end = y_start + sum_e Z_{e,s} and the tau row as there.
void FesdRun::GroupForward(const Vector& w, int group_elements, int remaining, const Matrix& start,
                           Matrix* end) {
  const GroupSetup& setup = group_.setup();
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  double da = 0.0, db = 0.0;
  EventWeights(w, &da, &db);
  const int k = static_cast<int>(start.cols());
  Matrix rhs = Matrix::Zero(group_.num_unknowns(), k);
  for (int c = 0; c < k; ++c) {
    // The lengths move with the start time: h = rest / remaining (fixed elements), h_max =
    // rest / m and h_ref = rest / remaining (with the event equation).
    const double d_tau = start(ny_, c);
    GroupSystem::LengthChanges dh;
    dh.fixed = -d_tau / remaining;
    dh.max = -d_tau / group_elements;
    dh.reference = -d_tau / remaining;
    group_.AddBlockProduct(w, da, db, start.col(c).head(ny_), tape_.theta.col(c).head(np),
                           tape_.theta.col(c).segment(np + nu * segment_, nu), dh, rhs.col(c));
  }
  const LinearSolver* solver = solved_by_->last_jacobian_solver();
  MOREAU_ASSERT(solver != nullptr, "no factorized Jacobian for sensitivities");
  solver->SolveMatrix(rhs);  // rhs = -dw
  *end = start;
  const int last = group_.element_size() / s_ * (s_ - 1);  // stage s of an element
  for (int e = 0; e < setup.elements; ++e) {
    end->topRows(ny_) -= rhs.middleRows(group_.element_offset(e) + last, ny_);
  }
  if (setup.with_event) {
    end->row(ny_) -= setup.elements * rhs.row(group_.h_index());
  } else {
    end->row(ny_) = start.row(ny_) * (1.0 - 1.0 / remaining);
  }
}

// The transpose of GroupForward: with mu = sum_e E_e^T lambda_y (+ m lambda_tau at h) and
// R_w^T nu = mu, lambda_y -= B_y^T nu, the parameter gradient -= B_p^T nu, B_u^T nu, and the
// tau row takes the length terms.
bool FesdRun::GroupTransposed(const GroupStep& kept, Matrix* lambda, Matrix* gradient,
                              std::string* message) {
  // A checkpoint beyond the memory bound is read back from the file.
  GroupStep loaded;
  if (kept.file_offset >= 0) {
    loaded = kept;
    tape_.file->Read(&loaded);
  }
  const GroupStep& step = kept.file_offset >= 0 ? loaded : kept;
  if (tape_.layouts.size() > 1 &&
      WorkingFlags(system_) != tape_.layouts[static_cast<std::size_t>(step.layout)]) {
    system_.SetWorkingPairs(tape_.layouts[static_cast<std::size_t>(step.layout)]);
    group_.Resize();
  }
  system_.SetInputs(tape_.segment_inputs[static_cast<std::size_t>(step.segment)]);
  group_.Configure(step.setup);
  const GroupSetup& setup = step.setup;
  const int m = setup.elements;
  const int q = static_cast<int>(lambda->cols());
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  const int n = group_.num_unknowns();
  const int last = group_.element_size() / s_ * (s_ - 1);
  Matrix weights = Matrix::Zero(n, q);  // -nu, the rows' multipliers
  // An element whose statuses leave a smooth field (trial elements of Stewart modes, free
  // moving sets, relays: InitializeSmoothFields) is a Radau IIA step of that field: the field
  // depends on the algebraic unknowns only through values the statuses fix (theta = e_k or
  // 1/2, lambda = 0), so the element's map y_start -> Z equals the collocation equations'
  // alone, R_C(Z; y_start) = Z_i - h sum_j a_ij F(Y_j) = 0 with Jacobian I - h (A x I)
  // diag(F_y(Y_j)). Their transposed solve (n_y s unknowns instead of (n_y + n_z) s) gives
  // the collocation rows' multipliers, the other rows' being zero: the same products.
  // Not for a relay sliding on a memory boundary (two active regions, theta = 1/2): there
  // the statuses make the algebraic rows a constraint on the stage states (g_A(Y) = g_B(Y)
  // keeps w on the boundary), which the smooth field w' = 0 does not differentiate.
  bool one_region = true;
  for (std::size_t i = 0; reduction_ == Reduction::kRelayModes && i < relay_theta_.size(); ++i) {
    int active = 0;
    for (std::size_t k = 0; k < 4; ++k) active += setup.a_zero[4 * i + k] ? 0 : 1;
    one_region = one_region && active == 1;
  }
  const bool smooth_element = !setup.with_event && m == 1 && reduction_ != Reduction::kNone &&
                              one_region && s_ * ny_ <= kDenseSizeLimit &&
                              SmoothField(setup.a_zero) >= 0;
  if (smooth_element) {
    group_.EvaluateForSensitivities(step.w);
    const CollocationStages& stages = group_.element(0);
    const Matrix& a = stages.tableau().a;
    const double h = group_.H(step.w);
    const int rows = s_ * ny_;
    Matrix jacobian = Matrix::Identity(rows, rows);
    for (int j = 0; j < s_; ++j) {
      const Matrix f_y = stages.stage(j).F_y.ToDense();
      for (int i = 0; i < s_; ++i) jacobian.block(i * ny_, j * ny_, ny_, ny_) -= h * a(i, j) * f_y;
    }
    Matrix mu = Matrix::Zero(rows, q);
    mu.bottomRows(ny_) = lambda->topRows(ny_);  // y_end = y_start + Z_s
    const Eigen::PartialPivLU<Matrix> lu(jacobian.transpose());
    const Matrix nu_c = lu.solve(mu);
    if (!nu_c.allFinite()) {
      *message = "the collocation Jacobian of a smooth element is singular at its solution";
      return false;
    }
    const int collocation_rows = ny_ + system_.num_equations();  // per stage: F rows, then G
    for (int i = 0; i < s_; ++i) {
      weights.middleRows(i * collocation_rows, ny_) = -nu_c.middleRows(i * ny_, ny_);
    }
  } else {
    // The Jacobian at the solution exactly as Newton factorizes it there
    // (SemismoothNewtonOptions::factorize_at_solution): NCP derivatives of its options. One
    // evaluation with every derivative serves the Jacobian and the blocks (it is
    // EvaluateForSensitivities's, with the element-length pair's data of Evaluate).
    Vector r, a, b;
    group_.set_parameter_derivatives(true);
    group_.Evaluate(step.w, true, &r, &a, &b);
    group_.set_parameter_derivatives(false);
    const SemismoothNewtonOptions& newton = options_.newton;
    Vector da(a.size()), db(a.size());
    for (Eigen::Index k = 0; k < a.size(); ++k) {
      const NcpValue v =
          newton.ncp_function == NcpFunctionKind::kFischerBurmeister && newton.smoothing > 0.0
              ? SmoothedFischerBurmeister(a[k], b[k], newton.smoothing)
              : EvaluateNcp(newton.ncp_function, a[k], b[k]);
      da[k] = v.da;
      db[k] = v.db;
    }
    // A solver per system size (trial elements and switch groups alternate), each keeping its
    // sparse symbolic analysis while the pattern holds.
    if (reverse_solvers_.size() >= kReverseSolvers && reverse_solvers_.count(n) == 0) {
      reverse_solvers_.clear();  // (near-active filter: many sizes; each keeps its factors)
    }
    std::unique_ptr<LinearSolver>& solver = reverse_solvers_[n];
    if (solver == nullptr) {
      solver =
          MakeLinearSolver(options_.newton.linear_solver, n, group_.EstimatedJacobianNonzeros());
    }
    reverse_jacobian_.Reset(n, solver->wants_sparse());
    group_.AssembleJacobian(da, db, &reverse_jacobian_);
    reverse_jacobian_.Finalize();
    const FactorizationStatus status = solver->Factorize(reverse_jacobian_);
    if (status != FactorizationStatus::kSuccess) {
      std::ostringstream s;
      s << "the Jacobian of the group starting at clock "
        << step.setup.y_start[system_.clock_index()] << " is " << ToString(status)
        << " at its solution";
      *message = s.str();
      return false;
    }
    for (int e = 0; e < m; ++e) {
      weights.middleRows(group_.element_offset(e) + last, ny_) += lambda->topRows(ny_);
    }
    if (setup.with_event) weights.row(group_.h_index()) += m * lambda->row(ny_);
    for (int c = 0; c < q; ++c) solver->SolveTransposed(weights.col(c));
    weights = -weights;  // -nu: the rhs enters dw with a minus sign
  }
  double event_da = 0.0, event_db = 0.0;
  EventWeights(step.w, &event_da, &event_db);
  for (int c = 0; c < q; ++c) {
    const double tau =
        setup.with_event ? (*lambda)(ny_, c) : (*lambda)(ny_, c) * (1.0 - 1.0 / step.remaining);
    const GroupSystem::LengthChanges lengths = group_.AddTransposedBlockProduct(
        step.w, event_da, event_db, weights.col(c), lambda->col(c).head(ny_),
        gradient->col(c).head(np), gradient->col(c).segment(np + nu * step.segment, nu));
    (*lambda)(ny_, c) =
        tau - (lengths.fixed + lengths.reference) / step.remaining - lengths.max / m;
  }
  return true;
}

FesdGradient FesdRun::ReverseSweep(const Matrix& final_weights, const Matrix& sample_weights) {
  const RunClock run_clock;
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  const int segments = static_cast<int>(tape_.segment_inputs.size());
  const int n_params = np + nu * segments;
  const int samples = static_cast<int>(tape_.sample_states.size());
  Matrix final_shaped, sample_shaped;
  const int q = static_cast<int>(ShapedAdjointWeights(final_weights, sample_weights, nx_, ny_,
                                                      samples, &final_shaped, &sample_shaped));
  Matrix lambda = Matrix::Zero(ny_ + 2, q);
  if (final_shaped.size() > 0) lambda.topRows(final_shaped.rows()) = final_shaped;
  Matrix gradient = Matrix::Zero(n_params, q);
  FesdGradient out;
  // The sweep sets the system up as each group had it; what it had before is restored after
  // (a shared system: FesdIntegrator's next run starts from it, the filter's working set too).
  const std::vector<bool> layout_before =
      tape_.layouts.size() > 1 ? WorkingFlags(system_) : std::vector<bool>();
  const Vector parameters_before = system_.parameters();
  const Vector inputs_before = system_.inputs();
  if (np > 0) system_.SetParameters(tape_.parameters);
  for (auto it = tape_.steps.rbegin(); it != tape_.steps.rend() && out.success; ++it) {
    std::visit(
        [&](const auto& step) {
          using T = std::decay_t<decltype(step)>;
          if constexpr (std::is_same_v<T, GroupStep>) {
            out.success = GroupTransposed(step, &lambda, &gradient, &out.message);
          } else if constexpr (std::is_same_v<T, SaltationStep>) {
            ApplyTransposed(step, np, nu, &lambda, &gradient);
          } else if constexpr (std::is_same_v<T, ClockStep> || std::is_same_v<T, StepStart>) {
            ApplyTransposed(step, ny_, &lambda);
          } else if constexpr (std::is_same_v<T, ProjectionStep>) {
            ApplyTransposed(step, np, &lambda, &gradient);
          } else if (sample_shaped.size() > 0) {
            lambda.topRows(sample_shaped.rows()) += sample_shaped.middleCols(step.sample * q, q);
          }
        },
        *it);
  }
  if (!layout_before.empty() && WorkingFlags(system_) != layout_before) {
    system_.SetWorkingPairs(layout_before);
    group_.Resize();
  }
  if (np > 0) system_.SetParameters(parameters_before);
  if (nu > 0) system_.SetInputs(inputs_before);
  if (out.success) {
    out.lowered.resize(q, ny_ + n_params);
    out.lowered << lambda.topRows(ny_).transpose(), gradient.transpose();
    out.theta.resize(q, nx_ + n_params);
    out.theta << lambda.topRows(nx_).transpose(), gradient.transpose();
  }
  out.cpu_seconds = run_clock.CpuSeconds();
  return out;
}

void FesdRun::FinishSensitivities() {
  if (full_) {
    const int np = system_.num_parameters();
    result_.sensitivities.initial_state = sensitivity_.topLeftCorner(nx_, nx_);
    result_.sensitivities.parameters = sensitivity_.block(0, ny_, nx_, np);
    result_.sensitivities.inputs = sensitivity_.topRightCorner(nx_, sensitivity_.cols() - ny_ - np);
    result_.sensitivities.lowered = sensitivity_.topRows(ny_);
  }
  result_.sensitivities.segment_starts = control_starts_;
  const bool success = result_.status == FesdStatus::kSuccess;
  if (success && tape_.next_sample < tape_.sample_times.size()) {
    std::ostringstream s;
    s.precision(17);
    s << "sample time " << tape_.sample_times[tape_.next_sample]
      << " is not an element end of the run (fixed steps: a multiple of the step h from a "
         "control breakpoint; a switch within min_element_fraction of a step end merges the "
         "step into the next)";
    throw std::invalid_argument(s.str());
  }
  result_.sample_states = tape_.sample_states;
  if (tape_.directional && success) {
    result_.sensitivities.directional_lowered = tape_.d.topRows(ny_);
    result_.sensitivities.directional = tape_.d.topRows(nx_);
    for (const Matrix& d : tape_.sample_d) {
      result_.sensitivities.sample_directional.push_back(d.topRows(nx_));
    }
  }
  if (!tape_.adjoint) return;
  result_.stats.adjoint_memory_bytes = static_cast<double>(tape_.bytes);
  result_.stats.adjoint_file_bytes = static_cast<double>(tape_.file_bytes);
  const bool weighted =
      options_.adjoint_weights.size() > 0 || options_.adjoint_sample_weights.size() > 0;
  if (!weighted || !success) return;
  const FesdGradient gradient =
      ReverseSweep(options_.adjoint_weights, options_.adjoint_sample_weights);
  result_.stats.adjoint_cpu_seconds = gradient.cpu_seconds;
  if (!gradient.success) {
    Fail(FesdStatus::kSensitivityFailure, result_.final_time, gradient.message);
    return;
  }
  result_.sensitivities.adjoint = gradient.theta;
  result_.sensitivities.adjoint_lowered = gradient.lowered;
}

}  // namespace moreau::internal

namespace moreau {

FesdAdjoint::FesdAdjoint(std::shared_ptr<internal::FesdRun> run) : run_(std::move(run)) {}

FesdGradient FesdAdjoint::Sweep(const Matrix& final_weights, const Matrix& sample_weights) const {
  return run_->ReverseSweep(final_weights, sample_weights);
}

}  // namespace moreau
