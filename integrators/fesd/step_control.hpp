#pragma once
// Step-size control of adaptive FESD (docs/fesd-formulation.md, section 10). Private to
// moreau::integrators.
//
// The controller sees one number per attempted step, err = ||le|| / (H / L): the weighted local
// error estimate of the step (see FesdRun::EstimateError) per unit step, L the horizon. A step
// is accepted iff err <= 1. For a method of order p the error per unit step behaves like
// C H^p, so the step that would give err = 1 is H err^(-1/p). Proposals:
//   after an accepted step (elementary controller, with Gustafsson's predictive correction
//   when the previous step was accepted as well; Hairer & Wanner II, IV.8, eq. (8.21)):
//     fac = kSafety err^(-1/p),  fac_pred = fac (H / H_prev) (err_prev / err)^(1/p),
//     H_new = H clamp(min(fac, fac_pred), kMinFactor, kMaxFactor)   (no growth right after
//     a rejection);
//   after a rejection: H_new = H clamp(kSafety err^(-1/p), kMinFactor, kRejectFactor).
// A step that ended on a switch starts the history afresh (the new mode has another error
// constant); its proposal is bounded by kMaxFactor times the step that was attempted.

#include <algorithm>
#include <cmath>

namespace moreau::internal {

class StepController {
 public:
  // Safety factor on the optimal step (Hairer & Wanner's 0.9: the estimate is asymptotic).
  static constexpr double kSafety = 0.9;
  // Bounds of one change of the step: at most 5 times larger (an estimate far below the
  // tolerance is unreliable, e.g. at round-off, and says nothing about what lies beyond the
  // step: a step that grows 90-fold in one go can cross a whole pulse of a switching
  // function) and at least 5 times smaller (Hairer & Wanner's RADAU5 uses 1/8 to 5; a larger
  // cut wastes the information of a nearly good step). The bound holds for every step, the
  // first included: from a cautious starting step (F1, s = 4, rtol 1e-4: 0.0084 against the
  // 0.4 the estimate asks for) it costs two or three steps more to get there.
  static constexpr double kMinFactor = 0.2;
  static constexpr double kMaxFactor = 5.0;
  // A rejected step shrinks by at least this factor.
  static constexpr double kRejectFactor = 0.9;
  // Estimates below this count as this (err^(-1/p) of an estimate at round-off or zero).
  static constexpr double kMinError = 1e-10;

  explicit StepController(int order) : exponent_(1.0 / order) {}

  // The next step after accepting a step of length h (the piece actually integrated) with
  // estimate err <= 1. `attempted` is the length that was attempted (> h when a switch ended
  // the step early); `switched` says whether it did.
  double Accept(double h, double attempted, double err, bool switched) {
    const double e = std::max(err, kMinError);
    double factor = kSafety * std::pow(e, -exponent_);
    if (have_previous_ && !switched) {
      const double predictive =
          factor * (h / previous_h_) * std::pow(previous_error_ / e, exponent_);
      factor = std::min(factor, predictive);
    }
    factor = std::max(factor, kMinFactor);
    if (last_rejected_) factor = std::min(factor, 1.0);
    // A switch that ended the step early: the bound is relative to the attempted step (the
    // piece may be much shorter; its estimate, at round-off, then allows growth by up to
    // kSafety kMinError^(-1/p) within it). Attempting the whole step again after every switch
    // costs a located switch per step where switches are dense (hard_fast_switching: 6912
    // Newton iterations instead of 1183).
    const double next = std::min(h * factor, kMaxFactor * (switched ? attempted : h));
    if (switched) {
      have_previous_ = false;
    } else {
      have_previous_ = true;
      previous_h_ = h;
      previous_error_ = e;
    }
    last_rejected_ = false;
    // A piece of zero length (a switch decided at the very start of the step) says nothing
    // about the step: the attempted length is tried again with the new statuses. Its zero
    // proposal made every later attempt an element of length zero, whose residual is not
    // finite, down to min_step_size (random brush scenes on microsecond scales).
    if (!(next > 0.0)) return attempted;
    return next;
  }

  // The next attempt after rejecting a step of length h with estimate err > 1 (infinite if
  // the comparison solve failed).
  double Reject(double h, double err) {
    last_rejected_ = true;
    if (!std::isfinite(err)) return kMinFactor * h;
    return h * std::clamp(kSafety * std::pow(err, -exponent_), kMinFactor, kRejectFactor);
  }

  // After a failed solve (the step is halved by the caller): no growth on the next step.
  void Failed() { last_rejected_ = true; }

 private:
  double exponent_;
  bool have_previous_ = false;
  double previous_h_ = 0.0, previous_error_ = 0.0;
  bool last_rejected_ = false;
};

}  // namespace moreau::internal
