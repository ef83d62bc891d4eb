// Right by default (docs/accuracy.md): every built-in scene (moreau::SceneCatalog) and every
// file in examples/scenes/, run through moreau::Simulate with no options (the automatic
// integrator, its default tolerances and the scene's own [defaults]), meets kAccuracy against a
// tight reference solution, or returns a non-success status with its reason, and then it is
// one of kScenesWithStatus (the list docs/accuracy.md publishes; the goal is none).
//
// The references (tests/data/default_references.json) were computed once by
// make_default_references (tests/integrators/default_references.cpp; the command is in the
// file), each cross-checked against an independent solution (IDA at its reference settings or
// a closed form) to 1e-8.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// What a run with no options must achieve: x(T) within this of the reference, relative to
// each state's scale (the largest |x_i| along the reference trajectory, with the floor below),
// and every event time within this of the reference's, relative to the horizon.
constexpr double kAccuracy = 1e-5;
// States whose scale is below this fraction of the largest state scale are measured against
// that fraction (a state that stays at zero has no scale of its own).
constexpr double kScaleFloor = 1e-6;

// Scenes whose default run ends with a non-success status (docs/accuracy.md lists them with
// their reasons; the goal is none). A scene listed here needs no reference: the test asks its
// default run for a non-success status with a message, and fails once it succeeds (then it
// needs a reference). D2: the robot meets obs1 at t = 2.83 at a rate of 0.23 m/s that only a
// jump of its velocity could cancel, and the algebraic inputs act on V' and theta' (index 3
// met at a nonzero rate: no solution without look-ahead once the steps are short).
const std::set<std::string> kScenesWithStatus = {"D2"};

// Scenes not checked here, with the reason; docs/accuracy.md names them. The crowd's default
// run (100 discs, about 2.5 s of CPU in the release build) takes minutes under ASan and
// UBSan, beyond the sanitizer build's share of the test budget: it is checked in the release
// build only.
const std::map<std::string, std::string> kScenesUnchecked =
    MOREAU_SANITIZED
        ? std::map<std::string, std::string>{{"crowd",
                                              "sanitizer build: the default run takes minutes "
                                              "there; checked in the release build"}}
        : std::map<std::string, std::string>{};

// Event kinds left out of the comparison: 'ambiguous' reports a point where the solution is
// not unique (after hard_zeno's accumulation point), and how often it is reported depends on
// the steps.
const std::set<std::string> kUncomparedEventKinds = {"ambiguous"};

struct ReferenceEvent {
  double t = 0.0;
  std::string kind, what;
};

struct SceneReference {
  std::string name, source, integrator;
  bool checked = true;
  std::string reason;  // without a reference: why
  double final_time = 0.0;
  Vector final_state, scale;
  std::vector<ReferenceEvent> events;
};

Vector ToVector(const nlohmann::json& list) {
  Vector v(static_cast<Eigen::Index>(list.size()));
  for (std::size_t i = 0; i < list.size(); ++i) v[static_cast<Eigen::Index>(i)] = list[i];
  return v;
}

std::vector<SceneReference> LoadReferences() {
  std::ifstream in(MOREAU_TESTS_DIR "/data/default_references.json");
  EXPECT_TRUE(in.good()) << "cannot read tests/data/default_references.json";
  const nlohmann::json data = nlohmann::json::parse(in);
  std::vector<SceneReference> references;
  for (const nlohmann::json& entry : data.at("scenes")) {
    SceneReference r;
    r.name = entry.at("name");
    r.source = entry.at("source");
    if (entry.at("reference").is_null()) {
      r.checked = false;
      r.reason = entry.at("reason");
      references.push_back(std::move(r));
      continue;
    }
    r.integrator = entry.at("integrator");
    r.final_time = entry.at("final_time");
    r.final_state = ToVector(entry.at("final_state"));
    r.scale = ToVector(entry.at("scale"));
    for (const nlohmann::json& event : entry.at("events")) {
      r.events.push_back({event.at(0), event.at(1), event.at(2)});
    }
    references.push_back(std::move(r));
  }
  return references;
}

const std::vector<SceneReference>& References() {
  static const std::vector<SceneReference> references = LoadReferences();
  return references;
}

Scene MakeReferenceScene(const SceneReference& reference) {
  if (reference.source == "catalog") return MakeScene(reference.name);
  return LoadScene(std::string(MOREAU_EXAMPLES_DIR) + "/scenes/" + reference.name);
}

