// Adaptive steps of FESD (docs/fesd-formulation.md, section 10): the step loop with error
// estimate, rejection and failure retries, and the replay of a step sequence.
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <sstream>
#include <utility>

#include "fesd_run.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

// A step that would end within this fraction of itself before the segment end lands on the
// end instead (no needlessly short last step; the smooth Radau IIA integrator does the same).
constexpr double kLandingFraction = 0.01;
// A step whose solves failed (Newton, event location, status decision) is retried with this
// fraction of its length.
constexpr double kFailureFactor = 0.5;
// A committed element whose complementarity or cross-complementarity certificate exceeds this
// many event tolerances holds a switch that was not located (e.g. two roots of a multiplier
// inside one long element): the step counts as failed and is retried shorter. Correct
// elements have certificates at the Newton tolerance (tests: <= 1e-10).
constexpr double kMissedSwitchCertificate = 10.0;
// Consecutive steps of zero length (switches decided at the step's start) allowed before the
// run ends with kStatusDecisionFailure: one is a switch that the next step then passes; more
// in a row is a decision that keeps changing without progress.
constexpr int kMaxZeroLengthPieces = 2;
// The solutions compared by the error estimate are rounded to eps (1 + |y|) and converged to
// their Newton residuals r (scaled by 1 + |y|), so their difference is known to about
// kNewtonNoise eps (1 + |y|) at best and kNewtonNoise r (1 + |y|) for the solves at hand. The
// allowed local error of a state is never below the first (the step proposal) nor, for
// accepting a step, below the second: error per unit step would otherwise ask, on short
// steps, for local errors below what floating point and the solves resolve (the 1e-6
// transient of hard_stiff_set). The residual varies from solve to solve (1e-16 to 5e-14 on F1)
// and would make the proposals jump, so proposals use the first floor only.
constexpr double kNewtonNoise = 10.0;
// Resolution of the continuous free sides (IndicatorResolution): the interpolant of their
// values at the element start and stages may miss the value in a gap by at most this fraction
// of their range over the element; beyond it sign checks at the stages could miss a pair of
// roots between them.
constexpr double kIndicatorResolution = 0.1;
// Indicators that vary by less than this (relative to 1 + their size) over an element count
// as resolved.
constexpr double kIndicatorFloor = 1e-8;
// The interpolant of the free sides is searched for a minimum below zero at this many equally
// spaced points of every element (IndicatorResolution). A polynomial of degree s <= 4 has at
// most three local minima in an element; 64 points find a dip narrower than 2% of the element,
// where it is deeper than the interpolant's change over 1/64 of the element.
constexpr int kDipSamples = 64;
double DipSample(int m) { return (m + 0.5) / kDipSamples; }
// Steps below this many ulps of the time cannot be told apart from zero-length steps.
constexpr double kMinStepUlps = 64.0;
// An attempt whose crossing search stayed unresolved (the indicator bounds admit a zero between
// an element's nodes that neither samples nor halvings decided, FesdRun::InsideViolation) is
// retried with half the step (the search's resolution in time halves with it), at most this
// many times in a row; then it is accepted and the run warns (FesdResult::warnings), and so are
// the steps after it until one is free of unresolved crossings. Twice: a graze within the
// bounds' overestimate of zero (the doorway S5's pusher passing a doorway disc at a distance of
// 1e-3) stays undecided at every resolution, and six halvings walked the steps onto the
// tangency, where the statuses could not be decided (status_decision_failure).
constexpr int kMaxUnresolvedRetries = 2;
// Accepted steps whose results (FesdResult::elements, step_sequence) are reserved before the
// first step (at most max_steps): an error-controlled run does not know its step count, and
// growing the results by doubling would allocate in steps without an event. Longer runs grow
// them by doubling beyond (a few allocations per run); Finish trims what a shorter run left.
// 1024 steps cover the catalog's error-controlled runs (F1: 24, S3: 94) at 115 kB with two
// elements per step.
constexpr long kReservedSteps = 1024;

// y = y0 + increments * weights (a point of a collocation polynomial) with the arithmetic Eigen
// uses for that expression (its matrix-vector product sums each row from zero over the columns
// in order, and the sum is then added to y0; no fused multiply-add on our targets), so the
// bits are the expression's, without its temporary. y must not be y0.
void PolynomialPoint(const Vector& y0, const Matrix& increments, const Vector& weights, Vector* y) {
  const Eigen::Index n = y0.size(), s = increments.cols();
  y->resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    double sum = 0.0;
    for (Eigen::Index j = 0; j < s; ++j) sum += increments(i, j) * weights[j];
    (*y)[i] = y0[i] + sum;
  }
}

