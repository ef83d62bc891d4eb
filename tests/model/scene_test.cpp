#include "moreau/model/scene.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Expects std::invalid_argument whose message contains `fragment`.
template <class F>
void ExpectInvalid(F f, const std::string& fragment) {
  try {
    f();
    FAIL() << "expected std::invalid_argument containing '" << fragment << "'";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
        << "message: " << error.what();
  }
}

Scene MakeLinearScene() {
  Scene scene;
  scene.name = "linear";
  scene.state_names = {"a", "b"};
  scene.initial_state = Vector{{1.0, 2.0}};
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 2.0, "rate");
  scene.dynamics = MakeSmoothFunction(
      "linear.f", 2, [k](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = -p[k] * x[0];
        out[1] = x[0] - x[1];
      });
  return scene;
}

TEST(SceneTest, ValidSceneAndCatalogScenesPass) {
  EXPECT_NO_THROW(ValidateScene(MakeLinearScene()));
  for (const SceneDefinition& definition : SceneCatalog()) {
    EXPECT_NO_THROW(ValidateScene(definition.make())) << definition.name;
  }
}

TEST(SceneTest, DimensionMismatchIsAClearError) {
  Scene scene = MakeLinearScene();
  scene.initial_state = Vector{{1.0, 2.0, 3.0}};
  ExpectInvalid([&] { ValidateScene(scene); }, "initial state has 3 entries, expected 2");

  scene = MakeLinearScene();
  scene.dynamics = MakeSmoothFunction(
      "bad.f", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0];
        out[1] = x[2];  // reads a third state that does not exist
      });
  ExpectInvalid([&] { ValidateScene(scene); }, "reads x[2], but x has 2 components");

  scene = MakeLinearScene();
  scene.dynamics = MakeSmoothFunction(
      "short.f", 3, [](const auto&, const auto&, const auto&, const auto&, auto&) {});
  ExpectInvalid([&] { ValidateScene(scene); }, "must have 2 outputs, got 3");
}

TEST(SceneTest, NonFiniteInitialStateIsAClearError) {
  Scene scene = MakeLinearScene();
  scene.initial_state[1] = std::numeric_limits<double>::quiet_NaN();
  ExpectInvalid([&] { ValidateScene(scene); }, "initial state x0.b is not finite");
}

TEST(SceneTest, NonPositiveHorizonIsAClearError) {
  Scene scene = MakeLinearScene();
  scene.final_time = -1.0;
  ExpectInvalid([&] { ValidateScene(scene); }, "horizon must be positive");
  scene.final_time = 0.0;
  ExpectInvalid([&] { ValidateScene(scene); }, "horizon must be positive");
}

TEST(SceneTest, OverridesByNameAndUnknownNames) {
  Scene scene = MakeLinearScene();
  SetSceneValue(&scene, "k", 5.0);
  SetSceneValue(&scene, "x0.b", -1.0);
  SetSceneValue(&scene, "tf", 3.0);
  EXPECT_EQ(scene.parameters[0].value, 5.0);
  EXPECT_EQ(scene.initial_state[1], -1.0);
  EXPECT_EQ(scene.final_time, 3.0);
  ExpectInvalid([&] { SetSceneValue(&scene, "omega", 1.0); },
                "has no value named 'omega'; valid names: tf, x0.a, x0.b, k");
  ExpectInvalid([&] { SetSceneValue(&scene, "k", std::nan("")); }, "must be finite");
}

TEST(SceneTest, UnknownSceneListsTheCatalog) {
  ExpectInvalid([] { MakeScene("nope"); }, "unknown scene 'nope'; available scenes: hopf");
}

TEST(SceneTest, DuplicateNamesAreRejected) {
  Scene scene = MakeLinearScene();
  scene.state_names = {"a", "a"};
  ExpectInvalid([&] { ValidateScene(scene); }, "duplicate name 'a'");
}

TEST(SceneTest, PiecewiseConstantControlSignal) {
  PiecewiseConstantSignal signal{{1.0, 2.0}, {10.0, 20.0, 30.0}};
  EXPECT_EQ(signal.ValueAt(0.5), 10.0);
  EXPECT_EQ(signal.ValueAt(1.0), 20.0);  // right-continuous
  EXPECT_EQ(signal.ValueAt(2.5), 30.0);
}

}  // namespace
}  // namespace moreau
