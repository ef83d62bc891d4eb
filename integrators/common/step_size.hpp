#pragma once
// What the error-controlled integrators (FESD, smooth Radau IIA) share about step sizes
// (private to moreau::integrators; docs/accuracy.md): the per-state scale behind the automatic
// absolute tolerance, and the starting step.

#include <functional>

#include "moreau/core/types.hpp"

namespace moreau::internal {

// The largest |y_i| a run has had so far, per state (initial value included): the scale of
// state i. With the automatic absolute tolerance (atol = 0) state i is controlled to
// atol_i = rtol * scale_i, i.e. relative to its own scale whatever its unit.
class StateScale {
 public:
  void Reset(const Vector& y0) { scale_ = y0.cwiseAbs(); }
  void Update(const Vector& y) { scale_ = scale_.cwiseMax(y.cwiseAbs()); }
  const Vector& scale() const { return scale_; }
  // atol_i: the given absolute tolerance if positive, else rtol times the scale of state i.
  double AbsoluteTolerance(int i, double atol, double rtol) const {
    return atol > 0.0 ? atol : rtol * scale_[i];
  }

 private:
  Vector scale_;
};

// Hairer, Norsett & Wanner, Solving Ordinary Differential Equations I (1993), Sec. II.4
// ("Starting step size"), for a method of order p, in the weighted RMS norm with the weights
// w_i = atol_i + rtol |y0_i| over the first `count` states (a state with w_i = 0, a state at
// zero with the automatic absolute tolerance, has no scale yet and is left out):
//   d0 = ||y0||, d1 = ||f0||, h0 = 0.01 d0 / d1 (`quiet` if d0 or d1 < 1e-5: nothing moves
//   at t0 on the states' scale); d2 = ||f(y0 + h0 f0) - f0|| / h0 (0 if that is not finite);
//   h1 = (0.01 / max(d1, d2))^(1/(p+1)) (max(quiet, 1e-3 h0) if max(d1, d2) <= 1e-15);
//   h = min(100 h0, h1, span).
// Every quantity is a ratio of the model's own rates and scales, so the step scales with the
// model's time scale (a model with time in milliseconds gets a starting step 1000 times
// shorter). `field(y, f)` evaluates the field at y into *f.
double StartingStep(const Vector& y0, const Vector& f0, const Vector& weights, int count, int order,
                    double span, double quiet,
                    const std::function<void(const Vector&, Vector*)>& field);

}  // namespace moreau::internal