void Truncate(Trajectory* trajectory, std::size_t size) {
  trajectory->t.resize(size);
  trajectory->x.resize(size);
  trajectory->algebraic.resize(size);
  trajectory->step.resize(size);
}

std::string Text(double value) {
  std::ostringstream s;
  s.precision(6);
  s << value;
  return s.str();
}

}  // namespace

void FesdRun::Save(Snapshot* snapshot) const {
  Snapshot& s = *snapshot;  // every member assigned (a kept snapshot: no allocation per step)
  s.y = y_;
  s.velocity = velocity_;
  s.z_guess = z_guess_;
  s.z_last = z_last_;
  s.boundary_a = boundary_a_;
  s.boundary_b = boundary_b_;
  s.last_w = last_w_;
  s.tau = tau_;
  s.last_h = last_h_;
  s.first_unresolved_time = first_unresolved_time_;
  s.have_last_w = have_last_w_;
  s.a_zero = a_zero_;
  filter_.working(&s.working);
  s.last_z_matrix = last_z_matrix_;
  s.sensitivity = sensitivity_;
  s.d_step_end = d_step_end_;
  s.tape = tape_.Save();
  s.trajectory = result_.trajectory.size();
  s.stage_trajectory = result_.stage_trajectory.size();
  s.numerical_trajectory = result_.numerical_trajectory.size();
  s.events = result_.events.size();
  s.elements = result_.elements.size();
  s.next_output = next_output_;
  s.relay_jumps.clear();
  for (const RelaySignal& relay : result_.relays) s.relay_jumps.push_back(relay.jump_times.size());
  s.stats = result_.stats;
}

void FesdRun::Restore(const Snapshot& s) {
  // The working set of the snapshot first: the vectors below are laid out in it.
  LoweredSystem::WorkingLayout previous;
  if (filter_.Restore(s.working, &previous)) {
    nz_ = system_.num_algebraic();
    np_ = system_.num_pairs();
    group_.Resize();
  }
  y_ = s.y;
  velocity_ = s.velocity;
  z_guess_ = s.z_guess;
  z_last_ = s.z_last;
  boundary_a_ = s.boundary_a;
  boundary_b_ = s.boundary_b;
  last_w_ = s.last_w;
  tau_ = s.tau;
  last_h_ = s.last_h;
  first_unresolved_time_ = s.first_unresolved_time;
  have_last_w_ = s.have_last_w;
  a_zero_ = s.a_zero;
  last_z_matrix_ = s.last_z_matrix;
  sensitivity_ = s.sensitivity;
  d_step_end_ = s.d_step_end;
  tape_.Restore(s.tape);
  Truncate(&result_.trajectory, s.trajectory);
  Truncate(&result_.stage_trajectory, s.stage_trajectory);
  Truncate(&result_.numerical_trajectory, s.numerical_trajectory);
  result_.events.resize(s.events);
  result_.elements.resize(s.elements);
  next_output_ = s.next_output;
  for (std::size_t i = 0; i < result_.relays.size(); ++i) {
    result_.relays[i].jump_times.resize(s.relay_jumps[i]);
    result_.relays[i].values.resize(s.relay_jumps[i]);
  }
  // The solution goes back; the work done on the rejected attempt stays counted.
  const FesdStats work = result_.stats;
  result_.stats = s.stats;
  result_.stats.num_newton_iterations = work.num_newton_iterations;
  result_.stats.num_groups = work.num_groups;
  result_.stats.num_event_retries = work.num_event_retries;
  result_.stats.num_rejected_steps = work.num_rejected_steps;
  result_.stats.num_failed_steps = work.num_failed_steps;
  result_.stats.num_bound_evaluations = work.num_bound_evaluations;
  result_.status = FesdStatus::kSuccess;
  result_.message.clear();
}

