#pragma once
/// @file
/// NCP (complementarity) functions: phi(a, b) = 0  <=>  a >= 0, b >= 0, a b = 0.
///
/// Fischer-Burmeister: phi(a, b) = a + b - sqrt(a^2 + b^2). It is semismooth (strongly), and
/// 1/2 phi^2 is continuously differentiable, which makes it the function of choice for a
/// line search on the merit 1/2 ||Phi||^2. Away from the origin its gradient is
/// (1 - a/r, 1 - b/r), r = sqrt(a^2 + b^2). At (a, b) = (0, 0) the B-subdifferential is
/// {(1 - xi_a, 1 - xi_b) : xi on the unit circle}; moreau uses the element
/// (1 - 1/sqrt(2), 1 - 1/sqrt(2)) (the limit along a = b > 0), which treats both sides
/// alike and is nonsingular together with any direction that moves a or b off zero.
/// The value is computed as 2ab / (a + b + r) when a + b > 0 to avoid cancellation.
///
/// Min map: phi(a, b) = min(a, b) with gradient (1, 0) if a <= b (ties count as "a active")
/// and (0, 1) otherwise. Semismooth Newton on the min map is a primal-dual active-set
/// method; it is provided for comparison (its merit is not differentiable).

#include <string>

namespace moreau {

/// The NCP function that turns complementarity 0 <= a ⟂ b >= 0 into the equation phi(a, b) = 0.
enum class NcpFunctionKind { kFischerBurmeister, kMin };
/// "fischer-burmeister" or "min".
std::string ToString(NcpFunctionKind kind);
/// Parses "fischer-burmeister" (or "fb") or "min"; throws std::invalid_argument otherwise.
NcpFunctionKind ParseNcpFunctionKind(const std::string& name);

/// Value of an NCP function with the element of its generalized gradient used by Newton.
struct NcpValue {
  /// phi(a, b).
  double value = 0.0;
  double da = 0.0;  ///< d phi / d a
  double db = 0.0;  ///< d phi / d b
};

/// Fischer-Burmeister: phi(a, b) = a + b - sqrt(a^2 + b^2), zero iff a >= 0, b >= 0, a b = 0
/// (semismooth; at (0, 0) an element of the generalized gradient).
NcpValue FischerBurmeister(double a, double b);
/// Smoothed Fischer-Burmeister (Kanzow): phi_mu(a, b) = a + b - sqrt(a^2 + b^2 + 2 mu^2), whose
/// zeros are a > 0, b > 0, a b = mu^2. Continuously differentiable for mu > 0; mu = 0 gives
/// FischerBurmeister. Used for continuation (mu -> 0) when plain semismooth Newton fails.
NcpValue SmoothedFischerBurmeister(double a, double b, double mu);
/// The min map: phi(a, b) = min(a, b) (piecewise linear; ties take the gradient of a).
NcpValue MinMap(double a, double b);
/// The NCP function `kind` at (a, b).
inline NcpValue EvaluateNcp(NcpFunctionKind kind, double a, double b) {
  return kind == NcpFunctionKind::kFischerBurmeister ? FischerBurmeister(a, b) : MinMap(a, b);
}

/// Natural residual |min(a, b)|: zero exactly at complementary pairs; the certificate
/// reported by integrators (independent of the NCP function used to solve).
double ComplementarityResidual(double a, double b);

}  // namespace moreau
