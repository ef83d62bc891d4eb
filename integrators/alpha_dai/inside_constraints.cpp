#include "inside_constraints.hpp"

#include <cmath>
#include <limits>

namespace moreau::internal {
namespace {

// Rows within this many tolerances of zero at the step's end are not searched (as FESD's
// InsideViolation leaves out sides at zero at an element's end): a bound over any piece next to
// that end admits phi > tolerance, so the search could not decide them, and the next step,
// which starts there, watches them.
constexpr double kGrazeBand = 10.0;

}  // namespace

InsideConstraintSearch::InsideConstraintSearch(const std::vector<SmoothFunction>& constraints,
                                               const Vector& parameters,
                                               const std::vector<int>& algebraic)
    : constraints_(constraints), parameters_(parameters), algebraic_(algebraic) {}

bool InsideConstraintSearch::Values(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                    Vector* values) {
  for (std::size_t j = 0; j < algebraic_.size(); ++j) {
    full_inputs_[algebraic_[j]] = u[static_cast<Eigen::Index>(j)];
  }
  values->resize(nphi_);
  int row = 0;
  for (const SmoothFunction& g : constraints_) {
    g.Evaluate(x, full_inputs_, t, parameters_, &value_);
    values->segment(row, g.num_outputs()) = -value_;
    row += g.num_outputs();
  }
  return values->allFinite();
}

void InsideConstraintSearch::Bounds(double t_lower, double t_upper, Vector* lower, Vector* upper) {
  lower->resize(nphi_);
  upper->resize(nphi_);
  const Eigen::Index nx = x_lower_.size();
  x_box_.resize(static_cast<std::size_t>(nx));
  for (Eigen::Index i = 0; i < nx; ++i) {
    x_box_[static_cast<std::size_t>(i)] = Interval(x_lower_[i], x_upper_[i]);
  }
  u_box_.resize(static_cast<std::size_t>(full_inputs_.size()));
  for (Eigen::Index i = 0; i < full_inputs_.size(); ++i) {
    u_box_[static_cast<std::size_t>(i)] = Interval(full_inputs_[i]);
  }
  for (std::size_t j = 0; j < algebraic_.size(); ++j) {
    const Eigen::Index k = nx + static_cast<Eigen::Index>(j);  // u after x in the path
    u_box_[static_cast<std::size_t>(algebraic_[j])] = Interval(box_lower_[k], box_upper_[k]);
  }
  p_box_.resize(static_cast<std::size_t>(parameters_.size()));
  for (Eigen::Index i = 0; i < parameters_.size(); ++i) {
    p_box_[static_cast<std::size_t>(i)] = Interval(parameters_[i]);
  }
  const Interval t(t_lower, t_upper);
  int row = 0;
  for (const SmoothFunction& g : constraints_) {
    const int k = g.num_outputs();
    // SmoothFunction::Bounds takes the inputs as a point; the algebraic inputs vary over the
    // step, so the function's interval evaluation is called with an input box.
    TypedFunction* typed = g.typed();
    const bool decided =
        typed != nullptr && typed->BoxBounds(x_box_.data(), static_cast<int>(nx), u_box_.data(),
                                             static_cast<int>(u_box_.size()), t, p_box_.data(),
                                             static_cast<int>(p_box_.size()), &out_box_);
    constexpr double kInf = std::numeric_limits<double>::infinity();
    for (int r = 0; r < k; ++r) {
      (*lower)[row + r] = decided ? -out_box_[static_cast<std::size_t>(r)].upper() : -kInf;
      (*upper)[row + r] = decided ? -out_box_[static_cast<std::size_t>(r)].lower() : kInf;
    }
    row += k;
  }
}

Crossing InsideConstraintSearch::Search(const AlphaStepPoint& start, const AlphaStepPoint& end,
                                        const Vector& inputs, std::vector<char> watched,
                                        const Vector& margin, double tolerance,
                                        const std::function<Vector()>& thresholds) {
  full_inputs_ = inputs;
  nphi_ = 0;
  for (const SmoothFunction& g : constraints_) nphi_ += g.num_outputs();
  const Vector &x0 = *start.x, &x1 = *end.x, &f0 = *start.f, &f1 = *end.f;
  const Vector &u0 = *start.u, &u1 = *end.u;
  const Eigen::Index nx = x0.size(), nq = u0.size();
  const double h = end.t - start.t;
  // The end values: rows near zero there are left out (kGrazeBand).
  bool any = false;
  if (Values(x1, u1, end.t, &y_)) {
    for (int k = 0; k < nphi_; ++k) {
      auto& w = watched[static_cast<std::size_t>(k)];
      if (w && !(y_[k] > kGrazeBand * tolerance)) w = 0;  // y = -phi
      any |= w != 0;
    }
  }
  if (!any) return {};
  // y(theta) = (x, u): the cubic Hermite interpolant of x, the linear one of u.
  Matrix& c = path_.coefficients();
  c.setZero(nx + nq, 4);
  c.col(0).head(nx) = x0;
  c.col(1).head(nx) = h * f0;
  c.col(2).head(nx) = 3.0 * (x1 - x0) - h * (2.0 * f0 + f1);
  c.col(3).head(nx) = 2.0 * (x0 - x1) + h * (f0 + f1);
  c.col(0).tail(nq) = u0;
  c.col(1).tail(nq) = u1 - u0;
  auto values_at = [&](double theta, Vector* values) {
    path_.Point(theta, &y_);
    return Values(y_.head(nx), y_.tail(nq), start.t + theta * h, values);
  };
  auto bounds_over = [&](double a, double b, Vector* lower, Vector* upper) {
    path_.Box(a, b, &box_lower_, &box_upper_);
    x_lower_ = box_lower_.head(nx) - margin;
    x_upper_ = box_upper_.head(nx) + margin;
    // (t = start.t + theta h is monotone in theta in floating point: the samples' times lie
    // in this interval.)
    Bounds(start.t + a * h, start.t + b * h, lower, upper);
  };
  const CrossingFunctionRefs functions{values_at, bounds_over};
  functions.bounds(0.0, 1.0, &step_lower_, &step_upper_);
  bool suspicious = false;
  for (int k = 0; k < nphi_; ++k) {
    suspicious |= watched[static_cast<std::size_t>(k)] && !(step_lower_[k] >= -tolerance);
  }
  if (!suspicious) {
    Crossing none;
    none.bound_evaluations = 1;
    return none;
  }
  Crossing crossing = SearchCrossing(watched, thresholds(), functions, {}, &search_);
  ++crossing.bound_evaluations;  // the whole step's
  return crossing;
}

}  // namespace moreau::internal
