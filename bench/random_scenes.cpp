// The random-scene campaign of differential testing (docs/differential-testing.md,
// scripts/bench-random-scenes): scenes from seeds first .. first + count - 1, each run with the
// default settings and compared with its reference; prints the counts (agree, honest failure,
// silent disagreement, no reference), per family, and every scene that did not agree.
#include "../tests/random/random_scenes.hpp"

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <map>
#include <string>

int main(int argc, char** argv) {
  using namespace moreau::testing;
  CLI::App app{"random-scene campaign: defaults against an independent reference"};
  long count = 10000;
  long first = 1;
  bool print_scenes = false;
  app.add_option("--count", count, "number of scenes")->check(CLI::PositiveNumber);
  app.add_option("--first", first, "first seed")->check(CLI::PositiveNumber);
  app.add_flag("--print-scenes", print_scenes,
               "print the scene file of every scene that did not "
               "agree");
  CLI11_PARSE(app, argc, argv);
  const auto start = std::chrono::steady_clock::now();
  std::map<Verdict, long> counts;
  std::map<std::string, std::map<Verdict, long>> by_family;
  double worst_agreeing = 0.0;
  for (long seed = first; seed < first + count; ++seed) {
    const RandomScene scene = GenerateRandomScene(static_cast<std::uint64_t>(seed));
    const Comparison comparison = CompareWithReference(scene);
    ++counts[comparison.verdict];
    ++by_family[scene.families][comparison.verdict];
    if (comparison.verdict == Verdict::kAgree) {
      worst_agreeing = std::max(worst_agreeing, comparison.error);
      continue;
    }
    std::printf("seed %ld (%s, tau %.3g): %s: %s\n", seed, scene.families.c_str(), scene.time_scale,
                ToString(comparison.verdict).c_str(), comparison.detail.c_str());
    if (print_scenes) std::printf("%s\n", scene.toml.c_str());
    std::fflush(stdout);
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("\n%-28s %8s %8s %8s %8s\n", "family", "agree", "honest", "silent", "no ref");
  for (const auto& [family, c] : by_family) {
    auto get = [&c](Verdict v) { return c.count(v) ? c.at(v) : 0L; };
    std::printf("%-28s %8ld %8ld %8ld %8ld\n", family.c_str(), get(Verdict::kAgree),
                get(Verdict::kHonestFailure), get(Verdict::kSilentDisagreement),
                get(Verdict::kNoReference));
  }
  auto total = [&counts](Verdict v) { return counts.count(v) ? counts.at(v) : 0L; };
  std::printf("%-28s %8ld %8ld %8ld %8ld\n", "all", total(Verdict::kAgree),
              total(Verdict::kHonestFailure), total(Verdict::kSilentDisagreement),
              total(Verdict::kNoReference));
  std::printf(
      "\nscenes %ld (seeds %ld..%ld): agree %ld, honest failure %ld, silent disagreement "
      "%ld, no reference %ld; largest agreeing error %.2e (bound %.0e); %.1f s\n",
      count, first, first + count - 1, total(Verdict::kAgree), total(Verdict::kHonestFailure),
      total(Verdict::kSilentDisagreement), total(Verdict::kNoReference), worst_agreeing, kAgreement,
      seconds);
  return total(Verdict::kSilentDisagreement) == 0 ? 0 : 1;
}