Violation FesdRun::JumpStageViolation(const CollocationStages& stages, const Vector& scales,
                                      int element) const {
  Violation first;
  // Screen: the stage values of the jump sides approximate the consistent ones to O(h^s);
  // an element whose jump sides are positive at every stage is not checked further (a missed
  // pair of roots inside shows as negative stage values, and the certificates of committed
  // elements catch the rest, see IntegrateAdaptive).
  bool suspicious = false;
  for (int k = 0; k < np_ && !suspicious; ++k) {
    if (!FreeSideIsJump(k)) continue;
    const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
    for (int i = 0; i < s_; ++i) {
      const double free = a_zero ? stages.stage(i).B[k] : stages.stage(i).A[k];
      suspicious |= !(free > options_.event_tolerance * scales[k]);
    }
  }
  if (!suspicious) return first;
  Vector previous = Vector::Constant(np_, std::numeric_limits<double>::quiet_NaN());
  double previous_c = 0.0;
  for (int i = 0; i < s_ && !first.found; ++i) {
    const Vector free = ConsistentFreeSides(stages, i);
    for (int k = 0; k < np_; ++k) {
      if (!FreeSideIsJump(k) || !(free[k] < -options_.event_tolerance * scales[k])) continue;
      double fraction = tableau_.c[i];
      if (std::isfinite(previous[k]) && std::isfinite(free[k]) && previous[k] > free[k]) {
        fraction =
            previous_c + (tableau_.c[i] - previous_c) * previous[k] / (previous[k] - free[k]);
      }
      fraction = std::clamp(fraction, 1e-3, 1.0);
      if (!first.found || fraction < first.fraction) first = {true, element, fraction, k};
    }
    previous = free;
    previous_c = tableau_.c[i];
  }
  return first;
}

void FesdRun::OnCommittedElement(ElementPolynomial&& element) {
  DenseOutput(element);  // (reads the element alone, not the piece)
  (capture_piece_ ? piece_ : spare_polynomials_).push_back(std::move(element));
}

