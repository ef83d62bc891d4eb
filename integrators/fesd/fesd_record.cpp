#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <utility>

#include "fesd_run.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/projection.hpp"

namespace moreau::internal {

// Captures the elements of the system just solved (group_ holds its stage data and Newton
// its factorization). a0, b0: pair sides at the last stage before it (boundary values).
// `remaining` is the element count that fixed the lengths (h = rest / remaining).
// Overwrites every part of *out that a record sets, reusing its vectors (a kept record: no
// allocation per element once their sizes are reached).
ElementPolynomial FesdRun::SparePolynomial() {
  if (spare_polynomials_.empty()) return {};
  ElementPolynomial polynomial = std::move(spare_polynomials_.back());
  spare_polynomials_.pop_back();
  return polynomial;
}

void FesdRun::RecyclePolynomials(std::vector<ElementPolynomial>* list) {
  for (ElementPolynomial& polynomial : *list) {
    // Moved-from ones (committed: their storage went on) have nothing to give.
    if (polynomial.y0.size() > 0) spare_polynomials_.push_back(std::move(polynomial));
  }
  list->clear();
}

void FesdRun::Record(const Vector& w, double h, bool ends_at_switch,
                     const SemismoothNewtonResult& solved, int remaining, const Vector& a0,
                     const Vector& b0, SolveRecord* out) {
  const GroupSetup& setup = group_.setup();
  const int m = setup.elements;
  SolveRecord& record = *out;
  RecyclePolynomials(&record.polynomials);
  record.ClearLists();
  record.length = 0.0;
  record.frozen = system_.TimeFrozen(a_zero_);
  if (options_.sensitivities) TrackGroup(w, m, remaining, a0, &record);
  Vector& y0 = record.y_end;  // the start of each element, at the end the record's end state
  y0 = setup.y_start;
  // Boundary values of each element: a0, b0, then the last stage of the element before.
  const Vector* a_previous = &a0;
  const Vector* b_previous = &b0;
  record.elements.reserve(static_cast<std::size_t>(m));
  for (int e = 0; e < m; ++e) {
    const internal::CollocationStages& stages = group_.element(e);
    const auto w_e = w.segment(group_.element_offset(e), group_.element_size());
    FesdElement element;
    element.length = h;
    element.physical_start = y0[system_.clock_index()];
    element.frozen = record.frozen;
    element.ends_at_switch = ends_at_switch && e + 1 == m;
    element.newton_iterations = static_cast<int>(solved.stats.iterations);
    element.newton_residual = solved.residual_norm;
    Certificates(stages, *a_previous, *b_previous, &element);
    if (filter_.enabled() && static_cast<std::size_t>(e) < excluded_min_.size()) {
      // Constraints left out by the near-active filter (lambda = 0): |min(c, 0)| at the
      // stages, so that the certificates cover every declared constraint.
      const double left_out = std::max(0.0, -excluded_min_[static_cast<std::size_t>(e)]);
      element.complementarity = std::max(element.complementarity, left_out);
      element.cross_complementarity = std::max(element.cross_complementarity, left_out);
    }
    record.elements.push_back(element);
    if (keep_polynomials_) {
      ElementPolynomial polynomial = SparePolynomial();  // its storage, every member set here
      polynomial.y0 = y0;
      polynomial.increments.resize(ny_, s_);
      polynomial.algebraic.resize(nz_, s_);
      for (int i = 0; i < s_; ++i) {
        polynomial.increments.col(i) = w_e.segment(stages.state_offset(i), ny_);
        polynomial.algebraic.col(i) = w_e.segment(stages.algebraic_offset(i), nz_);
      }
      polynomial.h = h;
      polynomial.a_zero = a_zero_;
      polynomial.frozen = record.frozen;
      record.polynomials.push_back(std::move(polynomial));
    }
    if (options_.record_stages && !record.frozen) {
      for (int i = 0; i < s_; ++i) {
        const Vector& yi = stages.stage_state(i);  // y0 + Z_i
        record.stage_points.Append(yi[system_.clock_index()], yi.head(nx_),
                                   TrajectoryAlgebraic(stages.Algebraic(w_e, i)), h);
      }
    }
    y0 += w_e.segment(stages.state_offset(s_ - 1), ny_);  // the element's end state
    a_previous = &stages.stage(s_ - 1).A;
    b_previous = &stages.stage(s_ - 1).B;
    record.z_last = w_e.segment(stages.algebraic_offset(s_ - 1), nz_);  // Algebraic(w_e, s - 1)
    if (options_.record_trajectory && e + 1 < m) {
      record.ends.push_back(y0);
      record.algebraic.push_back(record.z_last);
    }
    record.length += h;
  }
  record.a_last = *a_previous;
  record.b_last = *b_previous;
}

void FesdRun::Commit(SolveRecord& record) {
  for (std::size_t e = 0; e < record.elements.size(); ++e) {
    if (!record.polynomials.empty()) OnCommittedElement(std::move(record.polynomials[e]));
    FesdElement element = record.elements[e];
    element.t_start = tau_;
    tau_ += element.length;
    if (record.frozen) result_.stats.frozen_time += element.length;
    result_.elements.push_back(element);
    result_.stats.max_cross_complementarity =
        std::max(result_.stats.max_cross_complementarity, element.cross_complementarity);
    result_.stats.max_complementarity =
        std::max(result_.stats.max_complementarity, element.complementarity);
    result_.stats.min_element_length = std::min(result_.stats.min_element_length, element.length);
    ++result_.stats.num_elements;
    if (options_.record_trajectory) {
      // Interior ends of a group were stored; the last end is the record's y_end. Frozen
      // elements leave the physical trajectory (x and the clock do not move).
      const bool last = e + 1 == record.elements.size();
      const Vector& y = last ? record.y_end : record.ends[e];
      const Vector z = TrajectoryAlgebraic(last ? record.z_last : record.algebraic[e]);
      if (!record.frozen && !dense_output_) {  // dense output: the output times instead
        result_.trajectory.Append(y[system_.clock_index()], y.head(nx_), z, element.length);
      }
      if (system_.time_freezing()) {
        result_.numerical_trajectory.Append(tau_, y, z, element.length);
      }
    }
  }
  Trajectory& points = record.stage_points;
  for (std::size_t i = 0; i < points.size(); ++i) {
    result_.stage_trajectory.Append(points.t[i], std::move(points.x[i]),
                                    std::move(points.algebraic[i]), points.step[i]);
  }
  y_ = record.y_end;
  z_last_ = record.z_last;
  boundary_a_ = record.a_last;
  boundary_b_ = record.b_last;
  if (options_.sensitivities) CommitTracks(record);
  if (progress_) progress_(y_[system_.clock_index()]);
}

// Free side of every pair at stage i: continuous sides from the stage values, jump sides
// consistent with the stage state, see FreeSideIsJump.
Vector FesdRun::ConsistentFreeSides(const internal::CollocationStages& stages, int i) const {
  Vector free;
  ConsistentFreeSides(stages, i, &free);
  return free;
}

void FesdRun::ConsistentFreeSides(const internal::CollocationStages& stages, int i,
                                  Vector* free_out) const {
  const PointEvaluation& stage = stages.stage(i);
  const Vector& y = stages.stage_state(i);
  const Vector& z = stages.stage_algebraic(i);
  Vector& free = *free_out;
  free.resize(np_);
  bool jump = false;
  for (int k = 0; k < np_; ++k) {
    free[k] = a_zero_[static_cast<std::size_t>(k)] ? stage.B[k] : stage.A[k];
    jump |= FreeSideIsJump(k);
  }
  if (!jump) return;
  // Smooth-field statuses: the consistent values without a velocity-level solve.
  if (JumpFreeSidesInClosedForm(&free)) return;
  if (end_level_.valid && end_level_.a_zero == a_zero_ && y.size() == end_level_.y.size() &&
      z.size() == end_level_.z.size() && (y.array() == end_level_.y.array()).all() &&
      (z.array() == end_level_.z.array()).all()) {
    // The element's end state: solved by EndViolation with the same arguments.
    for (int k = 0; k < np_; ++k) {
      if (FreeSideIsJump(k)) free[k] = end_level_.indicators[k];
    }
    return;
  }
  Vector& v = stage_v_;
  // From the stage's evaluation where it has derivatives (a linear velocity level then needs
  // no evaluation of its own); otherwise the solve evaluates the system at (y, z) itself.
  const PointEvaluation* with_derivatives = stages.stage_with_derivatives(i);
  const bool solved = with_derivatives != nullptr
                          ? system_.SolveVelocityLevel(y, a_zero_, z, z, *with_derivatives, &v)
                          : system_.SolveVelocityLevel(y, a_zero_, z, &v);
  if (!solved) {
    free.setConstant(-std::numeric_limits<double>::infinity());  // no consistent value
    return;
  }
  IndicatorEvaluation& indicators = indicators_;
  system_.EvaluateEventIndicators(y, v, a_zero_, Derivatives::kNone, &indicators);
  for (int k = 0; k < np_; ++k) {
    if (FreeSideIsJump(k)) free[k] = indicators.values[k];
  }
}

bool FesdRun::JumpFreeSidesInClosedForm(Vector* free) const {
  if (reduction_ == Reduction::kNone) return false;
  const int field = SmoothField();
  if (field < 0) return false;
  if (reduction_ == Reduction::kRelayModes) {
    // Relays: pair 4 i + k is region k's theta_ik ⟂ lambda_ik, its free side theta_ik where
    // lambda_ik = 0 is kept. The velocity level's theta is RelayTheta's: one active region
    // (theta_j = 0 kept for the others, e^T theta = 1) or two on a memory boundary, where the
    // differentiated row g_1 - g_2 (or g_3 - g_4), a function of w_i alone, makes w_i' =
    // a_i (theta_1 - theta_2 + theta_3 - theta_4) = 0 and so theta 1/2 on both.
    closed_theta_.setZero(nz_);
    RelayTheta(a_zero_, &closed_theta_);
    for (std::size_t i = 0; i < relay_theta_.size(); ++i) {
      for (std::size_t k = 0; k < 4; ++k) {
        const int pair = static_cast<int>(4 * i + k);
        if (FreeSideIsJump(pair)) (*free)[pair] = closed_theta_[relay_theta_[i].theta[k]];
      }
    }
    return true;
  }
  if (reduction_ == Reduction::kStewartMode) {
    // Pair `field` is mode k = field's theta_k ⟂ lambda_k with lambda_k = 0 kept.
    MOREAU_ASSERT(FreeSideIsJump(field), "Stewart mode pair without a jump free side");
    (*free)[field] = 1.0;
  }
  return true;
}

// Certificates of an element (see FesdElement): the enforced side of every pair at the
// stages and at the start boundary (its continuous side) against the consistent free sides.
void FesdRun::Certificates(const internal::CollocationStages& stages, const Vector& a0,
                           const Vector& b0, FesdElement* element) const {
  double cross = 0.0, stage_residual = 0.0;
  std::vector<Vector>& free = free_sides_;
  free.resize(static_cast<std::size_t>(s_));
  for (int i = 0; i < s_; ++i) ConsistentFreeSides(stages, i, &free[static_cast<std::size_t>(i)]);
  for (int k = 0; k < np_; ++k) {
    const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
    const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
    const bool continuous_a = side == ContinuousSide::kA;
    const double boundary = continuous_a ? a0[k] : b0[k];
    for (int j = 0; j < s_; ++j) {
      const PointEvaluation& sj = stages.stage(j);
      const double free_j = free[static_cast<std::size_t>(j)][k];
      const double enforced_j = a_zero ? sj.A[k] : sj.B[k];
      stage_residual = std::max(stage_residual, ComplementarityResidual(enforced_j, free_j));
      if (side == ContinuousSide::kBoth) {
        // Both sides continuous (index-1 pairs): each side at the start against the other
        // side at stage j.
        const double a_j = a_zero ? enforced_j : free_j;
        const double b_j = a_zero ? free_j : enforced_j;
        cross = std::max(cross, ComplementarityResidual(a0[k], b_j));
        cross = std::max(cross, ComplementarityResidual(b0[k], a_j));
      } else {
        // The jump side at stage j: enforced (zero) or free (consistent value).
        const double jump_j = FreeSideIsJump(k) ? free_j : enforced_j;
        cross = std::max(cross, ComplementarityResidual(boundary, jump_j));
      }
      for (int i = 0; i < s_; ++i) {
        const double enforced_i = a_zero ? stages.stage(i).A[k] : stages.stage(i).B[k];
        cross = std::max(cross, ComplementarityResidual(enforced_i, free_j));
      }
    }
  }
  element->cross_complementarity = cross;
  element->complementarity = stage_residual;
  end_level_.valid = false;  // used by this element's last stage only
}

}  // namespace moreau::internal
