// FESD's cost per element against smooth Radau IIA elements of the same size, in instructions:
// the pairs of BM_FesdElementRatio (fesd_bench.cpp, the same options and smooth parts), one
// steady run of each (after warm-up runs: set-up included, first-run costs such as lazily made
// tableaus not) in functions of their own for callgrind's --toggle-collect. The counts do not
// depend on the machine's load, unlike the CPU times of fesd_bench.
//
//   scripts/bench-element-cost   (F1 and S3, s = 2 and 3, under callgrind; prints the ratios)
//   valgrind --tool=callgrind --toggle-collect='MeasuredFesdRun*'
//     --toggle-collect='MeasuredRadauRun*' build/release/bench/element_cost F1 2   (one line)
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
  if (argc != 3) {
    std::fprintf(stderr, "usage: element_cost <scene> <stages>\n");
    return 2;
  }
  const moreau::Scene scene = moreau::MakeScene(argv[1]);
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
