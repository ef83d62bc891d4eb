#include "crossing_search.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "moreau/core/error.hpp"
#include "moreau/core/interval.hpp"

namespace moreau::internal {

const Matrix& PolynomialPath::WeightCoefficients(const RadauTableau& tableau) {
  const int s = tableau.stages;
  if (weight_stages_ == s) return weight_coefficients_;
  // w_j(c_i) = delta_ij and w_j(0) = 0 with w_j of degree s: the monomial coefficients M
  // (w_j(theta) = sum_d M(j, d - 1) theta^d) solve M V^T = I, V(i, d - 1) = c_i^d.
  Matrix v(s, s);
  for (int i = 0; i < s; ++i) {
    double power = 1.0;
    for (int d = 0; d < s; ++d) {
      power *= tableau.c[i];
      v(i, d) = power;
    }
  }
  weight_coefficients_ = v.transpose().fullPivLu().inverse();
  weight_stages_ = s;
  return weight_coefficients_;
}

void PolynomialPath::SetCollocation(const RadauTableau& tableau, const ConstVectorRef& y0,
                                    const Matrix& increments) {
  const Matrix& m = WeightCoefficients(tableau);
  const int s = tableau.stages;
  coefficients_.resize(y0.size(), s + 1);
  coefficients_.col(0) = y0;
  coefficients_.rightCols(s).noalias() = increments * m;
}

void PolynomialPath::Point(double theta, Vector* y) const {
  const Eigen::Index q = coefficients_.cols() - 1;
  *y = coefficients_.col(q);
  for (Eigen::Index d = q - 1; d >= 0; --d) *y = *y * theta + coefficients_.col(d);
}

void PolynomialPath::Derivative(double theta, Vector* dy) const {
  const Eigen::Index q = coefficients_.cols() - 1;
  dy->setZero(coefficients_.rows());
  for (Eigen::Index d = q; d >= 1; --d) {
    *dy = *dy * theta + static_cast<double>(d) * coefficients_.col(d);
  }
}

void PolynomialPath::SetShape(Eigen::Index n, int degree) {
  coefficients_.setZero(n, degree + 1);
  taylor_.resize(n, degree + 1);
}

void PolynomialPath::Box(double a, double b, Vector* lower, Vector* upper) const {
  const Eigen::Index n = coefficients_.rows(), q = coefficients_.cols() - 1;
  const double m = 0.5 * (a + b), r = 0.5 * (b - a);
  // Taylor coefficients at m: T_d = sum_{k >= d} binom(k, d) a_k m^(k - d), by repeated
  // synthetic division (Horner's scheme for the shifted polynomial).
  taylor_ = coefficients_;
  for (Eigen::Index d = 0; d < q; ++d) {
    for (Eigen::Index k = q - 1; k >= d; --k) taylor_.col(k) += m * taylor_.col(k + 1);
  }
  lower->resize(n);
  upper->resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    // The radius is rounded up term by term; the centre's rounding (a few ulps of the
    // coefficients' size) is covered by a relative margin.
    double radius = 0.0, scale = std::fabs(taylor_(i, 0)), power = 1.0;
    for (Eigen::Index d = 1; d <= q; ++d) {
      power *= r;
      radius += std::fabs(taylor_(i, d)) * power;
      scale = std::max(scale, std::fabs(coefficients_(i, d)));
    }
    const double margin = 8.0 * std::numeric_limits<double>::epsilon() * (scale + radius) *
                          static_cast<double>(q + 1);
    (*lower)[i] = RoundDown(taylor_(i, 0) - radius - margin);
    (*upper)[i] = RoundUp(taylor_(i, 0) + radius + margin);
  }
}

void CrossingWorkspace::Reserve(int functions, const CrossingSearchLimits& limits) {
  const auto n = static_cast<std::size_t>(std::max(functions, 0));
  lower.resize(functions);
  upper.resize(functions);
  values.resize(functions);
  levels.resize(functions);
  bounded.reserve(n);
  // Depth first: at most one pending right half per level besides the node taken.
  stack.reserve(static_cast<std::size_t>(limits.max_depth) + 2);
}

