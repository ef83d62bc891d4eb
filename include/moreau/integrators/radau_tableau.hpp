#pragma once
/// @file
/// Radau IIA collocation methods with s = 1..kMaxRadauStages stages.
///
/// Nodes c_1 < ... < c_s = 1 are the roots of d^{s-1}/dx^{s-1} [x^{s-1} (x - 1)^s] (the
/// Radau right polynomial), computed as companion-matrix eigenvalues and polished by Newton's
/// method in long double. The coefficients follow from the collocation conditions
/// C(s): sum_j a_ij c_j^{k-1} = c_i^k / k (k = 1..s), and b_j = a_sj (stiffly accurate).
/// The method has classical order 2s - 1 (B(2s-1), C(s), D(s-1)) and is L-stable.
/// Reference: Hairer & Wanner, Solving ODEs II, Sec. IV.5.

#include "moreau/core/types.hpp"

namespace moreau {

/// Largest number of Radau IIA stages moreau computes tableaus for (order 13).
inline constexpr int kMaxRadauStages = 7;

/// Butcher tableau of Radau IIA with s stages, plus the data integrators derive from it.
struct RadauTableau {
  /// Number of stages s.
  int stages = 0;
  Vector c;          ///< nodes, c_s = 1
  Matrix a;          ///< coefficients a_ij
  Vector b;          ///< weights (= last row of a)
  Matrix a_inverse;  ///< A^{-1}, used to recover stage derivatives h F = A^{-1} Z
  /// Embedded error estimator of local order s + 1 (Hairer-Wanner IV.8 generalized to any s):
  /// err = (I - h gamma0 J)^{-1} (gamma0 h f(y0) + sum_j e_j Z_j), Z_j = Y_j - y0.
  double gamma0 = 0.0;
  Vector error_weights;  ///< e = A^{-T} (bhat - b)

  /// The classical order 2s - 1.
  int order() const { return 2 * stages - 1; }
  /// Weights w_j(theta) of the collocation polynomial: u(t0 + theta h) = y0 + sum_j w_j Z_j.
  Vector InterpolationWeights(double theta) const;
  /// The same weights into *w (resized to the stages; no allocation once sized).
  void InterpolationWeights(double theta, Vector* w) const;
  /// Weights of its derivative: h u'(t0 + theta h) = sum_j w'_j Z_j.
  Vector InterpolationDerivativeWeights(double theta) const;
  /// The same derivative weights into *w (resized to the stages; no allocation once sized).
  void InterpolationDerivativeWeights(double theta, Vector* w) const;
};

/// The tableau with `stages` stages (computed once and cached). Throws std::invalid_argument
/// unless 1 <= stages <= kMaxRadauStages.
const RadauTableau& RadauIIA(int stages);

}  // namespace moreau
