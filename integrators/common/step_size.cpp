#include "step_size.hpp"

#include <algorithm>
#include <cmath>

namespace moreau::internal {

double StartingStep(const Vector& y0, const Vector& f0, const Vector& weights, int count, int order,
                    double span, double quiet,
                    const std::function<void(const Vector&, Vector*)>& field) {
  // Weighted RMS over the states with a scale (see the header).
  auto norm = [&](const Vector& value) {
    double sum = 0.0;
    int used = 0;
    for (int i = 0; i < count; ++i) {
      if (!(weights[i] > 0.0)) continue;
      const double scaled = value[i] / weights[i];
      sum += scaled * scaled;
      ++used;
    }
    return used > 0 ? std::sqrt(sum / used) : 0.0;
  };
  const double d0 = norm(y0), d1 = norm(f0);
  double h0 = (d0 < 1e-5 || d1 < 1e-5) ? quiet : 0.01 * d0 / d1;
  h0 = std::min(h0, span);
  Vector f1;
  field(y0 + h0 * f0, &f1);
  const double d2 = f1.allFinite() ? norm(f1 - f0) / h0 : 0.0;
  const double p = order;
  const double h1 = std::max(d1, d2) <= 1e-15 ? std::max(quiet, h0 * 1e-3)
                                              : std::pow(0.01 / std::max(d1, d2), 1.0 / (p + 1.0));
  return std::min({100.0 * h0, h1, span});
}

}  // namespace moreau::internal
