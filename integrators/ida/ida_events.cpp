// IDA's root functions, roots that begin and end inside one step, and the projection onto
// the position-level conditions at the end of a phase (ida_run.hpp).

#include <Eigen/SparseCholesky>
#include <array>
#include <cmath>

#include "../common/crossing_search.hpp"
#include "ida_run.hpp"

namespace moreau::internal {
namespace {

// Hidden roots (FindHiddenRoot): sub-intervals sampled per step (five evaluations of the
// root functions per step); parabolic refinements of a predicted dip; the bisection's
// resolution in units of eps (|t| + h), IDA's own root resolution (IDARcheck3: 100 uround).
constexpr int kHiddenRootIntervals = 4;
constexpr int kHiddenRootRefinements = 8;
constexpr double kHiddenRootResolution = 100.0;
// Projection onto the phase's position-level conditions: Gauss-Newton iterations until |P|
// is at round-off level.
constexpr int kProjectionIterations = 3;
constexpr double kProjectionTolerance = 1e-15;
// Regularization of the sparse projection's Gram matrix relative to its largest diagonal
// entry (ProjectionStep): a contraction of 1e-8 per iteration down to sigma = 1e-4 of it.
constexpr double kProjectionRegularization = 1e-12;

}  // namespace

// Roots inside a step. IDA compares the signs of the root functions at the ends of each
// step, so a root function that falls below zero and recovers within one step is not seen.
// In free flight at constant velocity the solution is linear, BDF's local error is zero and
// the steps double without bound: a body passed straight through a fixed disc (x' = (1, 0)
// from (-5, 0.9), no event at any rtol), and the doorway's optimal controls lost a contact
// of 0.018 time units inside a step of 0.21 (pusher and slider at t = 0.96), which left
// IDA's re-simulation 1.2e-4 from FESD and time-stepping (docs/ida.md, "Contacts inside a
// step"). The root functions are sampled on IDA's interpolant at kHiddenRootIntervals + 1
// equally spaced times of the step; around the smallest sample of each function a
// parabola through three samples predicts the minimum (exact for the quadratic distance
// functions of bodies in free flight), refined by successive parabolic interpolation
// while the predicted minimum is below -event_tolerance. A function found below
// -event_tolerance (the resolution of the status decisions: a shallower dip is a graze the
// decision would not resolve) has its first zero located by bisection on the interpolant,
// to IDA's own root resolution. Only functions positive at the step's start are watched
// (IDA reports decreases through zero only). On success *t_root is the time and
// hidden_roots_ flags the functions at or below zero there.
bool IdaRun::FindHiddenRoot(double t_a, double t_b, double* t_root) {
  const int m = np_ + nr_;
  if (m == 0) return false;
  constexpr int K = kHiddenRootIntervals;
  std::array<double, K + 1> times{};
  hidden_samples_.resize(K + 1, m);
  for (int j = 0; j <= K; ++j) {
    times[static_cast<std::size_t>(j)] = j == K ? t_b : t_a + (t_b - t_a) * j / K;
    if (j == 0 && t_a == last_sample_time_) {
      // The previous step's end, sampled there: the same accepted solution (the interpolant
      // passes through it), with the root offsets of now.
      hidden_work_ = last_sample_;
      for (int k = 0; k < np_; ++k) hidden_work_[k] += root_offset_[static_cast<std::size_t>(k)];
    } else if (!RootsAt(times[static_cast<std::size_t>(j)], &hidden_work_)) {
      return false;
    }
    hidden_samples_.row(j) = hidden_work_.transpose();
  }
  // Kept without the offsets, which ArmRoots may change before the next step.
  last_sample_time_ = t_b;
  last_sample_ = hidden_samples_.row(K).transpose();
  for (int k = 0; k < np_; ++k) last_sample_[k] -= root_offset_[static_cast<std::size_t>(k)];
  const double threshold = -options_.event_tolerance;
  double t_negative = std::numeric_limits<double>::infinity();
  for (int i = 0; i < m; ++i) {
    const auto g = hidden_samples_.col(i);
    if (!(g[0] > 0.0)) continue;
    // An interior sample below the threshold (the step's end is IDA's own test).
    bool below = false;
    for (int j = 1; j < K && !below; ++j) {
      if (g[j] < threshold) {
        t_negative = std::min(t_negative, times[static_cast<std::size_t>(j)]);
        below = true;
      }
    }
    if (below) continue;
    Eigen::Index j_min = 0;
    g.minCoeff(&j_min);
    const int j0 = std::clamp(static_cast<int>(j_min) - 1, 0, K - 2);
    std::array<double, 3> a{times[static_cast<std::size_t>(j0)],
                            times[static_cast<std::size_t>(j0 + 1)],
                            times[static_cast<std::size_t>(j0 + 2)]};
    std::array<double, 3> b{g[j0], g[j0 + 1], g[j0 + 2]};
    for (int iteration = 0; iteration < kHiddenRootRefinements; ++iteration) {
      // The parabola through (a, b) in Newton form, and its vertex.
      const double d1 = (b[1] - b[0]) / (a[1] - a[0]);
      const double d2 = (b[2] - b[1]) / (a[2] - a[1]);
      const double c2 = (d2 - d1) / (a[2] - a[0]);
      if (!(c2 > 0.0)) break;  // not convex: no interior minimum
      const double t_v = 0.5 * (a[0] + a[1]) - d1 / (2.0 * c2);
      if (!(t_v > a[0] && t_v < a[2]) || t_v == a[1]) break;
      const double predicted = b[0] + d1 * (t_v - a[0]) + c2 * (t_v - a[0]) * (t_v - a[1]);
      if (!(predicted < threshold)) break;
      if (!RootsAt(t_v, &hidden_work_)) break;
      const double value = hidden_work_[i];
      if (value < threshold) {
        t_negative = std::min(t_negative, t_v);
        break;
      }
      // Keep the three points that bracket the smallest value.
      if (t_v < a[1]) {
        a = value < b[1] ? std::array<double, 3>{a[0], t_v, a[1]}
                         : std::array<double, 3>{t_v, a[1], a[2]};
        b = value < b[1] ? std::array<double, 3>{b[0], value, b[1]}
                         : std::array<double, 3>{value, b[1], b[2]};
      } else {
        a = value < b[1] ? std::array<double, 3>{a[1], t_v, a[2]}
                         : std::array<double, 3>{a[0], a[1], t_v};
        b = value < b[1] ? std::array<double, 3>{b[1], value, b[2]}
                         : std::array<double, 3>{b[0], b[1], value};
      }
    }
  }
  // A pulse narrower than the samples: the bounds of the root functions on the interpolant.
  if (!std::isfinite(t_negative) && !BoundedHiddenRoot(t_a, t_b, &t_negative)) return false;
  // The first zero of the watched functions in [t_a, t_negative]: positive at lo, a
  // watched function at or below zero at hi.
  auto watched_minimum = [&](const Vector& values) {
    double minimum = std::numeric_limits<double>::infinity();
    for (int i = 0; i < m; ++i) {
      if (hidden_samples_(0, i) > 0.0) minimum = std::min(minimum, values[i]);
    }
    return minimum;
  };
  double lo = t_a, hi = t_negative;
  const double resolution = kHiddenRootResolution * std::numeric_limits<double>::epsilon() *
                            (std::fabs(t_b) + (t_b - t_a));
  while (hi - lo > resolution) {
    const double mid = 0.5 * (lo + hi);
    if (!RootsAt(mid, &hidden_work_)) return false;
    (watched_minimum(hidden_work_) <= 0.0 ? hi : lo) = mid;
  }
  if (!RootsAt(hi, &hidden_work_)) return false;
  hidden_roots_.assign(static_cast<std::size_t>(m), 0);
  for (int i = 0; i < m; ++i) {
    if (hidden_samples_(0, i) > 0.0 && hidden_work_[i] <= 0.0) {
      hidden_roots_[static_cast<std::size_t>(i)] = -1;
    }
  }
  *t_root = hi;
  return true;
}

bool IdaRun::BoundedHiddenRoot(double t_a, double t_b, double* t_negative) {
  const int m = np_ + nr_;
  int order = 0;
  if (IDAGetLastOrder(memory_, &order) < 0 || order < 1) return false;
  // y(t_a + theta H) = sum_k D_k ((theta - 1) H)^k / k!, D_k the k-th derivative at t_b:
  // monomial coefficients a_d = sum_{k >= d} E_k binom(k, d) (-1)^(k - d), E_k = D_k H^k / k!.
  const double span = t_b - t_a;
  BoundedRootBuffers& b = bounded_root_;
  MOREAU_ASSERT(order <= kMaxBdfOrder, "IDA's order above the one set");
  internal::PolynomialPath& path = b.paths[static_cast<std::size_t>(order)];
  Matrix& a = path.coefficients();
  a.setZero(n_, order + 1);
  double scale = 1.0;  // H^k / k!
  for (int k = 0; k <= order; ++k) {
    if (k > 0) scale *= span / k;
    if (IDAGetDky(memory_, t_b, k, dky_->vector) < 0) return false;
    Vector& e = b.e;
    e.noalias() = View(dky_->vector) * scale;
    double binomial = 1.0;  // binom(k, d)
    for (int d = 0; d <= k; ++d) {
      if (d > 0) binomial = binomial * (k - d + 1) / d;
      a.col(d) += ((k - d) % 2 == 0 ? binomial : -binomial) * e;
    }
  }
  std::vector<char>& watched = b.watched;
  watched.assign(static_cast<std::size_t>(m), 0);
  for (int i = 0; i < m; ++i) watched[static_cast<std::size_t>(i)] = hidden_samples_(0, i) > 0.0;
  b.thresholds.setConstant(m, options_.event_tolerance);
  auto values_at = [&](double theta, Vector* values) {
    return RootsAt(t_a + theta * span, values);
  };
  auto bounds_over = [&](double lo, double hi, Vector* lower, Vector* upper) {
    path.Box(lo, hi, &b.box_lower, &b.box_upper);
    lower->resize(m);
    upper->resize(m);
    if (np_ > 0) {
      system_.BoundEventIndicators(b.box_lower.head(ny_), b.box_upper.head(ny_), a_zero_,
                                   &b.pair_lower, &b.pair_upper);
      for (int k = 0; k < np_; ++k) {
        const double offset = root_offset_[static_cast<std::size_t>(k)];
        (*lower)[k] = b.pair_lower[k] + offset;
        (*upper)[k] = b.pair_upper[k] + offset;
      }
    }
    if (nr_ > 0) {
      system_.BoundMemorySwitchingFunctions(b.box_lower.head(ny_), b.box_upper.head(ny_),
                                            &b.relay_lower, &b.relay_upper);
      lower->tail(nr_) = b.relay_lower;
      upper->tail(nr_) = b.relay_upper;
    }
  };
  const internal::CrossingFunctionRefs functions{values_at, bounds_over};
  const internal::Crossing crossing =
      internal::SearchCrossing(watched, b.thresholds, functions, {}, &b.search);
  if (crossing.outcome == internal::CrossingOutcome::kUnresolved) {
    if (result_.stats.num_unresolved_crossings == 0) first_unresolved_time_ = t_a;
    ++result_.stats.num_unresolved_crossings;
  }
  if (crossing.outcome != internal::CrossingOutcome::kFound) return false;
  *t_negative = t_a + crossing.sample * span;
  return true;
}

// The root functions at t on IDA's interpolant of the last step; false outside it.
bool IdaRun::RootsAt(double t, Vector* g) {
  if (IDAGetDky(memory_, t, 0, dky_->vector) < 0) return false;
  g->resize(np_ + nr_);
  try {
    Roots(dky_->vector, g->data());
  } catch (const std::exception&) {
    return false;  // not evaluable there: IDA's own test at the step's end stands
  }
  return g->allFinite();
}

int IdaRun::Roots(N_Vector Y, double* out) {
  Unpack(Y, &root_y_, &root_z_, &root_v_);
  const Vector& y = root_y_;
  if (np_ > 0) {
    system_.EvaluateEventIndicators(y, root_v_, a_zero_, Derivatives::kNone, &indicators_);
    for (int k = 0; k < np_; ++k) {
      out[k] = indicators_.values[k] + root_offset_[static_cast<std::size_t>(k)];
    }
  }
  if (nr_ > 0) {
    const Vector switching = system_.MemorySwitchingFunctions(y);
    for (int i = 0; i < nr_; ++i) out[np_ + i] = switching[i];
  }
  return 0;
}

// At the end of a phase: the drift certificate |P| (position-level conditions of the phase),
// then the state is projected back onto P = 0 (minimum-norm Gauss-Newton correction of x and
// z_c; relay memories and the clock stay), so that the status decision at the event sees
// the kept sides at zero rather than at the integration error. At a root (`roots`: IDA's
// root flags), the continuous free sides that reached zero are kept at zero by the same
// projection: the correction of the drift (of the size of the integration error) would
// otherwise move them off zero, and a constraint just reached could be found violated by
// more than the event tolerance (the doorway plan at rtol 1e-8: -5.4e-8 for the slider on
// the left disc, a status-decision failure).
void IdaRun::EndPhase(const std::vector<int>* roots) {
  if (nz_ == 0) return;
  // Rows: P (nz), then per pair whose continuous free side is a root, that free side.
  std::vector<int> reached_row(static_cast<std::size_t>(np_), -1);
  int rows = nz_;
  for (int k = 0; roots != nullptr && k < np_; ++k) {
    if ((*roots)[static_cast<std::size_t>(k)] != 0 && FreeSideIsContinuous(k)) {
      reached_row[static_cast<std::size_t>(k)] = rows++;
    }
  }
  auto Y = View(Y_->vector);
  for (int iteration = 0; iteration < kProjectionIterations; ++iteration) {
    Vector y, z, v;
    Unpack(Y_->vector, &y, &z, &v);
    system_.Evaluate(y, z, Derivatives::kStates, &point_);
    Vector p;
    PositionLevel(point_, &p);
    const double size = p.lpNorm<Eigen::Infinity>();
    if (iteration == 0) result_.stats.max_drift = std::max(result_.stats.max_drift, size);
    p.conservativeResize(rows);
    for (int k = 0; k < np_; ++k) {
      const int row = reached_row[static_cast<std::size_t>(k)];
      if (row >= 0) p[row] = a_zero_[static_cast<std::size_t>(k)] ? point_.B[k] : point_.A[k];
    }
    if (p.lpNorm<Eigen::Infinity>() <= kProjectionTolerance) break;
    Vector step;
    if (!ProjectionStep(reached_row, p, &step)) break;
    Y.head(nx_) += step.head(nx_);
    Y.segment(ny_, nc_) += step.tail(nc_);
  }
  y_ = Y.head(ny_);
}

// add(row, column, value) for the derivatives of the projection's rows (EndPhase) with
// respect to its unknowns: the scene states x (columns 0..nx) and z_c (nx + c).
template <class Add>
void IdaRun::ForEachProjectionEntry(const std::vector<int>& reached_row, Add&& add) const {
  auto column = [this](int j, bool wrt_z) {
    if (!wrt_z) return j < nx_ ? j : -1;  // relay memories and the clock stay
    const int col = z_column_[static_cast<std::size_t>(j)];
    return col < ny_ + nc_ ? nx_ + col - ny_ : -1;  // jump unknowns are not moved
  };
  ForEachPositionEntry(point_, [&](int r, int j, bool wrt_z, double value) {
    const int col = column(j, wrt_z);
    if (col >= 0) add(r, col, value);
  });
  auto free_side = [&](bool b_side, bool wrt_z) {
    return [&, b_side, wrt_z](int k, int j, double value) {
      const int row = reached_row[static_cast<std::size_t>(k)];
      if (row < 0 || a_zero_[static_cast<std::size_t>(k)] != b_side) return;
      const int col = column(j, wrt_z);
      if (col >= 0) add(row, col, value);
    };
  };
  if (std::none_of(reached_row.begin(), reached_row.end(), [](int row) { return row >= 0; })) {
    return;
  }
  ForEachEntry(point_.A_y, free_side(false, false));
  ForEachEntry(point_.A_z, free_side(false, true));
  ForEachEntry(point_.B_y, free_side(true, false));
  ForEachEntry(point_.B_z, free_side(true, true));
}

// The minimum-norm Gauss-Newton step of (x, z_c) for the projection rows with values p at
// point_. Dense storage: complete orthogonal decomposition of the rows x (nx + nc)
// Jacobian. Sparse storage: step = -D^T (D D^T + delta I)^{-1} p with a sparse Cholesky
// (LDL^T) factorization of the Gram matrix; delta (kProjectionRegularization relative to
// its largest diagonal entry) keeps it definite when rows are redundant (a jammed crowd has
// more contacts than degrees of freedom) or empty (pairs without a condition), and moves the
// step from the minimum-norm one by a relative delta / sigma (sigma the smallest nonzero
// eigenvalue of D D^T), which the next iteration corrects. False if the factorization fails.
bool IdaRun::ProjectionStep(const std::vector<int>& reached_row, const Vector& p,
                            Vector* step) const {
  const auto rows = p.size();
  const int cols = nx_ + nc_;
  if (!system_.sparse()) {
    Matrix jacobian = Matrix::Zero(rows, cols);
    ForEachProjectionEntry(reached_row,
                           [&](int r, int c, double value) { jacobian(r, c) += value; });
    *step = jacobian.completeOrthogonalDecomposition().solve(-p);
    return true;
  }
  std::vector<Eigen::Triplet<double, int>> entries;
  ForEachProjectionEntry(reached_row,
                         [&](int r, int c, double value) { entries.emplace_back(r, c, value); });
  SparseMatrix jacobian(rows, cols);
  jacobian.setFromTriplets(entries.begin(), entries.end());
  SparseMatrix gram = jacobian * SparseMatrix(jacobian.transpose());
  const double largest = gram.diagonal().size() > 0 ? gram.diagonal().maxCoeff() : 0.0;
  const double delta = kProjectionRegularization * std::max(largest, 1.0);
  for (Eigen::Index i = 0; i < rows; ++i) gram.coeffRef(i, i) += delta;
  Eigen::SimplicialLDLT<SparseMatrix> cholesky(gram);
  if (cholesky.info() != Eigen::Success) return false;
  const Vector w = cholesky.solve(-p);
  if (cholesky.info() != Eigen::Success || !w.allFinite()) return false;
  *step = jacobian.transpose() * w;
  return true;
}

// True if pair k's free side for the current statuses is a continuous variable (a
// constraint value or a Stewart lambda: a position-level condition when it is zero) rather
// than a jump variable (a multiplier, zero only at velocity level).
bool IdaRun::FreeSideIsContinuous(int k) const {
  const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
  if (side == ContinuousSide::kBoth) return true;
  const bool free_b = a_zero_[static_cast<std::size_t>(k)];
  return free_b == (side == ContinuousSide::kB);
}

int IdaRun::RootCallback(double, N_Vector Y, N_Vector, double* out, void* user_data) {
  auto* run = static_cast<IdaRun*>(user_data);
  try {
    return run->Roots(Y, out);
  } catch (const std::exception& error) {
    run->last_error_ = error.what();
    return -1;
  }
}

}  // namespace moreau::internal