Crossing SearchCrossing(const std::vector<char>& watched, const Vector& thresholds,
                        const CrossingFunctionRefs& functions, const CrossingSearchLimits& limits,
                        CrossingWorkspace* workspace) {
  Crossing crossing;
  const auto n = static_cast<Eigen::Index>(watched.size());
  MOREAU_ASSERT(thresholds.size() == n, "SearchCrossing: one threshold per function");
  Vector& lower = workspace->lower;
  Vector& upper = workspace->upper;
  Vector& values = workspace->values;
  // Functions the bound decides (a finite lower bound over the whole step); the others are
  // checked by the samples the search takes for the rest.
  std::vector<char>& bounded = workspace->bounded;
  bounded.assign(watched.size(), 0);
  auto suspicious = [&](double a, double b) {
    functions.bounds(a, b, &lower, &upper);
    ++crossing.bound_evaluations;
    bool any = false;
    for (Eigen::Index k = 0; k < n; ++k) {
      const auto i = static_cast<std::size_t>(k);
      if (bounded[i] && !(lower[k] >= -thresholds[k])) any = true;
    }
    return any;
  };
  // The whole step first: which functions have a bound at all.
  functions.bounds(0.0, 1.0, &lower, &upper);
  ++crossing.bound_evaluations;
  bool any = false;
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto i = static_cast<std::size_t>(k);
    bounded[i] = watched[i] && std::isfinite(lower[k]);
    if (bounded[i] && !(lower[k] >= -thresholds[k])) any = true;
  }
  if (!any) return crossing;
  // Depth-first, left half first, so that the first negative sample found lies in the
  // leftmost suspicious interval.
  using Node = CrossingWorkspace::Node;
  std::vector<Node>& stack = workspace->stack;
  stack.reserve(static_cast<std::size_t>(limits.max_depth) + 2);  // (Reserve's size)
  stack.assign(1, Node{0.0, 1.0, 0});
  bool root = true;  // the whole step's bound is already known to be suspicious
  bool unresolved = false;
  double unresolved_at = 1.0;
  int unresolved_function = -1;
  while (!stack.empty()) {
    const Node node = stack.back();
    stack.pop_back();
    if (!root) {
      if (crossing.bound_evaluations >= limits.max_bounds) {
        unresolved = true;
        unresolved_at = std::min(unresolved_at, node.a);
        break;
      }
      if (!suspicious(node.a, node.b)) continue;
    }
    root = false;
    const double mid = 0.5 * (node.a + node.b);
    if (functions.values(mid, &values)) {
      for (Eigen::Index k = 0; k < n; ++k) {
        if (watched[static_cast<std::size_t>(k)] && values[k] < -thresholds[k]) {
          crossing.outcome = CrossingOutcome::kFound;
          crossing.function = static_cast<int>(k);
          crossing.sample = mid;
          break;
        }
      }
      if (crossing.outcome == CrossingOutcome::kFound) break;
    }
    if (node.depth >= limits.max_depth) {
      // Next to the path's ends the values are known to be above the thresholds: a dip of
      // this width there is a graze, not a crossing to resolve.
      if (node.a > 0.0 && node.b < 1.0) {
        unresolved = true;
        if (node.a < unresolved_at) {
          unresolved_at = node.a;
          for (Eigen::Index k = 0; k < n; ++k) {
            if (bounded[static_cast<std::size_t>(k)] && !(lower[k] >= -thresholds[k])) {
              unresolved_function = static_cast<int>(k);
            }
          }
        }
      }
      continue;
    }
    stack.push_back({mid, node.b, node.depth + 1});
    stack.push_back({node.a, mid, node.depth + 1});
  }
  if (crossing.outcome == CrossingOutcome::kFound) {
    // The first zero before the sample: bisection between the path's start (values above the
    // thresholds) and the sample on the minimum of the watched functions.
    // A function that starts at or below zero (within its threshold: a pair that has just
    // switched) counts as below once it is below minus its threshold, others once negative.
    Vector& levels = workspace->levels;
    levels.setZero(n);
    if (functions.values(0.0, &values)) {
      for (Eigen::Index k = 0; k < n; ++k) levels[k] = values[k] <= 0.0 ? -thresholds[k] : 0.0;
    }
    double lo = 0.0, hi = crossing.sample;
    for (int i = 0; i < limits.bisections; ++i) {
      const double mid = 0.5 * (lo + hi);
      bool below = false;
      if (functions.values(mid, &values)) {
        for (Eigen::Index k = 0; k < n && !below; ++k) {
          below = watched[static_cast<std::size_t>(k)] && values[k] < levels[k];
        }
      }
      (below ? hi : lo) = mid;
    }
    crossing.theta = hi;
    return crossing;
  }
  if (unresolved) {
    crossing.outcome = CrossingOutcome::kUnresolved;
    crossing.sample = unresolved_at;
    crossing.function = unresolved_function;
  }
  return crossing;
}