void FesdRun::IntegrateAdaptive(bool clock_targets) {
  const Scene& scene = system_.scene();
  const int clock = system_.clock_index();
  const bool replay = !options_.step_sequence.empty();
  // The error per unit step is measured against the horizon (in the integration variable;
  // with time-freezing the physical horizon, the frozen intervals being exact up to round-off).
  const double horizon = scene.final_time - scene.initial_time;
  StepController controller(2 * s_ - 1);
  // The initial step: h0, else a given H (adaptive with a step), else the starting step.
  // Replays use it only for frozen steps left over when the sequence runs out.
  double step = options_.initial_step_size > 0.0 ? options_.initial_step_size
                : options_.step_size > 0.0       ? options_.step_size
                                                 : StartingStep(horizon);
  std::size_t next_replay = 0;
  if (full_) d_step_end_ = Eigen::RowVectorXd::Zero(sensitivity_.cols());
  // Twice the nominal elements of the reserved steps (switch groups add some), as the fixed
  // grids reserve theirs (Integrate).
  const auto reserved_steps =
      static_cast<std::size_t>(std::min(options_.max_steps, kReservedSteps));
  result_.step_sequence.reserve(result_.step_sequence.size() + reserved_steps);
  result_.elements.reserve(result_.elements.size() +
                           2 * reserved_steps * static_cast<std::size_t>(options_.finite_elements));
  Snapshot before;             // the state before the current attempt (kept across attempts)
  int unresolved_retries = 0;  // consecutive attempts retried for an unresolved crossing
  int zero_pieces = 0;         // consecutive accepted steps that did not move the time
  for (std::size_t segment = 0; segment + 1 < segment_ends_.size() && !failed(); ++segment) {
    segment_ = segment_control_[segment];
    system_.SetInputs(scene.InputValues(segment_ends_[segment]));
    if (StartsControlSegment(segment) && !smooth_ && !DecideAtBreakpoint()) break;
    const double segment_end = segment_ends_[segment + 1];
    const double reached =
        clock_targets ? kClockTolerance * std::max(1.0, std::fabs(segment_end)) : 0.0;
    while (!failed()) {
      const double position = clock_targets ? y_[clock] : tau_;
      const double rest = segment_end - position;
      if (rest <= reached) break;
      // With time-freezing a frozen step does not move the clock: it never lands.
      const bool frozen = clock_targets && system_.TimeFrozen(a_zero_);
      double length = 0.0;
      bool lands = false;
      if (result_.stats.num_steps >= options_.max_steps) {
        Fail(FesdStatus::kMaxStepsReached, position,
             "max_steps = " + std::to_string(options_.max_steps) + " steps before the final time");
        return;
      }
      system_.ClearNonFinite();
      if (replay) {
        const double entry = next_replay < options_.step_sequence.size()
                                 ? options_.step_sequence[next_replay++]
                                 : 0.0;
        lands = !frozen && (entry == 0.0 || entry >= rest);
        length = lands ? rest : (entry > 0.0 ? entry : step);
      } else {
        if (options_.max_step_size > 0.0) step = std::min(step, options_.max_step_size);
        lands = !frozen && step * (1.0 + kLandingFraction) >= rest;
        length = lands ? rest : step;
      }
      // Running clock at rate 1: landing in numerical time takes the clock distance.
      const double step_end = lands && !clock_targets ? segment_end : tau_ + length;
      if (!replay) Save(&before);  // (replay: not read)
      // Row n_y of sensitivity_ is d(tau - step_end). Step lengths are held fixed (internal
      // differentiation), so a step's end moves with its start, except a landing step whose
      // end is the segment end (a constant; with time-freezing the clock's target).
      if (options_.sensitivities) TrackStepStart(lands, clock_targets);
      capture_piece_ = keep_polynomials_;
      RecyclePolynomials(&piece_);
      ProgressCallback progress;
      std::swap(progress, progress_);  // no progress reports from attempts that may be rejected
      int remaining = options_.finite_elements;
      bool switched = false;
      if (smooth_) {
        AdvanceSmooth(step_end, remaining);
      } else {
        switched = Advance(step_end, &remaining);
      }
      std::swap(progress, progress_);
      capture_piece_ = false;
      if (replay) {
        if (failed()) return;
        result_.step_sequence.push_back(lands ? 0.0 : length);
        ++result_.stats.num_steps;
        if (progress_) progress_(y_[clock]);
        continue;
      }
      const double minimum =
          std::max(options_.min_step_size, kMinStepUlps * std::numeric_limits<double>::epsilon() *
                                               std::max(1.0, std::fabs(tau_)));
      // The attempt's checks: certificates, resolution of the free sides, error estimate.
      const double piece_length = tau_ - before.tau;
      ErrorEstimate estimate;
      double resolution = 0.0;
      if (!failed()) {
        double certificate = 0.0;
        for (std::size_t e = before.elements; e < result_.elements.size(); ++e) {
          certificate = std::max({certificate, result_.elements[e].cross_complementarity,
                                  result_.elements[e].complementarity});
        }
        if (certificate > kMissedSwitchCertificate * options_.event_tolerance) {
          Fail(FesdStatus::kEventLocationFailure, position,
               "an element of the step has complementarity certificate " + Text(certificate) +
                   ": a switch inside it was not located");
        }
      }
      if (!failed()) {
        resolution = IndicatorResolution() / kIndicatorResolution;
        if (!std::isfinite(resolution)) {
          Fail(FesdStatus::kEventLocationFailure, position,
               "a free side is negative between the stages of an element of the step: a switch "
               "inside it was not located");
        }
      }
      if (!failed() &&
          result_.stats.num_unresolved_crossings > before.stats.num_unresolved_crossings &&
          unresolved_retries < kMaxUnresolvedRetries && kFailureFactor * length >= minimum) {
        ++unresolved_retries;
        Restore(before);
        ++result_.stats.num_failed_steps;
        controller.Failed();
        step = kFailureFactor * length;
        continue;
      }
      if (!failed()) {
        estimate = EstimateError(piece_length / horizon, before.elements);
        if (!std::isfinite(estimate.acceptance)) {
          Fail(FesdStatus::kNewtonFailure, position,
               "a comparison solve of the error estimate (the step's interval with another "
               "element count) did not converge");
        }
      }
      if (failed()) {
        // A solve or check failed: retry the step shorter (a switch then falls into a shorter
        // step, with other element lengths around it), down to the minimum step.
        const FesdStatus status = result_.status;
        const std::string reason = result_.message;
        Restore(before);
        ++result_.stats.num_failed_steps;
        controller.Failed();
        step = kFailureFactor * length;
        if (step < minimum) {
          result_.status = status;
          result_.message = reason + " (adaptive: retried with the step halved down to " +
                            Text(length) + ", below which lies min_step_size " + Text(minimum) +
                            ")";
          return;
        }
        continue;
      }
      const double error = std::max(estimate.acceptance, resolution);
      const double proposal = std::max(estimate.proposal, resolution);
      if (!(error <= 1.0)) {
        Restore(before);
        ++result_.stats.num_rejected_steps;
        step = controller.Reject(piece_length, proposal);
        if (step < minimum) {
          Fail(FesdStatus::kStepSizeTooSmall, position,
               "the error estimate (" + Text(error) + " times the tolerance per unit step) of a " +
                   "step of " + Text(piece_length) + " calls for a step below min_step_size " +
                   Text(minimum));
          return;
        }
        continue;
      }
      result_.step_sequence.push_back(lands ? 0.0 : length);
      ++result_.stats.num_steps;
      // The accumulated estimate (FesdStats::error_estimate) and the states' scales, from
      // the accepted step.
      result_.stats.error_estimate +=
          options_.relative_tolerance * (piece_length / horizon) * estimate.proposal;
      scale_.Update(y_);
      step = controller.Accept(piece_length, length, proposal, switched);
      // A switch decided at a step's start leaves a piece of zero length, and the controller
      // then tries the attempted step again (StepController::Accept). Switches decided there
      // again and again without the time moving have no consistent continuation: the run
      // stops at once instead of taking max_steps steps of zero length.
      zero_pieces = piece_length > 0.0 ? 0 : zero_pieces + 1;
      if (zero_pieces > kMaxZeroLengthPieces) {
        Fail(FesdStatus::kStatusDecisionFailure, position,
             "switches were decided at this time " + std::to_string(zero_pieces) +
                 " times in a row without the time moving: no consistent continuation");
        return;
      }
      // The retries start again after a step without an unresolved crossing: next to an
      // undecidable graze every step is unresolved, and retrying each of them again would
      // cost 2^kMaxUnresolvedRetries steps per step without ever deciding it.
      if (result_.stats.num_unresolved_crossings == before.stats.num_unresolved_crossings) {
        unresolved_retries = 0;
      }
      if (progress_) progress_(y_[clock]);
    }
  }
}

