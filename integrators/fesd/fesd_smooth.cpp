// Smooth elements and reduced switch groups (docs/fesd-formulation.md section 5): which
// statuses leave a smooth field, its Radau IIA solver, the guess of a smooth element, and the
// group that ends on a switch solved as Radau IIA steps of that field with its length the root
// of the switching indicator.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <variant>
#include <vector>

#include "fesd_run.hpp"

namespace moreau::internal {

// --- smooth elements ----------------------------------------------------------------------

void FesdRun::InitializeSmoothFields() {
  const Scene& scene = system_.scene();
  if (!options_.reduce_smooth_elements || filter_.enabled() || scene.effects.empty()) return;
  if (system_.time_freezing()) {
    // Relays only (their state derivative depends on z through theta alone); each relay's
    // theta unknowns found by name (docs/lowering.md: "<relay>.theta_<region>").
    for (const Effect& effect : scene.effects) {
      if (!std::holds_alternative<HysteresisRelay>(effect)) return;
    }
    const char* const regions[] = {"mode_A", "to_A", "to_B", "mode_B"};
    const std::vector<std::string>& names = system_.algebraic_names();
    auto index = [&](const std::string& name) {
      const auto found = std::find(names.begin(), names.end(), name);
      return found == names.end() ? -1 : static_cast<int>(found - names.begin());
    };
    std::vector<RelayUnknowns> theta;
    for (const std::string& relay : system_.relay_names()) {
      RelayUnknowns indices;
      for (std::size_t k = 0; k < 4; ++k) {
        indices.theta[k] = index(relay + ".theta_" + regions[k]);
        indices.lambda[k] = index(relay + ".lambda_" + regions[k]);
        if (indices.theta[k] < 0 || indices.lambda[k] < 0) return;
      }
      indices.mu = index(relay + ".mu");
      if (indices.mu < 0) return;
      theta.push_back(indices);
    }
    // The pairs are (theta, lambda) of the regions, relay by relay (lower_hysteresis.cpp).
    if (np_ != 4 * static_cast<int>(theta.size())) return;
    relay_theta_ = std::move(theta);
    reduction_ = Reduction::kRelayModes;
    smooth_fields_.resize(1);  // the field of the lowered system itself, built on first use
    return;
  }
  if (ny_ != nx_ + 1) return;
  const auto* switching = std::get_if<SwitchingSurfaces>(&scene.effects.front());
  if (switching != nullptr) {
    // Stewart's form, one switching effect and nothing else: a field per mode.
    if (options_.switching_form != SwitchingForm::kStewart || !scene.dynamics.empty() ||
        scene.effects.size() != 1 || static_cast<int>(switching->modes.size()) != np_) {
      return;
    }
    reduction_ = Reduction::kStewartMode;
    smooth_fields_.resize(static_cast<std::size_t>(np_));  // built on first use
    return;
  }
  for (const Effect& effect : scene.effects) {
    if (!std::holds_alternative<MovingSet>(effect)) return;
  }
  reduction_ = Reduction::kFreeMovingSets;  // one field: the scene's dynamics
  smooth_fields_.resize(1);
}

int FesdRun::SmoothField(const std::vector<bool>& a_zero) const {
  switch (reduction_) {
    case Reduction::kNone:
      return -1;
    case Reduction::kStewartMode: {
      // Stewart's pair k: theta_k ⟂ lambda_k, b = lambda_k = 0 kept (a_zero false) iff mode k
      // is active; with one active mode, e^T theta = 1 and theta_j = 0 (j != k) give theta =
      // e_k, so x' = f_k(x) at every stage, and lambda, mu follow from the state (g - lambda -
      // mu e = 0).
      int mode = -1;
      for (int k = 0; k < np_; ++k) {
        if (a_zero[static_cast<std::size_t>(k)]) continue;
        if (mode >= 0) return -1;  // a sliding mode: theta is not a unit vector
        mode = k;
      }
      return mode;
    }
    case Reduction::kFreeMovingSets:
      // Moving-set pair k: c_k ⟂ lambda_k; with b = lambda_k = 0 kept (a_zero false) for every
      // constraint, x' = f(x) + P grad c lambda = f(x).
      for (int k = 0; k < np_; ++k) {
        if (a_zero[static_cast<std::size_t>(k)]) return -1;  // a constraint is active
      }
      return 0;
    case Reduction::kRelayModes:
      return RelayTheta(a_zero, nullptr) ? 0 : -1;
  }
  return -1;
}

bool FesdRun::RelayTheta(const std::vector<bool>& a_zero, Vector* z) const {
  for (std::size_t i = 0; i < relay_theta_.size(); ++i) {
    // Active regions of relay i (pair 4 i + k: b = lambda_k = 0 kept iff a_zero is false).
    std::array<bool, 4> active{};
    int count = 0;
    for (std::size_t k = 0; k < 4; ++k) {
      active[k] = !a_zero[4 * i + k];
      count += active[k] ? 1 : 0;
    }
    std::array<double, 4> theta{};
    if (count == 1) {
      for (std::size_t k = 0; k < 4; ++k) theta[k] = active[k] ? 1.0 : 0.0;
    } else if (count == 2 && ((active[0] && active[1]) || (active[2] && active[3]))) {
      for (std::size_t k = 0; k < 4; ++k) theta[k] = active[k] ? 0.5 : 0.0;
    } else {
      return false;
    }
    if (z == nullptr) continue;
    for (std::size_t k = 0; k < 4; ++k) (*z)[relay_theta_[i].theta[k]] = theta[k];
  }
  return true;
}

const Vector& FesdRun::RelayStageAlgebraic(const Vector& y) const {
  // lambda = g - min g, mu = min g (InitialAlgebraicGuess): g_k = lambda_k + mu.
  Vector& z = relay_stage_z_;
  z = ConsistentGuess(y, z_guess_);
  for (std::size_t i = 0; i < relay_theta_.size(); ++i) {
    const RelayUnknowns& relay = relay_theta_[i];
    std::size_t active = 0;
    while (active < 3 && a_zero_[4 * i + active]) ++active;
    const double g_active = z[relay.lambda[active]] + z[relay.mu];
    for (std::size_t k = 0; k < 4; ++k) {
      z[relay.theta[k]] = relay_field_z_[relay.theta[k]];
      if (k != active) z[relay.lambda[k]] += z[relay.mu] - g_active;
    }
    z[relay.lambda[active]] = 0.0;
    z[relay.mu] = g_active;
  }
  return z;
}

internal::SmoothCollocationSolver* FesdRun::SmoothFieldSolver(const std::vector<bool>& a_zero) {
  const int index = SmoothField(a_zero);
  if (index < 0) return nullptr;
  FieldSolver& field = smooth_fields_[static_cast<std::size_t>(index)];
  if (reduction_ == Reduction::kRelayModes) {
    // The lowered system itself with theta held at its constant values (RelayTheta); the
    // other algebraic unknowns do not enter F.
    if (field.solver == nullptr) {
      field.solver = std::make_unique<internal::SmoothCollocationSolver>(
          &system_, s_, options_.newton.linear_solver);
    }
    relay_field_z_.setZero(nz_);
    RelayTheta(a_zero, &relay_field_z_);
    field.solver->SetFixedAlgebraic(relay_field_z_);
    return field.solver.get();
  }
  if (reduction_ == Reduction::kStewartMode) {
    // The lowered system itself, evaluating mode `index`'s field alone (EvaluateField's
    // switching_mode): the same F and F_y as a system lowered from that mode's dynamics, without
    // lowering one per mode in every run. The algebraic unknowns are not read.
    if (field.solver == nullptr) {
      field.solver = std::make_unique<internal::SmoothCollocationSolver>(
          &system_, s_, options_.newton.linear_solver, index);
      field.solver->SetFixedAlgebraic(Vector::Zero(nz_));
    }
    return field.solver.get();
  }
  if (field.solver == nullptr) {
    // The scene without its effects, built member by member: copying it whole would clone
    // every effect's functions only to drop them (SmoothFunction copies are deep).
    const Scene& scene = system_.scene();
    Scene smooth;
    smooth.name = scene.name;
    smooth.state_names = scene.state_names;
    smooth.initial_state = scene.initial_state;
    smooth.initial_time = scene.initial_time;
    smooth.final_time = scene.final_time;
    smooth.parameters = scene.parameters;
    smooth.inputs = scene.inputs;
    smooth.time_scale_input = scene.time_scale_input;
    smooth.dynamics = scene.dynamics;  // kFreeMovingSets: the dynamics without the sets
    field.system = std::make_unique<LoweredSystem>(smooth, Lowering(options_));
    if (field.system->num_states() != ny_ || field.system->num_algebraic() != 0) {
      reduction_ = Reduction::kNone;  // another layout: never reduce
      return nullptr;
    }
    field.solver = std::make_unique<internal::SmoothCollocationSolver>(
        field.system.get(), s_, options_.newton.linear_solver);
  }
  // The run may have changed parameters (FesdIntegrator) and inputs (control segments).
  field.system->SetParameters(system_.parameters());
  field.system->SetInputs(system_.inputs());
  return field.solver.get();
}

bool FesdRun::SmoothElementGuess(const Vector& y0, double h, const Vector* previous, Vector* w,
                                 int* iterations, long* factorizations) {
  internal::SmoothCollocationSolver* solver = SmoothFieldSolver(a_zero_);
  if (solver == nullptr) return false;
  const internal::CollocationStages& stages = group_.element(0);
  // Stage increments extrapolated as for the full element; algebraic values set below.
  stages.InitialGuess(y0, h, previous, previous != nullptr ? h : 0.0, z_guess_, w,
                      /*algebraic=*/false);
  smooth_field_z_.resize(ny_, s_);
  for (int i = 0; i < s_; ++i) smooth_field_z_.col(i) = w->segment(stages.state_offset(i), ny_);
  internal::SmoothCollocationSolver::Stopping stopping;
  stopping.tolerance = options_.newton.tolerance;
  stopping.max_iterations = options_.newton.max_iterations;
  // Relays: simplified Newton from the field's last Jacobians (the field is the lowered
  // system with theta fixed; its derivative evaluation costs several value evaluations). The
  // element is then checked on the full system.
  stopping.simplified = reduction_ == Reduction::kRelayModes;
  stopping.reuse_jacobian = stopping.simplified;
  const long before = solver->num_factorizations();
  const auto outcome = solver->Solve(h, y0, stopping, &smooth_field_z_, iterations);
  *factorizations = solver->num_factorizations() - before;
  if (outcome != internal::SmoothCollocationSolver::Outcome::kConverged) return false;
  for (int i = 0; i < s_; ++i) {
    w->segment(stages.state_offset(i), ny_) = smooth_field_z_.col(i);
    stage_y_ = y0 + smooth_field_z_.col(i);
    // Both return their kept result (const Vector&): the conditional copies nothing.
    w->segment(stages.algebraic_offset(i), nz_) = reduction_ == Reduction::kRelayModes
                                                      ? RelayStageAlgebraic(stage_y_)
                                                      : ConsistentGuess(stage_y_, z_guess_);
  }
  return true;
}

// --- reduced switch groups --------------------------------------------------------------

bool FesdRun::ReducedSwitchGuess(const std::vector<Vector>& trial_w, const Vector& y_start,
                                 double h_trial, int element, int m, double h_guess, int pair,
                                 double weight, int power, Vector* w, int* iterations,
                                 long* factorizations) {
  // The scaled indicator is driven below this fraction of the Newton tolerance: the event row
  // (Fischer-Burmeister of a positive length slack and the indicator, about the indicator
  // itself there) then holds in the full check with margin, and the switch is located at least
  // as accurately as by the full group solve, which stops when its residual (the event row
  // included) is below the tolerance.
  constexpr double kIndicatorFraction = 0.1;
  // Indicator evaluations (each m Radau IIA steps of the field) before giving up.
  constexpr int kMaxEvaluations = 10;
  // Relays only. Elsewhere (one Stewart mode, free moving sets) the reduced group is as valid,
  // but the full group solve it replaces stops at its tolerance (F1, s = 2: the switch at pi
  // off by 2.8e-13, the reduced group's by 4e-16), so the fixed-step results would move by that
  // much (FesdTest.SmoothElementsAgreeWithTheFullSolve holds them to 1e-13 of the full solve).
  if (reduction_ != Reduction::kRelayModes) return false;
  internal::SmoothCollocationSolver* solver = SmoothFieldSolver(a_zero_);
  if (solver == nullptr || m > static_cast<int>(trial_w.size())) return false;
  const internal::CollocationStages& stages = group_.element(0);
  internal::SmoothCollocationSolver::Stopping stopping;
  stopping.tolerance = options_.newton.tolerance;
  stopping.max_iterations = options_.newton.max_iterations;
  // Simplified Newton from the field's last stage Jacobians (the root iteration re-solves the
  // same field from the same start, over lengths that it changes ever less).
  stopping.simplified = true;
  stopping.reuse_jacobian = true;
  const long factorizations_before = solver->num_factorizations();
  // Stage increments of the m elements, for the length z_h (first guess: the trial elements).
  // (kept across groups: no allocation per group)
  std::vector<Matrix>& z = switch_z_;
  if (static_cast<int>(z.size()) < m) z.resize(static_cast<std::size_t>(m));
  for (int e = 0; e < m; ++e) z[static_cast<std::size_t>(e)].resize(ny_, s_);
  for (int e = 0; e < m; ++e) {
    for (int i = 0; i < s_; ++i) {
      z[static_cast<std::size_t>(e)].col(i) =
          trial_w[static_cast<std::size_t>(e)].segment(stages.state_offset(i), ny_);
    }
  }
  double z_h = h_trial;
  // (kept across groups: no allocation per group)
  SwitchBuffers& buffers = switch_buffers_;
  Vector &level = buffers.level, &solved_v = buffers.solved_v, &y_end = buffers.y_end;
  level = v();
  IndicatorEvaluation& indicator = indicators_;
  // A continuous free side is a function of the state (the velocity level does not enter it
  // for the blocks at hand, and where it would, the last iterate is checked with it below):
  // the iteration then evaluates it at v() without solving the velocity level.
  bool solve_level = FreeSideIsJump(pair);
  // Scaled indicator at the end state y_end (velocity level from `level`, which is updated).
  auto scaled_indicator = [&](double h) {
    if (solve_level) {
      if (!system_.SolveVelocityLevel(y_end, a_zero_, level, &solved_v)) {
        return std::numeric_limits<double>::quiet_NaN();
      }
      level = solved_v;
    }
    system_.EvaluateEventIndicators(y_end, level, a_zero_, Derivatives::kNone, &indicator);
    return weight * indicator.values[pair] / std::pow(h / h_trial, power);
  };
  // The m elements of length h from y_start (increments rescaled from z_h as a guess).
  // Increments for the length h from those for z_h: the collocation polynomial of each
  // element evaluated at the new stage times c_i h / z_h (a guess accurate to the change in h
  // times the element's local error, where rescaling the increments is accurate to first order
  // only; the secant steps change h by ever less).
  Matrix& rescale = buffers.rescale;
  rescale.resize(s_, s_);
  auto solve = [&](double h) {
    for (int i = 0; i < s_; ++i) {
      tableau_.InterpolationWeights(tableau_.c[i] * h / z_h, &buffers.weights);
      rescale.col(i) = buffers.weights;
    }
    y_end = y_start;
    for (int e = 0; e < m; ++e) {
      Matrix& ze = z[static_cast<std::size_t>(e)];
      // ze = ze * rescale, through a kept matrix (the same product, without a temporary).
      buffers.product.noalias() = ze * rescale;
      ze.swap(buffers.product);
      int its = 0;
      const auto outcome = solver->Solve(h, y_end, stopping, &ze, &its);
      *iterations += its;
      if (outcome != internal::SmoothCollocationSolver::Outcome::kConverged) {
        z_h = h;
        return std::numeric_limits<double>::quiet_NaN();
      }
      y_end += ze.col(s_ - 1);
    }
    z_h = h;
    return scaled_indicator(h);
  };
  *iterations = 0;
  // h_trial: the trial elements themselves (the same equations from the same start).
  y_end = y_start;
  for (int e = 0; e < m; ++e) y_end += z[static_cast<std::size_t>(e)].col(s_ - 1);
  double a = h_trial, fa = scaled_indicator(h_trial);
  double b = CrossingGuess(trial_w, y_start, h_trial, element, pair, m, h_guess), fb = solve(b);
  const double tolerance = kIndicatorFraction * options_.newton.tolerance;
  const double h_max = group_.setup().h_max;
  int evaluation = 1;
  if (!solve_level && std::isfinite(fb) && std::fabs(fb) > tolerance) {
    // A Newton step from b where the trial end h_trial is far (a secant through it is not):
    // the end state moves with the common length h at m F(y_end) (the flow of the field over
    // m elements, to the elements' local error), so f'(h) = weight (d iota/dy) m F(y_end) /
    // (h / h_trial)^p - p f(h) / h.
    PointEvaluation& field = switch_field_;
    system_.EvaluateField(y_end, relay_field_z_, Derivatives::kNone, &field);
    system_.EvaluateEventIndicators(y_end, level, a_zero_, Derivatives::kStates, &indicator);
    const double rate = m * indicator.d_y.Row(pair).dot(field.F);
    const double slope = weight * rate / std::pow(b / h_trial, power) - power * fb / b;
    const double c = b - fb / slope;
    if (std::isfinite(c) && c > 0.0 && c <= h_max) {
      a = b;
      fa = fb;
      b = c;
      fb = solve(c);
      ++evaluation;
    }
  }
  // Secant steps through the last two lengths; once two values of opposite signs bracket the
  // root, a step that leaves the bracket is replaced by the bracket's false position.
  bool has_negative = false, has_positive = false;
  double negative = 0.0, f_negative = 0.0, positive = 0.0, f_positive = 0.0;
  auto bracket = [&](double h, double f) {
    if (f < 0.0) {
      has_negative = true;
      negative = h;
      f_negative = f;
    } else if (f > 0.0) {
      has_positive = true;
      positive = h;
      f_positive = f;
    }
  };
  bracket(a, fa);
  bracket(b, fb);
  bool found = false;
  for (; evaluation <= kMaxEvaluations; ++evaluation) {
    if (!std::isfinite(fa) || !std::isfinite(fb)) break;
    if (std::fabs(fb) <= tolerance) {
      if (solve_level) {
        found = true;
        break;
      }
      // The root with the consistent velocity level at the end state (the group's v_end).
      solve_level = true;
      fb = scaled_indicator(b);
      continue;
    }
    if (fa == fb) break;
    double c = b - fb * (b - a) / (fb - fa);
    if (has_negative && has_positive &&
        !(c > std::min(negative, positive) && c < std::max(negative, positive))) {
      c = positive - f_positive * (positive - negative) / (f_positive - f_negative);
    }
    if (!(c > 0.0 && c <= h_max)) break;
    a = b;
    fa = fb;
    b = c;
    fb = solve(c);
    bracket(b, fb);
  }
  *factorizations = solver->num_factorizations() - factorizations_before;
  if (!found) return false;
  if (z_h != b) solve(b);  // z holds the last evaluation's elements
  // The group's unknowns at h = b.
  w->setZero(group_.num_unknowns());
  Vector y0 = y_start;
  for (int e = 0; e < m; ++e) {
    const Matrix& ze = z[static_cast<std::size_t>(e)];
    auto unknowns = w->segment(group_.element_offset(e), group_.element_size());
    for (int i = 0; i < s_; ++i) {
      unknowns.segment(stages.state_offset(i), ny_) = ze.col(i);
      stage_y_ = y0 + ze.col(i);
      unknowns.segment(stages.algebraic_offset(i), nz_) = RelayStageAlgebraic(stage_y_);
    }
    y0 += ze.col(s_ - 1);
  }
  w->segment(group_.v_offset(), nz_) = level;
  (*w)[group_.h_index()] = b;
  return true;
}

double FesdRun::CrossingGuess(const std::vector<Vector>& trial_w, const Vector& y_start,
                              double h_trial, int element, int pair, int m, double h_guess) {
  // Bisection steps on the interpolant (no system evaluations): 2^-40 of a gap.
  constexpr int kBisections = 40;
  if (FreeSideIsJump(pair) || element >= static_cast<int>(trial_w.size())) return h_guess;
  const internal::CollocationStages& stages = group_.element(0);
  const Vector& w = trial_w[static_cast<std::size_t>(element)];
  Vector y0 = y_start;
  for (int e = 0; e < element; ++e) {
    y0 += trial_w[static_cast<std::size_t>(e)].segment(stages.state_offset(s_ - 1), ny_);
  }
  // The nodes 0, c_1, ..., c_s and their differences are the tableau's (Resolution: made once
  // per run); the node values are kept across calls (no allocation per switch).
  const ResolutionGrid& grid = Resolution();
  const std::vector<double>& nodes = grid.nodes;
  std::vector<double>& values = crossing_values_;
  values.clear();
  IndicatorEvaluation& at = indicators_;
  system_.EvaluateEventIndicators(y0, v(), a_zero_, Derivatives::kNone, &at);
  values.push_back(at.values[pair]);
  for (int i = 0; i < s_; ++i) {
    stage_y_ = y0 + w.segment(stages.state_offset(i), ny_);
    system_.EvaluateEventIndicators(stage_y_, v(), a_zero_, Derivatives::kNone, &at);
    values.push_back(at.values[pair]);
  }
  // The Lagrange interpolant through the nodes: the basis of node j is the product over l != j
  // of (theta - nodes[l]) / (nodes[j] - nodes[l]), in the order of l; theta - nodes[l] is formed
  // once per theta (the same value in every basis).
  const std::size_t count = nodes.size();
  std::array<double, kMaxRadauStages + 1> offsets{};
  MOREAU_ASSERT(count <= offsets.size(), "CrossingGuess: more nodes than stages + 1");
  auto interpolant = [&](double theta) {
    for (std::size_t l = 0; l < count; ++l) offsets[l] = theta - nodes[l];
    double sum = 0.0;
    for (std::size_t j = 0; j < count; ++j) {
      const double* difference = grid.differences.col(static_cast<Eigen::Index>(j)).data();
      double basis = 1.0;
      for (std::size_t l = 0; l < count; ++l) {
        if (l != j) basis *= offsets[l] / difference[l];
      }
      sum += basis * values[j];
    }
    return sum;
  };
  for (std::size_t j = 1; j < nodes.size(); ++j) {
    if (!(values[j - 1] >= 0.0 && values[j] < 0.0)) continue;
    double low = nodes[j - 1], high = nodes[j];
    for (int k = 0; k < kBisections; ++k) {
      const double middle = 0.5 * (low + high);
      (interpolant(middle) >= 0.0 ? low : high) = middle;
    }
    const double h = (element + 0.5 * (low + high)) * h_trial / m;
    return h > 0.0 && h <= group_.setup().h_max ? h : h_guess;
  }
  return h_guess;
}

}  // namespace moreau::internal
