// make_default_references: the tight reference solutions that tests/integrators/
// default_accuracy_test.cpp compares every built-in scene and every file in examples/scenes/
// with, run with no options (docs/accuracy.md). Not a test: it runs for minutes. Regenerate
// after a change of a scene (the test names a scene without a reference):
//
//   build/release/tests/make_default_references examples/scenes >
//   tests/data/default_references.json
//
// (names after the directory restrict it to those scenes, to regenerate one entry). A scene
// without a reference (its tight runs failed, or kTooExpensive) is written with
// "reference": null and the reason, and the test lists it as unchecked.
// Per scene, the reference is the default integrator run far tighter than its defaults (FESD
// rtol 1e-11 with s = 4, order 7; smooth Radau IIA rtol 1e-12 with s = 5, order 9; the alpha
// stepper at rtol 1e-8, or where that fails its order-2 steps at two small step sizes,
// Richardson-extrapolated), cross-checked
// against an independent solution where one exists (IDA at its reference settings, or a closed
// form): their largest difference, relative to each state's scale, is stored with the
// reference, and the program refuses to write a reference that its check contradicts
// (kAgreement). Events (time, kind, what) are those of the reference run.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {

using moreau::Scene;
using moreau::SimulationResult;
using moreau::Vector;

// Two independent tight solutions must agree to this, relative to each state's scale (with
// the floor below), for the reference to be written: 1000 times below the accuracy the test
// asks of the defaults (1e-5), so that the reference's own error does not matter there.
constexpr double kAgreement = 1e-8;
// States whose scale is below this fraction of the largest state scale are measured against
// that fraction (a state that stays at zero has no scale of its own).
constexpr double kScaleFloor = 1e-6;

struct Reference {
  std::string method;
  SimulationResult result;
  Vector final_state;
  Vector scale;  // per state: the largest |x_i| along the reference trajectory
};

Vector Scale(const moreau::Trajectory& trajectory, const Vector& final_state) {
  Vector scale = final_state.cwiseAbs();
  for (const Vector& x : trajectory.x) scale = scale.cwiseMax(x.cwiseAbs());
  return scale;
}

double RelativeDifference(const Vector& a, const Vector& b, const Vector& scale) {
  const double floor = kScaleFloor * std::max(scale.maxCoeff(), 1e-300);
  double worst = 0.0;
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    worst = std::max(worst, std::fabs(a[i] - b[i]) / std::max(scale[i], floor));
  }
  return worst;
}

SimulationResult Run(const Scene& scene, const std::string& integrator,
                     std::map<std::string, moreau::SettingValue> options) {
  moreau::SimulationSettings settings;
  settings.integrator = integrator;
  settings.options = std::move(options);
  return moreau::Simulate(scene, settings);
}

// The alpha stepper's order-2 steps at h and h/2, extrapolated: x = (4 x_{h/2} - x_h) / 3,
// with h = (tf - t0)/n for the first n of kAlphaDivisions whose two runs succeed (the stepper's
// regularization can fail at particular step sizes near rank-deficient contacts).
constexpr double kAlphaDivisions[] = {4096.0, 3000.0, 2048.0, 6000.0};

// First the stepper's own error control far tighter than its default (rtol 1e-8): fixed steps
// cross a constraint's activation with an O(h) error that Richardson extrapolation does not
// remove (dai_index2: 5e-5 at n = 3000).
constexpr double kAlphaReferenceTolerance = 1e-8;