// Hairer, Norsett & Wanner's starting step (../common/step_size.hpp) for order p = 2s - 1 on
// the scene states, with F at the consistent algebraic values of the initial statuses, times
// the elements per step (the heuristic sizes one collocation element). Where the states do
// not move at t0 the heuristic has no information: a state at rest while a moving set or a
// switching function of time approaches (S2) starts with kQuietStart of the horizon instead,
// and the step grows from there.
double FesdRun::StartingStep(double span) {
  constexpr double kQuietStart = 1e-3;
  const double rtol = options_.relative_tolerance;
  Vector weights(nx_);
  for (int i = 0; i < nx_; ++i) {
    weights[i] =
        scale_.AbsoluteTolerance(i, options_.absolute_tolerance, rtol) + rtol * std::fabs(y_[i]);
  }
  PointEvaluation point;
  system_.Evaluate(y_, ConsistentGuess(y_, v()), Derivatives::kNone, &point);
  const Vector f0 = point.F;
  const double h = internal::StartingStep(
      y_, f0, weights, nx_, 2 * s_ - 1, span, kQuietStart * span,
      [this, &point](const Vector& y1, Vector* f1) {
        system_.Evaluate(y1, ConsistentGuess(y1, v()), Derivatives::kNone, &point);
        *f1 = point.F;
      });
  // The trial evaluations beyond t0 are not the run's: a non-finite value there says nothing.
  system_.ClearNonFinite();
  return std::min(options_.finite_elements * h, span);
}

FesdRun::ErrorEstimate FesdRun::EstimateError(double fraction, std::size_t first_element) {
  MOREAU_ASSERT(!piece_.empty(), "adaptive step without committed elements");
  const int m = static_cast<int>(piece_.size());
  const double h = piece_.front().h;
  const Vector& y_start = piece_.front().y0;
  Vector& y_end = comparison_.piece_end;  // kept (no allocation per step)
  piece_.back().End(&y_end);
  const std::vector<bool>& a_zero = piece_.front().a_zero;
  const double p = 2.0 * s_ - 1.0;
  // How accurately the compared solutions are known (see kNewtonNoise); the smooth kernel
  // stops on increments below the Newton tolerance.
  double residual = smooth_ ? options_.newton.tolerance : 0.0;
  for (std::size_t e = first_element; e < result_.elements.size(); ++e) {
    residual = std::max(residual, result_.elements[e].newton_residual);
  }
  comparison_residual_ = 0.0;
  const double infinity = std::numeric_limits<double>::infinity();
  const ErrorEstimate failed{infinity, infinity};
  Vector& local = comparison_.local;
  if (m >= 2) {
    Vector& coarse = comparison_.coarse;
    if (!SolveComparisonElement(y_start, 0.0, m * h, a_zero, &coarse)) return failed;
    local = (coarse - y_end) / (std::pow(m, p) - 1.0);
  } else {
    Vector &half = comparison_.half, &fine = comparison_.fine;
    if (!SolveComparisonElement(y_start, 0.0, 0.5 * h, a_zero, &half) ||
        !SolveComparisonElement(half, 0.5 * h, 0.5 * h, a_zero, &fine)) {
      return failed;
    }
    const double power = std::pow(2.0, p);
    local = (y_end - fine) * (power / (power - 1.0));
  }
  residual = std::max(residual, comparison_residual_);
  ErrorEstimate estimate;
  for (int i = 0; i < ny_; ++i) {
    const double size = std::max(std::fabs(y_start[i]), std::fabs(y_end[i]));
    const double atol =
        scale_.AbsoluteTolerance(i, options_.absolute_tolerance, options_.relative_tolerance);
    const double allowed =
        std::max((atol + options_.relative_tolerance * size) * fraction,
                 kNewtonNoise * std::numeric_limits<double>::epsilon() * (1.0 + size));
    const double noise = kNewtonNoise * residual * (1.0 + size);
    estimate.proposal = std::max(estimate.proposal, std::fabs(local[i]) / allowed);
    estimate.acceptance =
        std::max(estimate.acceptance, std::fabs(local[i]) / std::max(allowed, noise));
  }
  return estimate;
}