// Every scene has a reference: a new scene needs one (make_default_references).
TEST(DefaultAccuracy, EveryCatalogSceneAndExampleFileHasAReference) {
  std::set<std::string> covered;
  for (const SceneReference& r : References()) covered.insert(r.name);
  for (const SceneDefinition& definition : SceneCatalog()) {
    EXPECT_TRUE(covered.count(definition.name) > 0)
        << "built-in scene '" << definition.name
        << "' has no reference in tests/data/default_references.json (regenerate it: the "
           "command is in the file)";
  }
  for (const auto& file :
       std::filesystem::directory_iterator(std::string(MOREAU_EXAMPLES_DIR) + "/scenes")) {
    if (file.path().extension() != ".toml") continue;
    EXPECT_TRUE(covered.count(file.path().filename().string()) > 0)
        << "scene file '" << file.path().filename().string() << "' has no reference";
  }
}

class DefaultAccuracyTest : public ::testing::TestWithParam<std::size_t> {};

// The scenes without a reference are documented ones.
TEST(DefaultAccuracy, ScenesWithoutReferenceAreDocumented) {
  for (const SceneReference& r : References()) {
    if (!r.checked) {
      EXPECT_TRUE(kScenesUnchecked.count(r.name) > 0 || kScenesWithStatus.count(r.name) > 0)
          << r.name << " has no reference (" << r.reason
          << ") and is in neither kScenesUnchecked nor kScenesWithStatus";
    }
  }
}

TEST_P(DefaultAccuracyTest, NoOptionsMeetsTheAccuracyOrSaysWhy) {
  const SceneReference& reference = References()[GetParam()];
  if (const auto it = kScenesUnchecked.find(reference.name); it != kScenesUnchecked.end()) {
    GTEST_SKIP() << reference.name << ": not checked (" << it->second << ")";
  }
  const Scene scene = MakeReferenceScene(reference);
  const SimulationResult result = Simulate(scene, SimulationSettings{});
  if (!reference.checked) {
    // Listed with a status (ScenesWithoutReferenceAreDocumented): it must still end with one.
    EXPECT_FALSE(result.success)
        << reference.name
        << " now succeeds: compute its reference (make_default_references) "
           "and remove it from kScenesWithStatus and the docs";
    EXPECT_FALSE(result.message.empty()) << "a non-success status must say why";
    return;
  }
  EXPECT_EQ(result.integrator, reference.integrator);
  if (!result.success) {
    EXPECT_FALSE(result.message.empty()) << "a non-success status must say why";
    EXPECT_TRUE(kScenesWithStatus.count(reference.name) > 0)
        << reference.name << " returned " << result.status << " (" << result.message
        << "); list it in kScenesWithStatus and docs/accuracy.md, or fix it";
    return;
  }
  EXPECT_TRUE(kScenesWithStatus.count(reference.name) == 0)
      << reference.name << " now succeeds: remove it from kScenesWithStatus and the docs";
  EXPECT_EQ(result.final_time, reference.final_time) << "the run must end exactly at tf";
  const double floor = kScaleFloor * std::max(reference.scale.maxCoeff(), 1e-300);
  for (Eigen::Index i = 0; i < reference.final_state.size(); ++i) {
    const double scale = std::max(reference.scale[i], floor);
    EXPECT_LE(std::fabs(result.final_state[i] - reference.final_state[i]), kAccuracy * scale)
        << reference.name << ": x(T) of state " << scene.state_names[static_cast<std::size_t>(i)]
        << " = " << result.final_state[i] << ", reference " << reference.final_state[i]
        << ", scale " << scale;
  }
  // Events, per (kind, what) in time order: the same number, each time within kAccuracy of
  // the horizon.
  const double horizon = scene.final_time - scene.initial_time;
  std::map<std::pair<std::string, std::string>, std::vector<double>> expected, actual;
  for (const ReferenceEvent& e : reference.events) {
    if (kUncomparedEventKinds.count(e.kind) == 0) expected[{e.kind, e.what}].push_back(e.t);
  }
  for (const Event& e : result.events) {
    const std::string kind = ToString(e.kind);
    if (kUncomparedEventKinds.count(kind) == 0) actual[{kind, e.what}].push_back(e.t);
  }
  EXPECT_EQ(actual.size(), expected.size()) << reference.name << ": other kinds of events";
  for (const auto& [key, times] : expected) {
    const std::vector<double>& found = actual[key];
    ASSERT_EQ(found.size(), times.size())
        << reference.name << ": events " << key.first << " " << key.second;
    for (std::size_t k = 0; k < times.size(); ++k) {
      EXPECT_LE(std::fabs(found[k] - times[k]), kAccuracy * horizon)
          << reference.name << ": event " << key.first << " " << key.second << " #" << k;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Scenes, DefaultAccuracyTest,
                         ::testing::Range<std::size_t>(0, References().size()),
                         [](const ::testing::TestParamInfo<std::size_t>& param) {
                           std::string name = References()[param.param].name;
                           std::replace_if(
                               name.begin(), name.end(),
                               [](char c) { return !std::isalnum(static_cast<unsigned char>(c)); },
                               '_');
                           return name;
                         });

}  // namespace
}  // namespace moreau
