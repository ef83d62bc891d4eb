// The tolerance proportionality of adaptive FESD (issue 16), as a table: for F1, S3, S4
// (u = 2) and H1 with s = 2, 3, 4 and rtol = 1e-4 ... 1e-10 (atol = rtol / 100), the error at
// tf and of the switch times relative to rtol times the solution scale (max |x| over the
// closed form; switch times: max(1, tf)), steps, rejections and failed attempts. The test
// tests/integrators/fesd_adaptive_test.cpp asserts the bound 10 on the same runs; this prints
// the measured values quoted in the README.
//
//   build/release/bench/adaptive_tolerance
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "../tests/problems/reference_problems.hpp"
#include "moreau/integrators/fesd.hpp"

namespace {

using moreau::Event;
using moreau::EventKind;
using moreau::Vector;

struct Answer {
  std::function<Vector(double)> solution;
  std::vector<double> switch_times;
  bool relays = false;
};

Answer AnswerFor(const std::string& name) {
  if (name == "H1") {
    const moreau::testing::Thermostat h1 = moreau::testing::H1();
    std::vector<double> times;
    for (const auto& s : h1.Switches(moreau::MakeScene("H1").final_time)) times.push_back(s.t);
    return {[h1](double t) { return Vector{{h1.State(t)}}; }, times, true};
  }
  const moreau::testing::ReferenceProblem p = name == "F1"   ? moreau::testing::F1()
                                              : name == "S3" ? moreau::testing::S3()
                                                             : moreau::testing::S4();
  return {p.solution, p.switch_times, false};
}

double SwitchError(const Answer& answer, const std::vector<Event>& events) {
  std::vector<double> reported;
  for (const Event& e : events) {
    if (e.kind != EventKind::kAmbiguous && answer.relays == (e.kind == EventKind::kRelaySwitch)) {
      reported.push_back(e.t);
    }
  }
  if (reported.empty()) return INFINITY;
  auto one_sided = [](const std::vector<double>& from, const std::vector<double>& to) {
    double worst = 0.0;
    for (double a : from) {
      double nearest = INFINITY;
      for (double b : to) nearest = std::min(nearest, std::fabs(a - b));
      worst = std::max(worst, nearest);
    }
    return worst;
  };
  return std::max(one_sided(reported, answer.switch_times),
                  one_sided(answer.switch_times, reported));
}

}  // namespace

int main() {
  std::printf("scene  s   rtol    error/(rtol scale)  switch/(rtol max(1,tf))  steps  rejected  failed\n");
  double low = INFINITY, high = 0.0;
  for (const char* name : {"F1", "S3", "S4", "H1"}) {
    const moreau::Scene scene = moreau::MakeScene(name);
    const Answer answer = AnswerFor(name);
    double scale = 1.0;
    for (int k = 0; k <= 200; ++k) {
      const double t = scene.initial_time + (scene.final_time - scene.initial_time) * k / 200.0;
      scale = std::max(scale, answer.solution(t).lpNorm<Eigen::Infinity>());
    }
    for (double t : answer.switch_times) {
      scale = std::max(scale, answer.solution(t).lpNorm<Eigen::Infinity>());
    }
    const double time_scale = std::max(1.0, scene.final_time);
    for (int s = 2; s <= 4; ++s) {
      for (double rtol : {1e-4, 1e-6, 1e-8, 1e-10}) {
        moreau::FesdOptions options;
        options.stages = s;
        options.adaptive = true;
        options.relative_tolerance = rtol;
        options.absolute_tolerance = 1e-2 * rtol;
        options.step_size = 0.0;
        options.record_trajectory = false;
        const moreau::FesdResult r = moreau::SimulateFesd(scene, options);
        if (r.status != moreau::FesdStatus::kSuccess) {
          std::printf("%-5s  %d  %.0e  %s\n", name, s, rtol, r.message.c_str());
          continue;
        }
        const double state =
            (r.final_state - answer.solution(r.final_time)).lpNorm<Eigen::Infinity>() /
            (rtol * scale);
        const double event = SwitchError(answer, r.events) / (rtol * time_scale);
        low = std::min(low, std::max(state, event));
        high = std::max(high, std::max(state, event));
        std::printf("%-5s  %d  %.0e  %18.3g  %23.3g  %5ld  %8ld  %6ld\n", name, s, rtol, state,
                    event, r.stats.num_steps, r.stats.num_rejected_steps,
                    r.stats.num_failed_steps);
      }
    }
  }
  std::printf("max(error, switch) / rtol over all runs: %.3g to %.3g\n", low, high);
  return 0;
}
