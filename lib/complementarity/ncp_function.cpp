#include "moreau/complementarity/ncp_function.hpp"

#include <cmath>

#include "moreau/core/error.hpp"

namespace moreau {

std::string ToString(NcpFunctionKind kind) {
  return kind == NcpFunctionKind::kFischerBurmeister ? "fischer-burmeister" : "min";
}

NcpFunctionKind ParseNcpFunctionKind(const std::string& name) {
  if (name == "fischer-burmeister" || name == "fb") return NcpFunctionKind::kFischerBurmeister;
  if (name == "min") return NcpFunctionKind::kMin;
  ThrowInvalidArgument("unknown complementarity function '", name,
                       "'; expected fischer-burmeister (fb) or min");
}

NcpValue FischerBurmeister(double a, double b) {
  const double r = std::hypot(a, b);
  if (r == 0.0) {
    // Chosen element of the B-subdifferential at the origin (see header).
    constexpr double kOrigin = 1.0 - 0.70710678118654752440;
    return {0.0, kOrigin, kOrigin};
  }
  const double sum = a + b;
  // a + b - r loses all digits when a, b > 0 and one is tiny: use (a+b)^2 - r^2 = 2ab.
  const double value = sum > 0.0 ? 2.0 * a * b / (sum + r) : sum - r;
  return {value, 1.0 - a / r, 1.0 - b / r};
}

NcpValue SmoothedFischerBurmeister(double a, double b, double mu) {
  if (mu == 0.0) return FischerBurmeister(a, b);
  const double r = std::sqrt(a * a + b * b + 2.0 * mu * mu);
  const double sum = a + b;
  // (a + b)^2 - r^2 = 2 (ab - mu^2): stable form when a + b > 0.
  const double value = sum > 0.0 ? 2.0 * (a * b - mu * mu) / (sum + r) : sum - r;
  return {value, 1.0 - a / r, 1.0 - b / r};
}

NcpValue MinMap(double a, double b) {
  if (a <= b) return {a, 1.0, 0.0};
  return {b, 0.0, 1.0};
}

double ComplementarityResidual(double a, double b) { return std::fabs(std::fmin(a, b)); }

}  // namespace moreau
