// FESD's cost per element against smooth Radau IIA elements of the same size, in instructions:
// the pairs of BM_FesdElementRatio (fesd_bench.cpp, the same options and smooth parts), one
// steady run of each (after warm-up runs: set-up included, first-run costs such as lazily made
// tableaus not) in functions of their own for callgrind's --toggle-collect. The counts do not
// depend on the machine's load, unlike the CPU times of fesd_bench.
//
//   scripts/bench-element-cost   (F1 and S3, s = 2 and 3, under callgrind; prints the ratios)
//   valgrind --tool=callgrind --toggle-collect='MeasuredFesdRun*'
//     --toggle-collect='MeasuredRadauRun*' build/release/bench/element_cost F1 2   (one line)
// An optional third argument replaces the scene's horizon (scripts/bench-element-cost
// --decompose: runs that end before the first switch, for the cost of an element without one).
#include <cstdio>
#include <cstdlib>
#include <string>

#include "element_ratio.hpp"
#include "moreau/scenes/catalog.hpp"

// The measured runs (not inlined: callgrind collects inside them by name).
[[gnu::noinline]] moreau::FesdResult MeasuredFesdRun(const moreau::Scene& scene,
                                                     const moreau::FesdOptions& options) {
  return moreau::SimulateFesd(scene, options);
}
[[gnu::noinline]] moreau::RadauResult MeasuredRadauRun(const moreau::Scene& scene,
                                                       const moreau::RadauOptions& options) {
  return moreau::SimulateRadau(scene, options);
}

int main(int argc, char** argv) {
  if (argc != 3 && argc != 4) {
    std::fprintf(stderr, "usage: element_cost <scene> <stages> [final time]\n");
    return 2;
  }
  moreau::Scene scene = moreau::MakeScene(argv[1]);
  if (argc == 4) {
    char* end = nullptr;
    const double final_time = std::strtod(argv[3], &end);
    if (*end != '\0' || !(final_time > scene.initial_time)) {
      std::fprintf(stderr, "element_cost: the final time '%s' is not a number after t0 = %g\n",
                   argv[3], scene.initial_time);
      return 2;
    }
    scene.final_time = final_time;
  }
  const moreau::Scene smooth = moreau::bench::SmoothPart(scene);
  const moreau::bench::PairedOptions options =
      moreau::bench::ElementRatioOptions(std::atoi(argv[2]));
  constexpr int kWarmUpRuns = 2;
  for (int i = 0; i < kWarmUpRuns; ++i) {
    (void)moreau::SimulateFesd(scene, options.fesd);
    (void)moreau::SimulateRadau(smooth, options.radau);
  }
  const moreau::FesdResult fesd = MeasuredFesdRun(scene, options.fesd);
  const moreau::RadauResult radau = MeasuredRadauRun(smooth, options.radau);
  if (fesd.status != moreau::FesdStatus::kSuccess || radau.stats.num_steps == 0) {
    std::fprintf(stderr, "a run failed: %s\n", fesd.message.c_str());
    return 1;
  }
  std::printf("fesd_elements=%ld radau_steps=%ld\n", fesd.stats.num_elements,
              radau.stats.num_steps);
  return 0;
}
