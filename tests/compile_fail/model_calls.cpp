// Model lambdas for the compile-failure tests (CMakeLists.txt in this folder): CASE_<NAME>
// selects the expression; the nonsmooth ones must fail with moreau's message, the smooth one
// must compile (so that a failure is due to the call, not to the set-up).
#include "moreau/core/smooth_function.hpp"

namespace user_model {

moreau::SmoothFunction Model() {
  return moreau::MakeSmoothFunction(
      "case", 1, [](const auto& x, const auto&, const auto& t, const auto&, auto& out) {
#if defined(CASE_SMOOTH)
        out[0] = std::sin(x[0]) + cos(x[1]) * std::exp(t) + pow(x[0], 2);
#elif defined(CASE_ABS)
        out[0] = abs(x[0]);
#elif defined(CASE_STD_ABS)
        out[0] = std::abs(x[0]);
#elif defined(CASE_STD_MIN)
        out[0] = std::min(x[0], x[1]);
#elif defined(CASE_COMPARISON)
        out[0] = x[0] > 0.0 ? x[0] : -x[0];
#elif defined(CASE_STD_FLOOR)
        out[0] = std::floor(t);
#else
#error "no CASE_<NAME> defined"
#endif
      });
}

}  // namespace user_model

int main() { return user_model::Model().num_outputs() == 1 ? 0 : 1; }