Reference AlphaReference(const Scene& scene) {
  const double horizon = scene.final_time - scene.initial_time;
  std::string failures;
  const SimulationResult controlled =
      Run(scene, "alpha", {{"rtol", kAlphaReferenceTolerance}, {"record_trajectory", true}});
  if (controlled.success) {
    Reference reference;
    reference.method = "alpha, rtol 1e-8 (error-controlled)";
    reference.result = controlled;
    reference.final_state = controlled.final_state;
    reference.scale = Scale(controlled.trajectory, reference.final_state);
    return reference;
  }
  failures += " rtol 1e-8: " + controlled.status + ";";
  for (double n : kAlphaDivisions) {
    const double h = horizon / n;
    const SimulationResult coarse = Run(scene, "alpha",
                                        {{"h", h},
                                         {"max_steps", 10'000'000L},
                                         {"record_trajectory", false},
                                         {"estimate_error", false}});
    const SimulationResult fine = Run(scene, "alpha",
                                      {{"h", 0.5 * h},
                                       {"max_steps", 10'000'000L},
                                       {"record_trajectory", true},
                                       {"estimate_error", false}});
    if (!coarse.success || !fine.success) {
      failures += " n = " + std::to_string(static_cast<long>(n)) + ": " +
                  (coarse.success ? fine.status : coarse.status) + ";";
      continue;
    }
    Reference reference;
    reference.method = "alpha, h = (tf - t0)/" + std::to_string(static_cast<long>(n)) +
                       " and half of it, Richardson-extrapolated (order 2)";
    reference.result = fine;
    reference.final_state = (4.0 * fine.final_state - coarse.final_state) / 3.0;
    reference.scale = Scale(fine.trajectory, reference.final_state);
    return reference;
  }
  throw std::runtime_error("alpha reference failed at every step size:" + failures);
}

Reference TightReference(const Scene& scene, const std::string& integrator) {
  Reference reference;
  if (integrator == "fesd") {
    reference.method = "fesd, rtol 1e-11, s = 4";
    reference.result = Run(scene, "fesd", {{"rtol", 1e-11}, {"stages", 4L}});
  } else if (integrator == "radau") {
    reference.method = "radau, rtol 1e-12, s = 5";
    reference.result = Run(scene, "radau", {{"rtol", 1e-12}, {"stages", 5L}});
  } else if (integrator == "alpha") {
    return AlphaReference(scene);
  } else {
    throw std::runtime_error("no reference method for integrator " + integrator);
  }
  if (!reference.result.success) {
    throw std::runtime_error(reference.method + " failed: " + reference.result.message);
  }
  reference.final_state = reference.result.final_state;
  reference.scale = Scale(reference.result.trajectory, reference.final_state);
  return reference;
}

// Closed forms of the DAI scenes (their descriptions): x(T) from the scene's own values.
bool ClosedForm(const Scene& scene, Vector* x) {
  const double t = scene.final_time - scene.initial_time;
  if (scene.name == "dai_index2") {
    // The default objective (u = w = 0 unless the floor x2 >= sin x1 needs u): from x1(0) = 4
    // the floor falls away, x2 and x3 stay (x3' = -x3 with x3(0) = 0) until sin x1 climbs back
    // to x2(0) = sin x1(0) at x1 = 3 pi - x1(0); from there x2 = sin x1, u = cos x1 and
    // x3 = (cos x1 + sin x1)/2 + c e^{-(t - t1)}. Valid for the scene's x1(0) in (pi, 3 pi/2)
    // and x1(T) in [3 pi/2, 2 pi] (checked).
    const Vector& x0 = scene.initial_state;
    const double pi = std::numbers::pi;
    const double x1 = x0[0] + t;
    const double entry = 3.0 * pi - x0[0];  // x1 where the floor is active again
    if (!(x0[0] > pi && x0[0] < 1.5 * pi && x1 >= entry && x1 <= 2.0 * pi &&
          x0[1] == std::sin(x0[0]))) {
      return false;
    }
    const double x3_entry = x0[2] * std::exp(-(entry - x0[0]));
    *x = Vector{
        {x1, std::sin(x1),
         0.5 * (std::cos(x1) + std::sin(x1)) +
             (x3_entry - 0.5 * (std::cos(entry) + std::sin(entry))) * std::exp(-(x1 - entry))}};
    return true;
  }
  if (scene.name == "hard_index3") {
    const double a = scene.parameters[static_cast<std::size_t>(scene.FindParameter("A"))].value;
    const double w = scene.parameters[static_cast<std::size_t>(scene.FindParameter("omega"))].value;
    *x = Vector{{a * std::sin(w * t), a * w * std::cos(w * t)}};
    return true;
  }
  return false;
}