const FesdRun::ResolutionGrid& FesdRun::Resolution() const {
  // The grid depends on the stage count alone: made once per process for each (a run of a
  // small scene spent 5% of its instructions making it anew).
  static std::array<std::once_flag, kMaxRadauStages + 1> made;
  static std::array<ResolutionGrid, kMaxRadauStages + 1> grids;
  MOREAU_ASSERT(s_ >= 1 && s_ <= kMaxRadauStages, "Resolution: stages out of range");
  const auto s = static_cast<std::size_t>(s_);
  std::call_once(made[s], [&] { MakeResolutionGrid(tableau_, &grids[s]); });
  return grids[s];
}

void FesdRun::MakeResolutionGrid(const RadauTableau& tableau, ResolutionGrid* made) {
  ResolutionGrid& grid = *made;
  const int stages = tableau.stages;
  // Nodes: the element start and the stages; test points: the midpoints of the two widest gaps
  // between nodes, where the interpolation error of a function the element does not resolve
  // is largest.
  grid.nodes = {0.0};
  for (int i = 0; i < stages; ++i) grid.nodes.push_back(tableau.c[i]);
  const std::vector<double>& nodes = grid.nodes;
  std::vector<std::pair<double, double>> gaps;  // (width, midpoint)
  for (std::size_t j = 0; j + 1 < nodes.size(); ++j) {
    gaps.emplace_back(nodes[j + 1] - nodes[j], 0.5 * (nodes[j] + nodes[j + 1]));
  }
  std::sort(gaps.rbegin(), gaps.rend());
  for (std::size_t j = 0; j < std::min<std::size_t>(2, gaps.size()); ++j) {
    grid.tests.push_back(gaps[j].second);
  }
  const auto n = static_cast<Eigen::Index>(nodes.size());
  // Row: the Lagrange weights of the nodes at theta.
  auto lagrange = [&](double theta, Matrix* weights, Eigen::Index row) {
    for (Eigen::Index j = 0; j < n; ++j) {
      double basis = 1.0;
      for (Eigen::Index l = 0; l < n; ++l) {
        if (l != j) basis *= (theta - nodes[l]) / (nodes[j] - nodes[l]);
      }
      (*weights)(row, j) = basis;
    }
  };
  grid.test_weights.resize(static_cast<Eigen::Index>(grid.tests.size()), n);
  for (std::size_t t = 0; t < grid.tests.size(); ++t) {
    lagrange(grid.tests[t], &grid.test_weights, static_cast<Eigen::Index>(t));
  }
  for (double theta : grid.nodes)
    grid.node_state_weights.push_back(tableau.InterpolationWeights(theta));
  for (double theta : grid.tests)
    grid.test_state_weights.push_back(tableau.InterpolationWeights(theta));
  grid.differences.resize(n, n);
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index l = 0; l < n; ++l) grid.differences(l, j) = nodes[j] - nodes[l];
  }
  grid.dip_weights.resize(kDipSamples, n);
  for (int m = 0; m < kDipSamples; ++m) lagrange(DipSample(m), &grid.dip_weights, m);
}

