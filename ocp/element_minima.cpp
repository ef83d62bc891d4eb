// The element minima of the collocation transcription (collocation_impl.hpp;
// OcpOptions::collocation_element_minima; docs/ocp.md, "Element minima"): which inactive pieces
// get a row, the rows' bounds, and the minimiser theta* of each row at an evaluation.

#include <algorithm>
#include <cmath>

#include "collocation_impl.hpp"
#include "moreau/core/error.hpp"

namespace moreau::ocp_internal {

namespace {
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
// OpposedToActivePiece: normals at least this close to opposite (the doorway's two discs at
// their touching point: -1; a pusher constraint against a slider constraint: |cosine| <=
// 1/sqrt(2), the pusher-slider gradient has both bodies' components). -0.99 is reached by the
// slider on one disc within |x2| < 0.57 of the doorway (discs of radius 8).
constexpr double kOpposedNormalCosine = 0.99;
}  // namespace

// On the exact level (same pieces): c_m's minimum over the element >= 0 for every inactive
// piece instead of c_m >= 0 at the check points (the minimum bounds c there, and an active
// check row next to an active minimum at almost the same theta would be an almost parallel
// pair of active constraints). The check rows' multipliers move to the minimum's row: to
// first order the same force, acting at the minimiser instead of at the check points.
// Except where the minimum is opposed to an active piece (OpposedToActivePiece): there the
// check points stay.
void CollocationNlp::Impl::ImposeElementMinima(const Vector& z, Vector* multipliers) {
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
auto CollocationNlp::Impl::OpposedToActivePiece(const Vector& z, int k, int e, int m) -> bool {
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
void CollocationNlp::Impl::ImposeElementMinimumRows(const std::vector<bool>& rows_present,
                                                    Vector* multipliers) {
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

auto CollocationNlp::Impl::MinimumWeight(int k, int e, int m) const -> Weight {
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
void CollocationNlp::Impl::LocateMinima(int k, int e, double start, double h, const Vector& u,
                                        bool derivatives) {
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
      set.constraints.Jacobian(x, u, start + theta * h, parameters_, Wrt::XT(), &value, &jacobian);
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
      return std::pair<double, double>{c / phi, (dc * phi - c * weight.Slope(theta)) / (phi * phi)};
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
    EvaluatePoint(PolynomialState(k, e, tableau_.InterpolationWeights(theta)), start + theta * h, u,
                  nullptr, derivatives, &minimum_points_[piece]);
  }
}

auto CollocationNlp::Impl::InteriorMinimumRows(const Vector& z, double margin) -> std::vector<int> {
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

}  // namespace moreau::ocp_internal