nlohmann::json Entry(const std::string& name, const std::string& source, const Scene& scene) {
  const std::string integrator = moreau::AutomaticIntegrator(scene);
  const Reference reference = TightReference(scene, integrator);
  nlohmann::json entry;
  entry["name"] = name;
  entry["source"] = source;
  entry["integrator"] = integrator;
  entry["reference"] = reference.method;
  // The independent check.
  Vector closed;
  std::string check = "none (no independent solution)";
  double agreement = -1.0;
  if (ClosedForm(scene, &closed)) {
    agreement = RelativeDifference(reference.final_state, closed, reference.scale);
    check = "closed form";
  } else {
    const std::vector<std::string> supporting = moreau::IntegratorsSupporting(scene);
    if (std::find(supporting.begin(), supporting.end(), "ida") != supporting.end()) {
      const moreau::IdaResult ida = moreau::SimulateIda(scene, moreau::IdaOptions::Reference());
      if (ida.status == moreau::IdaStatus::kSuccess) {
        agreement = RelativeDifference(reference.final_state, ida.final_state, reference.scale);
        check = "ida, rtol 1e-12";
      } else {
        check = "ida failed (" + ida.message + ")";
      }
    }
  }
  if (agreement > kAgreement) {
    throw std::runtime_error(name + ": the reference (" + reference.method + ") and its check (" +
                             check + ") differ by " + std::to_string(agreement));
  }
  entry["check"] = check;
  entry["agreement"] = agreement;
  entry["final_time"] = reference.result.final_time;
  entry["final_state"] = std::vector<double>(
      reference.final_state.data(), reference.final_state.data() + reference.final_state.size());
  entry["scale"] =
      std::vector<double>(reference.scale.data(), reference.scale.data() + reference.scale.size());
  nlohmann::json events = nlohmann::json::array();
  for (const moreau::Event& event : reference.result.events) {
    events.push_back({event.t, moreau::ToString(event.kind), event.what});
  }
  entry["events"] = events;
  return entry;
}

// A scene whose reference cannot be computed (or whose default run is too expensive to check
// in the test suite) gets an entry with "reference": null and the reason: the test lists it.
nlohmann::json Unchecked(const std::string& name, const std::string& source,
                         const std::string& reason) {
  nlohmann::json entry;
  entry["name"] = name;
  entry["source"] = source;
  entry["reference"] = nullptr;
  entry["reason"] = reason;
  return entry;
}

// Built-in scenes whose default run takes minutes: not checked by the test (the reason is
// recorded); docs/accuracy.md names them.
const std::map<std::string, std::string> kTooExpensive = {
    {"crowd",
     "100 discs: the default error-controlled FESD run takes about 22 s of CPU (fixed h = 0.1: "
     "5 s), minutes under the sanitizers, and a reference far longer: too long for the test "
     "suite"},
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(
        stderr, "usage: make_default_references EXAMPLES_SCENES_DIR [NAME...] > references.json\n");
    return 2;
  }
  const std::set<std::string> only(argv + 2, argv + argc);
  auto wanted = [&only](const std::string& name) { return only.empty() || only.count(name) > 0; };
  nlohmann::json scenes = nlohmann::json::array();
  auto add = [&scenes](const std::string& name, const std::string& source, const auto& make) {
    std::fprintf(stderr, "%s\n", name.c_str());
    if (const auto it = kTooExpensive.find(name); it != kTooExpensive.end()) {
      scenes.push_back(Unchecked(name, source, it->second));
      return;
    }
    try {
      scenes.push_back(Entry(name, source, make()));
    } catch (const std::exception& error) {
      std::fprintf(stderr, "  no reference: %s\n", error.what());
      scenes.push_back(Unchecked(name, source, error.what()));
    }
  };
  for (const moreau::SceneDefinition& definition : moreau::SceneCatalog()) {
    if (wanted(definition.name)) add(definition.name, "catalog", definition.make);
  }
  std::vector<std::filesystem::path> files;
  for (const auto& file : std::filesystem::directory_iterator(argv[1])) {
    if (file.path().extension() == ".toml") files.push_back(file.path());
  }
  std::sort(files.begin(), files.end());
  for (const auto& file : files) {
    const std::string name = file.filename().string();
    if (!wanted(name)) continue;
    add(name, "examples/scenes/" + name, [&file] { return moreau::LoadScene(file.string()); });
  }
  nlohmann::json out;
  out["command"] =
      "build/release/tests/make_default_references examples/scenes > "
      "tests/data/default_references.json";
  out["agreement_required"] = kAgreement;
  out["scenes"] = scenes;
  std::cout << out.dump(1) << "\n";
  return 0;
}