double FesdRun::IndicatorResolution() const {
  if (np_ == 0) return 0.0;
  const ResolutionGrid& grid = Resolution();
  const auto n = static_cast<Eigen::Index>(grid.nodes.size());
  double worst = 0.0;
  // Kept across elements and calls (no allocation per step, element and test point).
  ResolutionBuffers& buffers = resolution_;
  IndicatorEvaluation& at = buffers.at;
  std::vector<int>& continuous = buffers.continuous;
  Vector &v = buffers.v, &y = buffers.y, &predicted = buffers.predicted;
  Matrix &node_values = buffers.node_values, &dense = buffers.dense;
  node_values.resize(n, np_);
  for (const ElementPolynomial& element : piece_) {
    continuous.clear();
    for (int k = 0; k < np_; ++k) {
      const bool continuous_a =
          system_.pairs()[static_cast<std::size_t>(k)].continuous == ContinuousSide::kA;
      // The free side is continuous when the status keeps the jump side at zero.
      if (element.a_zero[static_cast<std::size_t>(k)] != continuous_a) continuous.push_back(k);
    }
    if (continuous.empty()) continue;
    v = element.algebraic.col(0);
    // The free sides at the point of the element's collocation polynomial whose interpolation
    // weights (RadauTableau::InterpolationWeights) are `state_weights`.
    auto indicators = [&](const Vector& state_weights) -> const Vector& {
      PolynomialPoint(element.y0, element.increments, state_weights, &y);
      system_.EvaluateEventIndicators(y, v, element.a_zero, Derivatives::kNone, &at);
      return at.values;
    };
    for (Eigen::Index j = 0; j < n; ++j) {
      node_values.row(j) =
          indicators(grid.node_state_weights[static_cast<std::size_t>(j)]).transpose();
    }
    // The free sides at a point (`state_weights` as above) against their interpolant through
    // the nodes (`weights`, a row of Lagrange weights). Returns false at a negative value: a
    // switch that was not located.
    auto test = [&](const Vector& state_weights, const auto& weights) {
      const Vector& actual = indicators(state_weights);
      predicted.setZero(np_);
      for (Eigen::Index j = 0; j < n; ++j) predicted += weights[j] * node_values.row(j).transpose();
      for (int k : continuous) {
        double low = actual[k], high = actual[k], size = std::fabs(actual[k]);
        double nearest = std::fabs(actual[k]);  // closest approach to zero
        for (Eigen::Index j = 0; j < n; ++j) {
          const double value = node_values(j, k);
          low = std::min(low, value);
          high = std::max(high, value);
          size = std::max(size, std::fabs(value));
          nearest = std::min(nearest, std::fabs(value));
        }
        // A free side negative between the checked points: a switch that was not located.
        if (actual[k] < -options_.event_tolerance * std::max(1.0, std::fabs(node_values(0, k)))) {
          return false;
        }
        // Relative to the variation over the element, or to the distance from zero where that
        // is larger (a free side that stays far from zero cannot hide a pair of roots).
        worst =
            std::max(worst, std::fabs(actual[k] - predicted[k]) /
                                (std::max(high - low, nearest) + kIndicatorFloor * (1.0 + size)));
      }
      return true;
    };
    for (std::size_t t = 0; t < grid.tests.size(); ++t) {
      if (!test(grid.test_state_weights[t], grid.test_weights.row(static_cast<Eigen::Index>(t)))) {
        return std::numeric_limits<double>::infinity();
      }
    }
    // A free side positive at every node can still dip below zero between them: a contact that
    // begins and ends inside one element (two bodies in free flight, whose distance is quadratic
    // in t, pass through each other). Where the interpolant's minimum over the element is below
    // zero, the free side is evaluated there; negative, it is a switch that was not located.
    // Where it is not, the interpolant was wrong there and its miss counts as resolution.
    // Only the continuous free sides' columns are read: each is the matrix-vector product of
    // the weights with its node values (the same sums, from zero over the nodes in order, as
    // the matrix product of all columns; no fused multiply-add on our targets).
    dense.resize(kDipSamples, np_);
    for (int k : continuous) dense.col(k).noalias() = grid.dip_weights * node_values.col(k);
    for (int k : continuous) {
      Eigen::Index lowest = 0;
      const double minimum = dense.col(k).minCoeff(&lowest);
      if (minimum < -options_.event_tolerance * std::max(1.0, std::fabs(node_values(0, k))) &&
          !test(tableau_.InterpolationWeights(DipSample(static_cast<int>(lowest))),
                grid.dip_weights.row(lowest))) {
        return std::numeric_limits<double>::infinity();
      }
    }
  }
  return worst;
}

