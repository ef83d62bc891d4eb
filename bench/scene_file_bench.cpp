// Scene-file model functions against the compiled lambdas of the same scenes: value and
// Jacobian per evaluation, and a whole FESD run (s = 3, h = 0.1). Targets (issue "Scene
// files"): at most 2x per evaluation, at most 1.3x per FESD run.
//
//   build/release/bench/scene_file_bench --benchmark_repetitions=5
//   (with --benchmark_report_aggregates_only=true for the medians only)
#include <benchmark/benchmark.h>

#include <string>

#include "moreau/integrators/fesd.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {

const char* const kScenes[] = {"F1", "S3", "H1"};

moreau::Scene SceneOf(int index, bool from_file) {
  const std::string name = kScenes[index];
  return from_file
             ? moreau::LoadScene(std::string(MOREAU_EXAMPLES_DIR) + "/scenes/" + name + ".toml")
             : moreau::MakeScene(name);
}

// The function each scene's Newton iterations evaluate most: F1's switching-mode field, S3's
// and H1's smooth dynamics or relay field.
const moreau::SmoothFunction& Hot(const moreau::Scene& scene) {
  if (const auto* sw = std::get_if<moreau::SwitchingSurfaces>(&scene.effects[0])) {
    return sw->modes[1];
  }
  if (const auto* relay = std::get_if<moreau::HysteresisRelay>(&scene.effects[0])) {
    return relay->mode_a;
  }
  return scene.dynamics;
}

void Evaluate(benchmark::State& state, bool from_file, bool jacobian) {
  const moreau::Scene scene = SceneOf(static_cast<int>(state.range(0)), from_file);
  const moreau::SmoothFunction f = Hot(scene);
  const moreau::Vector x = scene.initial_state.array() + 0.1;
  const moreau::Vector u = scene.InputValues(0.0), p = scene.ParameterValues();
  moreau::Vector out;
  moreau::Matrix jac;
  for (auto _ : state) {
    if (jacobian) {
      f.Jacobian(x, u, 0.3, p, moreau::Wrt::XT(), &out, &jac);
    } else {
      f.Evaluate(x, u, 0.3, p, &out);
    }
    benchmark::DoNotOptimize(out.data());
  }
  state.SetLabel(std::string(kScenes[state.range(0)]) + (from_file ? " file" : " compiled"));
}
void BM_ValueCompiled(benchmark::State& s) { Evaluate(s, false, false); }
void BM_ValueFile(benchmark::State& s) { Evaluate(s, true, false); }
void BM_JacobianCompiled(benchmark::State& s) { Evaluate(s, false, true); }
void BM_JacobianFile(benchmark::State& s) { Evaluate(s, true, true); }

void Fesd(benchmark::State& state, bool from_file) {
  const moreau::Scene scene = SceneOf(static_cast<int>(state.range(0)), from_file);
  moreau::FesdOptions options;
  options.record_trajectory = false;
  for (auto _ : state) {
    const moreau::FesdResult result = moreau::SimulateFesd(scene, options);
    if (result.status != moreau::FesdStatus::kSuccess) state.SkipWithError(result.message.c_str());
    benchmark::DoNotOptimize(result.final_state.data());
  }
  state.SetLabel(std::string(kScenes[state.range(0)]) + (from_file ? " file" : " compiled"));
}
void BM_FesdCompiled(benchmark::State& s) { Fesd(s, false); }
void BM_FesdFile(benchmark::State& s) { Fesd(s, true); }

BENCHMARK(BM_ValueCompiled)->DenseRange(0, 2);
BENCHMARK(BM_ValueFile)->DenseRange(0, 2);
BENCHMARK(BM_JacobianCompiled)->DenseRange(0, 2);
BENCHMARK(BM_JacobianFile)->DenseRange(0, 2);
BENCHMARK(BM_FesdCompiled)->DenseRange(0, 2)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_FesdFile)->DenseRange(0, 2)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
