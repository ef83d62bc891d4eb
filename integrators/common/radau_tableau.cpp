#include "moreau/integrators/radau_tableau.hpp"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <vector>

#include "moreau/core/error.hpp"

namespace moreau {
namespace {

using LongVector = Eigen::Matrix<long double, Eigen::Dynamic, 1>;
using LongMatrix = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;

// Coefficients (lowest degree first) of d^{s-1}/dx^{s-1} [x^{s-1} (x - 1)^s].
std::vector<long double> RadauPolynomial(int s) {
  // (x - 1)^s by the binomial theorem, shifted by x^{s-1}.
  std::vector<long double> q(static_cast<std::size_t>(2 * s), 0.0L);
  long double binomial = 1.0L;
  for (int k = 0; k <= s; ++k) {
    const long double sign = ((s - k) % 2 == 0) ? 1.0L : -1.0L;
    q[static_cast<std::size_t>(k + s - 1)] = sign * binomial;
    binomial = binomial * static_cast<long double>(s - k) / static_cast<long double>(k + 1);
  }
  for (int d = 0; d < s - 1; ++d) {
    for (std::size_t k = 0; k + 1 < q.size(); ++k) {
      q[k] = q[k + 1] * static_cast<long double>(k + 1);
    }
    q.pop_back();
  }
  return q;  // degree s
}

long double EvaluatePolynomial(const std::vector<long double>& p, long double x,
                               long double* derivative) {
  long double value = 0.0L, slope = 0.0L;
  for (auto it = p.rbegin(); it != p.rend(); ++it) {
    slope = slope * x + value;
    value = value * x + *it;
  }
  *derivative = slope;
  return value;
}

std::vector<long double> RadauNodes(int s) {
  const std::vector<long double> p = RadauPolynomial(s);
  // Companion matrix of the monic polynomial.
  Matrix companion = Matrix::Zero(s, s);
  const double leading = static_cast<double>(p.back());
  for (int i = 0; i < s; ++i) {
    companion(0, i) = -static_cast<double>(p[static_cast<std::size_t>(s - 1 - i)]) / leading;
    if (i + 1 < s) companion(i + 1, i) = 1.0;
  }
  Eigen::EigenSolver<Matrix> eigen(companion);
  std::vector<long double> nodes;
  for (int i = 0; i < s; ++i) {
    long double x = eigen.eigenvalues()[i].real();
    for (int iteration = 0; iteration < 50; ++iteration) {  // Newton polish in long double
      long double slope;
      const long double value = EvaluatePolynomial(p, x, &slope);
      const long double step = value / slope;
      x -= step;
      if (std::fabs(step) < 1e-19L) break;
    }
    nodes.push_back(x);
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.back() = 1.0L;  // exact by construction
  return nodes;
}

RadauTableau ComputeTableau(int s) {
  const std::vector<long double> nodes = RadauNodes(s);
  LongVector c(s);
  for (int i = 0; i < s; ++i) c[i] = nodes[static_cast<std::size_t>(i)];
  // Vandermonde V(k, j) = c_j^k, k = 0..s-1.
  LongMatrix v(s, s);
  for (int j = 0; j < s; ++j) {
    long double power = 1.0L;
    for (int k = 0; k < s; ++k) {
      v(k, j) = power;
      power *= c[j];
    }
  }
  Eigen::PartialPivLU<LongMatrix> lu(v);
  LongMatrix a(s, s);
  for (int i = 0; i < s; ++i) {
    LongVector rhs(s);
    long double power = c[i];
    for (int k = 0; k < s; ++k) {
      rhs[k] = power / static_cast<long double>(k + 1);  // C(s): c_i^{k+1} / (k + 1)
      power *= c[i];
    }
    a.row(i) = lu.solve(rhs).transpose();
  }
  const LongMatrix a_inverse = a.inverse();
  // gamma0: geometric mean of the eigenvalues of A^{-1} (any positive value gives an
  // estimator of local order s + 1; this one scales the stiffness filter like the method).
  const long double gamma0 = std::pow(a_inverse.determinant(), 1.0L / static_cast<long double>(s));
  // Embedded weights bhat with bhat_0 = gamma0 at node 0: quadrature exact for degree < s.
  LongVector rhs(s);
  for (int k = 0; k < s; ++k) {
    rhs[k] = 1.0L / static_cast<long double>(k + 1) - (k == 0 ? gamma0 : 0.0L);
  }
  const LongVector bhat = lu.solve(rhs);
  const LongVector b = a.row(s - 1).transpose();
  const LongVector error_weights = a_inverse.transpose() * (bhat - b);

  RadauTableau tableau;
  tableau.stages = s;
  tableau.c = c.cast<double>();
  tableau.a = a.cast<double>();
  tableau.b = b.cast<double>();
  tableau.a_inverse = a_inverse.cast<double>();
  tableau.gamma0 = static_cast<double>(gamma0);
  tableau.error_weights = error_weights.cast<double>();
  return tableau;
}

}  // namespace

Vector RadauTableau::InterpolationWeights(double theta) const {
  Vector w;
  InterpolationWeights(theta, &w);
  return w;
}

void RadauTableau::InterpolationWeights(double theta, Vector* w) const {
  // Lagrange basis on the nodes {0, c_1, ..., c_s}; the value at node 0 is y0 (Z_0 = 0).
  w->resize(stages);
  for (int j = 0; j < stages; ++j) {
    double l = theta / c[j];
    for (int k = 0; k < stages; ++k) {
      if (k != j) l *= (theta - c[k]) / (c[j] - c[k]);
    }
    (*w)[j] = l;
  }
}

Vector RadauTableau::InterpolationDerivativeWeights(double theta) const {
  Vector w;
  InterpolationDerivativeWeights(theta, &w);
  return w;
}

void RadauTableau::InterpolationDerivativeWeights(double theta, Vector* w) const {
  // d/dtheta of the Lagrange basis above, by the product rule over its linear factors
  // (theta - 0)/c_j and (theta - c_k)/(c_j - c_k), k != j. The roots live on the stack: dense
  // output calls this per output time.
  w->resize(stages);
  std::array<double, kMaxRadauStages> roots{};
  for (int j = 0; j < stages; ++j) {
    int num_roots = 0;
    roots[num_roots++] = 0.0;
    double scale = 1.0 / c[j];
    for (int k = 0; k < stages; ++k) {
      if (k == j) continue;
      roots[num_roots++] = c[k];
      scale /= (c[j] - c[k]);
    }
    double derivative = 0.0;
    for (int m = 0; m < num_roots; ++m) {
      double product = 1.0;
      for (int n = 0; n < num_roots; ++n) {
        if (n != m) product *= theta - roots[n];
      }
      derivative += product;
    }
    (*w)[j] = scale * derivative;
  }
}

const RadauTableau& RadauIIA(int stages) {
  RequireArgument(stages >= 1 && stages <= kMaxRadauStages, "Radau IIA stages must be in [1, ",
                  kMaxRadauStages, "], got ", stages);
  static std::array<RadauTableau, kMaxRadauStages + 1> cache;
  static std::array<std::once_flag, kMaxRadauStages + 1> once;
  const auto index = static_cast<std::size_t>(stages);
  std::call_once(once[index], [&] { cache[index] = ComputeTableau(stages); });
  return cache[index];
}

}  // namespace moreau
