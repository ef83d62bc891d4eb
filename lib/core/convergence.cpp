#include "moreau/core/convergence.hpp"

#include <cmath>

#include "moreau/core/error.hpp"

namespace moreau {

OrderFit FitOrder(const std::vector<double>& step_sizes, const std::vector<double>& errors,
                  double floor) {
  RequireArgument(step_sizes.size() == errors.size(), "FitOrder: ", step_sizes.size(),
                  " step sizes but ", errors.size(), " errors");
  double sx = 0.0, sy = 0.0, sxx = 0.0, sxy = 0.0;
  int n = 0;
  for (std::size_t k = 0; k < step_sizes.size(); ++k) {
    RequireArgument(step_sizes[k] > 0.0, "FitOrder: step sizes must be positive, got ",
                    step_sizes[k]);
    if (!(errors[k] > floor) || !std::isfinite(errors[k])) continue;
    const double x = std::log(step_sizes[k]);
    const double y = std::log(errors[k]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
    ++n;
  }
  OrderFit fit;
  fit.points_used = n;
  if (n < 2) return fit;
  const double denominator = n * sxx - sx * sx;
  if (denominator <= 0.0) {
    fit.points_used = 1;  // all step sizes equal: no slope
    return fit;
  }
  fit.order = (n * sxy - sx * sy) / denominator;
  fit.constant = (sy - fit.order * sx) / n;
  return fit;
}

std::vector<double> PairwiseOrders(const std::vector<double>& step_sizes,
                                   const std::vector<double>& errors) {
  RequireArgument(step_sizes.size() == errors.size(), "PairwiseOrders: size mismatch");
  std::vector<double> orders;
  for (std::size_t k = 0; k + 1 < step_sizes.size(); ++k) {
    orders.push_back(std::log(errors[k] / errors[k + 1]) /
                     std::log(step_sizes[k] / step_sizes[k + 1]));
  }
  return orders;
}

}  // namespace moreau