namespace {

// The Hermite interpolant through (nodes[i], values[i], slopes[i]) in Newton form on the doubled
// nodes z = (x_0, x_0, x_1, x_1, ...): p(x) = sum_l coefficients[l] prod_{i < l} (x - z_i), its
// divided differences with f[z_2i, z_2i+1] = f'(x_i). z, the table and the coefficients live in
// `storage` (3 m entries, m = 2 n).
void HermiteNewtonForm(const std::vector<double>& nodes, const std::vector<double>& values,
                       const std::vector<double>& slopes, double* storage) {
  const std::size_t n = nodes.size();
  MOREAU_ASSERT(n > 0 && values.size() == n && slopes.size() == n,
                "Hermite interpolant: one value and slope per node");
  const std::size_t m = 2 * n;
  double* const z = storage;
  double* const table = storage + m;
  double* const coefficients = storage + 2 * m;
  for (std::size_t i = 0; i < n; ++i) {
    z[2 * i] = z[2 * i + 1] = nodes[i];
    table[2 * i] = table[2 * i + 1] = values[i];
  }
  coefficients[0] = table[0];
  for (std::size_t level = 1; level < m; ++level) {
    for (std::size_t i = m - 1; i >= level; --i) {
      const double dz = z[i] - z[i - level];
      table[i] = dz == 0.0 ? slopes[i / 2] : (table[i] - table[i - 1]) / dz;
    }
    coefficients[level] = table[level];
  }
}

// The Newton form (3 m entries) and HermiteLowerBound's polynomials (2 m more): on the stack for
// the sizes an element has (its start and stages, s <= 7), as this runs per element.
constexpr std::size_t kStackNodes = 16;
struct HermiteStorage {
  std::array<double, 10 * kStackNodes> stack;
  std::vector<double> heap;
  // Room for `per_node` entries per node.
  double* Get(std::size_t n, std::size_t per_node) {
    if (n <= kStackNodes && per_node <= 10) return stack.data();
    heap.resize(per_node * n);
    return heap.data();
  }
};

}  // namespace

double HermiteMinimum(const std::vector<double>& nodes, const std::vector<double>& values,
                      const std::vector<double>& slopes, int samples, double* theta) {
  const std::size_t m = 2 * nodes.size();
  HermiteStorage storage;
  double* const data = storage.Get(nodes.size(), 6);
  HermiteNewtonForm(nodes, values, slopes, data);
  const double* const z = data;
  const double* const coefficients = data + 2 * m;
  double best = std::numeric_limits<double>::infinity();
  *theta = 0.5;
  for (int k = 0; k < samples; ++k) {
    const double x = (k + 0.5) / samples;
    double value = coefficients[m - 1];
    for (std::size_t i = m - 1; i-- > 0;) value = value * (x - z[i]) + coefficients[i];
    if (value < best) {
      best = value;
      *theta = x;
    }
  }
  return best;
}

double HermiteLowerBound(const std::vector<double>& nodes, const std::vector<double>& values,
                         const std::vector<double>& slopes) {
  const std::size_t m = 2 * nodes.size();  // coefficients; degree m - 1
  HermiteStorage storage;
  double* const data = storage.Get(nodes.size(), 10);
  HermiteNewtonForm(nodes, values, slopes, data);
  const double* const z = data;
  const double* const coefficients = data + 2 * m;
  // Powers: nested multiplication p <- p (x - z_l) + c_l from the highest coefficient down,
  // with the same recursion on absolute values (|p| <- |p| (x + |z_l|) + |c_l|) bounding the
  // size of every term that enters a coefficient.
  double* const power = data + 3 * m;
  double* const size = data + 4 * m;
  std::fill(power, power + m, 0.0);
  std::fill(size, size + m, 0.0);
  power[0] = coefficients[m - 1];
  size[0] = std::fabs(coefficients[m - 1]);
  for (std::size_t l = m - 1; l-- > 0;) {
    // Multiply by (x - z_l) (the degree rises by one), then add c_l.
    for (std::size_t j = m - 1; j > 0; --j) {
      power[j] = power[j - 1] - z[l] * power[j];
      size[j] = size[j - 1] + std::fabs(z[l]) * size[j];
    }
    power[0] = coefficients[l] - z[l] * power[0];
    size[0] = std::fabs(coefficients[l]) + std::fabs(z[l]) * size[0];
  }
  // Bernstein coefficients of degree d = m - 1: b_j = sum_{i <= j} C(j, i) / C(d, i) a_i, a
  // combination of the a_i with weights in [0, 1] (Farouki and Rajan, "On the numerical
  // condition of polynomials in Bernstein form", 1987).
  const std::size_t d = m - 1;
  double least = std::numeric_limits<double>::infinity();
  double total_size = 0.0;
  for (std::size_t j = 0; j <= d; ++j) {
    double b = 0.0;
    double weight = 1.0;  // C(j, i) / C(d, i), from i = 0
    for (std::size_t i = 0; i <= j; ++i) {
      b += weight * power[i];
      if (i < j) weight *= static_cast<double>(j - i) / static_cast<double>(d - i);
    }
    least = std::min(least, b);
    total_size += size[j];
  }
  // Each conversion step rounds relative to the sizes it combines: at most about m^2 roundings
  // of terms bounded by the sum of the sizes, which also bounds the rounding of HermiteMinimum's
  // Horner evaluations (about m roundings each). A tenfold allowance.
  const double rounding =
      10.0 * static_cast<double>(m * m) * std::numeric_limits<double>::epsilon() * total_size;
  return least - rounding;
}

}  // namespace moreau::internal