void FesdRun::PieceState(double offset, Vector* y, Vector* z) const {
  const double h = piece_.front().h;
  const int m = static_cast<int>(piece_.size());
  const int e = std::clamp(static_cast<int>(std::floor(offset / h)), 0, m - 1);
  const ElementPolynomial& element = piece_[static_cast<std::size_t>(e)];
  const double theta = offset / h - e;
  tableau_.InterpolationWeights(theta, &piece_weights_);
  PolynomialPoint(element.y0, element.increments, piece_weights_, y);
  if (nz_ == 0) {
    z->resize(0);
    return;
  }
  Eigen::Index nearest = 0;
  (tableau_.c.array() - theta).abs().minCoeff(&nearest);
  *z = element.algebraic.col(nearest);
}

bool FesdRun::SolveComparisonElement(const Vector& y0, double t0, double h,
                                     const std::vector<bool>& a_zero, Vector* y_end) {
  // Kept across comparisons (no allocation per comparison element).
  Vector& base = comparison_.base;
  Vector& z = comparison_.z;
  PieceState(t0, &base, &z);
  std::vector<Vector>& states = comparison_.states;
  std::vector<Vector>& algebraic = comparison_.algebraic;
  states.resize(static_cast<std::size_t>(s_));
  algebraic.resize(static_cast<std::size_t>(s_));
  for (int i = 0; i < s_; ++i) {
    PieceState(t0 + tableau_.c[i] * h, &states[static_cast<std::size_t>(i)],
               &algebraic[static_cast<std::size_t>(i)]);
  }
  // Without pairs, or where the statuses leave a smooth field (smooth elements, section 5),
  // the comparison solution is a Radau IIA step of that field: the states of the full element
  // system's solution with these statuses (whose algebraic values are functions of them), to
  // the Newton tolerance, at the cost of the field's Newton.
  SmoothCollocationSolver* field = smooth_ ? smooth_.get() : SmoothFieldSolver(a_zero);
  if (field != nullptr) {
    Matrix& increments = comparison_.increments;
    increments.resize(ny_, s_);
    for (int i = 0; i < s_; ++i) increments.col(i) = states[static_cast<std::size_t>(i)] - base;
    SmoothCollocationSolver::Stopping stopping;
    stopping.tolerance = options_.newton.tolerance;
    stopping.max_iterations = options_.newton.max_iterations;
    // Relays: simplified Newton from the field's last Jacobians, as for their smooth elements
    // (SmoothElementGuess); the comparison is known to the tolerance either way.
    stopping.simplified = reduction_ == Reduction::kRelayModes;
    stopping.reuse_jacobian = stopping.simplified;
    const long factorizations = field->num_factorizations();
    int iterations = 0;
    const auto outcome = field->Solve(h, y0, stopping, &increments, &iterations);
    result_.stats.num_newton_iterations += iterations;
    factorizations_ += field->num_factorizations() - factorizations;
    if (outcome == SmoothCollocationSolver::Outcome::kConverged) {
      // Known to its last Newton increment (relative to 1 + |y0|, as kNewtonNoise scales).
      if (!smooth_) comparison_residual_ = std::max(comparison_residual_, field->last_increment());
      *y_end = y0 + increments.col(s_ - 1);
      return true;
    }
    if (smooth_) return false;  // otherwise the full element system below
  }
  GroupSetup& setup = comparison_.setup;  // only these members are ever set
  setup.y_start = y0;
  setup.a_zero = a_zero;
  setup.h_fixed = h;
  group_.Configure(setup);
  const CollocationStages& stages = group_.element(0);
  Vector& guess = comparison_.guess;
  guess.resize(group_.num_unknowns());
  for (int i = 0; i < s_; ++i) {
    guess.segment(stages.state_offset(i), ny_) = states[static_cast<std::size_t>(i)] - base;
    guess.segment(stages.algebraic_offset(i), nz_) = algebraic[static_cast<std::size_t>(i)];
  }
  SemismoothNewtonResult& solved = comparison_.solved;
  newton_.Solve(group_, guess, &solved);
  CountNewton(solved);
  if (!solved.converged()) return false;
  comparison_residual_ = std::max(comparison_residual_, solved.residual_norm);
  group_.EndState(solved.solution, y_end);
  return true;
}

}  // namespace moreau::internal
