#pragma once
/// @file
/// Observed order of convergence from errors measured on a sequence of step sizes.

#include <vector>

namespace moreau {

/// Result of fitting log(error) = p log(h) + c by least squares.
struct OrderFit {
  double order = 0.0;     ///< fitted slope p
  double constant = 0.0;  ///< fitted log-constant c
  int points_used = 0;    ///< points above the floor that entered the fit
};

/// Least-squares order over the points whose error exceeds `floor` (points at or below the
/// floor are dominated by round-off or solver tolerances and are excluded). Returns
/// points_used < 2 when fewer than two points remain. Throws std::invalid_argument for
/// mismatched sizes or non-positive step sizes.
OrderFit FitOrder(const std::vector<double>& step_sizes, const std::vector<double>& errors,
                  double floor);

/// Orders between consecutive points: log(e_k / e_{k+1}) / log(h_k / h_{k+1}).
std::vector<double> PairwiseOrders(const std::vector<double>& step_sizes,
                                   const std::vector<double>& errors);

}  // namespace moreau
